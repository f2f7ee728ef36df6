"""``mdaug train-estimator`` and ``mdaug sbc``: the amortized calibration's estimators.

train-estimator simulates drones of a class under an acquisition (resumable shards,
``--workers`` processes), trains the amortized posterior and the learned likelihood
(progress bar, early stopping, checkpoints; ``--device``), ends with its own SBC and
writes the estimator ZIP. sbc checks an estimator (shipped or a file) on fresh
simulated drones: both routes, rank statistics, coverage, TARP, widths.
"""
from __future__ import annotations

import json
from pathlib import Path

from .common import add_verb, count, info, nonneg_float, nonneg_int, positive_float, positive_int, result, seed_int

MAX_SIMULATIONS = 2_000_000
MAX_MEASUREMENTS = 32


_sims = count(100, MAX_SIMULATIONS)
_meas = count(1, MAX_MEASUREMENTS, f"an integer from 1 to {MAX_MEASUREMENTS} (measurements per drone)")


SBC_MEASUREMENTS = 5     # measurements of each SBC drone (inference.estimator_job.SBC_MEASUREMENTS)
ROUTE_SBC_SECONDS = 180.0  # the smc route's most seconds per SBC drone of train-estimator (calibrate's default)


def check_estimator_sizes(args) -> None:
    """Every size of ``train-estimator`` or ``sbc`` against memory and a day of work
    (:func:`.common.check_size`), the radar's bound on --ramps first; before any file
    or folder is written."""
    from ..radar import RadarConfig
    from .common import SECONDS_CNN_PROFILE, SECONDS_SIMULATED_RAMP, check_size, ramps_factor

    k = ramps_factor("--ramps", args.ramps)
    profile = RadarConfig().slice_length * 4  # float32
    training = args.verb == "train-estimator"
    truths_name = "--sbc-truths" if training else "--truths"
    route_name = "--sbc-route-truths" if training else "--route-truths"
    truths, routes = (args.sbc_truths, args.sbc_route_truths) if training else (args.truths, args.route_truths)
    if routes > truths:
        raise ValueError(f"{route_name} {routes:,} exceeds {truths_name} {truths:,}: the routes are compared on "
                         f"the first {route_name} of the {truths_name} drones")
    if training:
        sims, meas = ("--simulations", args.simulations, 20000), ("--measurements", args.measurements, 10)
        check_size(sims, meas, bytes_each=2 * profile, what="simulated profiles in memory")
        check_size(sims, meas, k, seconds_each=SECONDS_SIMULATED_RAMP, what="simulated ramps")
        check_size(sims, meas, ("--epochs", args.epochs or 1, 100), seconds_each=2 * SECONDS_CNN_PROFILE,
                   what="profile passes of the two networks")
    simulated = [(truths_name, truths, 300, "SBC drones")]
    if not training and args.specimens:  # sbc simulates its specimen drones with or without a route table
        simulated.append(("--specimens", args.specimens, 50, "specimen drones"))
    for name, count_, typical, what in simulated:
        n = (name, count_, typical)
        check_size(n, bytes_each=SBC_MEASUREMENTS * profile + 2 * 13 * 4 * 8, what=f"{what}' profiles and vectors")
        check_size(n, k, seconds_each=SBC_MEASUREMENTS * SECONDS_SIMULATED_RAMP, what=f"simulated ramps of {what}")
    budget = ROUTE_SBC_SECONDS if training else args.time_budget
    spec_name = "--sbc-specimens" if training else "--specimens"
    specimens = (args.sbc_specimens if training else args.specimens) if routes else 0
    if training:
        check_size((route_name, routes, 10), seconds_each=budget,
                   what=f"SBC drones through the smc route, at most {budget / 60:.0f} min each")
        check_size((spec_name, specimens, 50), seconds_each=budget,
                   what=f"specimen drones through the smc route, at most {budget / 60:.0f} min each")
    else:
        check_size((route_name, routes, 10), ("--time-budget", budget, 60), seconds_each=1.0,
                   what="seconds of the smc route")
        check_size((spec_name, specimens, 50), ("--time-budget", budget, 60), seconds_each=1.0,
                   what="seconds of the smc route on specimen drones")


def _interrupted(args) -> str:
    if args.verb == "train-estimator":
        return (f"the simulations and training checkpoints in {_work(args)} are kept; run the same command again "
                "to resume")
    return "nothing was written"


def _work(args) -> Path:
    return args.work if args.work is not None else Path(f"{args.out}.work")


def _class(text: str) -> str:
    from ..generator import load_reference

    name = text.upper()
    try:
        load_reference(name)
    except (KeyError, ValueError):
        raise ValueError(f"--class: no class reference {text!r} (known: HELI, QUAD)") from None
    return name


def _command(args, cls: str, epochs: int) -> str:
    """The command line that trains this estimator again (kept in its file)."""
    budgets = "".join(f" --{name}-budget {v:g}" for name, v in (("posterior", args.posterior_budget),
                                                                 ("ratio", args.ratio_budget)) if v is not None)
    return (f"mdaug train-estimator --class {cls} --ramps {args.ramps} --simulations {args.simulations} "
            f"--measurements {args.measurements} --seed {args.seed} --epochs {epochs}{budgets}"
            + (f" --start-from {args.start_from.name}" if args.start_from is not None else "")
            + f" --out {args.out.name}")


def run_train(args) -> int:
    from ..generator.acquisition import Acquisition
    from ..inference.estimator_job import train_estimator
    from ..inference.amortized.shipped import default_nets, default_training
    from ..inference.amortized.simulate import SimulationSpec
    from ..inference.amortized.train import device_of
    from ..radar.progress import progress_enabled
    from .guard import Output, check_paths

    cls = _class(args.class_name)
    device_of(args.device)  # refuses cuda without a GPU, before any work
    check_estimator_sizes(args)
    for name, budget in (("--posterior-budget", args.posterior_budget), ("--ratio-budget", args.ratio_budget)):
        if budget == 0 and args.start_from is None:
            raise ValueError(f"{name} 0 trains nothing; it keeps the network of a --start-from file, and none "
                             "was given")
    check_paths(inputs=[("--start-from", args.start_from)],
                outputs=[Output("--out", args.out, "model"), Output("--work", _work(args), "folder")],
                overwrite=args.overwrite)
    spec = SimulationSpec(cls, Acquisition.measured(args.ramps), args.measurements)
    start = _start(args, spec, cls)
    cfg = default_training()
    if args.epochs is not None:
        from dataclasses import replace

        cfg = replace(cfg, max_epochs=args.epochs)
    work, out_existed = _work(args), Path(args.out).exists()
    created = _make_work(args, work)
    info(f"training the {cls} estimator at K = {args.ramps}: {args.simulations} simulated drones x "
         f"{args.measurements} measurements, work folder {work}")
    try:
        est = train_estimator(spec, args.simulations, work, args.out, seed=args.seed, workers=args.workers,
                              device=args.device, net_cfg=default_nets(cls), train_cfg=cfg,
                              post_budget=args.posterior_budget, ratio_budget=args.ratio_budget,
                              sbc_truths=args.sbc_truths, sbc_route_truths=args.sbc_route_truths,
                              sbc_specimens=args.sbc_specimens, temperature_truths=args.temperature_truths,
                              summary=not args.no_summary, near_simulations=args.near_simulations,
                              summary_cfg=_summary_config(args), start=start,
                              command=_command(args, cls, cfg.max_epochs),
                              progress=progress_enabled(), log=info)
    except Exception:  # failed (an interrupt keeps the work folder, to resume): leave nothing this run made
        import shutil

        if not out_existed:
            Path(args.out).unlink(missing_ok=True)
        if created is not None:
            shutil.rmtree(created, ignore_errors=True)
        raise
    result(f"wrote {args.out} ({est.meta['job_seconds']:.0f} s)")
    return 0


def _start(args, spec, cls: str):
    """The --start-from estimator, checked against this training's class, K, measurements
    and networks before any work (EstimatorError naming the file and the field)."""
    if args.start_from is None:
        return None
    from ..inference.amortized.estimator import AmortizedEstimator, EstimatorError
    from ..inference.amortized.shipped import default_nets
    from ..inference.estimator_job import check_start

    try:
        est = AmortizedEstimator.load(args.start_from)
    except EstimatorError as exc:
        raise EstimatorError(f"--start-from: {exc}") from None
    try:
        check_start(est, spec, default_nets(cls))
    except ValueError as exc:
        raise EstimatorError(f"--start-from {args.start_from}: {exc}") from None
    return est


def _summary_config(args):
    from ..inference.emulator.train import EmulatorConfig

    if args.summary_epochs is None:
        return EmulatorConfig()
    return EmulatorConfig(epochs=args.summary_epochs, cov_epochs=max(1, args.summary_epochs // 2))


def _make_work(args, work: Path) -> Path | None:
    """Create the work folder (and the folders above it) before any work, naming the
    option when it cannot be; returns the topmost folder created (None: it existed)."""
    top = work
    while not top.parent.exists() and top.parent != top:
        top = top.parent
    existed = work.exists()
    try:
        work.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        where = f"--work {work}" if args.work is not None else f"the work folder {work} (OUT.work of --out {args.out})"
        raise ValueError(f"{where}: cannot be created ({exc.strerror or exc}); give --work a writable folder") \
            from None
    return None if existed else top


def run_sbc(args) -> int:
    from ..generator.acquisition import Acquisition
    from ..inference.estimator_job import estimator_sbc
    from ..inference.amortized.shipped import find
    from ..inference.settings import CalibrationSettings
    from ..radar.progress import progress_enabled
    from .guard import Output, check_paths

    if args.class_name is None or args.ramps is None:
        given = [f"--{n} {v}" for n, v in (("estimator", args.estimator), ("json", args.json),
                                            ("figure", args.figure), ("route-truths", args.route_truths or None),
                                            ("specimens", args.specimens or None)) if v is not None]
        if args.stored and args.class_name is None and args.ramps is None and not given:
            _print_shipped()
            return 0
        raise ValueError("--class and --ramps: both are needed"
                         + (f" (with {', '.join(given)})" if given else "")
                         + "; `mdaug sbc --stored` alone lists every shipped estimator")
    cls = _class(args.class_name)
    check_estimator_sizes(args)
    check_paths(inputs=[("--estimator", args.estimator)], outputs=[Output("--json", args.json, "json"),
                                                                    Output("--figure", args.figure, "plot")],
                overwrite=args.overwrite)
    est = find(cls, Acquisition.measured(args.ramps), path=args.estimator)
    from ..radar import RadarConfig

    where = "the shipped estimator" if args.estimator is None else f"--estimator {args.estimator}"
    est.check_acquisition(Acquisition.measured(args.ramps), RadarConfig(),  # calibrate's own check of its data
                          f"--ramps {args.ramps} with {where}")
    if args.stored:  # what the file says, simulating nothing
        if args.figure is not None:
            raise ValueError("--figure: the rank histograms need the drones' ranks, which a file does not store; "
                             "run the SBC without --stored")
        asked = [f"--{n} {v}" for n, v in (("route-truths", args.route_truths), ("specimens", args.specimens)) if v]
        if asked:
            raise ValueError(f"{', '.join(asked)}: --stored simulates no drones; run the SBC without --stored")
        out = est.meta.get("sbc") or {}
        if not any(isinstance(s, dict) and "coverage90_range" in s for s in out.values()):
            raise ValueError(f"{where}: the file stores no SBC (field 'sbc' of its meta.json); run the SBC "
                             "without --stored")
        result(f"{cls} K={args.ramps}: the SBC stored in {where} (default route {est.default_route})")
    else:
        settings = CalibrationSettings(progress=False, time_budget=args.time_budget)
        out = estimator_sbc(est, args.truths, seed=args.seed, workers=args.workers, route_truths=args.route_truths,
                            route_settings=settings, progress=progress_enabled(), log=info,
                            specimens=args.specimens)
    _print_sbc(cls, args.ramps, out)
    if args.figure is not None:
        from ..inference.diagnostics.sbc_figure import sbc_figure

        sbc_figure(out, args.figure, f"{cls} K = {args.ramps}: SBC on {args.truths} simulated drones")
        result(f"wrote {args.figure}")
    if args.json is not None:
        from ..radar.io import atomic_write

        from ..reports.results_file import plain

        text = json.dumps(plain(out, args.json.parent), indent=1, allow_nan=False)
        atomic_write(args.json, lambda fh: fh.write(text.encode()))
        result(f"wrote {args.json}")
    return 0


def _print_shipped() -> None:
    """``mdaug sbc --stored`` alone: one row per shipped estimator file, its default
    route's SBC as stored (fresh prior drones) with the gate's word, and where the file
    stores them, that route's log score and brightest-engine lines on drones like a
    user's (the specimen model around the class reference). Simulates nothing."""
    from ..inference.amortized.estimator import AmortizedEstimator
    from ..inference.amortized.shipped import DATA, available
    from ..inference.result.status import verdict

    result("the shipped estimators (mdaug's inference/amortized/data/): each file's default route and its SBC")
    result("on fresh prior drones as stored; on drones like a user's, where stored, its log score (nats, lower")
    result("is better) and the brightest engine's lines 1-4 (median 90% width / truth)")
    result(f"{'file':13s} {'route':9s} {'drones':>6s} {'outer':>6s} {'cov90':>9s} {'log score':>9s}  "
           f"{'gate':13s} {'users':>5s} {'log score':>9s}  lines 1-4")

    def by_class_and_k(stem: str):
        cls, _, k = stem.partition("-k")
        return cls, int(k) if k.isdigit() else 0

    for stem in sorted(available(), key=by_class_and_k):
        est = AmortizedEstimator.load(DATA / f"{stem}.zip")
        route = est.default_route
        sbc = est.meta.get("sbc") or {}
        s = sbc.get(route) or {}
        if "coverage90_range" not in s:
            result(f"{stem + '.zip':13s} {route:9s} (no SBC stored for this route)")
            continue
        lo, hi = s["coverage90_range"]
        score = f"{s['log_score']:9.2f}" if "log_score" in s else f"{'-':>9s}"
        row = est.users_row(route)
        users = (f"{row['drones']:5d} {row['log_score']:9.2f}  " + (" ".join(f"{v:.2f}" for v in row["lines"]) or "-")
                 if row else f"{'-':>5s} {'-':>9s}  -")
        result(f"{stem + '.zip':13s} {route:9s} {s['n_replicates']:6d} {s['outer_share']:6.3f} {lo:4.2f}-{hi:4.2f} "
               f"{score}  {verdict(s):13s} {users}")
    result("`mdaug sbc --class C --ramps K --stored` prints one file's every route, its route table and how its "
           "default was named")


def _print_sbc(cls: str, ramps: int, out: dict) -> None:
    """The SBC figures ``out`` (estimator_sbc's, or a file's stored ones), route by route:
    the gate's headline, the lines' widths, the specimen rows, the default route."""
    from ..inference.diagnostics.routes import headline, least_covered, score_by
    from ..inference.result.status import COVERAGE_MIN
    from ..inference.samplers.smc import describe_route_knobs

    for route, s in out.items():
        if not isinstance(s, dict) or "coverage90_range" not in s:  # the route table's own record
            continue
        result(f"{cls} K={ramps} {route}: {headline(s)}")
        lowest = least_covered(s) if s["coverage90_range"][0] < COVERAGE_MIN else []
        if lowest:  # which quantities fail the coverage rule
            result("  least covered (90%): " + ", ".join(f"{q} {c:.2f}" for q, c in lowest))
        prior = s.get("prior_width_over_truth")  # the amortized route's SBC carries the prior's beside
        if "width_over_truth" in s:  # a stacked row derived from stored ranks alone has no draws to measure
            widths = " ".join(f"{k.split()[2][0]}{k.split()[1]}{k[-3:]} {v:.2f}" + (f"/{prior[k]:.2f}" if prior else "")
                              for k, v in s["width_over_truth"].items() if k.startswith("line"))
            result(f"  median 90% width / truth{' (posterior/prior)' if prior else ''}: {widths}")
    if "specimens" in out:
        for route, s in out["specimens"]["rows"].items():
            widths = " ".join(f"{v:.2f}" for k, v in s.get("width_over_truth", {}).items() if k.startswith("line"))
            result(f"{cls} K={ramps} {route} on {out['specimens']['drones']} specimen drones: log score "
                   f"{s['log_score']:.2f}{score_by(s)}" + (f", lines' median 90% width / truth {widths}" if widths
                                                           else ""))
    if "route_table" in out:
        t = out["route_table"]
        rows = "; ".join(f"{name} {r['verdict']} (outer {r['outer_share']:.3f}, coverage "
                         f"{r['coverage90_range'][0]:.2f}-{r['coverage90_range'][1]:.2f}, log score {r['log_score']:.2f})"
                         for name, r in t.get("rows", {}).items() if "verdict" in r and "log_score" in r)
        if rows:  # the rows that named the default, each on the table's own drones
            result(f"{cls} K={ramps} route table on {t['drones']} drones: {rows}")
        result(f"{cls} K={ramps} default route: {t['default']} ({t['default_by']})")
        if "route_settings" in t:
            k = t["route_settings"]
            result("  the smc route's knobs (the settings', else the file's, else the defaults): "
                   + describe_route_knobs(k))


def add_train(sub, parents, help):
    p = add_verb(sub, "train-estimator", parents, help=help, interrupted=_interrupted,
                 description="Simulate drones of a class from its calibration prior through the scene simulator "
                             "and the radar chain, train the amortized posterior and the learned likelihood, check "
                             "them by SBC on fresh drones and write the estimator (a ZIP of weights and JSON "
                             "metadata, no pickle). A rerun of the same command resumes.")
    p.add_argument("--class", dest="class_name", required=True, metavar="CLASS", help="HELI or QUAD")
    p.add_argument("--ramps", type=positive_int, required=True, metavar="K", help="ramps per frame of the data")
    p.add_argument("--out", type=Path, required=True, help="estimator ZIP")
    p.add_argument("--work", type=Path, default=None, help="work folder (simulations, checkpoints) (default: "
                                                           "OUT.work)")
    p.add_argument("--simulations", type=_sims, default=20000, metavar="N",
                   help="simulated drones (default: %(default)s)")
    p.add_argument("--measurements", type=_meas, default=10, metavar="M",
                   help="most measurements of one drone the estimator takes (default: %(default)s)")
    p.add_argument("--workers", type=positive_int, default=1, metavar="N", help="simulation processes (default: %(default)s)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="where to train (auto: a GPU when present) (default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of simulations and training (default: %(default)s)")
    p.add_argument("--epochs", type=positive_int, default=None, metavar="N", help="most epochs per network (default: 300, early stopping first)")
    p.add_argument("--posterior-budget", type=nonneg_float, default=None, metavar="SECONDS",
                   help="training seconds of the posterior network (default: none; 0 with --start-from: keep "
                        "that file's network)")
    p.add_argument("--ratio-budget", type=nonneg_float, default=None, metavar="SECONDS",
                   help="training seconds of the likelihood network (default: none; 0 with --start-from: keep "
                        "that file's network)")
    p.add_argument("--start-from", type=Path, default=None, metavar="FILE",
                   help="estimator ZIP of the same class, K, measurements and networks whose weights the "
                        "training starts from (more drones refine a file, the shipped one too, instead of "
                        "training from scratch); its summary likelihood is kept, not retrained (default: none)")
    p.add_argument("--sbc-truths", type=nonneg_int, default=300, metavar="N",
                   help="SBC drones of the amortized route (default: %(default)s; 0: none)")
    p.add_argument("--sbc-route-truths", type=nonneg_int, default=0, metavar="N",
                   help="SBC drones of the smc route, on which both routes form the route table that names "
                        "the file's default route (default: %(default)s: no table, the amortized route)")
    p.add_argument("--sbc-specimens", type=nonneg_int, default=50, metavar="N",
                   help="with --sbc-route-truths: drones like a user's (the specimen model around the class "
                        "reference) through both routes; the default route is the best log score on them among "
                        "the routes that pass the gate (default: %(default)s; 0: judged on the prior drones)")
    p.add_argument("--temperature-truths", type=nonneg_int, default=0, metavar="N",
                   help="fresh drones on which the amortized posterior's temperature is chosen before its SBC: "
                        "among those whose SBC passes the gate there, the best exact log score of the truth "
                        "(default: %(default)s: the flow as trained, temperature 1)")
    p.add_argument("--no-summary", action="store_true",
                   help="no summary likelihood (the smc route then uses the likelihood ratio network)")
    p.add_argument("--near-simulations", type=count(0, MAX_SIMULATIONS), default=None, metavar="N",
                   help="drones simulated near the class reference (the specimen model at 4 x its spreads) for "
                        "the summary likelihood, beside the prior's (default: half of --simulations)")
    p.add_argument("--summary-epochs", type=positive_int, default=None, metavar="N",
                   help="most epochs of the summary likelihood's networks (default: 300 and 150, early stopping "
                        "first)")
    p.set_defaults(func=run_train)
    return p


def add_sbc(sub, parents, help):
    p = add_verb(sub, "sbc", parents, help=help, interrupted=_interrupted,
                 description="Simulation-based calibration of an estimator on fresh simulated drones (5 "
                             "measurements each): outer-10% share (0.10 when honest), 90% coverage, rank "
                             "chi-square, TARP, and the median 90% width over the truth beside the prior's.")
    p.add_argument("--class", dest="class_name", default=None, metavar="CLASS",
                   help="HELI or QUAD (no default: needed, except with --stored alone)")
    p.add_argument("--ramps", type=positive_int, default=None, metavar="K",
                   help="ramps per frame of the data (no default: needed, except with --stored alone)")
    p.add_argument("--estimator", type=Path, default=None, help="estimator ZIP (default: the shipped one)")
    p.add_argument("--truths", type=positive_int, default=300, metavar="N",
                   help="fresh simulated drones, 5 measurements each (default: %(default)s)")
    p.add_argument("--route-truths", type=nonneg_int, default=0, metavar="N",
                   help="of those, how many also through the smc route (tempered SMC from the amortized posterior "
                        "to the learned likelihood's posterior), for the route table (default: %(default)s)")
    p.add_argument("--specimens", type=nonneg_int, default=0, metavar="N",
                   help="also N drones like a user's (the specimen model around the class reference): both "
                        "routes with --route-truths, which then name the default route; the amortized route "
                        "alone without (default: %(default)s)")
    p.add_argument("--time-budget", type=positive_float, default=60.0, metavar="SECONDS",
                   help="smc route seconds per drone (default: %(default)s)")
    p.add_argument("--workers", type=positive_int, default=1, metavar="N",
                   help="simulation processes (default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=1, help="seed of the SBC drones (default: %(default)s)")
    p.add_argument("--json", type=Path, default=None, help="write the figures as JSON (default: none)")
    p.add_argument("--figure", type=Path, default=None,
                   help="write the rank histograms and coverage curves (default: none)")
    p.add_argument("--stored", action="store_true",
                   help="print the SBC, route table and specimen rows the estimator file stores (how its default "
                        "route was named) and simulate nothing; without --class and --ramps, one row per shipped "
                        "estimator")
    p.set_defaults(func=run_sbc)
    return p


VERBS = {
    "train-estimator": ("train a class's amortized calibration estimator on the simulator", add_train),
    "sbc": ("check an estimator by simulation-based calibration", add_sbc),
}
