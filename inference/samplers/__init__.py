"""The sampler registry, the face of this room: every sampler is a plugin that turns a
log posterior and a fit into one result type, :class:`~.base.SamplerRun`.

* ``emcee`` (default, :mod:`.ensemble`): the affine-invariant ensemble from the
  fit's modes, run by the one emcee driver (:mod:`.emcee_run`) until the chain is
  ``min_tau_multiple`` integrated autocorrelation times long (an honest lower-bound
  check) or the time budget ends;
* ``smc`` (:mod:`.smc`, the algorithm in :mod:`.tempering`, its mode jumps in
  :mod:`.modes`): tempered sequential Monte Carlo from the prior, with the evidence;
* ``laplace`` (:mod:`.laplace`): importance sampling from Laplace approximations at
  the fit's modes (seconds; Pareto k-hat and ESS say whether it can be trusted).

A sampler is any object with a ``name`` and ``run(post, fit, settings, seed_seq,
backend_path=None, fingerprint="") -> SamplerRun`` (:class:`~.base.Sampler`, the
interface); :func:`get_sampler` looks one up by name (:data:`SAMPLERS`). Each plugin
owns its knobs in a small frozen dataclass beside it (:class:`.ensemble.EmceeSettings`,
:class:`.smc.SMCSettings`, :class:`.laplace.LaplaceSettings`;
:func:`settings_class`); the shared ``CalibrationSettings`` carries one of each and a
plugin reads its own with ``settings.of(name)``. emcee and SMC
checkpoint to ``backend_path`` and resume from it; a Ctrl-C stops them at the next
step boundary with the checkpoint saved (:class:`~.base.CalibrationInterrupted`,
one line, no dump). Plugins are leaves: they import :mod:`.base`, the shared
:mod:`.toolbox` (tau, curvature, the one Hessian, the fit's modes, the one systematic
resampler, the one Laplace approximation + Student-t mixture) and their own helpers
(emcee's driver :mod:`.emcee_run`; SMC's algorithm :mod:`.tempering` and mode jumps
:mod:`.modes`), never another plugin, so this registry and its plugins form no loop.
"""
from __future__ import annotations

import importlib

from .base import CalibrationInterrupted, Sampler, SamplerRun, stop_on_sigint

__all__ = ["SAMPLERS", "get_sampler", "settings_class", "CalibrationInterrupted", "Sampler", "SamplerRun",
           "stop_on_sigint"]

PLUGINS = {"emcee": (".ensemble", "EmceeSampler", "EmceeSettings"),
           "smc": (".smc", "SMCSampler", "SMCSettings"),
           "laplace": (".laplace", "LaplaceSampler", "LaplaceSettings")}
"""name -> (module, sampler class, settings class): the registry (plugins imported on first use)."""

SAMPLERS = tuple(PLUGINS)


def _member(name: str, which: int):
    if name not in PLUGINS:
        raise ValueError(f"unknown sampler {name!r}; expected one of {SAMPLERS}")
    module, *members = PLUGINS[name]
    return getattr(importlib.import_module(module, __name__), members[which])


def get_sampler(name: str) -> Sampler:
    """The sampler plugin called ``name`` (one of :data:`SAMPLERS`)."""
    return _member(name, 0)()


def settings_class(name: str) -> type:
    """The frozen dataclass of plugin ``name``'s own knobs, defined in its module (its
    defaults there, a ``quick()`` preset, ``LEGACY``: the flat names older files and
    callers give them, ``BUDGETS``: knobs a resumed run may change)."""
    return _member(name, 1)
