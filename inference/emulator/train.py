"""Training a :class:`.model.SummaryModel` from simulated drones.

Drones (class vectors x (N, 13E)) with M >= 2 measurements each (profiles (N, M, L),
peak-normalised; :func:`mdaug.inference.amortized.simulate.simulate` makes them) are
split, by a seeded permutation, into a training share and two held-out shares:

1. training: the whitening (:class:`.summary.Whitening`), the emulator of the mean
   (:class:`.net.Emulator`) on each drone's mean summary, and the within-drone
   covariance network (:class:`.net.CovarianceNet`) on the deviations from it;
2. held-out A: the emulator's own error, a(u) W(u) + b(u) I (:class:`.net.ErrorNet`,
   started from the pooled constants a, b), by maximum likelihood of its residuals
   (the M-measurement means; their noise W / M is part of the model);
3. held-out B: the inflation c >= 1: the median chi-square of the truth's residual for
   ``n_calibration``-measurement subsets (at most the drones' M) over its expected median;
   then, on ``n_widening`` of them, the widening w(u) (:mod:`.model`): twice the gap
   between the likelihood's global maximum and its value at the truth is taken as
   w(u) x a chi-square of d degrees of freedom, log w linear and quadratic in u, fitted
   by maximum likelihood and floored at 1 (the model's covariance scaled until the
   truth sits where a chi-square says it should). The maximum is searched by BOBYQA
   from the truth and from the ``n_starts`` training drones whose summaries lie
   nearest the held-out drone's: a search from the truth alone finds the nearest
   local maximum and misses the distant ones that emcee, started from the whole
   amortized posterior, does find (on held-out HELI K = 32 prior drones: median gap
   11.1 from the truth alone, 15.1 with the other starts).

Nothing here sees the drones an SBC or a study tests on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from .model import SummaryModel, gaussian_log_density
from .net import CovarianceNet, Emulator, ErrorNet, fit, fit_covariance, fit_error
from .sketch import sketch
from .summary import Whitening, folded_log_profile


@dataclass(frozen=True)
class EmulatorConfig:
    """Sizes and training knobs: ``n_offsets`` bins of the folded profile, ``n_components``
    whitened components kept, hidden widths, epochs, the held-out shares, and the
    number of measurements the inflation is chosen for."""

    n_offsets: int = 128
    n_components: int = 32
    hidden: int = 256
    depth: int = 3
    members: int = 4
    cov_hidden: int = 256
    epochs: int = 300
    cov_epochs: int = 150
    held_out: float = 0.1
    n_calibration: int = 5
    n_widening: int = 300
    n_starts: int = 6

    def to_dict(self) -> dict:
        import dataclasses

        return dataclasses.asdict(self)


def train_summary_model(x: np.ndarray, profiles: np.ndarray, label_free, class_name: str,
                        acquisition: Acquisition, radar: RadarConfig = RadarConfig(),
                        config: EmulatorConfig = EmulatorConfig(), *, seed: int = 0, log=print) -> tuple[SummaryModel, dict]:
    """The model and a report of its training (module doc)."""
    x = np.asarray(x, float)
    profiles = np.asarray(profiles)
    n, m = profiles.shape[:2]
    if m < 2:
        raise ValueError(f"need at least 2 measurements per drone (the within-drone covariance), got {m}")
    s = folded_log_profile(profiles, config.n_offsets)  # (N, M, F)
    u = label_free.to_unbounded(label_free.quantities(x))
    sk = sketch(label_free.from_unbounded(u), label_free.E, config.n_offsets, radar)
    perm = np.random.default_rng(seed).permutation(n)
    n_out = max(2, int(round(config.held_out * n)))
    if n - 2 * n_out < 10:
        raise ValueError(f"too few drones to train the summary likelihood: {n} (needs 10 to train on after two "
                         f"held-out shares of {config.held_out:g})")
    held_a, held_b, train = perm[:n_out], perm[n_out: 2 * n_out], perm[2 * n_out:]
    wh = Whitening.fit(s[train], config.n_components)
    z_all = wh(s)  # (N, M, D)
    z = z_all.mean(1)
    nets, hists = [], []
    for k in range(config.members):  # a bagged ensemble: each member its own seed (split, batches, start)
        net = Emulator.member(label_free.dim, wh.basis, wh.centre, config.hidden, config.depth)
        hists.append(fit(net, u[train], sk[train], z[train], seed=seed + k, epochs=config.epochs))
        nets.append(net)
    net = Emulator.stack(nets)
    best_epochs, member_val = [h["best_epoch"] for h in hists], float(np.mean([h["best_val"] for h in hists]))
    log(f"emulator: {len(train)} drones, {config.members} member(s), best epochs {best_epochs}, validation mse "
        f"{member_val:.4f} per member")
    cov_net = CovarianceNet(label_free.dim, config.n_offsets, config.n_components, config.cov_hidden)
    chist = fit_covariance(cov_net, u[train], sk[train], z_all[train], seed=seed, epochs=config.cov_epochs)
    log(f"within-drone covariance: best epoch {chist['best_epoch']}, validation nll {chist['best_val']:.4f}")
    error_net = ErrorNet(label_free.dim)
    model = SummaryModel(class_name, acquisition, radar, label_free, wh, net, cov_net, error_net)
    mean_a, w_a, _ = model.nets(u[held_a])
    ens_mse = float(((mean_a - z[held_a]) ** 2).mean())
    log(f"emulator: the ensemble's mean squared error on {len(held_a)} held-out drones {ens_mse:.4f}")
    alpha, beta = _error_model(w_a, z[held_a] - mean_a, m)
    ehist = fit_error(error_net, u[held_a], w_a, z[held_a] - mean_a, m, start=(alpha, beta), seed=seed)
    ab = model.nets(u[held_a])[2]  # the fitted error network's
    log(f"emulator error: pooled a {alpha:.4f}, b {beta:.4f}; per drone a {np.median(ab[:, 0]):.4f} "
        f"({np.quantile(ab[:, 0], 0.1):.4f}-{np.quantile(ab[:, 0], 0.9):.4f}), b {np.median(ab[:, 1]):.4f} "
        f"({np.quantile(ab[:, 1], 0.1):.4f}-{np.quantile(ab[:, 1], 0.9):.4f}), best epoch {ehist['best_epoch']}")
    k = min(config.n_calibration, m)  # the drones' measurements bound the subsets
    chi = residual_chi2(model, u[held_b], z_all[held_b][:, :k].mean(1), k)
    from scipy.stats import chi2

    ratio = float(np.median(chi) / chi2.median(config.n_components))
    model.inflation = max(1.0, ratio)
    log(f"inflation: median chi-square / expected {ratio:.3f} -> c = {model.inflation:.3f}")
    if config.n_widening:
        hb = held_b[: config.n_widening]
        z_b = z_all[hb][:, :k].mean(1)
        starts = nearest_drones(z[train], u[train], z_b, config.n_starts)
        gaps = likelihood_gaps(model, u[hb], z_b, k, starts=starts)
        model.widening = fit_widening(u[hb], gaps, label_free.dim)
        w = model.widen(u[hb])
        log(f"widening: 2 x likelihood gap at the truth median {np.median(gaps):.2f} (chi-square {label_free.dim}: "
            f"{chi2.median(label_free.dim):.2f}), q90 {np.quantile(gaps, 0.9):.2f} ({chi2.ppf(0.9, label_free.dim):.2f}); "
            f"w(u) median {np.median(w):.2f}, 10-90% {np.quantile(w, 0.1):.2f}-{np.quantile(w, 0.9):.2f}")
    report = {"config": config.to_dict(), "n_drones": int(n), "n_train": int(len(train)),
              "emulator_best_epoch": best_epochs, "emulator_val_mse": member_val,
              "emulator_held_out_mse": ens_mse,
              "covariance_best_epoch": chist["best_epoch"], "covariance_val_nll": float(chist["best_val"]),
              "error_pooled": [alpha, beta], "error_best_epoch": ehist["best_epoch"], "chi2_median_ratio": ratio,
              "chi2_q90_ratio": float(np.quantile(chi, 0.9) / chi2.ppf(0.9, config.n_components)),
              "inflation": model.inflation, "seed": int(seed)}
    if model.widening:
        report["gap_median"] = float(np.median(gaps))
        report["gap_q90"] = float(np.quantile(gaps, 0.9))
    return model, report


def residual_chi2(model: SummaryModel, u: np.ndarray, z_bar: np.ndarray, n_measurements: int) -> np.ndarray:
    """(N,) chi-square of z_bar - mu(u) under the model's covariance for n measurements."""
    mean, cov = model.moments(u, n_measurements)
    r = z_bar - mean
    return np.einsum("ni,ni->n", r, np.linalg.solve(cov, r[..., None])[..., 0])


def _error_model(w: np.ndarray, r: np.ndarray, m: int) -> tuple[float, float]:
    """alpha, beta >= 0 maximising sum_i log N(r_i; 0, W_i (1 / m + alpha) + beta I): the
    pooled emulator error, from residuals r (N, D) = z_bar - mu(u) and W (N, D, D)."""
    from scipy.optimize import minimize

    eye = np.eye(w.shape[-1])

    def nll(t):
        a, b = np.exp(t)
        c = np.linalg.cholesky(w * (1.0 / m + a) + b * eye)
        y = np.linalg.solve(c, r[..., None])[..., 0]
        return float(np.log(np.diagonal(c, axis1=1, axis2=2)).sum() + 0.5 * (y * y).sum())

    best = minimize(nll, np.log([0.05, 0.01]), method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-3})
    a, b = np.exp(best.x)
    return float(a), float(b)


def nearest_drones(z_train: np.ndarray, u_train: np.ndarray, z: np.ndarray, k: int) -> np.ndarray:
    """(N, k, d): for each whitened summary z (N, D), the u of the k training drones
    (summaries z_train (T, D), coordinates u_train (T, d)) nearest it (Euclidean in the
    whitened components, where the within-drone spread is the identity)."""
    if k <= 0:
        return np.zeros((len(z), 0, u_train.shape[1]))
    d2 = (z * z).sum(1)[:, None] - 2 * z @ z_train.T + (z_train * z_train).sum(1)[None]
    idx = np.argsort(d2, axis=1)[:, :k]
    return u_train[idx]


def likelihood_gaps(model: SummaryModel, u: np.ndarray, z_bar: np.ndarray, n_measurements: int,
                    max_eval: int = 400, starts: np.ndarray | None = None,
                    plug_in: np.ndarray | None = None) -> np.ndarray:
    """(N,) twice the gap between the summary likelihood's maximum and its value at the
    truth u (N, d), for the whitened means z_bar (N, D) of n measurements; the model's
    widening left out. The maximum: BOBYQA from the truth and from each of ``starts``
    (N, k, d) if given, in the box the truth and the starts span, padded by 1 (3 about the
    truth alone). plug_in (N, d): the covariance held at plug_in[i], as the smc route
    holds it (:class:`.posterior.EmulatedPosterior`); None: free in u."""
    import nlopt

    out = np.zeros(len(u))
    starts = np.zeros((len(u), 0, u.shape[1])) if starts is None else np.asarray(starts, float)
    for i, (ui, zi) in enumerate(zip(u, z_bar)):
        chol = None if plug_in is None else np.linalg.cholesky(
            model.moments(np.asarray(plug_in[i], float)[None], n_measurements, widen=False)[1][0])

        def loglik(t, grad, zi=zi, chol=chol):
            if chol is None:
                v = model.log_likelihood(t[None], zi, n_measurements, widen=False)[0]
            else:
                v = gaussian_log_density(model.mean(t[None]) - zi, chol)[0]
            return float(v) if np.isfinite(v) else -1e12

        pts = np.concatenate([ui[None], starts[i]])
        pad = 3.0 if len(pts) == 1 else 1.0
        lo, hi = pts.min(0) - pad, pts.max(0) + pad
        at_truth = loglik(ui, None)
        best = at_truth
        for p0 in pts:
            opt = nlopt.opt(nlopt.LN_BOBYQA, len(ui))
            opt.set_max_objective(loglik)
            opt.set_maxeval(int(max_eval))
            opt.set_lower_bounds(lo)
            opt.set_upper_bounds(hi)
            opt.set_initial_step(0.05)
            try:
                opt.optimize(p0.copy())
            except (nlopt.RoundoffLimited, RuntimeError, ValueError):
                pass  # BOBYQA stopped early: the best point it reached still counts
            found = opt.last_optimum_value()
            if np.isfinite(found):
                best = max(best, found)
        out[i] = 2.0 * max(best - at_truth, 0.0)
    return out


def reference_gaps(model: SummaryModel, u: np.ndarray, plug_in: np.ndarray, n_measurements: int,
                   draws: int = 2, seed: int = 0, max_eval: int = 600) -> np.ndarray:
    """(N,) the mean twice-gap a right likelihood would show at drones u (N, d): summaries
    drawn from the model itself, z* ~ N(mu(u), Sigma held at plug_in), ``draws`` per drone,
    each gap found as :func:`likelihood_gaps` finds it (BOBYQA from the truth and from the
    plug-in point). Where the data identify few of d quantities (QUAD: about 10 of 35, the
    prior bounding the rest), this is far below chi-square(d)'s mean d, so d is the wrong
    yardstick for the real gaps; this reference is each drone's own."""
    rng = np.random.default_rng(seed)
    u, plug_in = np.atleast_2d(np.asarray(u, float)), np.atleast_2d(np.asarray(plug_in, float))
    out = np.zeros(len(u))
    for i, (ui, pi) in enumerate(zip(u, plug_in)):
        mu = model.mean(ui[None])[0]
        chol = np.linalg.cholesky(model.moments(pi[None], n_measurements, widen=False)[1][0])
        z = mu + rng.normal(size=(draws, len(mu))) @ chol.T
        out[i] = np.mean(likelihood_gaps(model, np.repeat(ui[None], draws, 0), z, n_measurements, max_eval,
                                         starts=np.repeat(pi[None, None], draws, 0),
                                         plug_in=np.repeat(pi[None], draws, 0)))
    return out


def fit_widening(u: np.ndarray, gaps: np.ndarray, dim, quadratic: bool = True) -> dict:
    """The widening's model (:mod:`.model`): gaps_i ~ w(u_i) chi2_dim, log w = intercept +
    slope . t + quadratic . t^2, t = (u - centre) / scale, by maximum likelihood (L-BFGS
    on the analytic gradient), slopes and quadratic terms shrunk by a weak ridge; the
    quadratic terms (which let the edges of the prior widen more than its middle) only
    with ``quadratic``. dim: chi-square's degrees of freedom, one for all or (N,) one per
    drone (e.g. :func:`reference_gaps`)."""
    from scipy.optimize import minimize

    centre, scale = u.mean(0), np.maximum(u.std(0), 1e-9)
    t = (u - centre) / scale
    feats = np.concatenate([np.ones((len(u), 1)), t] + ([t * t] if quadratic else []), axis=1)
    g = np.maximum(np.asarray(gaps, float), 1e-6)
    k = np.asarray(dim, float) / 2.0

    def nll(p):  # -sum log chi2_dim(g / w) / w, up to a constant, + ridge on all but the intercept
        logw = feats @ p
        r = g * np.exp(-logw)
        val = -((k - 1) * np.log(r) - 0.5 * r - logw).sum() + 0.5 * np.sum(p[1:] ** 2)
        grad = -feats.T @ (-(k - 1) + 0.5 * r - 1.0)
        grad[1:] += p[1:]
        return float(val), grad

    best = minimize(nll, np.zeros(feats.shape[1]), jac=True, method="L-BFGS-B")
    d = u.shape[1]
    out = {"intercept": float(best.x[0]), "slope": best.x[1: d + 1].tolist(), "centre": centre.tolist(),
           "scale": scale.tolist()}
    if quadratic:
        out["quadratic"] = best.x[d + 1:].tolist()
    return out


def raise_widening(widening: dict, power: float = 1.0, scale: float = 1.0) -> dict:
    """The widening w(u)^power x scale (a copy): log w's intercept, slopes and quadratic
    terms times ``power``, then log ``scale`` added to the intercept.

    A constant scale widens every drone alike, where the gap fit found the emulator right
    (w near 1: the drones near the class reference it was trained on densely) as much as
    where it found it wrong. A power > 1 widens most where the fitted w is already
    largest and leaves drones the fit put at w = 1 at 1: one extra number, chosen like
    the scale by the route's SBC on held-out drones (docs/calibration-history.md, HELI K = 32).
    ``model.widen`` still clips log w to [0, 5], so the result is max(1, w_raw^power x
    scale), w_raw the fit before its clip. ``raise_widening(w, 1 / p, s ** (-1 / p))``
    undoes ``raise_widening(w, p, s)``."""
    if not (np.isfinite(power) and power > 0):
        raise ValueError(f"power must be a finite number > 0, got {power!r}")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
    out = {k: (list(v) if isinstance(v, (list, tuple, np.ndarray)) else v) for k, v in widening.items()}
    out["intercept"] = float(power * widening["intercept"] + np.log(scale))
    for key in ("slope", "quadratic"):
        if key in widening:
            out[key] = (float(power) * np.asarray(widening[key], float)).tolist()
    return out
