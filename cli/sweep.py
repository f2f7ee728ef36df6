"""``mdaug sweep``: the published sigma_P protocol (:mod:`mdaug.classify.protocol`) on
synthetic training sets of the strategy registry's ``sigma_p_published``
(:class:`SyntheticTrainSet`; mdaug.classify itself only trains on arrays), tested on
measured sets, with the honest choice on a selection set.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from .classify import CNN_BINS, check_boot_size, check_training_sizes
from .common import (SECONDS_FAST_RAMP, add_verb, check_size, check_training_memory, class_list, info, ramps_factor,
                     load_profile_file, model_list, nonneg_int, path_list, positive_int, result, seed_int,
                     sigma_list)
from .options import acquisition_from_args, add_acquisition_options, add_classifier_options, model_params

SWEEP_FILES = ("sweep.csv", "sweep.md", "settings.json", "sweep.png", "jobs/")
"""What ``mdaug sweep`` writes in its --out folder."""


@dataclass(frozen=True)
class SyntheticTrainSet:
    """Picklable ``make_train(sigma_p, seed) -> (X, y)`` for the sweep: the registry's
    sigma_p_published sets (:mod:`mdaug.strategies`) of ``classes`` under the given
    acquisition (``n_per_class`` profiles per class)."""

    classes: tuple
    n_per_class: int
    acquisition: dict = None
    perturb_phases: bool = True
    normalisation: str = "peak"
    dtype: str = "float32"
    sign_policy: str = "reflect"

    @property
    def cache_key(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def __call__(self, sigma_p: float, seed: int):
        from ..strategies import TrainingSpec, training_set

        spec = TrainingSpec("sigma_p_published", sigma_p=sigma_p, normalisation=self.normalisation,
                            acquisition=self.acquisition or {}, sign_policy=self.sign_policy,
                            perturb_phases=self.perturb_phases, dtype=self.dtype)
        X, y, _ = training_set(spec, self.classes, self.n_per_class, seed)
        return X, y


def check_sweep_sizes(args, acq, n_test: int) -> None:
    """Every size of the sweep against memory and time: the synthetic sets (their ramps
    included), the trainings, the bootstrap, the workers' copies."""
    from ..generator import load_reference

    cells = len(args.classes) * len(args.sigma_p)
    engines = max(load_reference(c).n_engines for c in args.classes)
    n = ("--n-per-class", args.n_per_class, 4000)
    check_size(n, ramps_factor("--ramps", acq.ramps), seconds_each=cells * engines * SECONDS_FAST_RAMP,
               what="rendered ramps")
    for m in args.models:
        check_training_sizes(args, m, args.n_per_class, cells)
    check_boot_size(args.n_boot, n_test * len(args.sigma_p) * len(args.models))
    check_size(("--workers", args.workers, 1), n, bytes_each=len(args.classes) * CNN_BINS * 8 * 3,
               what="training profiles held at once")
    check_size(("--workers", args.workers, 1), bytes_each=300 * 2 ** 20, what="worker processes")


def run_sweep(args) -> int:
    from ..classify.protocol import sigma_p_sweep
    from ..generator import load_reference
    from ..radar import DataFileError, RadarConfig, atomic_write

    from .guard import Output, check_paths

    check_paths(inputs=[*(("--test", p) for p in args.test), ("--select", args.select)],
                outputs=[Output("--out", args.out, "folder", inside=SWEEP_FILES)], overwrite=args.overwrite)
    out = Path(args.out)
    for c in args.classes:
        load_reference(c)  # unknown class: fail before any work
    check_training_memory(2 * args.n_per_class, "--n-per-class", args.n_per_class, len(args.classes))
    length = RadarConfig().slice_length
    tests = {}
    for path in args.test + ([args.select] if args.select is not None else []):
        ps = load_profile_file(path, length=length, why="the synthetic training set (400-bin signatures)")
        unknown = sorted(set(ps.classes) - set(args.classes))
        if unknown:
            raise DataFileError(f"{path}: field 'labels' holds classes {unknown} that are not trained "
                                f"(--classes {','.join(args.classes)})")
        name = SELECT if path is args.select else path.stem
        if name in tests:
            raise ValueError(f"--test: two test files share the name {name!r}; rename one")
        # the drone of each acquisition, when the file says: the intervals resample drones first
        tests[name] = (ps.profiles, ps.labels, *([ps.extra["specimen"]] if "specimen" in ps.extra else []))
    acq, perturb = acquisition_from_args(args)
    check_sweep_sizes(args, acq, sum(len(v[1]) for v in tests.values()))
    make_train = SyntheticTrainSet(tuple(args.classes), args.n_per_class, acquisition=acq.to_dict(),
                                   perturb_phases=perturb, normalisation=args.normalisation, dtype=args.dtype,
                                   sign_policy=args.sign_policy)
    params = {m: model_params(args, m) for m in args.models}
    out.mkdir(parents=True, exist_ok=True)
    executor = None
    if args.workers > 1:
        import os
        from concurrent.futures import ProcessPoolExecutor

        from ..radar.workers import worker_init

        executor = ProcessPoolExecutor(args.workers, initializer=worker_init, initargs=(os.getpid(),))
    info(f"sweep: {len(args.sigma_p)} sigma_P x {len(args.models)} models, {2 * args.n_per_class} training "
         f"profiles each, tests {', '.join(f'{k} ({len(v[1])})' for k, v in tests.items())}")
    try:
        res = sigma_p_sweep(make_train, tests, sigma_ps=args.sigma_p, models=args.models, random_state=args.seed,
                            executor=executor, model_params=params, n_boot=args.n_boot,
                            cache_dir=None if args.no_resume else out / "jobs")
    except BaseException:  # interrupted (Ctrl-C, SIGTERM) or failed: the workers stop now, before the one line
        if executor is not None:
            from ..radar.workers import stop_pool

            stop_pool(executor)
            executor = None
        raise
    finally:
        if executor is not None:
            executor.shutdown(cancel_futures=True)
    res.settings["make_train"] = asdict(make_train)
    res.settings["test_files"] = [str(p) for p in args.test]
    res.settings["intervals"] = intervals_used(tests, args.n_boot)
    md = res.to_markdown() + "\n" + "\n".join(f"95% intervals on {name}: {how}"
                                               for name, how in res.settings["intervals"].items()) + "\n"
    if args.select is not None:
        res.settings["select_file"] = str(args.select)
        md += "\n" + honest_choice(res, args.select)
    res.to_csv(out / "sweep.csv")
    atomic_write(out / "sweep.md", lambda fh: fh.write(md.encode()))
    atomic_write(out / "settings.json", lambda fh: fh.write(json.dumps(res.settings, indent=1).encode()))
    res.plot(out / "sweep.png")
    result(md)
    result(f"wrote {out / 'sweep.csv'}, {out / 'sweep.md'}, {out / 'sweep.png'} "
           f"({res.settings['seconds']:.0f} s, {res.settings['resumed_jobs']} sigma_P points reused)")
    return 0


SELECT = "select"  # the name of the --select set among the sweep's sets


def intervals_used(tests: dict, n_boot: int) -> dict:
    """{set name: which bootstrap its intervals use}: drones (the file's 'specimen') are
    the clusters when the file names them, else the acquisitions are resampled."""
    from ..classify.metrics import bootstrap_method

    if not n_boot:
        return {name: "none (--n-boot 0)" for name in tests}
    return {name: f"{bootstrap_method(v[2] if len(v) > 2 else None, v[1])} ({n_boot} resamples)"
            + ("" if len(v) > 2 else "; the file names no drones (field 'specimen')")
            for name, v in tests.items()}


def honest_choice(res, path) -> str:
    """Markdown: per model, the sigma_P with the best balanced accuracy on the selection
    set (ties: the smaller sigma_P), and what it scores on every test set."""
    tests = [t for t in res.test_sets if t != SELECT]
    lines = [f"**sigma_P chosen on the selection set** ({path}, disjoint from the test sets: no peeking) by balanced "
             "accuracy, and its scores on the test sets\n",
             "| model | sigma_P | balanced on the selection set | " + " | ".join(f"balanced on {t}" for t in tests) + " |",
             "|---" * (3 + len(tests)) + "|"]
    for m in res.models:
        b = res.best(m, SELECT, "balanced_accuracy")
        scores = [next(r["balanced_accuracy"] for r in res.rows if r["model"] == m and r["test_set"] == t
                       and r["sigma_p"] == b["sigma_p"]) for t in tests]
        lines.append(f"| {m} | {b['sigma_p']:.2f} | {100 * b['balanced_accuracy']:.1f} | "
                     + " | ".join(f"{100 * s:.1f}" for s in scores) + " |")
    return "\n".join(lines) + "\n"


def _sweep_interrupted(args) -> str:
    if args.no_resume:
        return "finished sigma_P points were not kept (--no-resume)"
    return f"finished sigma_P points are kept in {Path(args.out) / 'jobs'}; run the same command again to resume"


def add_sweep(sub, parents, help):
    from ..classify.protocol import FAST_MODELS, PUBLISHED_SIGMA_PS
    from ..generator.augment import SIGN_POLICIES

    p = add_verb(sub, "sweep", parents, help=help, interrupted=_sweep_interrupted,
                 description="Train classifiers on synthetic sigma_P sets and test them on measured sets; "
                             "writes sweep.csv, sweep.md and sweep.png to --out. An interrupted run resumes "
                             "from --out/jobs.")
    p.add_argument("--test", type=path_list, required=True, metavar="FILES",
                   help="comma-separated measured test files (e.g. old.npz,new.npz), 400-bin profiles + labels")
    p.add_argument("--out", type=Path, required=True, help="output folder (created if needed)")
    p.add_argument("--select", type=Path, default=None, metavar="FILE",
                   help="measured selection set disjoint from the test files (e.g. more acquisitions of the "
                        "calibration drones): sigma_P is also chosen on it, the honest choice, and its test "
                        "scores are reported (default: none; the published pick on each test set peeks)")
    p.add_argument("--sigma-p", type=sigma_list, default=list(PUBLISHED_SIGMA_PS), metavar="LIST",
                   help="comma-separated sigma_P grid, each in [0, 1] (default: the published "
                        f"{','.join(f'{s:g}' for s in PUBLISHED_SIGMA_PS)})")
    p.add_argument("--models", type=model_list, default=list(FAST_MODELS), metavar="LIST",
                   help=f"comma-separated classifiers, of svm, nb, xgb, cnn (default: {','.join(FAST_MODELS)})")
    p.add_argument("--classes", type=class_list, default=["HELI", "QUAD"], metavar="LIST",
                   help="comma-separated class references (default: HELI,QUAD)")
    p.add_argument("--n-per-class", type=positive_int, default=4000, metavar="N",
                   help="synthetic profiles per class and sigma_P; the paper used 16000 (default: %(default)s)")
    p.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect",
                   help="sigma_P draws that flip a non-negative parameter's sign (default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of every training set and model (default: "
                                                             "%(default)s)")
    p.add_argument("--n-boot", type=nonneg_int, default=1000, metavar="N",
                   help="bootstrap resamples per score, 0 = no intervals (default: %(default)s)")
    p.add_argument("--workers", type=positive_int, default=1, metavar="N",
                   help="parallel processes, one sigma_P point each (default: %(default)s)")
    p.add_argument("--no-resume", action="store_true", help="ignore results of an earlier run in --out/jobs")
    add_acquisition_options(p)
    add_classifier_options(p, normalisation=False)
    p.set_defaults(func=run_sweep)
    return p


VERBS = {
    "sweep": ("the published sigma_P protocol (Table IV, Fig. 13)", add_sweep),
}
