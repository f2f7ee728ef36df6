"""What every sampler plugin shares: the interface (:class:`Sampler`), the one result
type (:class:`SamplerRun`), the base of every plugin's settings (:class:`PluginSettings`), and the Ctrl-C handling (:func:`stop_on_sigint`,
:class:`CalibrationInterrupted`: a sampler stops at its next step boundary with its
checkpoint saved). Every plugin (:mod:`.ensemble`, :mod:`.smc`, :mod:`.laplace`)
imports this; the registry that names them is the room's face, :mod:`mdaug.inference.samplers`.
"""
from __future__ import annotations

import contextlib
import dataclasses
import signal
import threading
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

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


class PluginSettings:
    """Base of a plugin's own settings (a frozen dataclass in the plugin's module, its
    knobs and defaults its fields). ``LEGACY``: flat name -> field, for the names
    CalibrationSettings gave the knobs before each plugin had its own (a field's own
    name needs no entry); ``BUDGETS``: knobs a resumed run may change; ``quick()``:
    the preset of tests and ``--quick``."""

    LEGACY: ClassVar[dict] = {}
    BUDGETS: ClassVar[tuple] = ()

    @classmethod
    def quick(cls):
        return cls()

    def replace(self, **kw):
        return dataclasses.replace(self, **kw)


class Sampler(Protocol):
    name: str

    def run(self, post, fit, settings, seed_seq: np.random.SeedSequence, *, backend_path=None,
            fingerprint: str = "") -> SamplerRun: ...


@contextlib.contextmanager
def stop_on_signal(signum: int = signal.SIGINT, *, only_if_handled: bool = False):
    """While active, the signal sets ``flag["stop"]`` instead of raising inside the
    likelihood (where a sampler library would print its parameter dump); the sampler
    checks the flag at step boundaries and raises outside the library's call. Outside
    the main thread it does nothing; with ``only_if_handled``, nor where the signal has
    no handler of ours to defer (a worker, which SIGTERM kills at once, printing
    nothing). The previous handler is restored."""
    flag = {"stop": False}
    if threading.current_thread() is not threading.main_thread() or (
            only_if_handled and signal.getsignal(signum) in (signal.SIG_DFL, signal.SIG_IGN, None)):
        yield flag
        return

    def handler(signum, frame):
        flag["stop"] = True

    old = signal.signal(signum, handler)
    try:
        yield flag
    finally:
        signal.signal(signum, old)


def stop_on_sigint():
    """Ctrl-C as a flag (:func:`stop_on_signal`)."""
    return stop_on_signal(signal.SIGINT)
