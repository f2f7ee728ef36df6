"""How far the best fit lands from the truth, on drones like a user's.

python tests/benchmarks/best_fit.py --class QUAD --ramps 32 [--drones 11] [--seed 31] [--estimator FILE]

Drones of the specimen model around the class reference (as the study draws new drones;
5 measurements each), each calibrated as ``mdaug calibrate`` does it
(:func:`mdaug.inference.amortized.calibrate.calibrate_amortized`, the file's default
route, seeded by --seed + i). Prints |x - truth| / truth of the brightest engine's four
sorted lines for the calibration's best fit (``best_fit``: the label-free median of the
smc draws where the file has a summary likelihood, ``diagnostics['best_fit_from']``) and
for the label-free median of the posterior's draws (the same where the posterior is the
smc route's), per drone and the medians, and the seconds of each smc run (1 thread).
"""
from __future__ import annotations

import argparse
import os
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")


def main(argv=None) -> int:
    from dataclasses import replace

    import numpy as np
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import find
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
    errors, seconds, source = {"best fit": [], "posterior median": []}, [], set()
    print(f"{a.cls} K = {a.ramps}, {a.drones} specimen drones (seed {a.seed}): |x - truth| / truth, lines 1-4")
    for i, y in enumerate(profiles):
        res = calibrate_amortized(y, a.cls, acquisition=est.spec.acquisition, estimator=est, settings=settings,
                                  random_state=a.seed + i)
        d = res.diagnostics
        source.add(f"{d['best_fit_from']} (posterior: {d['route']} route)")
        if "smc" in d:
            seconds.append(d["smc"]["seconds"])
        errors["best fit"].append(lf.quantities(res.best_fit[None])[0, :4])
        errors["posterior median"].append(np.median(lf.quantities(res.draws()), axis=0)[:4])
        row = {k: np.round(np.abs(v[-1] - truths[i]) / truths[i], 3).tolist() for k, v in errors.items()}
        print(f"  drone {i}: {row}", flush=True)
    print(f"best fit from: {', '.join(sorted(source))}")
    for k, v in errors.items():
        e = np.abs(np.array(v) - truths) / truths
        print(f"{k:17s} median {np.round(np.median(e, axis=0), 3).tolist()}  range "
              f"{np.round(e.min(0), 2).tolist()} - {np.round(e.max(0), 2).tolist()}")
    if seconds:
        print(f"smc run: median {np.median(seconds):.1f} s per drone (range {min(seconds):.1f}-{max(seconds):.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
