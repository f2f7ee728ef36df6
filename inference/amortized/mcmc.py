"""nlopt + emcee on the learned likelihood.

The target, in the label-free coordinates u (:mod:`.target`): the calibration
prior's density there (:meth:`.target.LabelFree.log_prior_u`, in closed form: the
uniform box pushed through the label-free map) times the learned likelihood, the
per-measurement ratio network summed over the measurements as independent
(log p(x | u) - log p(x)). Not the amortized posterior's own density: the two routes
are learned apart and judged by the same SBC. Label-free coordinates have no
labelling symmetry and no walls but the prior's support, so the chain mixes.

Starts come from amortized draws: nlopt (a local derivative-free polish, BOBYQA in a
box around the draws) from the best of them, emcee's walkers from others; the
sampler is the calibration's one emcee driver
(:func:`mdaug.inference.samplers.emcee_run.run_ensemble`: DE moves, 50 tau with tau stable, time
budget, Ctrl-C), so the same convergence rule applies, with emcee's own moves for a
smooth target (:func:`~mdaug.inference.samplers.emcee_run.smooth_moves`: no phases,
no labelling symmetry in these coordinates). (Proposing a share of the moves
from the amortized posterior, independence Metropolis-Hastings, was tried and dropped:
on the default study's drones it left tau where it was, 140-160 steps HELI, 200-210
QUAD, at 2-3x the seconds per step, the flow's density being the dear part.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...radar.seeds import seed_sequence
from ..samplers.emcee_run import run_ensemble, smooth_moves
from ..samplers.base import SamplerRun


@dataclass
class LearnedPosterior:
    """log prior + learned log-likelihood of label-free draws u (W, d); vectorised."""

    estimator: object
    profiles: np.ndarray

    def __post_init__(self):
        self.label_free = self.estimator.label_free
        self.emb = self.estimator.embed(self.profiles)
        self.dim = self.label_free.dim
        self.n_calls = 0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(u)
        lp = self.label_free.log_prior_u(u)
        ok = np.isfinite(lp)
        if ok.any():
            lp[ok] += self.estimator.log_likelihood_u(u[ok], self.emb).sum(axis=1)
        self.n_calls += len(u)
        return lp

    def vectors(self, u: np.ndarray) -> np.ndarray:
        """Class vectors (n, 13E) of draws u (the prior's labelling closest to the reference)."""
        x, _ = self.label_free.vectors(self.label_free.from_unbounded(u))
        return x


def polish(post: LearnedPosterior, starts: np.ndarray, max_eval: int = 400) -> tuple[np.ndarray, float]:
    """nlopt BOBYQA from each start, maximising the learned posterior in the box the
    starts span (widened by half its size each side). Returns the best (u, log post)."""
    import nlopt

    lo, hi = starts.min(0), starts.max(0)
    pad = 0.5 * (hi - lo) + 1e-6
    lo, hi = lo - pad, hi + pad
    best_u, best_v = starts[0], -np.inf

    def f(t, grad):
        v = float(post(t)[0])
        return v if np.isfinite(v) else -1e12

    for u0 in starts:
        opt = nlopt.opt(nlopt.LN_BOBYQA, post.dim)
        opt.set_lower_bounds(lo)
        opt.set_upper_bounds(hi)
        opt.set_max_objective(f)
        opt.set_maxeval(int(max_eval))
        opt.set_initial_step(0.05 * (hi - lo))
        try:
            t = opt.optimize(u0)
            v = opt.last_optimum_value()
        except (nlopt.RoundoffLimited, RuntimeError, ValueError):
            t, v = u0, f(u0, None)
        if v > best_v:
            best_u, best_v = np.asarray(t, float), v
    return best_u, float(best_v)


def sample(post, u_draws: np.ndarray, settings, seed, *, n_polish: int = 4,
           log_q: np.ndarray | None = None) -> tuple[SamplerRun, dict]:
    """The fit and the chain (module doc). u_draws: amortized draws (n, d) to start
    from; log_q: their amortized log density (n,) or None. With it, the walkers start
    from the draws resampled by importance weight p(u | x) / q(u): where the target
    is, not spread over the (wider) amortized posterior, so the chain starts near its
    stationary state. Returns the emcee run and the fit's summary."""
    import time

    t0 = time.perf_counter()
    lp = post(u_draws)
    ok = np.isfinite(lp)
    starts, lp = u_draws[ok], lp[ok]
    if len(starts) < 2:
        raise ValueError("too few amortized draws inside the prior to start the sampler")
    rng = np.random.default_rng(seed_sequence(seed))
    n_walkers = max(int(settings.n_walkers), 2 * post.dim + 2) if settings.n_walkers else max(2 * post.dim + 2, 32)
    if log_q is not None:
        logw = lp - np.asarray(log_q, float)[ok]
        w = np.exp(logw - logw.max())
        w /= w.sum()
        ess = float(1.0 / np.sum(w * w))
        pick = rng.choice(len(starts), size=n_walkers, replace=True, p=w)
        if len(np.unique(pick)) < n_walkers:  # repeated draws: jitter them within the draws' spread
            sd = 0.05 * starts.std(0)
            p0 = starts[pick] + rng.standard_normal((n_walkers, starts.shape[1])) * sd
        else:
            p0 = starts[pick].copy()
    else:
        ess = float("nan")
        pick = rng.choice(len(starts), size=n_walkers, replace=len(starts) < n_walkers)
        p0 = starts[pick].copy()
    best = starts[np.argsort(lp)[::-1][:n_polish]]
    u_fit, v_fit = polish(post, best)
    fit = {"best": u_fit.tolist(), "log_post": v_fit, "start_log_post": float(lp.max()), "n_starts": len(best),
           "start_ess": ess, "seconds": time.perf_counter() - t0}
    p0[0] = u_fit
    run = run_ensemble(post, p0, settings, int(rng.integers(2**31 - 1)), phase_cols=(), moves=smooth_moves())
    return run, fit
