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

--compare-medians: the smc draws are kept (``check=True``: the same seeds, the same run)
and centres of them are compared on every engine's four lines, not the brightest alone,
each engine of a centre matched to the true engine whose sorted lines are nearest (the
brightness order swaps engines of about equal Gamma): the shipped best fit (the
label-free median, :func:`mdaug.inference.amortized.calibrate.label_free_median`), the
component-wise median of the class vectors (the best fit of earlier releases) and the
amortized posterior's label-free median; for the smc draws and the posterior's, the
quantities whose truth most often falls outside their central 90% interval (with the
truth's quantile in the prior: a quantity the data do not carry follows the prior);
and, where the file has a summary likelihood, how far each centre's expected summary lies
from the truth's in the noise of 5 measurements (sqrt of (mu_c - mu_t)' Sigma_t^-1
(mu_c - mu_t), the summary model's mean and covariance at the truth): a label-free
distance in what the data carry, 1 about one noise sd of the summary. --save FILE keeps
the truths and centres (npz).
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
    from mdaug.inference.amortized.calibrate import calibrate_amortized, label_free_median
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
    ap.add_argument("--compare-medians", action="store_true", help="every engine: label-free vs component-wise median")
    ap.add_argument("--save", help="npz file for the truths and centres (with --compare-medians)")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    est = (AmortizedEstimator.load(a.estimator) if a.estimator
           else find(a.cls, Acquisition.measured(a.ramps)))
    lf = est.label_free
    vectors, profiles = sbc_data(replace(est.spec, near_width=1.0), a.drones, a.seed, workers=a.workers)
    truths = lf.quantities(vectors)[:, :4]
    settings = CalibrationSettings(progress=False, time_budget=600)
    errors, seconds, source = {"best fit": [], "posterior median": []}, [], set()
    kept, dist, drawn = {}, {}, {}
    if a.compare_medians:
        errors["component-wise"] = []
    print(f"{a.cls} K = {a.ramps}, {a.drones} specimen drones (seed {a.seed}): |x - truth| / truth, "
          + ("every engine's lines 1-4 (engines matched to the truth's)" if a.compare_medians else "lines 1-4"))
    for i, y in enumerate(profiles):
        res = calibrate_amortized(y, a.cls, acquisition=est.spec.acquisition, estimator=est, settings=settings,
                                  random_state=a.seed + i, check=a.compare_medians)
        d = res.diagnostics
        source.add(f"{d['best_fit_from']} (posterior: {d['route']} route)")
        if "smc" in d:
            seconds.append(d["smc"]["seconds"])
        if not a.compare_medians:
            errors["best fit"].append(np.abs(lf.quantities(res.best_fit[None])[0, :4] / truths[i] - 1))
            errors["posterior median"].append(np.abs(np.median(lf.quantities(res.draws()), axis=0)[:4] / truths[i] - 1))
        else:
            smc = res.route_draws("smc")
            for k, v in (("smc", smc), ("posterior", res.draws())):
                drawn.setdefault(k, []).append(lf.quantities(v))
            centres = {"best fit": res.best_fit, "posterior median": label_free_median(lf, res.draws())[0],
                       "component-wise": np.median(smc, axis=0)}
            for k, v in centres.items():
                errors[k].append(_matched_lines(lf, v, vectors[i]))
                kept.setdefault(k, []).append(v)
                if est.summary is not None:
                    dist.setdefault(k, []).append(_summary_distance(est, v, vectors[i]))
        print(f"  drone {i}: " + ", ".join(f"{k} {np.mean(v[-1]):.3f}" for k, v in errors.items())
              + " (mean |x - truth| / truth)", flush=True)
    print(f"best fit from: {', '.join(sorted(source))}")
    for k, v in errors.items():
        e = np.array(v)
        print(f"{k:17s} median {np.round(np.median(e, axis=0), 3).tolist()}  range "
              f"{np.round(e.min(0), 2).tolist()} - {np.round(e.max(0), 2).tolist()}"
              + (f"  all lines: median {np.median(e):.3f}, mean {e.mean():.3f}" if a.compare_medians else ""))
    for k, v in dist.items():
        print(f"{k:17s} summary distance to the truth: median {np.median(v):.2f}, per drone {np.round(v, 2).tolist()}")
    if drawn:
        from mdaug.inference.diagnostics.routes import coverage

        space = est.spec.space()
        prior_q = lf.quantities(space.vectors(space.sample_prior(20000, np.random.default_rng(a.seed))))
        tq = lf.quantities(vectors)
        for k, qs in drawn.items():
            n = min(len(q) for q in qs)
            cov = coverage(np.stack([q[:n] for q in qs], axis=1), tq, lf.names)
            share = 1 - np.array([cov["coverage_by_quantity"][name]["0.90"] for name in lf.names])
            worst = np.argsort(-share, kind="stable")[:5]
            print(f"{k:17s} truth outside its 90% interval on {1 - cov['coverage']['0.90']:.3f} of (drone, quantity); "
                  "most often: "
                  + ", ".join(f"{lf.names[j]} {share[j]:.2f} (the truth at the prior's "
                              f"{np.median(np.mean(prior_q[:, j][:, None] < tq[:, j], axis=0)):.2f} quantile)"
                              for j in worst))
    if a.save and kept:
        np.savez(a.save, truths=vectors, **{k.replace(" ", "_").replace("-", "_"): np.array(v) for k, v in kept.items()})
    if seconds:
        print(f"smc run: median {np.median(seconds):.1f} s per drone (range {min(seconds):.1f}-{max(seconds):.1f})")
    return 0


def _matched_lines(lf, x, truth):
    """|w - w_true| / w_true (4E,) of class vector x's sorted lines against the truth's,
    engines in the truth's brightness order, each of x's engines matched to the true
    engine whose sorted lines are nearest (sum of |log w - log w_true|)."""
    import itertools

    import numpy as np

    from mdaug.inference.space.priors import label_free_lines

    e = lf.E
    w = label_free_lines(np.reshape(x, (1, e, 13)), by_brightness=True)[0, :, :, 0]  # (E, 4)
    wt = label_free_lines(np.reshape(truth, (1, e, 13)), by_brightness=True)[0, :, :, 0]
    perm = min(itertools.permutations(range(e)), key=lambda p: np.abs(np.log(w[list(p)] / wt)).sum())
    return np.abs(w[list(perm)] / wt - 1).reshape(-1)


def _summary_distance(est, x, truth, n_measurements: int = 5) -> float:
    """sqrt((mu(x) - mu(t))' Sigma(t)^-1 (mu(x) - mu(t))) in the file's summary model: the
    expected whitened summary of drone x against the truth's, in the noise of the mean
    of n measurements of the truth (no widening)."""
    import numpy as np

    lf, model = est.label_free, est.summary
    u = lf.to_unbounded(lf.quantities(np.stack([x, truth])))
    mu = model.mean(u)
    _, cov = model.moments(u[1:], n_measurements, widen=False)
    d = mu[0] - mu[1]
    return float(np.sqrt(d @ np.linalg.solve(cov[0], d)))


if __name__ == "__main__":
    raise SystemExit(main())
