"""nlopt + emcee on the learned likelihood.

The target: the calibration prior of the drone's physics (uniform box with its
ordering constraints, :class:`.target.DroneSpace`) times the learned likelihood,
the per-measurement ratio network summed over the measurements as independent
(log p(x | u) - log p(x), so a likelihood in the class vector's coordinates, no
Jacobian). Not the amortized posterior's own density: the two routes are learned
apart and judged by the same SBC.

Starts come from amortized draws: nlopt (a local derivative-free polish, BOBYQA in
the prior's box) from the best of them, emcee's walkers from others; the sampler is
the calibration's one emcee driver (:func:`mdaug.inference.ensemble.run_ensemble`:
DE moves plus the exact line-relabelling move, 50 tau with tau stable, time
budget, Ctrl-C), so the same convergence rule applies.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...radar.seeds import seed_sequence
from ..ensemble import run_ensemble
from ..sampler_run import SamplerRun
from .target import DroneSpace


@dataclass
class LearnedPosterior:
    """log prior + learned log-likelihood of drone draws s (W, dim); vectorised."""

    estimator: object
    profiles: np.ndarray

    def __post_init__(self):
        est = self.estimator
        self.space = DroneSpace(est.spec.reference.n_engines, est.priors)
        self.label_free = est.label_free
        self.emb = est.embed(self.profiles)
        self.n_calls = 0

    def u_of(self, s: np.ndarray) -> np.ndarray:
        lf = self.label_free
        return lf.to_unbounded(lf.quantities(self.space.vectors(s)))

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.atleast_2d(s)
        lp = self.space.log_prior(s)
        ok = np.isfinite(lp)
        if ok.any():
            lp[ok] += self.estimator.log_likelihood_u(self.u_of(s[ok]), self.emb).sum(axis=1)
        self.n_calls += len(s)
        return lp


def starts_from_draws(post: LearnedPosterior, u: np.ndarray) -> np.ndarray:
    """Amortized draws u (n, d) -> drone draws s inside the prior (the prior's labelling
    closest to the reference); draws without one are dropped."""
    x, ok = post.label_free.vectors(post.label_free.from_unbounded(u))
    s = post.space.from_vectors(x[ok])
    return s[np.isfinite(post.space.log_prior(s))]


def polish(post: LearnedPosterior, starts: np.ndarray, max_eval: int = 400) -> tuple[np.ndarray, float]:
    """nlopt BOBYQA from each start (maximising the learned posterior in the prior's
    box; outside the ordering constraints it sees a large penalty). Returns the best
    (s, log posterior)."""
    import nlopt

    lo, hi = post.space.layout.z_bounds()
    lo, hi = lo[: post.space.dim], hi[: post.space.dim]
    span = hi - lo
    best_s, best_v = None, -np.inf
    for s0 in starts:
        opt = nlopt.opt(nlopt.LN_BOBYQA, post.space.dim)
        opt.set_lower_bounds(np.zeros(post.space.dim))
        opt.set_upper_bounds(np.ones(post.space.dim))

        def f(t, grad):
            v = float(post(lo + t * span)[0])
            return v if np.isfinite(v) else -1e12

        opt.set_max_objective(f)
        opt.set_maxeval(int(max_eval))
        opt.set_initial_step(0.01)
        try:
            t = opt.optimize(np.clip((s0 - lo) / span, 1e-9, 1 - 1e-9))
            v = opt.last_optimum_value()
        except (nlopt.RoundoffLimited, RuntimeError, ValueError):
            t, v = (s0 - lo) / span, f((s0 - lo) / span, None)
        if v > best_v:
            best_s, best_v = lo + t * span, v
    return best_s, float(best_v)


def sample(post: LearnedPosterior, u_draws: np.ndarray, settings, seed, *, n_polish: int = 4) -> tuple[SamplerRun, dict]:
    """The fit and the chain (module doc). u_draws: amortized draws (n, d).
    Returns the emcee run and the fit's summary."""
    import time

    t0 = time.perf_counter()
    starts = starts_from_draws(post, u_draws)
    if len(starts) < 2:
        raise ValueError("too few amortized draws inside the prior to start the sampler")
    lp = post(starts)
    best = starts[np.argsort(lp)[::-1][:n_polish]]
    s_fit, v_fit = polish(post, best)
    fit = {"best": s_fit.tolist(), "log_post": v_fit, "start_log_post": float(lp.max()), "n_starts": len(best),
           "seconds": time.perf_counter() - t0}
    dim = post.space.dim
    n_walkers = max(2 * dim + 2, 32)
    rng = np.random.default_rng(seed_sequence(seed))
    pick = rng.choice(len(starts), size=n_walkers, replace=len(starts) < n_walkers)
    p0 = starts[pick]
    p0[0] = s_fit
    run = run_ensemble(post, p0, settings, int(rng.integers(2**31 - 1)), phase_cols=(),
                       relabel=post.space.random_relabel if settings.relabel > 0 else None)
    return run, fit
