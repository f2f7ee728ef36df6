"""Give a shipped estimator its summary likelihood and its route table.

python tests/benchmarks/summary_likelihood.py --class HELI --ramps 32 --prior DIR --near DIR \
    [--model PREFIX | --save-model PREFIX] [--no-widening] [--route-truths 40] [--specimens 20] [--time-budget 60] \
    [--workers 2] [--seed 7] [--moves | --thorough] --out FILE
python tests/benchmarks/summary_likelihood.py --class HELI --ramps 32 --from-file FILE [...] --out FILE2
   (the route table of a file that already carries its summary likelihood)

1. The training drones: --prior, shards of prior drones with 10 measurements each
   (``simulate_shards`` of ``SimulationSpec(CLASS, K)``, e.g. a train-estimator work
   folder's ``sims/``), and --near, shards of drones of the specimen model around the
   reference at 4 x its spreads (``SimulationSpec(..., near_width=4)``); the last 1,000
   prior drones are left out (fresh drones for a check by hand).
2. The summary likelihood (``mdaug.inference.emulator.train.train_summary_model``),
   or one trained before (--model PREFIX: PREFIX.json + PREFIX.pt as --save-model
   wrote them), attached to the shipped estimator of the class and K.
3. The route table: every route (or --routes) on --route-truths fresh prior drones (SBC: outer
   share, coverage, log score, widths, seconds, convergence) and on --specimens drones
   drawn as the study draws new drones (widths, truth inside, log score, and the
   Cramer-Rao bound); the file's default route is, among the routes that pass the gate
   on the prior drones, the best log score on the specimen drones (on the prior drones
   when no specimens ran).
Prints both tables and writes FILE.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")


def table(rows: dict, names: list[str], crb: dict | None = None) -> str:
    lines = [f"{'route':10s} {'verdict':13s} {'outer':>6s} {'cov90':>10s} {'log score':>9s} {'conv':>5s} {'s/drone':>7s}  "
             "90% width / truth: " + " ".join(n.replace("line ", "") for n in names)]
    for name, r in rows.items():
        lo, hi = r["coverage90_range"]
        lines.append(f"{name:10s} {r.get('verdict', ''):13s} {r['outer_share']:6.3f} {lo:4.2f}-{hi:4.2f} "
                     f"{r['log_score']:8.2f}{'*' if r.get('log_score_by') == 'exact' else ' '} "
                     f"{r['converged_share']:5.2f} {r['seconds_median']:7.1f}  "
                     + (" ".join(f"{r['width_over_truth'][n]:.2f}" for n in names) if "width_over_truth" in r else
                        "(derived from the smc and amortized rows: no draws to measure)"))
    if crb:
        lines.append(f"{'CRB':10s} {'':13s} {'':6s} {'':10s} {'':9s} {'':5s} {'':7s}  "
                     + " ".join(f"{crb[n]:.2f}" for n in names))
    lines += [f"lowest 90% coverage, {name}: " + ", ".join(f"{q} {c:.2f}" for q, c in r["lowest_coverage"])
              for name, r in rows.items() if r.get("lowest_coverage")]
    lines.append("(* the route's own density at the truth; else a Gaussian fitted to its draws)")
    chance = next((r["exact_fail_chance"] for r in rows.values() if "exact_fail_chance" in r), None)
    if chance is not None:
        lines.append(f"(an exact posterior fails the gate's coverage rule on these drones with chance {chance:.2f})")
    return "\n".join(lines)


def shard_seed(folder: str):
    """The seed the shards in ``folder`` were simulated with (its ``simulation.json``; None
    where it does not say), kept in the file so that its training drones can be made again."""
    try:
        return json.loads(json.loads(open(os.path.join(folder, "simulation.json")).read())["key"])["seed"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def main(argv=None) -> int:
    import numpy as np
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.estimator import EstimatorError
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.amortized.simulate import load_shards
    from mdaug.inference.emulator.model import from_parts, to_parts
    from mdaug.inference.emulator.train import EmulatorConfig, train_summary_model
    from mdaug.inference.estimator_job import adopt_route_table, estimator_sbc, name_default_route, specimen_table
    from mdaug.inference.samplers.smc import THOROUGH_ROUTE
    from mdaug.inference.settings import CalibrationSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", required=True)
    ap.add_argument("--ramps", type=int, required=True)
    ap.add_argument("--prior")
    ap.add_argument("--near")
    ap.add_argument("--from-file", default=None)
    ap.add_argument("--model", default=None)
    ap.add_argument("--save-model", default=None)
    ap.add_argument("--no-widening", action="store_true",
                    help="train without the widening fit (w = 1; EmulatorConfig(n_widening=0)): QUAD's 35 "
                         "dimensions, where BOBYQA alone stops short of the global maximum, take theirs from "
                         "refit_widening.py --maximum smc")
    ap.add_argument("--route-truths", type=int, default=40)
    ap.add_argument("--specimens", type=int, default=20)
    ap.add_argument("--time-budget", type=float, default=60.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--routes", default=None, help="comma-separated routes to compare (default: all the file has)")
    how = ap.add_mutually_exclusive_group()
    how.add_argument("--moves", action="store_true", help="the smc route with its moves across the golf course "
                    "(the SMC plugin's route_moves; off by default)")
    how.add_argument("--thorough", action="store_true", help="the smc route with its moves, slower tempering and "
                    "longer rejuvenation (samplers.smc.THOROUGH_ROUTE)")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    est = find(a.cls, Acquisition.measured(a.ramps), path=a.from_file)
    lf = est.label_free
    if a.from_file:
        try:
            model = est.summary_model(f"--from-file {a.from_file}")
        except EstimatorError as exc:
            ap.error(str(exc))
        report = est.meta["summary"]["training"]
    elif not (a.prior and a.near):
        ap.error("--prior and --near are needed unless --from-file is given")
    elif a.model:
        meta = json.load(open(f"{a.model}.json"))
        model = from_parts(meta, torch.load(f"{a.model}.pt", weights_only=True), a.cls, est.spec.acquisition,
                           est.spec.radar, lf, a.model)
        report = meta["training"]
    else:
        import glob

        xs, ys = [], []
        for i, folder in enumerate((a.prior, a.near)):
            x, y = load_shards(sorted(glob.glob(os.path.join(folder, "shard-*.npz"))))
            if i == 0:
                x, y = x[:-1000], y[:-1000]
            xs.append(x)
            ys.append(y)
        config = EmulatorConfig(n_widening=0) if a.no_widening else EmulatorConfig()
        model, report = train_summary_model(np.concatenate(xs), np.concatenate(ys), lf, a.cls, est.spec.acquisition,
                                            est.spec.radar, config, seed=a.seed)
        report.update(prior_drones=int(len(xs[0])), near_drones=int(len(xs[1])), near_width=4.0,
                      simulation_seeds=[shard_seed(a.prior), shard_seed(a.near)])
        if a.save_model:
            meta, state = to_parts(model, report)
            torch.save(state, f"{a.save_model}.pt")
            open(f"{a.save_model}.json", "w").write(json.dumps(meta))
    command = "python tests/benchmarks/summary_likelihood.py " + " ".join(sys.argv[1:])
    if not a.from_file:  # a file's model keeps the command that trained it; this one made its tables
        report = {**report, "command": command}
    est.with_summary(model, report)
    est.save(a.out)  # the routes read the file in their worker processes
    knobs = dict(THOROUGH_ROUTE) if a.thorough else {"route_moves": True} if a.moves else {}  # else the file's
    settings = CalibrationSettings(progress=False, time_budget=a.time_budget).with_plugin("smc", **knobs)
    names = lf.names[:8]
    routes = tuple(a.routes.split(",")) if a.routes else None
    old = est.meta.get("sbc", {})
    # with --from-file the file's model is unchanged: a part not rerun here is kept
    keep = ("amortized", "n_measurements") + (("route_table", "smc", "stacked", "specimens") if a.from_file else ())
    new = {k: v for k, v in old.items() if k in keep}
    if a.route_truths:
        sbc = estimator_sbc(est, a.route_truths, seed=a.seed, workers=a.workers, route_truths=a.route_truths,
                            route_settings=settings, estimator_path=a.out, log=print, routes=routes,
                            specimens=a.specimens, specimen_seed=a.seed + 1)
        new.update({k: v for k, v in sbc.items() if k not in ("amortized", "n_measurements")})
        new["route_table"]["command"] = command
        print(f"\nroute table, {a.route_truths} fresh prior drones (SBC), {a.cls} K = {a.ramps}, 5 measurements:")
        print(table(sbc["route_table"]["rows"], names))
    elif a.specimens:  # the file's route table kept, its specimen drones rerun
        new["specimens"] = specimen_table(est, a.specimens, settings=settings, seed=a.seed + 1, workers=a.workers,
                                          estimator_path=a.out, routes=routes)
    if a.specimens:
        spec = new["specimens"]
        spec["command"] = command
        print(f"\n{a.specimens} drones drawn as the study draws new drones (specimen model around the reference):")
        print(table(spec["rows"], names, spec.get("crb_width_over_truth")))
    if new.get("route_table"):  # honest on the prior, sharpest where users are
        name_default_route(new)
    est.meta["sbc"] = new
    adopt_route_table(est)
    default = est.meta["default_route"]
    est.save(a.out)
    print(f"\ndefault route: {default}; wrote {a.out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
