"""Is the summary likelihood right at the truth? Its emulator against the simulator, drone by drone.

python tests/benchmarks/emulator_error.py --class QUAD --ramps 32 [--drones 10] [--measurements 200] \
    [--seed 11] [--estimator FILE]

For --drones drones of the calibration prior and as many of the specimen model around
the class reference (where users' drones are), --measurements measurements each are
rendered through the scene and the chain and summarised as the file's summary model
does (whitened folded log-profile, per measurement). Printed per group of drones:

* the emulator's mean error at the truth, squared, in the noise of 5 measurements: (m -
  mu(u))' (S / 5)^-1 (m - mu(u)) less the m-mean's own expected share, m the simulated mean,
  S the simulated covariance of one measurement, mu(u) the emulator's mean (0 on average
  when the emulator is right; the noise of 5 measurements itself gives D, the number of
  components);
* the spread of the eigenvalues of W(u)^-1 S, W(u) the file's learned within-drone
  covariance (all 1 where it is right);
* the mean chi-square of the drone's 5-measurement means under the file's own covariance
  of 5 measurements (learned W, error term and widening: D when the likelihood is
  calibrated at the truth);
* where that chi-square sits: its mean share per direction along the TOP_K directions in
  which the emulated mean moves fastest with u (the leading left singular vectors of the
  Jacobian d mu / d u at the truth, whitened by that covariance), and along the other D -
  TOP_K (1 and 1 when the error model has the right shape; more along the top directions
  says the emulator's error lies where its mean moves with the drone, which moves the
  likelihood's maximum though the chi-square over all D looks right).

1 thread.
"""
from __future__ import annotations

import argparse
import os
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")

import numpy as np  # noqa: E402

N_CAL = 5
TOP_K = 3


def drone_errors(model, lf, x: np.ndarray, z: np.ndarray) -> tuple[float, np.ndarray, float, tuple[float, float]]:
    """(mean error squared in S/5 units, eigenvalues of W^-1 S, mean chi-square of the
    5-measurement means under the file's covariance, that chi-square's mean share per
    direction along the top TOP_K Jacobian directions and along the others) of drone x
    (13E,) from its per-measurement whitened summaries z (m, D)."""
    m, d = z.shape
    u = lf.to_unbounded(lf.quantities(x[None]))
    mu, w, _ = model.nets(u)
    s = np.cov(z.T)
    r = z.mean(0) - mu[0]
    err = float(r @ np.linalg.solve(s / N_CAL, r)) - d * N_CAL / m
    eig = np.sort(np.linalg.eigvals(np.linalg.solve(w[0], s)).real)
    means = z[: (m // N_CAL) * N_CAL].reshape(-1, N_CAL, d).mean(1) - mu[0]
    cov = model.moments(u, N_CAL)[1][0]
    chi2 = float(np.einsum("ij,ij->i", means, np.linalg.solve(cov, means.T).T).mean())
    chol = np.linalg.cholesky(cov)
    step, dim = 1e-3, u.shape[1]
    shifted = model.mean(np.concatenate([u + step * np.eye(dim), u - step * np.eye(dim)]))
    jac = (shifted[:dim] - shifted[dim:]).T / (2 * step)  # (D, d)
    top = np.linalg.svd(np.linalg.solve(chol, jac), full_matrices=False)[0][:, :TOP_K]
    white = np.linalg.solve(chol, means.T).T  # (n, D): chi-square = |white|^2
    along = float(((white @ top) ** 2).sum(1).mean())
    return err, eig, chi2, (along / TOP_K, (chi2 - along) / (d - TOP_K))


def main(argv=None) -> int:
    from dataclasses import replace

    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.generator.augment import Renderer
    from mdaug.inference.amortized.estimator import EstimatorError
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.emulator.summary import folded_log_profile
    from mdaug.inference.likelihood.base import prepare_measured

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", default="QUAD")
    ap.add_argument("--ramps", type=int, default=32)
    ap.add_argument("--drones", type=int, default=10, help="drones per group")
    ap.add_argument("--measurements", type=int, default=200, help="measurements per drone")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--estimator", help="estimator file (default: the shipped one)")
    a = ap.parse_args(argv)
    if a.measurements < 4 * N_CAL:
        raise SystemExit(f"--measurements must be at least {4 * N_CAL}, got {a.measurements}")
    torch.set_num_threads(1)
    try:
        est = find(a.cls, Acquisition.measured(a.ramps), path=a.estimator)
        lf, model = est.label_free, est.summary_model(a.estimator or f"the shipped {a.cls} K = {a.ramps} file")
    except EstimatorError as exc:
        raise SystemExit(str(exc)) from None
    renderer = Renderer(est.spec.acquisition, normalisation="none", radar=est.spec.radar, through_chain=True)
    rng = np.random.default_rng(a.seed)
    print(f"{a.cls} K = {a.ramps}, {a.drones} drones per group, {a.measurements} measurements each; "
          f"D = {model.n_components} components")
    for name, width in (("prior", 0.0), ("specimen model", 1.0)):
        spec = replace(est.spec, near_width=width) if width else est.spec
        xs = spec.sample_vectors(a.drones, rng)
        errs, eigs, chis, shares = [], [], [], []
        for x in xs:
            raw = renderer.render(np.repeat(x[None], a.measurements, axis=0), rng)
            y = prepare_measured(raw, est.spec.radar, "peak", what="simulated profiles")[0]
            e, eig, chi2, share = drone_errors(model, lf, x,
                                               model.whitening(folded_log_profile(y, model.whitening.n_offsets)))
            errs.append(e)
            shares.append(share)
            eigs.append(eig)
            chis.append(chi2)
        eigs = np.array(eigs)
        print(f"{name:15s} mean error squared (S / {N_CAL}): median {np.median(errs):.1f} (range {min(errs):.1f}-"
              f"{max(errs):.1f}); eig(W^-1 S) {eigs.min():.2f}-{eigs.max():.2f} (median {np.median(eigs):.2f}); "
              f"chi-square of 5-measurement means under the file's covariance: median {np.median(chis):.1f} "
              f"(range {min(chis):.1f}-{max(chis):.1f}); per direction along the top {TOP_K} Jacobian directions "
              f"{np.median([v[0] for v in shares]):.2f}, along the other {model.n_components - TOP_K} "
              f"{np.median([v[1] for v in shares]):.2f} (medians; 1 and 1 when the error model's shape is right)",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
