"""Model-based augmenters: parameter draws pushed through f(x).

Every augmenter has one interface: ``sample(n, rng=None) -> AugmentedBatch`` (and
``sample_params``), so sigma_P, posterior and data-space augmenters compose and can
be swapped. Randomness comes from ``random_state`` (an int seed or a
``numpy.random.Generator``); the same seed gives the same bytes.

Nuisances (SPEC section 3.1) are explicit options of every model augmenter:

* ``phases``: ``relative`` (published: phi + N(0, sigma_P |phi|)), ``uniform`` (each
  of the 4 term phases of every engine uniform on [-pi, pi)), ``fixed`` (untouched);
* ``range_jitter_bins``: R0 moved by U(-j/2, j/2) FFT bins (the target's sub-bin
  position); 0 = the config's model range exactly;
* ``n_ramps``: K ramps whose magnitude spectra are averaged; between ramps each
  vibration phase advances by w * ramp period (2.88 ms).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass

import numpy as np
from tqdm.auto import tqdm

from ..radar import RadarConfig, check_normalisation
from .model import profiles as model_profiles
from .params import NONNEGATIVE, N_PARAMS, PHASES, ClassParams, load_reference, validate_vectors

PHASE_TREATMENTS = ("relative", "uniform", "fixed")
SIGN_POLICIES = ("reflect", "truncate", "keep")
DEFAULT_BATCH = 4096


@dataclass(frozen=True)
class Nuisance:
    """What an acquisition randomises beyond the class vector (SPEC section 3.1).

    The defaults are the published behaviour: relative phases, no range jitter, one ramp.
    """

    phases: str = "relative"
    range_jitter_bins: float = 0.0
    n_ramps: int = 1

    def __post_init__(self) -> None:
        if self.phases not in PHASE_TREATMENTS:
            raise ValueError(f"phases must be one of {PHASE_TREATMENTS}, got {self.phases!r}")
        if not (np.isfinite(self.range_jitter_bins) and self.range_jitter_bins >= 0):
            raise ValueError(f"range_jitter_bins must be >= 0 (FFT bins), got {self.range_jitter_bins}")
        if int(self.n_ramps) != self.n_ramps or self.n_ramps < 1:
            raise ValueError(f"n_ramps must be an integer >= 1, got {self.n_ramps}")


@dataclass
class AugmentedBatch:
    """profiles (n, L), the parameter vectors that made them (n, 13 E) and R0 (n,) in m."""

    profiles: np.ndarray
    params: np.ndarray
    r0: np.ndarray


def as_generator(random_state) -> np.random.Generator:
    if isinstance(random_state, np.random.Generator):
        return random_state
    return np.random.default_rng(random_state)


def _check_n(n) -> int:
    if isinstance(n, bool) or int(n) != n or n <= 0:
        raise ValueError(f"n (profiles to make) must be a positive integer, got {n!r}")
    return int(n)


class ModelAugmenter(ABC):
    """Base of the augmenters that draw parameter vectors and run them through f(x)."""

    label: str
    n_engines: int

    def __init__(self, *, nuisance: Nuisance = Nuisance(), normalisation: str = "peak",
                 radar: RadarConfig = RadarConfig(), dtype: str = "float32", random_state=None):
        self.nuisance = nuisance
        self.normalisation = check_normalisation(normalisation)
        self.radar = radar
        self.dtype = np.dtype(dtype).name
        self.random_state = random_state
        self._rng = as_generator(random_state)

    @abstractmethod
    def _draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Parameter vectors (n, 13 E) before the phase nuisance."""

    def sample_params(self, n: int, rng=None) -> np.ndarray:
        """Draw n parameter vectors (n, 13 E), phases treated as ``nuisance.phases``."""
        n = _check_n(n)
        rng = self._rng if rng is None else as_generator(rng)
        x = self._draw(n, rng)
        if self.nuisance.phases == "uniform":
            cols = [k * N_PARAMS + c for k in range(self.n_engines) for c in PHASES]
            x[:, cols] = rng.uniform(-np.pi, np.pi, size=(n, len(cols)))
        return x

    def sample_r0(self, n: int, rng) -> np.ndarray:
        j = self.nuisance.range_jitter_bins
        r0 = np.full(n, self.radar.model_range_m)
        if j > 0:
            r0 += rng.uniform(-0.5 * j, 0.5 * j, size=n) * self.radar.model_range_per_bin()
        return r0

    def render(self, params: np.ndarray, r0: np.ndarray) -> np.ndarray:
        """f(x) of drawn vectors with this augmenter's ramps and normalisation."""
        return model_profiles(params, self.radar, r0=r0, n_ramps=self.nuisance.n_ramps,
                              normalisation=self.normalisation, dtype=self.dtype)

    def sample(self, n: int, rng=None, *, batch_size: int = DEFAULT_BATCH,
               progress: bool | None = None) -> AugmentedBatch:
        """Draw n vectors and their profiles. All random draws happen up front, so
        the result does not depend on ``batch_size``. ``progress``: None shows a bar
        on a terminal for large runs, True/False forces it."""
        n = _check_n(n)
        rng = self._rng if rng is None else as_generator(rng)
        params = self.sample_params(n, rng)
        r0 = self.sample_r0(n, rng)
        out = np.empty((n, self.radar.slice_length), dtype=self.dtype)
        show = (n > 4 * batch_size) if progress is None else progress
        with tqdm(total=n, desc=f"{self.label} profiles", unit="prof", disable=not show or None,
                  leave=False) as bar:
            for lo in range(0, n, batch_size):
                hi = min(n, lo + batch_size)
                out[lo:hi] = self.render(params[lo:hi], r0[lo:hi])
                bar.update(hi - lo)
        return AugmentedBatch(profiles=out, params=params, r0=r0)

    def settings(self) -> dict:
        return {"nuisance": asdict(self.nuisance), "normalisation": self.normalisation,
                "dtype": self.dtype, "n_engines": self.n_engines}


class SigmaPAugmenter(ModelAugmenter):
    """The published relative-Gaussian perturbation of a class reference.

    Each term x_i becomes x_i + N(0, sigma_p |x_i|), fresh for every sample; the
    mixing frequencies follow the perturbed w_a, w_b through the (perturbed) C_p, C_m
    because f(x) derives them. A draw that flips the sign of a non-negative term
    (Gamma, amplitudes, w_a, w_b, C) is handled by ``sign_policy``:

    * ``reflect`` (default): take |x_i|. In the model a negative amplitude is the
      positive one with the phase moved by pi, and a negative frequency the positive
      one with the phase negated, so the draw stays a physical vector;
    * ``truncate``: redraw until the sign holds (a truncated Gaussian);
    * ``keep``: leave it negative (the model is defined there; for comparison).

    Phases follow ``nuisance.phases``; with ``relative`` they get the same relative
    perturbation as everything else (the published behaviour).
    """

    def __init__(self, reference: ClassParams | str, sigma_p: float = 0.2, *,
                 sign_policy: str = "reflect", **kw):
        super().__init__(**kw)
        self.reference = load_reference(reference) if isinstance(reference, str) else reference
        if not isinstance(sigma_p, (int, float, np.floating)) or not (0.0 <= float(sigma_p) <= 1.0):
            raise ValueError(f"sigma_p must be a number in [0, 1], got {sigma_p!r}")
        if sign_policy not in SIGN_POLICIES:
            raise ValueError(f"sign_policy must be one of {SIGN_POLICIES}, got {sign_policy!r}")
        self.sigma_p = float(sigma_p)
        self.sign_policy = sign_policy
        self.label = self.reference.name
        self.n_engines = self.reference.n_engines

    def _draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        ref = self.reference.to_array()
        scale = self.sigma_p * np.abs(ref)
        if self.nuisance.phases != "relative":
            scale[[k * N_PARAMS + c for k in range(self.n_engines) for c in PHASES]] = 0.0
        x = ref + rng.standard_normal((n, ref.size)) * scale
        cols = np.array([k * N_PARAMS + c for k in range(self.n_engines) for c in NONNEGATIVE])
        if self.sign_policy == "reflect":
            x[:, cols] = np.abs(x[:, cols])
        elif self.sign_policy == "truncate":
            sub = x[:, cols]
            bad = sub < 0
            while bad.any():
                sub[bad] = (ref[cols] + rng.standard_normal(sub.shape) * scale[cols])[bad]
                bad = sub < 0
            x[:, cols] = sub
        return x

    def settings(self) -> dict:
        return {**super().settings(), "strategy": "sigma_p", "sigma_p": self.sigma_p,
                "sign_policy": self.sign_policy, "reference": self.reference.to_array().tolist()}


class FixedParamsAugmenter(ModelAugmenter):
    """Given parameter vectors, cycled; nuisances still apply (for tests and simulators)."""

    def __init__(self, params, label: str = "custom", **kw):
        super().__init__(**kw)
        self.params = validate_vectors(params, what=f"{label} parameter vectors", physical=False)
        self.label = label
        self.n_engines = self.params.shape[1] // N_PARAMS

    def _draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.params[np.arange(n) % len(self.params)].copy()

    def settings(self) -> dict:
        return {**super().settings(), "strategy": "fixed"}
