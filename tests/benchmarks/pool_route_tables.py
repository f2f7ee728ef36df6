"""Pool the route tables of several runs of summary_likelihood.py on disjoint fresh drones.

python tests/benchmarks/pool_route_tables.py FILE1:SEED1:WORKERS1 FILE2:SEED2:WORKERS2 [...]

Each FILE is what ``summary_likelihood.py ... --seed SEED --workers WORKERS --out FILE`` wrote
(the same estimator, likelihood and route knobs; other seeds, so other drones). The gate needs
many drones where a class has many quantities (``mdaug.inference.result.status.exact_fail_chance``:
QUAD's 35 on 100 drones fail it with chance 0.94 for an exact posterior), and one long run is
harder to fit in a day than two. Pooled per route: each quantity's 90% coverage, the outer-10%
share, the log score and TARP ATC weighted by drones, and the gate's verdict on the pooled figures.
The smc route's per-quantity coverage is stored in each file (``sbc.smc``); the amortized route's
is not (its rows keep the range only), so it is rerun on each file's drones (``sbc_data`` with
that run's count, seed and workers; milliseconds a drone). Prints one row per route with its
lowest coverages and the chance that an exact posterior's lowest coverage falls that low.
--stack-weight W adds the stacked route (W x smc + (1 - W) x amortized, its row derived from the two
routes' runs on the same drones; W a number, or a file --fit-stacking wrote, whose weight and the
record of how it was chosen then travel into --adopt's file); --fit-stacking OUT fits W on the
pooled drones by the truth's log score and writes a copy of the first FILE that states it (meta
field 'stacking').
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
import zipfile

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")


def _run(text: str) -> tuple[str, int, int]:
    try:
        path, seed, workers = text.rsplit(":", 2)
        return path, int(seed), int(workers)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected FILE:SEED:WORKERS") from None


def _weight(text: str) -> float | dict:
    """--stack-weight: a number, or a file whose meta field 'stacking' states a fitted weight (that record)."""
    try:
        return float(text)
    except ValueError:
        pass
    from mdaug.inference.amortized.estimator import EstimatorError, check_stacking

    try:
        meta = json.loads(zipfile.ZipFile(text).read("meta.json"))
    except (OSError, KeyError, zipfile.BadZipFile, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"{text}: neither a number nor an estimator file ({exc})") from None
    if not isinstance(meta.get("stacking"), dict):
        raise argparse.ArgumentTypeError(f"{text}: meta field 'stacking' states no weight "
                                         "(expected a file written by --fit-stacking)")
    try:
        check_stacking(meta, text)  # the weight in (0, 1), as a file's loader checks it
    except EstimatorError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return meta["stacking"]


def _tarp(row: dict) -> str:
    """TARP ATC as printed: '-' for a row without one (a stacked row derived where the routes'
    draws were not kept, as in tables written before its TARP was)."""
    t = row.get("tarp_atc", float("nan"))
    return "-" if t != t else f"{t:.3f}"


def _pool(parts: list[dict], names: list[str], n_draws: int = 199) -> dict:
    """Pooled figures of SBC summaries ``parts`` (each with n_replicates and coverage_by_quantity);
    n_draws: the draws their intervals stand for (a stacked row's: its CDF's, ``CDF_DRAWS``)."""
    from mdaug.inference.result.status import exact_fail_chance, verdict

    n = sum(p["n_replicates"] for p in parts)
    cov = {q: sum(p["coverage_by_quantity"][q]["0.90"] * p["n_replicates"] for p in parts) / n for q in names}
    row = {k: sum(p.get(k, float("nan")) * p["n_replicates"] for p in parts) / n
           for k in ("outer_share", "log_score", "tarp_atc")}  # nan where a part has no TARP
    row.update(coverage90_range=[min(cov.values()), max(cov.values())], n_replicates=n,
               lowest=sorted(cov.items(), key=lambda t: t[1])[:4],
               exact_fail_chance=exact_fail_chance(n, len(names), n_draws), n_draws=n_draws)
    row["verdict"] = verdict(row)
    return row


def main(argv=None) -> int:
    import torch

    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.diagnostics.routes import run
    from mdaug.inference.estimator_job import Route, sbc_data
    from mdaug.inference.result.status import lowest_coverage_chance

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=_run, metavar="FILE:SEED:WORKERS")
    ap.add_argument("--stack-weight", type=_weight, default=None, metavar="W|FILE",
                    help="also pool the stacked route at this weight of the smc route (derived from the two routes' "
                         "runs on each file's drones: mdaug.inference.diagnostics.stacking.stacked_row)")
    ap.add_argument("--adopt", default=None, metavar="OUT",
                    help="with one FILE and --stack-weight: write a copy of FILE whose route table holds the stacked "
                         "row beside its own, states the weight (meta field 'stacking') and names its default route "
                         "on these prior drones (its specimen table dropped: rerun it with summary_likelihood.py "
                         "--from-file OUT --route-truths 0 --specimens N, which then names the default there)")
    ap.add_argument("--fit-stacking", default=None, metavar="OUT",
                    help="fit the stacking weight on the pooled drones (the truth's log score of the mixture, "
                         "stacking_weight) and write a copy of the first FILE that states it (meta field 'stacking')")
    a = ap.parse_args(argv)
    if a.adopt and (len(a.runs) != 1 or a.stack_weight is None):
        ap.error("--adopt takes one FILE and --stack-weight")
    torch.set_num_threads(1)
    fitted = a.stack_weight if isinstance(a.stack_weight, dict) else {}  # how a given weight was chosen
    if fitted:
        a.stack_weight = float(fitted["weight"])
    metas = [json.loads(zipfile.ZipFile(path).read("meta.json")) for path, _, _ in a.runs]
    est = AmortizedEstimator.load(a.runs[0][0])
    lf = est.label_free
    amortized = []
    for (path, seed, workers), meta in zip(a.runs, metas):
        n = meta["sbc"]["route_table"]["drones"]
        vec, prof = sbc_data(est.spec, n, seed, workers)
        amortized.append(run(Route("amortized", path), lf.quantities(vec), prof, lf.names, seed=seed,
                             to_unbounded=lf.to_unbounded))
    rows = {"amortized": _pool(amortized, lf.names)}
    if all("smc" in m["sbc"] for m in metas):
        rows["smc"] = _pool([m["sbc"]["smc"] for m in metas], lf.names)
    if a.stack_weight is not None or a.fit_stacking:
        import numpy as np

        from mdaug.inference.diagnostics.stacking import CDF_DRAWS, stacked_row, stacking_weight

        log_smc = np.concatenate([m["sbc"]["smc"]["log_score_by_drone"] for m in metas])
        log_amortized = np.concatenate([r["log_score_by_drone"] for r in amortized])
        w = a.stack_weight if a.stack_weight is not None else stacking_weight(-log_smc, -log_amortized)
        stacked = [stacked_row(m["sbc"]["smc"], r, w) for m, r in zip(metas, amortized)]
        rows["stacked"] = _pool(stacked, lf.names, CDF_DRAWS)
        if a.stack_weight is None:
            how = f"fitted: the truth's log score on the {len(log_smc)} pooled drones"
        else:
            how = f"given: fitted on {fitted.get('drones')} drones, seeds {fitted.get('seeds')}" if fitted else "given"
        print(f"stacking weight of the smc route: {w:.3f} ({how})")
        if a.fit_stacking:
            est.meta["stacking"] = {
                "weight": round(w, 3), "drones": int(len(log_smc)), "seeds": [seed for _, seed, _ in a.runs],
                "log_score": {"smc": float(log_smc.mean()), "amortized": float(log_amortized.mean()),
                              "stacked": rows["stacked"]["log_score"]},
                "chosen_by": "the log score of the truth of the mixture on these prior drones (stacking, Yao et al. "
                             "2018), route tables of summary_likelihood.py at the file's route settings",
                "command": "python tests/benchmarks/pool_route_tables.py " + " ".join(sys.argv[1:])}
            est.save(a.fit_stacking)
            print(f"wrote {a.fit_stacking} (its default route unchanged: {est.default_route}; a route table on "
                  "other drones names it)")
    if a.adopt:
        from mdaug.inference.estimator_job import adopt_route_table, name_default_route, trimmed_row
        from mdaug.inference.result.status import verdict

        sbc = est.meta["sbc"]
        sbc["stacked"] = {**stacked[0], "verdict": verdict(stacked[0])}
        sbc["route_table"]["rows"]["stacked"] = trimmed_row(sbc["stacked"])
        made = sbc["route_table"].get("command", f"the route table of {a.runs[0][0]}")
        sbc["route_table"]["command"] = (f"{made}; then "
                                         "python tests/benchmarks/pool_route_tables.py " + " ".join(sys.argv[1:]))
        sbc.pop("specimens", None)  # its rows have no stacked route: rerun them
        name_default_route(sbc)
        est.meta["stacking"] = {**(fitted or est.meta.get("stacking") or {}), "weight": w}
        adopt_route_table(est)
        est.save(a.adopt)
        print(f"wrote {a.adopt}: default route {est.default_route} ({sbc['route_table']['default_by']})")
    d = len(lf.names)
    print(f"{len(a.runs)} route tables pooled, {rows['amortized']['n_replicates']} fresh prior drones, "
          f"{est.class_name} K = {est.spec.acquisition.ramps}, {d} quantities:")
    for name, r in rows.items():
        lo, hi = r["coverage90_range"]
        p_low = lowest_coverage_chance(r["n_replicates"], d, lo, r["n_draws"])  # an exact posterior this low
        print(f"{name:10s} {r['verdict']:13s} outer {r['outer_share']:.3f}  coverage {lo:.3f}-{hi:.3f}  log score "
              f"{r['log_score']:.2f}  TARP {_tarp(r)}  lowest: "
              + ", ".join(f"{q} {v:.3f}" for q, v in r["lowest"])
              + f"  (an exact posterior's lowest this low: chance {p_low:.3f})")
    print(f"(an exact posterior fails the gate's coverage rule on {rows['amortized']['n_replicates']} drones with "
          f"chance {rows['amortized']['exact_fail_chance']:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
