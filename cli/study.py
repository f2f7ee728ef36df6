"""``mdaug run``: the whole study (calibrate, augment two ways, classify, compare, report).

The whole configuration is checked (types, names, sizes, files) before the output
folder is created; progress shows one bar of the study's stages, with each stage's
own bar (calibration, sweep cells, CNN epochs) below it.
"""
from __future__ import annotations

from pathlib import Path

from .common import add_verb, format_table, info, positive_int, result, seed_int, warn


WORKER_BYTES = 300 * 2 ** 20  # a worker process with numpy, scikit-learn and torch loaded, at least


class StageProgress:
    """Listener of the study's stage cache: one bar over the stages, with an ETA."""

    def __init__(self, names: list[str]):
        from ..radar.progress import progress_bar

        self.bar = progress_bar(total=len(names), desc="study stages", unit="stage")
        self.done: set[str] = set()

    def stage_started(self, name: str) -> None:
        self.bar.set_postfix_str(name)

    def stage_finished(self, name: str, seconds: float, cached: bool) -> None:
        if name not in self.done:
            self.done.add(name)
            self.bar.set_postfix_str(f"{name} {'cached' if cached else f'{seconds:.0f} s'}", refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def _fmt(v, spec=".3f") -> str:
    return "-" if v is None else format(v, spec)


def summary(results: dict) -> str:
    """The final table of ``mdaug run``: each strategy's CNN on the selection set and the
    main test set, the choice, the separability ceiling, and the calibration."""
    classes = list(results["config"]["classes"])
    sel = results["selection"]["set"]
    rows = []

    def row(name, test, m):
        lo, hi = (m.get("ci") or {}).get("balanced_accuracy") or (None, None)
        ci = "-" if lo is None else f"[{lo:.3f}, {hi:.3f}]"
        recalls = [(m["per_class"].get(c) or {}).get("recall") for c in classes]
        rows.append([name, test, str(m.get("n", "")), _fmt(m.get("balanced_accuracy")), ci,
                     *(_fmt(r, ".2f") for r in recalls)])

    b = results.get("best_strategy") or {}
    best = b.get("tied") or ([b["name"]] if b.get("name") else [])  # the choice, or the strategies tied
    for name, s in results["strategies"].items():
        tests = s["tests"]
        test = "new" if "new" in tests else next(t for t in tests if t != sel)
        setting = next((f" ({k} {s[k]:g})" for k in ("sigma_p", "width") if s.get(k) is not None), "")
        row(f"CNN {name}{setting}{' *' if name in best else ''}", test, tests[test])
    for model, c in ((results.get("ceiling") or {}).get("models") or {}).items():
        tests = c["tests"]
        test = "new" if "new" in tests else next(iter(tests))
        row(f"ceiling {model}", test, tests[test])
    table = format_table(["strategy", "test", "n", "balanced acc.", "95% CI", *(f"recall {c}" for c in classes)],
                         rows, ["<", "<", ">", ">", "<", *(">" for _ in classes)])
    lines = [table, f"* the best strategy on the selection set '{sel}' ({results['selection']['what']})"
             + (" (tied)" if len(best) > 1 else "") + "; mean over each CNN's training runs", ""]
    from ..inference.result.status import calibration_status

    for cls, r in results["calibration"].items():
        st = calibration_status(r)
        detail = f" ({st.convergence_detail or 'see the report'})" if not st.converged else ""
        lines.append(f"calibration {cls}: {st.headline}{detail}")
    return "\n".join(lines)


def check_study_ramps(cfg) -> None:
    """--ramps against time: the simulated campaign and the synthetic sets render K ramps."""
    from .common import SECONDS_FAST_RAMP, SECONDS_SCENE_RAMP, check_size, ramps_factor

    s, p = cfg.simulation, cfg.protocol
    frames = 11
    acquisitions = sum(s.n_calibration + s.n_select + n * (1 + s.large_factor) for n in s.n_new.values())
    rendered = len(cfg.classes) * (p.cnn_n_per_class + p.sweep_n_per_class * len(p.sigma_p))
    check_size(ramps_factor("--ramps", cfg.scene_ramps), seconds_each=acquisitions * frames * SECONDS_SCENE_RAMP
               + rendered * SECONDS_FAST_RAMP, what="ramps per frame")


def invocation(args) -> str:
    """The ``mdaug run`` command line as it was run (its options, in a fixed order)."""
    import shlex

    parts = ["mdaug", "run"]
    for opt, value in (("--config", args.config), ("--out", args.out), ("--ramps", args.ramps),
                       ("--seed", args.seed), ("--workers", args.workers), ("--scheduler", args.scheduler),
                       ("--device", None if args.device == "auto" else args.device)):
        if value is not None:
            parts += [opt, str(value)]
    if args.quick:
        parts.insert(2, "--quick")
    if getattr(args, "threads", None) not in (None, 1):  # 1: the default
        parts += ["--threads", str(args.threads)]
    return shlex.join(parts)


def run_study(args) -> int:
    from ..reports.config import StudyConfig, load_config
    from ..reports.identity import (STUDY_FILES, check_not_in_use, check_study_folder, clear_study, remove_skeleton,
                                    snapshot, study_lock)

    from .guard import Output, check_paths

    check_paths(inputs=[("--config", args.config)],  # the study resumes: its folder's own rule (identity) decides
                outputs=[Output("--out", args.out, "folder", inside=STUDY_FILES, resumes=True)])
    out = Path(args.out)
    cfg = load_config(args.config) if args.config else StudyConfig()
    if args.seed is not None:
        cfg.seed = args.seed
    if args.workers is not None:
        from .common import check_size

        check_size(("--workers", args.workers, 1), bytes_each=WORKER_BYTES, what="worker processes")
        cfg.workers = args.workers
    if args.scheduler:
        cfg.scheduler = args.scheduler
    if args.device != "auto":
        from ..classify.cnn import resolve_device

        resolve_device(args.device)  # 'cuda' without a GPU: refused before the folder exists
        cfg.device = args.device
    if args.quick:
        cfg = cfg.quick_version()
    if args.ramps is not None:  # the config's ramps: the simulated scene's K, or that of files that do not say it
        cfg.ramps = args.ramps
        if cfg.simulated:
            check_study_ramps(cfg)
    cfg.validate()  # everything checked before the output folder exists
    from .study_sizes import check_study_sizes

    check_study_sizes(cfg)  # the config's sizes and its files', under the options' one bound
    data_files = [(f"[data] {group}.{name}", path) for group in ("calibration", "select", "test")
                  for name, path in (getattr(cfg.data, group) or {}).items()]
    check_paths(inputs=[("--config", args.config), *data_files],
                outputs=[Output("--out", out, "folder", inside=STUDY_FILES, resumes=True)])
    check_not_in_use(out)  # a folder another run is using: refused, never offered --overwrite
    from ..inference.sanity import shared_files

    for text in shared_files(cfg.data.calibration, cfg.data.test, str(cfg.source)):
        result(f"note: {text}")  # on stdout, always printed: stderr keeps its one line for errors and interrupts
    if check_study_folder(out, cfg, overwrite=args.overwrite):  # another study: refused, or replaced when asked
        clear_study(out)
        info(f"{out}: the other study's files were removed (--overwrite)")
    from ..reports.study import Study, stage_names

    before = snapshot(out)
    progress = StageProgress(stage_names(cfg))
    try:
        with study_lock(out):
            study = Study(cfg, out, log=info, invocation=invocation(args))
            study.cache.listener = progress
            results = study.run()
    except (ValueError, OSError, MemoryError):  # a refusal before the first stage leaves no skeleton behind
        remove_skeleton(out, before)
        raise
    finally:
        progress.close()
    result(f"\nstudy finished in {results['total_seconds']:.0f} s: {out / 'report.html'}, {out / 'results.json'}")
    result(summary(results))
    bad = [c for c, r in results["calibration"].items() if not r["converged"]]
    if bad:
        warn("run", f"calibration of {', '.join(bad)}: NOT converged (see the report's diagnostics)")
    return 0


def _interrupted(args) -> str:
    return (f"finished stages are kept in {Path(args.out) / 'stages'}; run the same command again to resume")


def add_run(sub, parents, help):
    p = add_verb(sub, "run", parents, help=help, interrupted=_interrupted,
                 overwrite="when --out holds another study (other data, seed, classes or scene), remove its files "
                           "and run this one (default: refuse; the same study always resumes)",
                 description="Calibrate each class, synthesise training sets (sigma_P and posterior), train the "
                             "classifiers and the CNN, compare against tsaug, report. The configuration is checked "
                             "in full before the output folder is created; an interrupted run resumes from "
                             "OUT/stages.")
    p.add_argument("--config", type=Path, default=None,
                   help="study TOML with sections [data], [protocol], [simulation] (default: the embedded "
                        "simulated scene)")
    p.add_argument("--out", type=Path, default=Path("mdaug-study"),
                   help="output folder, created if needed (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="small sizes: a run of one to two minutes")
    p.add_argument("--ramps", type=positive_int, default=None, metavar="K",
                   help="the study's K, ramps per frame: of the simulated campaign (default: the config's, 32; 4 "
                        "gives the 4-ramp campaign), or of measured files that do not state ramps_per_frame (one "
                        "that states another K is refused)")
    p.add_argument("--seed", type=seed_int, default=None, help="the study's one seed (default: the config's, 0)")
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="local worker processes for independent jobs: the classes' calibrations, the strategies' "
                        "CNNs (default: the config's, 2; the results do not depend on it)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="dask.distributed scheduler address, or 'local' to start a LocalCluster (default: none)")
    from .options import add_device_option

    add_device_option(p)
    p.set_defaults(func=run_study)
    return p


VERBS = {
    "run": ("run the whole study and write results.json + report.html", add_run),
}
