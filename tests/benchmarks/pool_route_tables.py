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
"""
from __future__ import annotations

import argparse
import json
import os
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


def _pool(parts: list[dict], names: list[str]) -> dict:
    """Pooled figures of SBC summaries ``parts`` (each with n_replicates and coverage_by_quantity)."""
    from mdaug.inference.result.status import exact_fail_chance, verdict

    n = sum(p["n_replicates"] for p in parts)
    cov = {q: sum(p["coverage_by_quantity"][q]["0.90"] * p["n_replicates"] for p in parts) / n for q in names}
    row = {k: sum(p[k] * p["n_replicates"] for p in parts) / n for k in ("outer_share", "log_score", "tarp_atc")}
    row.update(coverage90_range=[min(cov.values()), max(cov.values())], n_replicates=n,
               lowest=sorted(cov.items(), key=lambda t: t[1])[:4], exact_fail_chance=exact_fail_chance(n, len(names)))
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
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
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
    d = len(lf.names)
    print(f"{len(a.runs)} route tables pooled, {rows['amortized']['n_replicates']} fresh prior drones, "
          f"{est.class_name} K = {est.spec.acquisition.ramps}, {d} quantities:")
    for name, r in rows.items():
        lo, hi = r["coverage90_range"]
        p_low = lowest_coverage_chance(r["n_replicates"], d, lo)  # an exact posterior this low
        print(f"{name:10s} {r['verdict']:13s} outer {r['outer_share']:.3f}  coverage {lo:.3f}-{hi:.3f}  log score "
              f"{r['log_score']:.2f}  TARP {r['tarp_atc']:.3f}  lowest: "
              + ", ".join(f"{q} {v:.3f}" for q, v in r["lowest"])
              + f"  (an exact posterior's lowest this low: chance {p_low:.3f})")
    print(f"(an exact posterior fails the gate's coverage rule on {rows['amortized']['n_replicates']} drones with "
          f"chance {rows['amortized']['exact_fail_chance']:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
