"""emcee ensemble MCMC from the fit, resumable through emcee's HDF5 backend.

* Walkers start around the best fit with per-coordinate spreads from the local
  curvature of log p (:func:`curvature_scales`, x ``init_ball``): tight where the
  data pin a parameter, wide (up to 0.3 prior widths) where they do not.
* Moves: differential evolution (``DEMove``, three step scales) taken modulo 2 pi
  on the phases, so phases live on the circle without boundaries, and (a share
  ``settings.relabel``) the line relabelling of :meth:`.priors.Layout.random_relabel`,
  an exact symmetry no translation crosses (:func:`make_moves`).
* The chain runs in blocks of ``check_every`` steps (aligned to absolute step
  numbers, so a resumed run checks at the same steps as an uninterrupted one);
  after each block the integrated autocorrelation time tau of every coordinate is
  estimated (emcee.autocorr) and the run stops when the chain is at least
  ``min_tau_multiple`` x max tau long and tau moved by less than ``tau_rtol``.
  Otherwise it stops at ``max_steps`` and is flagged not converged.
* Resume: every step is written to the HDF5 file together with emcee's random
  state (a legacy ``RandomState``); on restart emcee reads both back, so an
  interrupted run continues to exactly the chain an uninterrupted one would give.
  The file also records a fingerprint of the problem; resuming a different
  problem is refused.
* Memory: every ``store_every``-th step is kept (auto: the chain stays under
  ~160 MB; HELI keeps every step, QUAD about every 14th); tau, burn-in and
  thinning are still counted in steps.
* Walkers are not independent chains: ESS per coordinate is
  n_walkers x (steps after burn-in) / tau, not arviz's R-hat/ESS over walkers.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .priors import wrap

GROUP = "mcmc"
DE_MIX = ((0.25, 0.5), (1.0, 0.4), (None, 0.1))  # (factor of the standard gamma or None = 1.0, weight)


@dataclass
class ChainResult:
    """chain (stored steps, walkers, dim) -- every ``store_every``-th step --,
    log_prob (stored steps, walkers), tau (dim,) in steps, burn and thin in steps,
    acceptance (walkers,), converged, reason, seconds, resumed_at (steps)."""

    chain: np.ndarray
    log_prob: np.ndarray
    tau: np.ndarray
    burn: int
    thin: int
    acceptance: np.ndarray
    converged: bool
    reason: str
    seconds: float
    resumed_at: int = 0
    store_every: int = 1

    @property
    def n_steps(self) -> int:
        return self.chain.shape[0] * self.store_every

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per coordinate from tau (after burn-in)."""
        return self.chain.shape[1] * max(self.n_steps - self.burn, 0) / np.maximum(self.tau, 1.0)

    def _rows(self) -> slice:
        k = self.store_every
        return slice(-(-self.burn // k), None, max(1, self.thin // k))

    def draws(self) -> np.ndarray:
        """Thinned post-burn-in draws (n, dim), step-major."""
        return self.chain[self._rows()].reshape(-1, self.chain.shape[2])

    def draws_log_prob(self) -> np.ndarray:
        return self.log_prob[self._rows()].reshape(-1)


MAX_STORED_FLOATS = 2e7  # chain kept in memory / on disk: ~160 MB of float64


def store_interval(settings, n_walkers: int, dim: int) -> int:
    """Steps per stored step: ``settings.store_every`` or, when 0, the smallest k that
    keeps max_steps / k x walkers x dim under MAX_STORED_FLOATS (QUAD: ~14)."""
    if settings.store_every:
        return int(settings.store_every)
    return max(1, int(np.ceil(settings.max_steps * n_walkers * dim / MAX_STORED_FLOATS)))


def fingerprint(*arrays, text: str = "") -> str:
    h = hashlib.sha256(text.encode())
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:32]


def estimate_tau(chain: np.ndarray, phase_cols=(), discard: float = 1 / 3) -> np.ndarray:
    """Integrated autocorrelation time per coordinate (emcee's estimator, c=5), in steps.

    The first ``discard`` of the chain (the expansion from the start ball) is left
    out. Phases are measured through cos and sin (the larger tau of the two), so a
    wrap at +-pi is not mistaken for a jump.
    """
    import emcee

    chain = chain[int(discard * chain.shape[0]):]
    cols = np.asarray(phase_cols, dtype=int)
    if cols.size:
        ang = chain[..., cols]
        chain = np.concatenate([chain, np.cos(ang), np.sin(ang)], axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        tau = emcee.autocorr.integrated_time(chain, c=5, tol=0, quiet=True)
    # a coordinate some walker never moved in has no estimate: count it as the whole chain
    tau = np.where(np.isfinite(tau), tau, chain.shape[0])
    d = chain.shape[2] - 2 * cols.size
    if cols.size:
        tau_c, tau_s = tau[d: d + cols.size], tau[d + cols.size:]
        tau = tau[:d].copy()
        tau[cols] = np.maximum(tau_c, tau_s)
    return tau


def make_moves(phase_cols, dim: int, relabel=None, p_relabel: float = 0.0):
    """Differential-evolution moves whose proposals are wrapped on the phase columns.

    A DE proposal is a translation x + gamma (x_j - x_k) + noise whose law is symmetric
    under sign change, so taking it modulo 2 pi on the circle keeps it a symmetric
    proposal on the torus (detailed balance holds). The snooker move is not a
    translation and is not used.

    Mixture (``DE_MIX``): scale 0.25 x the standard 2.38 / sqrt(2 dim) (half the
    steps: the posterior's ridges are narrow, the standard scale alone accepts ~2%),
    the standard scale, and gamma = 1 (10%: swaps a walker between the regions
    occupied by two others, the mode-hopping move of ter Braak 2006).
    ``relabel`` (coords, random) -> (coords', log |Jacobian|): a random bijection
    whose inverse is as likely (:meth:`.priors.Layout.random_relabel`), used as an
    emcee ``MHMove`` for a share ``p_relabel`` of the steps (the DE weights shrink).
    """
    import emcee

    cols = np.asarray(phase_cols, dtype=int)

    class WrappedDEMove(emcee.moves.DEMove):
        def get_proposal(self, s, c, random):
            q, f = super().get_proposal(s, c, random)
            if cols.size:
                q[:, cols] = wrap(q[:, cols])
            return q, f

    g_default = 2.38 / np.sqrt(2 * dim)
    share = 1.0 - (p_relabel if relabel is not None else 0.0)
    moves = [(WrappedDEMove(gamma0=f * g_default if f else 1.0), w * share) for f, w in DE_MIX]
    if relabel is not None and p_relabel > 0:
        moves.append((emcee.moves.MHMove(relabel), p_relabel))
    return moves


def curvature_scales(layout, theta_best: np.ndarray, log_post, rel_step: float = 0.01, cap: float = 0.3):
    """Per-coordinate scales (dim,) of the posterior at theta_best: 1 / sqrt(-d2 log p / d theta_j^2)
    by central differences (step ``rel_step`` x prior width), clipped to
    [1e-4, ``cap``] x width. A coordinate the data do not constrain (flat log p) gets
    ``cap`` x its prior width, so walkers start spread over it instead of in a
    ball that would take thousands of steps to expand."""
    lo, hi = layout.z_bounds()
    width = np.concatenate([hi - lo, np.full(layout.M, 2.0)])  # ln sigma: 2 nats
    h = rel_step * width
    pts = np.repeat(theta_best[None], 2 * layout.dim + 1, axis=0)
    idx = np.arange(layout.dim)
    pts[1 + idx, idx] += h
    pts[1 + layout.dim + idx, idx] -= h
    lp = log_post(pts)
    plus, minus = lp[1: 1 + layout.dim], lp[1 + layout.dim:]
    with np.errstate(invalid="ignore"):
        curv = -(plus - 2 * lp[0] + minus) / h**2
    one_sided = ~np.isfinite(curv)  # a bound or the ordering constraint on one side
    side = np.where(np.isfinite(plus), plus, minus)
    curv[one_sided] = -2 * (side[one_sided] - lp[0]) / h[one_sided] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(np.isfinite(curv) & (curv > 0), 1.0 / np.sqrt(curv), np.inf)
    return np.clip(scale, 1e-4 * width, cap * width)


def initial_ball(layout, theta_best: np.ndarray, log_post, n_walkers: int, scale,
                 rng: np.random.Generator) -> np.ndarray:
    """n_walkers points theta_best + scale * N(0, 1) (scale: (dim,) or a fraction of the
    prior widths), all inside the prior support (reflected at bounds, redrawn when
    they break the ordering constraints)."""
    lo, hi = layout.z_bounds()
    if np.ndim(scale) == 0:
        scale = float(scale) * np.concatenate([hi - lo, np.full(layout.M, 2.0)])
    out = np.empty((0, layout.dim))
    for _ in range(200):
        th = theta_best + scale * rng.standard_normal((n_walkers, layout.dim))
        z = th[:, : layout.dim_z]
        box = np.ones(layout.dim_z, bool)
        box[layout.phase_cols] = False
        z[:, box] = lo[box] + np.abs(z[:, box] - lo[box])
        z[:, box] = hi[box] - np.abs(hi[box] - z[:, box])
        z[:, layout.phase_cols] = wrap(z[:, layout.phase_cols])
        th = th[np.isfinite(log_post(th))]
        out = np.concatenate([out, th])[:n_walkers]
        if len(out) == n_walkers:
            return out
    raise ValueError("could not place walkers inside the prior around the best fit "
                     "(is the best fit on the boundary of the ordering constraint w_a < w_b?)")


def _check_backend(path: Path, fp: str, shape) -> int:
    """Iterations already in the backend at ``path`` (0 when new); refuses a foreign file."""
    import h5py

    if not path.exists():
        return 0
    try:
        with h5py.File(path, "r") as f:
            if GROUP not in f:
                raise ValueError(f"{path}: not an mdaug MCMC backend (no group {GROUP!r}); "
                                 "delete it or choose another backend path")
            g = f[GROUP]
            old = g.attrs.get("mdaug_fingerprint")
            it = int(g.attrs.get("iteration", 0))
            if old is not None and str(old) != fp:
                raise ValueError(f"{path}: holds a chain of a different problem (data, class, engines or "
                                 "settings differ); delete it or choose another backend path")
            if it and (int(g.attrs["nwalkers"]), int(g.attrs["ndim"])) != tuple(shape):
                raise ValueError(f"{path}: chain shape ({g.attrs['nwalkers']}, {g.attrs['ndim']}) walkers x dim, "
                                 f"expected {tuple(shape)}")
            return it
    except OSError as exc:
        raise ValueError(f"{path}: not a readable HDF5 file ({exc})") from exc


def run_sampler(log_post, p0: np.ndarray, settings, seed: int, backend_path=None,
                fp: str = "", phase_cols=(), relabel=None) -> ChainResult:
    """Run (or resume) the ensemble; see the module docstring.

    log_post: vectorised callable theta (W, dim) -> (W,); p0: (W, dim) start (ignored
    when the backend already holds steps); seed: int for emcee's RandomState;
    phase_cols: columns that live on the circle (wrapped by the moves); relabel: the
    exact-symmetry move (``settings.relabel`` of the steps), see :func:`make_moves`.
    """
    import emcee

    t0 = time.perf_counter()
    n_walkers, dim = p0.shape
    moves = make_moves(phase_cols, dim, relabel, settings.relabel)
    backend, resumed_at = None, 0
    if backend_path is not None:
        path = Path(backend_path)
        resumed_at = _check_backend(path, fp, (n_walkers, dim))
        backend = emcee.backends.HDFBackend(str(path), name=GROUP)
        if resumed_at == 0:
            backend.reset(n_walkers, dim)
        import h5py

        with h5py.File(path, "a") as f:
            g = f[GROUP]
            g.attrs["mdaug_fingerprint"] = fp
            if resumed_at:  # keep the stored interval of the file (auto k depends on max_steps)
                stored_k = int(g.attrs.get("mdaug_store_every", 1))
            else:
                g.attrs["mdaug_store_every"] = stored_k = store_interval(settings, n_walkers, dim)
    sampler = emcee.EnsembleSampler(n_walkers, dim, log_post, vectorize=True, moves=moves, backend=backend)
    if resumed_at:
        state = None  # emcee restores the last walkers, log-probs and random state
    else:
        state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    k = stored_k if backend_path is not None else store_interval(settings, n_walkers, dim)
    check = -(-settings.check_every // k) * k  # block length, a multiple of k steps
    max_steps = max(k, settings.max_steps // k * k)
    it = resumed_at * k  # steps done (the backend counts stored steps)
    tau, converged, reason = np.full(dim, np.inf), False, ""
    while True:
        if it > 0 and it % check == 0 or it >= max_steps:
            chain = sampler.get_chain()
            tau = estimate_tau(chain, phase_cols) * k
            long_enough = it >= settings.min_tau_multiple * tau.max()
            if long_enough and it > check:
                # tau one block earlier, recomputed (not remembered) so that a resumed
                # run takes exactly the decisions of an uninterrupted one
                tau_prev = estimate_tau(chain[: (it - check) // k], phase_cols) * k
                if np.all(np.abs(tau - tau_prev) <= settings.tau_rtol * tau):
                    converged = True
                    reason = f"chain {it} steps >= {settings.min_tau_multiple:g} x max tau {tau.max():.0f}"
                    break
        if it >= max_steps:
            ratio = it / tau.max()
            reason = (f"NOT CONVERGED: budget of {max_steps} steps ended at {ratio:.1f} x max tau "
                      f"({tau.max():.0f} steps; need {settings.min_tau_multiple:g})")
            if ratio >= settings.min_tau_multiple:
                reason += f"; tau still changing by more than {settings.tau_rtol:.0%} per block"
            elif ratio < 20:
                reason += "; tau is a lower bound (its estimate is capped by the chain length)"
            break
        n = min(max_steps, (it // check + 1) * check) - it
        sampler.run_mcmc(state, n // k, thin_by=k, progress=settings.progress, skip_initial_state_check=True)
        state = None
        it += n
    chain = sampler.get_chain()
    burn = min(int(np.ceil(settings.burn_tau * tau.max())), it // 2)
    thin = max(k, int(settings.thin_tau * tau.min()) // k * k)
    return ChainResult(chain=chain, log_prob=sampler.get_log_prob(), tau=tau, burn=burn, thin=thin,
                       acceptance=np.asarray(sampler.acceptance_fraction, float), converged=converged,
                       reason=reason, seconds=time.perf_counter() - t0, resumed_at=resumed_at * k,
                       store_every=k)
