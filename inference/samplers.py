"""One sampler interface: every sampler is a plugin that turns a log posterior and a
fit into one result type, :class:`SamplerRun`.

* ``emcee`` (default, :mod:`.ensemble`): the affine-invariant ensemble from the
  fit's modes, run until the chain is ``min_tau_multiple`` integrated
  autocorrelation times long (an honest lower-bound check) or the time budget ends;
* ``smc`` (:mod:`.tempering`): tempered sequential Monte Carlo from the prior, with
  the evidence.

A sampler is any object with a ``name`` and ``run(post, fit, settings, seed_seq,
backend_path=None, fingerprint="") -> SamplerRun``; :func:`get_sampler` looks one
up by name (:data:`SAMPLERS`). Both built-in samplers checkpoint to
``backend_path`` and resume from it; a Ctrl-C stops them at the next step boundary
with the checkpoint saved (:class:`CalibrationInterrupted`, one line, no dump).
"""
from __future__ import annotations

import contextlib
import signal
import threading
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class CalibrationInterrupted(KeyboardInterrupt):
    """A sampler was stopped by the user; its checkpoint holds everything done so far."""


@dataclass
class SamplerRun:
    """What every sampler returns.

    chain (stored steps, walkers, dim): the stored chain (emcee: every
    ``store_every``-th step; SMC: one step holding the N final particles);
    log_prob (stored steps, walkers); tau (dim,) integrated autocorrelation time in
    steps (SMC: N / ESS); burn, thin (steps); acceptance (walkers,); converged and
    the reason in words; seconds; resumed_at (steps or stages done before this run;
    0 = a fresh run); store_every; sampler (its name); extra: sampler-specific plain
    numbers for the diagnostics (e.g. SMC's evidence)."""

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
    sampler: str = "emcee"
    extra: dict = field(default_factory=dict)

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


class Sampler(Protocol):
    name: str

    def run(self, post, fit, settings, seed_seq: np.random.SeedSequence, *, backend_path=None,
            fingerprint: str = "") -> SamplerRun: ...


def get_sampler(name: str) -> Sampler:
    """The sampler plugin called ``name`` (one of :data:`SAMPLERS`)."""
    if name == "emcee":
        from .ensemble import EmceeSampler

        return EmceeSampler()
    if name == "smc":
        from .tempering import SMCSampler

        return SMCSampler()
    if name == "laplace":
        from .laplace import LaplaceSampler

        return LaplaceSampler()
    raise ValueError(f"unknown sampler {name!r}; expected one of {SAMPLERS}")


SAMPLERS = ("emcee", "smc", "laplace")


@contextlib.contextmanager
def stop_on_sigint():
    """While active, Ctrl-C sets ``flag["stop"]`` instead of raising inside the
    likelihood (where a sampler library would print its parameter dump); the sampler
    checks the flag at step boundaries. Outside the main thread it does nothing."""
    flag = {"stop": False}
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum, frame):
        flag["stop"] = True

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, old)
