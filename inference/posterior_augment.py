"""Posterior augmentation: parameter vectors drawn from a calibrated posterior.

Method (as many vectors as asked, even beyond the chain's length): a smoothed
bootstrap of the stored draws. Each new vector is a uniformly resampled posterior
draw plus Gaussian kernel jitter of ``jitter`` x the posterior sd of every
parameter (phases: x the circular sd, then wrapped; fixed Gamma of engine 0: no
jitter). The default jitter 0.1 inflates each marginal variance by 1% and makes
repeated draws distinct. Non-negative parameters that jitter below zero are
reflected (|x|). Phases of draw i come from the measurement the resampled draw
was paired with (all measurements used evenly); ``nuisance.phases="uniform"``
replaces them by uniform phases, ``"relative"``/``"fixed"`` keep the posterior's.
The fitted range offsets belong to the measurements and are not reused; the
target's sub-bin position is the ``nuisance.range_jitter_bins`` option.
"""
from __future__ import annotations

import numpy as np

from ..generator import ModelAugmenter, Nuisance
from ..generator.params import NONNEGATIVE, N_PARAMS, PHASES
from ..radar import RadarConfig
from .priors import wrap
from .result import CalibrationResult, circular_stats


class PosteriorAugmenter(ModelAugmenter):
    """Draws from a :class:`CalibrationResult` (or its NetCDF path) pushed through f(x)."""

    def __init__(self, posterior, *, label: str | None = None, nuisance: Nuisance = Nuisance(),
                 normalisation: str = "peak", radar: RadarConfig = RadarConfig(), dtype: str = "float32",
                 random_state=None, jitter: float = 0.1, allow_unconverged: bool = True):
        super().__init__(nuisance=nuisance, normalisation=normalisation, radar=radar, dtype=dtype,
                         random_state=random_state)
        self.source = None
        if not isinstance(posterior, CalibrationResult):
            self.source = str(posterior)
            posterior = CalibrationResult.load(posterior, class_name=label)
        if not (np.isfinite(jitter) and jitter >= 0):
            raise ValueError(f"jitter must be >= 0 (a multiple of the posterior sd), got {jitter}")
        if not allow_unconverged and not posterior.converged:
            raise ValueError(f"posterior of {posterior.class_name} did not converge: {posterior.diagnostics['reason']}")
        self.posterior = posterior
        self.label = (label or posterior.class_name).upper()
        self.n_engines = posterior.n_engines
        self.jitter = float(jitter)
        self._pool = np.concatenate([posterior.draws(measurement=m) for m in range(posterior.n_measurements)])
        self._phase_cols = np.array([k * N_PARAMS + c for k in range(self.n_engines) for c in PHASES])
        self._nonneg = np.array([k * N_PARAMS + c for k in range(self.n_engines) for c in NONNEGATIVE])
        sd = self._pool.std(axis=0)
        for j in self._phase_cols:
            sd[j] = circular_stats(self._pool[:, j])["sd"]
        sd[0] = 0.0  # Gamma of engine 0 is fixed
        self._sd = sd

    def _draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        idx = rng.integers(len(self._pool), size=n)
        x = self._pool[idx] + self.jitter * self._sd * rng.standard_normal((n, self._pool.shape[1]))
        x[:, self._phase_cols] = wrap(x[:, self._phase_cols])
        x[:, self._nonneg] = np.abs(x[:, self._nonneg])
        return x

    def settings(self) -> dict:
        d = self.posterior.diagnostics
        return {**super().settings(), "strategy": "posterior", "posterior_file": self.source,
                "class_name": self.posterior.class_name, "n_posterior_draws": int(len(self._pool)),
                "jitter": self.jitter, "method": "smoothed bootstrap: resampled draws + Gaussian jitter x posterior sd",
                "posterior_converged": bool(d["converged"]), "best_fit": self.posterior.best_fit.tolist()}
