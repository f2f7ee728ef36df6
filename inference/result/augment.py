"""Posterior augmentation: class vectors drawn from a calibrated posterior.

Method (as many vectors as asked, even beyond the chain's length): a bootstrap of the
stored draws. Each new vector is a uniformly resampled posterior draw; the acquisition
that renders it draws fresh phases, noise, carrier and range jitter where it has them,
so repeated draws give distinct profiles (under an acquisition without such nuisances,
the same profile). ``jitter`` > 0 makes it a smoothed bootstrap: Gaussian kernel jitter
of ``jitter`` x the posterior sd of every parameter (phases: x the circular sd, then
wrapped; the fixed Gamma of engine 0: no jitter; non-negative parameters that jitter
below zero are reflected, |x|). The default is no jitter: the kernel's width comes from
the marginal sd, which for a posterior with several modes in the lines (a sideband fits
nearly as well as the line) spans the modes, not one mode. On the default study's
posteriors (QUAD's brightest engine: its lines' marginal sd 0.25-0.65 x their median,
its amplitudes' 0.71-1.09), XGBoost / SVM trained on 1,000 renders per class scored
0.861 / 0.702 on ``new_large`` without jitter against 0.728 / 0.539 with 0.1 (QUAD
recall 0.80 / 0.44 against 0.49 / 0.08; ``python tests/benchmarks/calibration_gap.py DIR
--jitter 0.1``), and the study's ``posterior`` CNN 0.85 against 0.64. Phases of draw i
come from the measurement the resampled draw was paired with (all measurements used
evenly); a marginal posterior holds no phases, and the acquisition that renders the
vectors draws them.

The vectors are rendered by a :class:`~mdaug.generator.augment.Renderer` under an
acquisition: by default the one the posterior was calibrated under, with the
carrier-return and noise-floor ranges the calibration measured
(:meth:`CalibrationResult.measured_acquisition`). The training-set strategies that
use these sources (sigma_P around the best fit, posterior draws, ...) are rows of the
registry :mod:`mdaug.strategies`.
"""
from __future__ import annotations

import numpy as np

from ...generator.augment import ModelAugmenter, Renderer, SpecimenSource, VectorSource
from ...generator.params import NONNEGATIVE, N_PARAMS, PHASES
from ...generator.specimens import SpecimenSpread
from ...radar import RadarConfig
from ...generator.model import circular_stats, wrap_phase
from .posterior import CalibrationResult


def load_posterior(posterior, label: str | None = None, allow_unconverged: bool = True) -> CalibrationResult:
    """A CalibrationResult from a result or a NetCDF path (checked against ``label``)."""
    if not isinstance(posterior, CalibrationResult):
        posterior = CalibrationResult.load(posterior, class_name=label)
    if not allow_unconverged and not posterior.converged:
        raise ValueError(f"posterior of {posterior.class_name} did not converge: {posterior.diagnostics['reason']}")
    return posterior


class PosteriorSource(VectorSource):
    """Vectors from a posterior by the bootstrap of the module doc (smoothed when ``jitter`` > 0)."""

    def __init__(self, posterior, *, label: str | None = None, jitter: float = 0.0, allow_unconverged: bool = True):
        self.file = None if isinstance(posterior, CalibrationResult) else str(posterior)
        self.posterior = load_posterior(posterior, label, allow_unconverged)
        if not (np.isfinite(jitter) and jitter >= 0):
            raise ValueError(f"jitter must be >= 0 (a multiple of the posterior sd), got {jitter}")
        self.label = (label or self.posterior.class_name).upper()
        self.n_engines = self.posterior.n_engines
        self.jitter = float(jitter)
        post = self.posterior
        self._pool = np.concatenate([post.draws(measurement=m) for m in range(post.n_measurements)])
        self._phase_cols = np.array([k * N_PARAMS + c for k in range(self.n_engines) for c in PHASES])
        self._nonneg = np.array([k * N_PARAMS + c for k in range(self.n_engines) for c in NONNEGATIVE])
        sd = self._pool.std(axis=0)
        for j in self._phase_cols:
            sd[j] = circular_stats(self._pool[:, j])["sd"]
        sd[0] = 0.0  # Gamma of engine 0 is fixed
        self._sd = sd

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        idx = rng.integers(len(self._pool), size=n)
        if not self.jitter:
            return self._pool[idx].copy()
        x = self._pool[idx] + self.jitter * self._sd * rng.standard_normal((n, self._pool.shape[1]))
        x[:, self._phase_cols] = wrap_phase(x[:, self._phase_cols])
        x[:, self._nonneg] = np.abs(x[:, self._nonneg])
        return x

    def settings(self) -> dict:
        d = self.posterior.diagnostics
        return {"source": "posterior", "posterior_file": self.file, "class_name": self.posterior.class_name,
                "n_posterior_draws": int(len(self._pool)), "jitter": self.jitter,
                "method": ("smoothed bootstrap: resampled draws + Gaussian jitter x posterior sd" if self.jitter
                           else "bootstrap: resampled posterior draws"),
                "posterior_converged": bool(d["converged"]), "best_fit": self.posterior.best_fit.tolist()}


def _renderer(posterior: CalibrationResult, acquisition, **kw) -> Renderer:
    return Renderer(acquisition if acquisition is not None else posterior.measured_acquisition(), **kw)


class PosteriorAugmenter(ModelAugmenter):
    """Posterior draws (optionally widened by a specimen model, ``specimens``) rendered
    under ``acquisition`` (default: the calibration's, with its measured carrier and
    noise ranges)."""

    def __init__(self, posterior, *, label: str | None = None, acquisition=None, specimens: SpecimenSpread | None = None,
                 normalisation: str = "peak", radar: RadarConfig = RadarConfig(), dtype: str = "float32",
                 through_chain: bool = False, scene=None, random_state=None, jitter: float = 0.0,
                 allow_unconverged: bool = True):
        src = PosteriorSource(posterior, label=label, jitter=jitter, allow_unconverged=allow_unconverged)
        if specimens is not None:
            src = SpecimenSource(src, specimens)
        post = src.posterior if specimens is None else src.base.posterior
        super().__init__(src, _renderer(post, acquisition, normalisation=normalisation, dtype=dtype, radar=radar,
                                        through_chain=through_chain, scene=scene), random_state=random_state)
        self.posterior = post

    def settings(self) -> dict:
        return {**super().settings(), "strategy": "posterior" if not isinstance(self.source, SpecimenSource)
                else "posterior+specimens"}
