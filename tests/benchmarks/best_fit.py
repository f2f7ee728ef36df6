"""How far the best fit lands from the truth, on drones like a user's.

python tests/benchmarks/best_fit.py --class QUAD --ramps 32 [--drones 11] [--seed 31] [--estimator FILE]

Drones of the specimen model around the class reference (as the study draws new drones;
5 measurements each). For each, the two best fits an estimator file can give
(:func:`mdaug.inference.amortized.calibrate.calibrate_amortized`): the amortized
posterior's median (4,000 draws) and, where the file has a summary likelihood, the
median of its smc route's draws (what ``calibrate`` takes for the best fit beside the
amortized route). Prints |fit - truth| / truth of the brightest engine's four sorted
lines, per drone and the medians, and the seconds of each smc run (1 thread).
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")


def main(argv=None) -> int:
    from dataclasses import replace

    import numpy as np
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.amortized.tempered import smc_route
    from mdaug.inference.estimator_job import sbc_data
    from mdaug.inference.settings import CalibrationSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", default="QUAD")
    ap.add_argument("--ramps", type=int, default=32)
    ap.add_argument("--drones", type=int, default=11)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--estimator", help="estimator file (default: the shipped one)")
    ap.add_argument("--workers", type=int, default=1, help="processes simulating the drones (the drones depend on it)")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    est = (AmortizedEstimator.load(a.estimator) if a.estimator
           else find(a.cls, Acquisition.measured(a.ramps)))
    lf = est.label_free
    vectors, profiles = sbc_data(replace(est.spec, near_width=1.0), a.drones, a.seed, workers=a.workers)
    truths = lf.quantities(vectors)[:, :4]
    settings = CalibrationSettings(progress=False, time_budget=600)
    errors = {"amortized median": [], "smc median": []}
    seconds = []
    print(f"{a.cls} K = {a.ramps}, {a.drones} specimen drones (seed {a.seed}): |fit - truth| / truth, lines 1-4")
    for i, y in enumerate(profiles):
        u, _ = est.sample_u(y, 4000, a.seed + i, strict=False)
        errors["amortized median"].append(np.median(lf.from_unbounded(u), axis=0)[:4])
        if est.summary is not None:
            t0 = time.perf_counter()
            _, run = smc_route(est, y, settings, a.seed + 1000 + i, a.seed + 2000 + i)
            seconds.append(time.perf_counter() - t0)
            errors["smc median"].append(np.median(lf.from_unbounded(run.draws()), axis=0)[:4])
        row = {k: np.round(np.abs(v[-1] - truths[i]) / truths[i], 3).tolist() for k, v in errors.items() if v}
        print(f"  drone {i}: {row}", flush=True)
    for k, v in errors.items():
        if v:
            e = np.abs(np.array(v) - truths) / truths
            print(f"{k:17s} median {np.round(np.median(e, axis=0), 3).tolist()}  range "
                  f"{np.round(e.min(0), 2).tolist()} - {np.round(e.max(0), 2).tolist()}")
    if seconds:
        print(f"smc run: median {np.median(seconds):.1f} s per drone (range {min(seconds):.1f}-{max(seconds):.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
