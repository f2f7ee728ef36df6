"""The emcee plugin of :mod:`.samplers`: the ensemble from the fit's modes, run by the
one driver :func:`.emcee_run.run_ensemble` (its docstring: moves, the 50 tau rule,
resume, memory).

* Walkers start around the best fit with per-coordinate spreads from the local
  curvature of log p (:func:`.toolbox.curvature_scales`, x ``init_ball``): tight where the
  data pin a parameter, wide (up to 0.3 prior widths) where they do not; with
  ``init_modes`` also around every distinct rival mode the fit found
  (:func:`.toolbox.fit_modes`).
"""
from __future__ import annotations

import numpy as np

from ...radar.seeds import rng as seeded_rng
from ...generator.model import wrap_phase
from .base import SamplerRun
from .emcee_run import run_ensemble
from .toolbox import curvature_scales, fit_modes


def initial_ball(layout, theta_best: np.ndarray, log_post, n_walkers: int, scale,
                 rng: np.random.Generator) -> np.ndarray:
    """n_walkers points theta_best + scale * N(0, 1) (scale: (dim,) or a fraction of the
    prior widths), all inside the prior support (reflected at bounds, redrawn when
    they break the ordering constraints)."""
    lo, hi = layout.theta_bounds()
    if np.ndim(scale) == 0:
        scale = float(scale) * (hi - lo)
    out = np.empty((0, layout.dim))
    box = np.ones(layout.dim, bool)
    box[layout.phase_cols] = False
    for attempt in range(200):
        th = theta_best + scale * rng.standard_normal((n_walkers, layout.dim))
        th[:, box] = lo[box] + np.abs(th[:, box] - lo[box])
        th[:, box] = hi[box] - np.abs(hi[box] - th[:, box])
        th[:, layout.phase_cols] = wrap_phase(th[:, layout.phase_cols])
        th[:, : layout.dim_z] = layout.canonical(th[:, : layout.dim_z])  # the mirror image: same density
        th = th[np.isfinite(log_post(th))]
        out = np.concatenate([out, th])[:n_walkers]
        if len(out) == n_walkers:
            return out
        if attempt % 10 == 9:  # a narrow support near the best fit: a smaller ball
            scale = scale * 0.5
    raise ValueError("could not place walkers inside the prior around the best fit "
                     "(is the best fit on the boundary of the ordering constraint w_a < w_b?)")


def start_walkers(post, fit, settings, n_walkers: int, rng) -> tuple[np.ndarray, int]:
    """Initial walkers (n_walkers, dim): around the best fit, and with ``init_modes``
    also around every distinct rival mode the fit found (:func:`fit_modes`), split
    evenly, so the ensemble starts on every competitive mode it knows of.
    Returns (walkers, number of modes started on)."""
    layout = post.layout
    centres = fit_modes(post, fit) if settings.init_modes else [fit.best_z]
    counts = np.full(len(centres), n_walkers // len(centres))
    counts[0] += n_walkers - counts.sum()
    groups = []
    for v, n in zip(centres, counts):
        theta = post.theta_from_fit(np.asarray(v)[None])[0]
        scales = settings.init_ball * curvature_scales(layout, theta, post)
        groups.append(initial_ball(layout, theta, post, int(n), scales, rng))
    return np.concatenate(groups), len(centres)


class EmceeSampler:
    """The default sampler: emcee's ensemble (DE moves on the circle + line relabelling),
    run in blocks of ``check_every`` steps until ``min_tau_multiple`` x max tau or the
    time budget (module doc). Resumable from its HDF5 checkpoint."""

    name = "emcee"

    def run(self, post, fit, settings, seed_seq, *, backend_path=None, fingerprint: str = "") -> SamplerRun:
        layout = post.layout
        ball_ss, mc_ss = seed_seq.spawn(2)
        n_walkers = max(settings.n_walkers or 2 * layout.dim + 2, 2 * layout.dim + 2, 32)  # DE needs > 2 dim
        n_walkers += n_walkers % 2
        p0, n_modes = start_walkers(post, fit, settings, n_walkers, seeded_rng(ball_ss))
        run = run_ensemble(post, p0, settings, seed=int(mc_ss.generate_state(1)[0]), backend_path=backend_path,
                           fp=fingerprint, phase_cols=layout.phase_cols,
                           relabel=layout.random_relabel if settings.relabel > 0 and layout.labelled else None)
        run.extra["n_start_modes"] = int(n_modes)
        return run
