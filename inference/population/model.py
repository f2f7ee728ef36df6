"""Population calibration: the class as a population of drones, not one drone.

Model (the scene simulator's own specimen model, :class:`~mdaug.generator.specimens.
SpecimenSpread`, read in log coordinates): a drone d of the class has the log
parameters y_d = mu + e_d, e_d ~ N(0, Sigma(lambda)), where mu is the class's mean
drone and the five relative spreads lambda = (speed, frequency, amplitude, gamma,
skew) build Sigma:

* ln w_a, ln w_b of every engine: frequency^2 on the diagonal plus speed^2 between
  all of a drone's frequencies (one motor-speed factor scales them together);
* ln A_a, ln A_b, ln A_p, ln A_m: amplitude^2; ln C_p, ln C_m: skew^2;
* ln(Gamma_k / Gamma_0), k >= 1: 2 gamma^2 on the diagonal, gamma^2 between them
  (they share Gamma_0's factor; Gamma_0 itself is fixed: profiles are peak-normalised).

The simulator multiplies by (1 + N(0, spread)); its log is N(0, spread^2) to first
order (at 15%: sd 0.151, mean -0.011), the one approximation of the model.

Inference (what was chosen and why): each drone is calibrated on its own (the
class's trained estimator by default, :mod:`..amortized.calibrate`, or the closed-form
route of :mod:`..calibrate`); its posterior draws, relabelled to the
class reference's labelling (:func:`..space.priors.align_lines`), are summarised as a
Gaussian in y on the coordinates the drone identifies (posterior sd <= 0.5 prior
sd). The role-space prior is flat in its own coordinates (A, w, C; ln Gamma ratios),
so there the posterior is the likelihood: its mean and covariance there, carried to y
at the mean (y = ln x: mean ln m, covariance S_ij / (m_i m_j)). Dividing a Gaussian
fitted in y by the prior's tilt e^y instead (mean - S 1) put the drones' summaries
about one sd below their true values in the population SBC (the drones' likelihoods
are near-Gaussian in x, skewed in y), and the unseen drone's lines above the
population's predictive. With Gaussian drone likelihoods and mu's prior the
calibration's own (flat in x: a tilt e^mu in y; flat in the ln Gamma ratios), mu
integrates out in closed form (a normal-normal model), and the hyper-posterior of the
five spreads is a 5-dimensional density that emcee samples in milliseconds per step, through the one driver and
convergence rule of :func:`..samplers.emcee_run.run_ensemble`. Importance reweighting
of per-drone samples (as in gravitational-wave population analyses) was not used: a
drone's posterior is several times wider than the population spreads in 8-35
coordinates (an amortized HELI drone's line frequencies: 0.27-0.34 x the prior's sd,
against spreads of 2-15%), so the weights of a few thousand draws are degenerate.

Hyperprior: half-normal on each spread, of scale ``factor`` x the specimen model's
stated physical guess (motor speed ~5% with load and battery, build tolerances
~15%; :class:`SpecimenSpread`). With one drone the spreads are not identified:
their posterior is that prior, and the result says the spread was assumed.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...generator.params import IDX, N_PARAMS
from ...generator.specimens import SpecimenSpread
from ..space.priors import align_lines

SPREADS = ("speed", "frequency", "amplitude", "gamma", "skew")
"""The population's hyperparameters (relative spreads, :class:`SpecimenSpread` fields)."""
IDENTIFIED_SD_RATIO = 0.5  # a drone identifies a coordinate when posterior sd <= this x prior sd
_GROUPS = {"amplitude": ("A_a", "A_b", "A_p", "A_m"), "frequency": ("w_a", "w_b"), "skew": ("C_p", "C_m")}


@dataclass(frozen=True)
class Hyperprior:
    """Half-normal priors of the spreads: ``scales`` name -> scale (fractions)."""

    scales: dict = field(default_factory=lambda: Hyperprior.stated().scales)

    def __post_init__(self) -> None:
        bad = {k: v for k, v in self.scales.items() if k not in SPREADS or not (np.isfinite(v) and v > 0)}
        missing = [k for k in SPREADS if k not in self.scales]
        if bad or missing:
            raise ValueError(f"Hyperprior.scales needs a positive finite scale for each of {SPREADS}, "
                             f"got {dict(self.scales)}")

    @classmethod
    def stated(cls, spread: SpecimenSpread = SpecimenSpread(), factor: float = 2.0) -> "Hyperprior":
        """Scales ``factor`` x the specimen model's stated spreads (its physical guesses)."""
        return cls({k: factor * getattr(spread, k) for k in SPREADS})

    @property
    def scale_vector(self) -> np.ndarray:
        return np.array([self.scales[k] for k in SPREADS])

    def log_density(self, u: np.ndarray) -> np.ndarray:
        """Log prior of u = ln(spreads) (..., 5), Jacobian included."""
        s = np.exp(u)
        return np.sum(-0.5 * (s / self.scale_vector) ** 2 + u, axis=-1)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n spread vectors (n, 5)."""
        return np.abs(rng.standard_normal((n, len(SPREADS)))) * self.scale_vector


class PopulationModel:
    """The log coordinates of a class vector and the specimen model's covariance in them.

    ``cols``: flat indices into the (13E,) class vector; ``kinds``: the spread each
    coordinate belongs to; y = ln x except ln(Gamma_k / Gamma_0) for k >= 1.
    """

    def __init__(self, n_engines: int):
        self.E = int(n_engines)
        cols, kinds, names = [], [], []
        for k in range(self.E):
            for kind, group in _GROUPS.items():
                for name in group:
                    cols.append(k * N_PARAMS + IDX[name]), kinds.append(kind), names.append(f"{name}[{k}]")
            if k:
                cols.append(k * N_PARAMS + IDX["Gamma"]), kinds.append("gamma"), names.append(f"lnG[{k}]")
        self.cols, self.kinds, self.names = np.array(cols), np.array(kinds), names
        self.p = len(cols)
        self.linear_prior = self.kinds != "gamma"  # the prior is flat in x; for the Gamma ratios in y
        freq = (self.kinds == "frequency").astype(float)
        gam = (self.kinds == "gamma").astype(float)
        self.basis = np.stack([np.outer(freq, freq),  # speed: common to all of a drone's frequencies
                               np.diag(freq),
                               np.diag((self.kinds == "amplitude").astype(float)),
                               np.diag(gam) + np.outer(gam, gam),
                               np.diag((self.kinds == "skew").astype(float))])  # (5, p, p), order of SPREADS

    def covariance(self, spreads: np.ndarray) -> np.ndarray:
        """Sigma for spreads (..., 5) -> (..., p, p)."""
        return np.einsum("...g,gij->...ij", np.asarray(spreads) ** 2, self.basis)

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Class vectors (n, 13E) -> log coordinates (n, p) (floored at 1e-9); Gamma ratios
        to each vector's own Gamma_0 (a calibrated drone's is the prior's fixed Gamma_0)."""
        x = np.asarray(x, float)
        v = x[:, self.cols]
        v = np.where(self.kinds == "gamma", v / x[:, :1], v)
        return np.log(np.maximum(v, 1e-9))

    def fill(self, x: np.ndarray, y: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Copy of class vectors x (n, 13E) with the coordinates ``mask`` (p,) set from y (n, mask.sum())."""
        out = np.array(x, float)
        v = np.exp(y)
        v = np.where(self.kinds[mask] == "gamma", v * out[:, :1], v)
        out[:, self.cols[mask]] = v
        return out


@dataclass(frozen=True)
class DroneSummary:
    """One drone's likelihood, as a Gaussian in the population's log coordinates.

    ``mask`` (p,): the coordinates it identifies; ``mean`` (k,), ``cov`` (k, k) on
    them (prior divided out); ``draws`` (n, 13E): its posterior draws in the class
    reference's labelling; ``specimen``: its id.
    """

    specimen: str
    mask: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    draws: np.ndarray


def summarise_drone(result, model: PopulationModel, reference: np.ndarray, specimen: str = "") -> DroneSummary:
    """A :class:`DroneSummary` from a drone's :class:`~..result.posterior.CalibrationResult`."""
    x = align_lines(result.draws(), reference)
    y = model.transform(x)
    bounds = result.priors.bounds
    # identified: posterior sd <= IDENTIFIED_SD_RATIO x prior sd (uniform priors: width / sqrt 12), in the
    # prior's own coordinate (x for A, w, C; ln for the Gamma ratios)
    width = np.array([np.subtract(*bounds["lnG" if kind == "gamma" else name.split("[")[0]][::-1])
                      for name, kind in zip(model.names, model.kinds)])
    post_sd = np.where(model.kinds == "gamma", y.std(axis=0), x[:, model.cols].std(axis=0))
    mask = post_sd <= IDENTIFIED_SD_RATIO * width / np.sqrt(12)
    k = int(mask.sum())
    # the prior is flat in its own coordinate, so there the posterior is the likelihood: its moments
    # there, carried to the log coordinates at its mean (first order; the likelihood's peak in y)
    lin = model.linear_prior[mask]
    own = np.where(lin, np.exp(y[:, mask]), y[:, mask])
    centre = own.mean(axis=0)
    mean = np.where(lin, np.log(np.maximum(centre, 1e-9)), centre)
    jac = np.where(lin, 1.0 / np.maximum(centre, 1e-9), 1.0)
    cov = (np.cov(own, rowvar=False).reshape(k, k) if k else np.zeros((0, 0))) * np.outer(jac, jac) \
        + 1e-10 * np.eye(k)
    return DroneSummary(str(specimen), mask, mean, cov, x)


def log_marginal(spreads: np.ndarray, drones: list[DroneSummary], model: PopulationModel, measured: np.ndarray):
    """ln p(drone summaries | spreads) with mu integrated out, and mu's conditional
    posterior: returns (logL (W,), mu_hat (W, q), P (W, q, q)) for spreads (W, 5); q =
    measured.sum() coordinates identified by some drone. mu's prior is the
    calibration's, flat in the amplitudes, frequencies and skews (a tilt e^mu in log
    coordinates; flat in the ln Gamma ratios): a flat prior in log coordinates put the
    class mean, and so new drones, low by its posterior variance (the unseen drone's
    lines ranked high in the population SBC)."""
    sig = model.covariance(np.atleast_2d(spreads))  # (W, p, p)
    W, q = sig.shape[0], int(measured.sum())
    pos = np.cumsum(measured) - 1  # index of each measured coordinate among the q
    P = np.zeros((W, q, q))
    b = np.zeros((W, q))
    logl = np.zeros(W)
    groups: dict[bytes, list[DroneSummary]] = {}
    for d in drones:  # drones that identify the same coordinates are one batch
        groups.setdefault(np.asarray(d.mask, bool).tobytes(), []).append(d)
    for group in groups.values():
        idx = np.flatnonzero(group[0].mask)
        if not idx.size:
            continue  # a drone that identifies nothing says nothing of the spreads
        means = np.stack([d.mean for d in group])  # (G, k)
        c = np.stack([d.cov for d in group])[None] + sig[:, None, idx[:, None], idx[None, :]]  # (W, G, k, k)
        chol = np.linalg.cholesky(c)
        cinv = np.linalg.inv(c)
        cm = np.einsum("wgij,gj->wgi", cinv, means)
        logl -= (np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(-1) + 0.5 * np.einsum("wgi,gi->wg", cm, means)
                 + 0.5 * len(idx) * np.log(2 * np.pi)).sum(-1)
        j = pos[idx]
        P[:, j[:, None], j[None, :]] += cinv.sum(1)
        b[:, j] += cm.sum(1)
    b += model.linear_prior[measured].astype(float)  # mu's prior: exp(t . mu)
    chol = np.linalg.cholesky(P)
    mu = np.linalg.solve(P, b[..., None])[..., 0]
    logl += 0.5 * np.einsum("wi,wi->w", b, mu) - np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(-1) \
        + 0.5 * q * np.log(2 * np.pi)
    return logl, mu, P


def sample_spreads(drones: list[DroneSummary], model: PopulationModel, hyperprior: Hyperprior, rng, *,
                   n_walkers: int = 32, min_tau_multiple: float = 50.0, max_steps: int = 40000,
                   block: int = 1000, time_budget: float | None = None, progress: bool | None = False) -> dict:
    """emcee on ln(spreads) through the one driver and its convergence rule
    (:func:`..samplers.emcee_run.run_ensemble`: blocks of ``block`` steps, at least
    ``min_tau_multiple`` tau with tau stable, else ``max_steps`` or ``time_budget``
    and flagged): returns spreads (n, 5) and mu (n, q) draws (mu from its Gaussian
    conditional given each spread draw), the measured mask (p,), tau, steps, whether
    it converged and why."""
    from ..samplers.emcee_run import run_ensemble
    from ..samplers.ensemble import EmceeSettings
    from ..settings import CalibrationSettings

    measured = np.any([d.mask for d in drones], axis=0)  # none: the spreads keep their prior

    def log_post(u):
        lp = hyperprior.log_density(u)
        ok = np.isfinite(lp) & np.all(u < 5.0, axis=-1)
        out = np.full(len(u), -np.inf)
        if ok.any():
            out[ok] = lp[ok] + (log_marginal(np.exp(u[ok]), drones, model, measured)[0] if measured.any() else 0.0)
        return out

    u0 = np.log(hyperprior.sample(n_walkers, rng) + 1e-6)
    emcee = EmceeSettings(max_steps=max_steps, check_every=block, min_tau_multiple=min_tau_multiple, store_every=1)
    settings = CalibrationSettings(time_budget=time_budget, relabel=0.0, progress=bool(progress),
                                   plugins={"emcee": emcee})
    run = run_ensemble(log_post, u0, settings, int(rng.integers(2**31 - 1)))
    u = run.draws()
    spreads = np.exp(u)
    mu = np.empty((len(u), int(measured.sum())))
    for s in range(0, len(u) if measured.any() else 0, 512):  # mu | spreads ~ N(mu_hat, P^-1)
        _, mu_hat, P = log_marginal(spreads[s:s + 512], drones, model, measured)
        chol = np.linalg.cholesky(P)  # P = L L^T: mu = mu_hat + L^-T z
        z = rng.standard_normal(mu_hat.shape)
        mu[s:s + 512] = mu_hat + np.linalg.solve(np.swapaxes(chol, 1, 2), z[..., None])[..., 0]
    return {"spreads": spreads, "mu": mu, "measured": measured, "tau": run.tau, "steps": int(run.n_steps),
            "converged": bool(run.converged), "acceptance": float(np.mean(run.acceptance)), "reason": run.reason}
