"""Augmenters: a source of class vectors handed to the acquisition's renderer.

Every augmenter has one interface, ``sample(n, rng=None) -> AugmentedBatch``
(profiles, labels, the vectors that made them where defined, settings), so sigma_P,
posterior, specimen-widened and tsaug augmenters compose and can be swapped; a
:class:`MixtureAugmenter` of several is one augmenter. Randomness comes from
``random_state`` (an int seed, a SeedSequence or a Generator; see
:mod:`mdaug.radar.seeds`); the same seed gives the same bytes.

A model-based augmenter is a :class:`VectorSource` (what vectors: sigma_P around a
centre, fixed vectors, posterior draws, any of them widened by a specimen model)
and a :class:`Renderer` (how they become profiles: the
:class:`~.acquisition.Acquisition`, by its fast path or through the scene
simulator and the radar chain).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from ..radar import RadarConfig, check_normalisation
from ..radar.batch import AugmentedBatch, Augmenter
from ..radar.seeds import rng as as_generator
from ..radar.seeds import seed_sequence
from .acquisition import Acquisition, phase_columns
from .acquisition import render as render_fast
from .params import NONNEGATIVE, N_PARAMS, ClassParams, load_reference, validate_vectors
from .specimens import SpecimenSpread

SIGN_POLICIES = ("reflect", "truncate", "keep")
DEFAULT_BATCH = 4096
CHAIN_BAR_AT = 256  # through the chain (about 2-5 ms a profile) a bar from this many profiles on


def _check_n(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise ValueError(f"n (profiles to make) must be a positive integer, got {n!r}")
    return int(n)


# ---- the renderer ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Renderer:
    """Class vectors -> profiles under an acquisition.

    Fast path (default): f(x) with the acquisition's ramps, phases, jitter, carrier
    return, noise floor, yaw and MTI residual (:func:`.acquisition.render`). Chain
    path (``through_chain``): each vector becomes one raw acquisition of the scene
    simulator (``scene``: range, azimuth, drift, clutter, noise, ADC; its acquisition
    this one: ramps, phases, yaw and body return) processed by the radar
    chain (:func:`.chain.render_through_chain`, reduced computation)."""

    acquisition: Acquisition = Acquisition()
    normalisation: str = "peak"
    dtype: str = "float32"
    radar: RadarConfig = RadarConfig()
    through_chain: bool = False
    scene: object = None

    def __post_init__(self) -> None:
        check_normalisation(self.normalisation)
        if not isinstance(self.acquisition, Acquisition):
            raise ValueError(f"Renderer.acquisition must be an Acquisition, got {type(self.acquisition).__name__}")
        object.__setattr__(self, "dtype", np.dtype(self.dtype).name)

    def scene_config(self):
        """The scene of the chain path: ``scene`` (default scene) under this acquisition."""
        from .chain import SceneConfig

        return (self.scene if self.scene is not None else SceneConfig()).replace(acquisition=self.acquisition)

    def render(self, x, rng, progress=None) -> np.ndarray:
        """Profiles (n, L) in ``dtype`` of vectors x (n, 13E); bounded memory whatever n,
        and the result depends only on the generator (not on how it is chunked).
        ``progress``: None or a callable told how many profiles were added."""
        from ..radar import normalise

        if self.through_chain:
            from .chain import render_through_chain

            res = render_through_chain(x, self.scene_config(), self.radar, random_state=rng, progress=progress)
            return normalise(res.profiles.astype(np.float64), self.normalisation).astype(self.dtype)
        return render_fast(x, self.acquisition, rng, self.radar, normalisation=self.normalisation, dtype=self.dtype,
                           progress=progress)

    def settings(self) -> dict:
        out = {"acquisition": self.acquisition.to_dict(), "normalisation": self.normalisation, "dtype": self.dtype,
               "path": "chain" if self.through_chain else "fast"}
        if self.through_chain:
            out["scene"] = self.scene_config().to_dict()
        return out


# ---- sources of class vectors ---------------------------------------------------------------
class VectorSource(ABC):
    """Draws class vectors of one class: ``label``, ``n_engines``, ``draw(n, rng)``."""

    label: str
    n_engines: int

    @abstractmethod
    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """n vectors (n, 13 E)."""

    def settings(self) -> dict:
        return {}


def _centre(centre, label):
    if isinstance(centre, str):
        ref = load_reference(centre)
        return ref.to_array(), label or ref.name
    if isinstance(centre, ClassParams):
        return centre.to_array(), label or centre.name
    x = validate_vectors(centre, what="sigma_P centre")
    if x.shape[0] != 1:
        raise ValueError(f"sigma_P centre must be one vector, got {x.shape[0]}")
    return x[0], label or "custom"


class SigmaPSource(VectorSource):
    """The published relative-Gaussian perturbation: each term x_i + N(0, sigma_p |x_i|),
    fresh for every vector, around ``centre`` (a class name = its packaged
    reference, a ClassParams, or a vector such as a calibration's best fit).

    The mixing frequencies follow the perturbed w_a, w_b through the (perturbed)
    C_p, C_m because f(x) derives them. ``perturb_phases`` (published: True) gives
    the phases the same relative perturbation; with an acquisition that draws phases
    at random it does not matter. A draw that flips the sign of a non-negative
    term (Gamma, amplitudes, w_a, w_b, C) is handled by ``sign_policy``:
    ``reflect`` (default: |x_i|; a negative amplitude is the positive one with the
    phase moved by pi, a negative frequency the positive one with the phase
    negated), ``truncate`` (redrawn until the sign holds) or ``keep``."""

    def __init__(self, centre, sigma_p: float = 0.2, *, sign_policy: str = "reflect", perturb_phases: bool = True,
                 label: str | None = None):
        self.centre, self.label = _centre(centre, label)
        if isinstance(sigma_p, bool) or not isinstance(sigma_p, (int, float, np.floating)) \
                or not (0.0 <= float(sigma_p) <= 1.0):
            raise ValueError(f"sigma_p must be a number in [0, 1], got {sigma_p!r}")
        if sign_policy not in SIGN_POLICIES:
            raise ValueError(f"sign_policy must be one of {SIGN_POLICIES}, got {sign_policy!r}")
        self.sigma_p, self.sign_policy, self.perturb_phases = float(sigma_p), sign_policy, bool(perturb_phases)
        self.n_engines = self.centre.size // N_PARAMS

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        ref = self.centre
        scale = self.sigma_p * np.abs(ref)
        if not self.perturb_phases:
            scale[phase_columns(self.n_engines)] = 0.0
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
        return {"source": "sigma_p", "sigma_p": self.sigma_p, "sign_policy": self.sign_policy,
                "perturb_phases": self.perturb_phases, "centre": self.centre.tolist()}


class FixedSource(VectorSource):
    """Given vectors, cycled in order."""

    def __init__(self, params, label: str = "custom"):
        self.params = validate_vectors(params, what=f"{label} parameter vectors", physical=False)
        self.label, self.n_engines = label, self.params.shape[1] // N_PARAMS

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.params[np.arange(n) % len(self.params)].copy()

    def settings(self) -> dict:
        return {"source": "fixed", "n_vectors": int(len(self.params))}


class SpecimenSource(VectorSource):
    """Any source widened by the specimen model (:class:`.specimens.SpecimenSpread`):
    for drones other than the one calibrated (a common motor-speed factor, amplitude
    spread, ...), ``spread.width`` scaling all of it."""

    def __init__(self, base: VectorSource, spread: SpecimenSpread = SpecimenSpread()):
        self.base, self.spread = base, spread
        self.label, self.n_engines = base.label, base.n_engines

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.spread.apply(self.base.draw(n, rng), rng)

    def settings(self) -> dict:
        return {**self.base.settings(), "specimens": self.spread.to_dict()}


# ---- augmenters --------------------------------------------------------------------------------
class ModelAugmenter(Augmenter):
    """A vector source handed to a renderer (module doc).

    ``sample_params(n, rng)``: the vectors alone; ``sample(n, rng)``: vectors and
    profiles. All random draws of a call happen in a fixed order from one generator,
    so the result does not depend on ``batch_size``."""

    def __init__(self, source: VectorSource, renderer: Renderer = Renderer(), *, random_state=None):
        self.source, self.renderer = source, renderer
        self.label, self.n_engines = source.label, source.n_engines
        self.random_state = random_state
        self._rng = as_generator(random_state)

    # convenience views of the renderer
    @property
    def acquisition(self) -> Acquisition:
        return self.renderer.acquisition

    @property
    def radar(self) -> RadarConfig:
        return self.renderer.radar

    def sample_params(self, n: int, rng=None) -> np.ndarray:
        n = _check_n(n)
        return self.source.draw(n, self._rng if rng is None else as_generator(rng))

    def sample(self, n: int, rng=None, *, progress: bool | None = None) -> AugmentedBatch:
        """n vectors and their profiles (a bar on a terminal for large n unless
        ``progress`` is False)."""
        from ..radar.progress import progress_bar

        n = _check_n(n)
        rng = self._rng if rng is None else as_generator(rng)
        params = self.source.draw(n, rng)
        large = n > (CHAIN_BAR_AT if self.renderer.through_chain else 4 * DEFAULT_BATCH)  # a few seconds of work
        show = progress if progress is not None else (None if large else False)
        with progress_bar(total=n, desc=f"{self.label} profiles", unit="profile", progress=show, leave=False) as bar:
            out = self.renderer.render(params, as_generator(seed_sequence(rng)), progress=bar.update)
        return AugmentedBatch(profiles=out, labels=np.full(n, self.label), params=params, settings=self.settings())

    def settings(self) -> dict:
        return {**self.source.settings(), **self.renderer.settings(), "n_engines": self.n_engines}


class SigmaPAugmenter(ModelAugmenter):
    """sigma_P augmentation (:class:`SigmaPSource`) rendered under ``acquisition``
    (default: the published single chirp at the vectors' phases)."""

    def __init__(self, centre, sigma_p: float = 0.2, *, sign_policy: str = "reflect", perturb_phases: bool = True,
                 acquisition: Acquisition = Acquisition(), normalisation: str = "peak",
                 radar: RadarConfig = RadarConfig(), dtype: str = "float32", through_chain: bool = False,
                 scene=None, label: str | None = None, random_state=None):
        src = SigmaPSource(centre, sigma_p, sign_policy=sign_policy, perturb_phases=perturb_phases, label=label)
        super().__init__(src, Renderer(acquisition, normalisation, dtype, radar, through_chain, scene),
                         random_state=random_state)

    @property
    def sigma_p(self) -> float:
        return self.source.sigma_p

    def settings(self) -> dict:
        return {**super().settings(), "strategy": "sigma_p"}


class FixedParamsAugmenter(ModelAugmenter):
    """Given vectors, cycled; the acquisition still applies (for tests and simulators)."""

    def __init__(self, params, label: str = "custom", *, acquisition: Acquisition = Acquisition(),
                 normalisation: str = "peak", radar: RadarConfig = RadarConfig(), dtype: str = "float32",
                 random_state=None):
        super().__init__(FixedSource(params, label), Renderer(acquisition, normalisation, dtype, radar),
                         random_state=random_state)

    def settings(self) -> dict:
        return {**super().settings(), "strategy": "fixed"}


class MixtureAugmenter(Augmenter):
    """Several augmenters of one class as one: each profile comes from component i
    with probability ``weights[i]`` (multinomial counts from the generator), the
    components' batches concatenated in component order."""

    def __init__(self, components: list[Augmenter], weights=None, *, random_state=None):
        if not components:
            raise ValueError("MixtureAugmenter needs at least one component")
        labels = {c.label for c in components}
        if len(labels) != 1:
            raise ValueError(f"a mixture's components must share a class label, got {sorted(labels)}")
        w = np.ones(len(components)) if weights is None else np.asarray(weights, float)
        if w.shape != (len(components),) or np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise ValueError(f"weights must be {len(components)} non-negative numbers with a positive sum, got {weights!r}")
        self.components, self.weights = list(components), w / w.sum()
        self.label = components[0].label
        self._rng = as_generator(random_state)

    def sample(self, n: int, rng=None, **kw) -> AugmentedBatch:
        n = _check_n(n)
        rng = self._rng if rng is None else as_generator(rng)
        counts = rng.multinomial(n, self.weights)
        parts = [c.sample(int(k), rng, **kw) for c, k in zip(self.components, counts) if k > 0]
        params = None
        if all(p.params is not None for p in parts) and len({p.params.shape[1] for p in parts}) == 1:
            params = np.concatenate([p.params for p in parts])
        return AugmentedBatch(profiles=np.concatenate([p.profiles for p in parts]),
                              labels=np.concatenate([p.labels for p in parts]), params=params,
                              settings=self.settings())

    def settings(self) -> dict:
        return {"strategy": "mixture", "weights": self.weights.tolist(),
                "components": [c.settings() for c in self.components]}
