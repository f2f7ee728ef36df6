"""Tempered SMC from the amortized posterior to the learned likelihood's posterior.

The ``smc`` route. It replaced nlopt + emcee started from the amortized draws, whose
walkers started where the amortized draws, weighted by p(u | x) / q(u), put them;
when that weight sat on a few draws (an importance ESS of 2-4 of 1,000 on HELI K = 32
prior drones) the walkers started in one mode, and emcee's moves did not cross to the
others: on 208 fresh prior drones that posterior held the truth inside its 90% interval
for 62-71% of them (outer-10% share 0.317), converged or not. The posterior is multimodal in the lines (a sideband at
|w_i +- w_j| or 2 w_j fits nearly as well as the line itself), and the fix is not a
longer chain but weights between the modes.

Tempered SMC (:func:`mdaug.inference.samplers.tempering.run_smc`, the calibration's
one SMC engine) gives them: N draws of the amortized posterior q (restricted to the
prior's support) are moved through the targets q(u)^(1 - beta) p(u | x)^beta, beta
from 0 to 1, by reweighting (the next beta keeps an ESS share of ``ess``), resampling
and differential-evolution Metropolis sweeps. q is wider than the posterior and covers
its modes, so few stages are needed, and each mode's weight comes from the
reweighting, not from walkers crossing between modes. Knobs: the moves across the
likelihood's golf course (:func:`sample_tempered`, :mod:`.redraw`: one coordinate or one
quantity redrawn, one line moved, two engines swapped), the SMC plugin's ``route_*`` tempering, ``max_stages`` and ``n_particles``
(:class:`mdaug.inference.samplers.smc.SMCSettings`; 0 means max(1000, 100 x dim)) and
the shared ``time_budget``; an estimator file may state its own (meta field
``route_settings``, :func:`route_settings`), which unset knobs take.

How fast to temper (the plugin's ``route_ess``, ``route_p_move``, ``route_max_sweeps``):
HELI's 8 quantities are sampled well at 0.7, 0.9, 20. QUAD's 35 are not: each stage's few
differential-evolution sweeps leave the resampled cloud tight and off-centre (on 12 of
the self-check's drones, with the moves: outer-10% share 0.257 where an exact sampler
gives 0.10, and no truth in a hole the particles missed). Slower tempering with longer
rejuvenation, :data:`~mdaug.inference.samplers.smc.THOROUGH_ROUTE` (0.9, 0.99, 60),
took the same drones to 0.114 at 151 s a drone; either half alone to 0.195-0.276
(docs/calibration-history.md, "QUAD's sampler").
"""
from __future__ import annotations

import numpy as np

from ...radar.seeds import rng as seeded_rng
from ...radar.seeds import seed_sequence
from ..samplers.base import SamplerRun
from ..samplers.smc import sampler_run
from ..samplers.tempering import run_smc
from .redraw import EngineSwap, LineMove, QuantityRedraw


def n_particles(settings, dim: int) -> int:
    """The route's particle count (even): the SMC plugin's ``n_particles``, or max(1000, 100 x dim)."""
    n = settings.of("smc").n_particles or max(1000, 100 * int(dim))
    return n + n % 2


def route_settings(settings, est):
    """``settings`` with the SMC plugin's route knobs resolved for the estimator ``est``:
    each the settings' own where set, else the file's (meta field ``route_settings``: the
    knobs its route table was made with, so that the route runs as it was judged), else
    :data:`~mdaug.inference.samplers.smc.ROUTE_DEFAULTS`
    (:meth:`~mdaug.inference.samplers.smc.SMCSettings.route`)."""
    return settings.with_plugin("smc", **settings.of("smc").route(est.meta.get("route_settings")))


def route_knobs(settings, est) -> dict:
    """The route knobs the smc route of ``est`` takes with these settings
    (:func:`route_settings`), the particle count resolved: what a run, a route table and a
    file's meta field ``route_settings`` record."""
    settings = route_settings(settings, est)
    knobs = settings.of("smc").route()
    knobs["n_particles"] = n_particles(settings, est.label_free.dim)
    return knobs


MOVES = {"redraw": 0.15, "quantity_redraw": 0.15, "line_move": 0.1, "engine_swap": 0.1}
"""The moves across the golf course at the shares measured (:func:`sample_tempered`'s
keywords; docs/calibration-history.md, "where the sampler went wrong"), which the SMC plugin's
``route_moves`` turns on for the route. Not the route's default:
on HELI's route table (200 fresh prior drones) they left the gate where it was (outer
share 0.106 against 0.113, one quantity's coverage 0.84 against 0.85, which the gate's
rule reads as a fail) while the self-check on a right likelihood took 0.192 to 0.156; the
route keeps the release before's sampler until the widening is chosen again with them."""


def sample_tempered(post, log_q, u_start: np.ndarray, settings, seed, *, redraw: float = 0.0,
                    quantity_redraw: float = 0.0, line_move: float = 0.0, engine_swap: float = 0.0,
                    prior_u: np.ndarray | None = None) -> SamplerRun:
    """Posterior draws of ``post`` (a vectorised u (W, d) -> log prior + log likelihood,
    -inf outside the prior's support) by tempered SMC from the amortized posterior.

    log_q: u (W, d) -> (W,) the amortized posterior's log density; u_start (N, d): N
    amortized draws (N the particle count, even; those outside the prior's support are
    replaced by copies of those inside, drawn at random); settings:
    :class:`~mdaug.inference.settings.CalibrationSettings`. Returns a SamplerRun whose
    one stored step holds the N final particles (tau = N / the last reweighting's ESS).
    The tempering's knobs (:func:`run_smc`'s ess, p_move, max_sweeps) are the SMC plugin's
    ``route_ess``, ``route_p_move``, ``route_max_sweeps`` (unset: 0.7, 0.9, 20), lighter
    than the plugin's own (0.9, 0.99, 40), which start from the prior: q starts near the
    posterior, and on HELI K = 32 these took 5-17 s per calibration (all converged) where
    the plugin's took 24-30 s for the same draws' spread. QUAD needs more
    (:data:`~mdaug.inference.samplers.smc.THOROUGH_ROUTE`, the module doc).
    redraw, quantity_redraw, line_move, engine_swap: shares of the proposals that
    redraw one coordinate of u uniformly on the starting draws' range (padded by a tenth
    of it), one label-free quantity (:class:`.redraw.QuantityRedraw`), move one line
    (:class:`.redraw.LineMove`) or exchange two engines (:class:`.redraw.EngineSwap`;
    one-engine classes skip it); the redraws draw from kernel densities of the starting
    draws and, half and half, of ``prior_u`` (prior draws in u, where given): the moves
    across the likelihood's golf course (:mod:`.redraw`), all 0 by default (the route's
    sampler); :data:`MOVES` holds the shares measured."""
    own = settings.of("smc").route()
    u_start = np.asarray(u_start, float)
    if len(u_start) < 4 or len(u_start) % 2:
        raise ValueError(f"need an even number (>= 4) of starting draws, got {len(u_start)}")
    outside = ~np.isfinite(post(u_start))
    if outside.sum() > len(u_start) - 2:
        raise ValueError("too few amortized draws inside the prior to start the sampler")
    if outside.any():  # draws of q on the prior's support in their place: the base is q restricted there
        rng = np.random.default_rng(seed_sequence(seed, "fill"))
        u_start = u_start.copy()
        u_start[outside] = u_start[~outside][rng.integers(int((~outside).sum()), size=int(outside.sum()))]

    def target(u):  # base: q on the prior's support; "likelihood": p(u | x) / q(u)
        lp = post(u)
        inside = np.isfinite(lp)
        lq = np.full(len(u), -np.inf)
        if inside.any():
            lq[inside] = log_q(u[inside])
        return lq, np.where(inside, lp - np.where(inside, lq, 0.0), 0.0)

    lo, hi = u_start.min(axis=0), u_start.max(axis=0)
    pad = 0.1 * (hi - lo)
    sources = [u_start] if prior_u is None else [u_start, np.asarray(prior_u, float)]
    kernels, lf = [], getattr(post, "label_free", None)  # a target without label-free quantities: u redraws only
    if lf is None:
        quantity_redraw = line_move = engine_swap = 0.0
    if quantity_redraw > 0:
        kernels.append((quantity_redraw, QuantityRedraw(lf, sources, [1.0] * len(sources))))
    if line_move > 0:
        kernels.append((line_move, LineMove(lf, sources, [1.0] * len(sources))))
    if engine_swap > 0 and lf.E > 1:
        kernels.append((engine_swap, EngineSwap(lf)))
    res = run_smc(target, lambda k, rng: u_start, len(u_start), seed, ess_target=own["route_ess"],
                  p_move=own["route_p_move"], max_sweeps=own["route_max_sweeps"],
                  max_stages=settings.of("smc").max_stages,
                  progress=settings.progress, time_budget=settings.time_budget, bounds=(lo - pad, hi + pad),
                  p_redraw=redraw, kernels=kernels)
    return sampler_run(res)


def smc_route(est, profiles: np.ndarray, settings, start_seed, seed, plug_in: np.ndarray | None = None):
    """The smc route of an estimator ``est`` for measurements ``profiles`` (M, L), as
    ``calibrate`` and the route tables run it: :func:`n_particles` amortized draws
    (seeded by ``start_seed``) start :func:`sample_tempered` (seeded by ``seed``) to
    ``est.target(profiles, plug_in)``, the covariance held at ``plug_in`` (default: the
    starting draws' median). With the SMC plugin's ``route_moves`` (off by default) the
    moves across the golf course at the shares of :data:`MOVES`. Returns (that target,
    the SamplerRun, whose ``extra['route_settings']`` holds the knobs it ran with). The
    route's knobs: :func:`route_settings` (the settings', else the file's, else the defaults)."""
    settings = route_settings(settings, est)
    start, inside = est.sample_u(profiles, n_particles(settings, est.label_free.dim), start_seed, strict=False)
    post = est.target(profiles, plug_in=np.median(start, axis=0) if plug_in is None else plug_in)
    moves = settings.of("smc").route_moves
    extra = dict(MOVES, prior_u=prior_draws_u(est, len(start), seed)) if moves else {}
    run = sample_tempered(post, lambda v: est.log_prob_u(v, profiles), start, settings, seed, **extra)
    run.extra["start_inside_share"] = float(inside)
    run.extra["route_settings"] = route_knobs(settings, est)
    return post, run


def prior_draws_u(est, n: int, seed) -> np.ndarray:
    """n draws (n, d) of the estimator's calibration prior in u (seeded by a child of ``seed``
    named "prior draws"): the second source of the route's redraws."""
    lf = est.label_free
    return lf.to_unbounded(lf.quantities(est.spec.sample_vectors(n, seeded_rng(seed_sequence(seed, "prior draws")))))


def log_density(u: np.ndarray, post, log_q, run: SamplerRun) -> np.ndarray:
    """Normalised log density (n,) at u (n, d) of what the route's particles stand for:
    the last tempered target, q restricted to the prior's support times (p(u | x) /
    q(u))^beta, over its normaliser, which the SMC run estimated on its way (its
    ``smc_log_z``: the sum of the log mean incremental weights) times the share of q
    inside the support (``start_inside_share``). At beta = 1 (a converged run) that is
    p(u | x) = exp(post(u)) / Z, the posterior of the file's likelihood, up to the
    Monte Carlo error of the evidence estimate; -inf outside the support.
    post, log_q: as :func:`sample_tempered` took them (log q: the flow's density)."""
    u = np.atleast_2d(np.asarray(u, float))
    beta, log_z = float(run.extra["smc_betas"][-1]), float(run.extra["smc_log_z"])
    lp = post(u)
    out = np.full(len(u), -np.inf)
    ok = np.isfinite(lp)
    if ok.any():
        lq = log_q(u[ok])
        out[ok] = lq - np.log(run.extra["start_inside_share"]) + beta * (lp[ok] - lq) - log_z
    return out
