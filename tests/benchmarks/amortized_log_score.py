"""Which of two estimator files' amortized posteriors scores the truth better? The exact log score, paired.

python tests/benchmarks/amortized_log_score.py --class QUAD --ramps 32 FILE_A FILE_B \
    [--specimens 200] [--truths 300] [--draws 500] [--seed 6363]

The amortized posterior is a density, so its log score needs no density fitted to draws
(the Gaussian the route table uses for routes without one): -log q(u_true | x), the flow's own density at the truth in
the label-free coordinates u, truncated to the prior (minus the log of the share of q's
draws that fall inside it, from --draws draws). For --specimens drones of the specimen
model around the class reference (where users' drones are) and --truths drones of the
prior, 5 measurements each, the same drones for both files, it prints each file's mean
and median, and the paired difference B - A: mean with its standard error, median, and
the share of drones on which B scores better (negative: B is the better). FILE may be
``shipped`` (the shipped estimator of --class and --ramps). 1 thread.
"""
from __future__ import annotations

import argparse
import os
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")

import numpy as np  # noqa: E402


def exact_log_scores(est, truths_u: np.ndarray, profiles: np.ndarray, draws: int) -> np.ndarray:
    """(R,) -log q(u_true | x) of the amortized posterior truncated to the prior, per drone."""
    return np.array([-est.truncated_log_prob_u(u[None], y, i, draws)[0]
                     for i, (u, y) in enumerate(zip(truths_u, profiles))])


def main(argv=None) -> int:
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.estimator_job import sbc_data
    from dataclasses import replace

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--class", dest="cls", required=True)
    p.add_argument("--ramps", type=int, required=True)
    p.add_argument("files", nargs=2, metavar="FILE")
    p.add_argument("--specimens", type=int, default=200)
    p.add_argument("--truths", type=int, default=300)
    p.add_argument("--draws", type=int, default=500)
    p.add_argument("--seed", type=int, default=6363)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    acq = Acquisition.measured(a.ramps)
    ests = [find(a.cls, acq, path=None if f == "shipped" else f) for f in a.files]
    lf = ests[0].label_free
    for name, spec, n, seed in (("specimen drones", replace(ests[0].spec, near_width=1.0), a.specimens, a.seed),
                                ("prior drones", ests[0].spec, a.truths, a.seed + 1)):
        if n <= 0:
            continue
        vectors, profiles = sbc_data(spec, n, seed)
        u = lf.to_unbounded(lf.quantities(vectors))
        a_s, b_s = (exact_log_scores(e, u, profiles, a.draws) for e in ests)
        d = b_s - a_s
        print(f"{a.cls} K={a.ramps}, {n} {name}: exact log score A {a_s.mean():.2f} (median {np.median(a_s):.2f}), "
              f"B {b_s.mean():.2f} (median {np.median(b_s):.2f}); B - A {d.mean():.2f} +- {d.std() / np.sqrt(n):.2f} "
              f"(median {np.median(d):.2f}), B better on {np.mean(d < 0):.2f} of the drones", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
