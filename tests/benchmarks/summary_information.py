"""How much could a summary of the profiles carry? The Cramer-Rao bound of several summaries at
one drone, from the simulator alone (no emulator).

python tests/benchmarks/summary_information.py --class HELI --ramps 32 [--drone reference]
    [--measurements 5] [--draws 3000] [--step 0.02] [--seed 5]

For the class reference drone (or ``--drone specimen``: one drone of the specimen model),
every label-free quantity q_j is moved by +-step (relative) and ``--draws`` measurements
are simulated through the acquisition at each point with the same random numbers (common
random numbers, so the difference of the means is the derivative, not noise). For each
summary s of one measurement, J = d E[s] / d log q (central differences; relative units,
so that lines in rad/s and amplitudes in m are on one scale) and S = Cov(s) at the drone
(Ledoit-Wolf shrinkage); the Fisher information of M measurements is M J' S^-1 J and the
bound's 90% width over the truth is 2 x 1.645 x sqrt((I^-1)_jj).
It is the bound of a Gaussian model of the summary: what any likelihood or network on that
summary can reach at best, marginal over every other label-free quantity.

Summaries: the folded log-profile the summary likelihood whitens (128 offsets, the two
sides averaged), the two sides apart (256 offsets), and the same folded profile cut to
the 32 whitened components the shipped file uses (when it has a summary likelihood).
Estimates: noise in J adds tr(S^-1 Cov(J_hat)) to J' S^-1 J (the renderer's random draws do
not cancel fully between the two points: the plain estimate grew from 0.33 to 0.80 for HELI's
line 1 between 400 and 6,000 draws); that term, from the draws' own differences, is
subtracted. With S estimated from N draws in p dimensions the information is still overstated
by about N / (N - p) (1.09 for 256 of 3,000). The split-half line (J and S from each half of
the draws alone) shows how far the figures move. A marginal bound also depends on how the
slopes line up with each other, and noisy slopes of faintly seen quantities look more
independent than they are: where a quantity's slope is not well above its noise, the other
quantities' bounds come out too narrow (docs/calibration-history.md, HELI K = 32: at 3,000 draws this
does not settle line 3).
"""
from __future__ import annotations

import argparse
import os
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")


def summaries(profiles, n_offsets: int, whitening=None) -> dict:
    """Per-measurement summaries (N, p) of peak-normalised profiles (N, L)."""
    import numpy as np

    from mdaug.inference.emulator.summary import FLOOR, folded_log_profile

    lg = np.log10(np.maximum(profiles, FLOOR))
    c = profiles.shape[-1] // 2
    k = np.arange(1, n_offsets + 1)
    out = {"folded log-profile (128)": folded_log_profile(profiles, n_offsets),
           "two sides apart (256)": np.concatenate([lg[:, c - k], lg[:, c + k]], axis=1)}
    if whitening is not None:
        out["the file's 32 whitened components"] = whitening(folded_log_profile(profiles, whitening.n_offsets))
    return out


def bound(diffs, draws, m: int):
    """90% width / truth (d,) of the Cramer-Rao bound for m measurements. diffs (N, p, d): per
    draw, the summary's difference between the two points of each quantity over the step in
    log q (their mean is J = d E[s] / d log q); draws (N, p): the summary at the drone. The
    noise of J's mean, tr(S^-1 Cov(d_j, d_k)) / N, is taken off J' S^-1 J (module doc)."""
    import numpy as np
    from sklearn.covariance import LedoitWolf

    from mdaug.inference.emulator.model import cramer_rao

    n = len(diffs)
    jac = diffs.mean(0)
    cov = LedoitWolf().fit(draws).covariance_
    dev = diffs - jac  # (N, p, d)
    sinv_dev = np.linalg.solve(cov, dev.transpose(1, 0, 2).reshape(cov.shape[0], -1)).reshape(cov.shape[0], n, -1)
    noise = np.einsum("npj,pnk->jk", dev, sinv_dev) / (n - 1) / n  # tr(S^-1 Cov(d_j, d_k)) / N
    info = m * (jac.T @ np.linalg.solve(cov, jac) - noise)
    w, v = np.linalg.eigh(0.5 * (info + info.T))
    info = (v * np.maximum(w, 0.0)) @ v.T  # noise may take a direction below zero: it carries nothing
    return 2 * 1.645 * np.sqrt(np.diag(cramer_rao(info)))


def main(argv=None) -> int:
    import numpy as np

    from mdaug.generator.augment import Renderer
    from mdaug.generator.specimens import SpecimenSpread
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import shipped_path
    from mdaug.inference.likelihood.base import prepare_measured

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", required=True)
    ap.add_argument("--ramps", type=int, required=True)
    ap.add_argument("--drone", choices=("reference", "specimen"), default="reference")
    ap.add_argument("--measurements", type=int, default=5)
    ap.add_argument("--draws", type=int, default=3000)
    ap.add_argument("--step", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    est = AmortizedEstimator.load(shipped_path(a.cls, a.ramps))
    lf, spec = est.label_free, est.spec
    x0 = spec.reference.to_array()
    if a.drone == "specimen":
        x0 = SpecimenSpread().apply(x0[None], np.random.default_rng(a.seed))[0]
    q0 = lf.quantities(x0[None])[0]
    renderer = Renderer(spec.acquisition, normalisation="none", radar=spec.radar, through_chain=True)

    def simulate(q):
        x, ok = lf.vectors(q[None])
        if not ok[0]:
            raise SystemExit(f"a step of {a.step} leaves the prior at this drone; give a smaller --step")
        raw = renderer.render(np.repeat(x, a.draws, axis=0), np.random.default_rng(a.seed + 1))
        y, _ = prepare_measured(raw, spec.radar, "peak", what="simulated profiles")
        return summaries(y, 128, est.summary.whitening if est.summary is not None else None)

    centre = simulate(q0)
    d = len(q0)
    half = a.draws // 2
    parts = {"all": slice(None), "first": slice(None, half), "second": slice(half, None)}
    diffs = {name: np.empty(s.shape + (d,)) for name, s in centre.items()}
    for j in range(d):
        up, down = q0.copy(), q0.copy()
        up[j] *= 1 + a.step
        down[j] *= 1 - a.step
        su, sd = simulate(up), simulate(down)
        for name, dm in diffs.items():
            dm[:, :, j] = (su[name] - sd[name]) / (2 * a.step)
    print(f"{a.cls} K = {a.ramps}, the {a.drone} drone, {a.measurements} measurements; Cramer-Rao 90% width / truth "
          f"({a.draws} draws a point, {time.perf_counter() - t0:.0f} s)")
    print(f"{'summary':36s} " + " ".join(f"{n:>11s}" for n in lf.names))
    for name, s in centre.items():
        w = bound(diffs[name], s, a.measurements)
        print(f"{name:36s} " + " ".join(f"{v:11.2f}" for v in w))
        w1, w2 = (bound(diffs[name][parts[p]], s[parts[p]], a.measurements) for p in ("first", "second"))
        print(f"{'  (each half of the draws for S)':36s} " + " ".join(f"{x:5.2f}/{y:5.2f}" for x, y in zip(w1, w2)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
