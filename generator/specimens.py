"""Specimen variation: how drones of one class differ from the one that was calibrated.

A physically structured model (also the scene simulator's): a common motor-speed
factor N(1, speed) scales every roll and pitch frequency of a drone together (and
so its mixing lines, which follow them); each w_a, w_b further gets
(1 + N(0, frequency)); every vibration amplitude (1 + N(0, amplitude)); every Gamma
(1 + N(0, gamma)); the skews C_p, C_m (1 + N(0, skew)); magnitudes taken (a
negative factor is a sign, not a physical drone). ``width`` scales all of them
at once (0: every specimen is the vector itself). Units: fractions (0.05 = 5%).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .params import IDX, N_PARAMS


@dataclass(frozen=True)
class SpecimenSpread:
    """Relative spreads of the specimen model (module doc); the defaults are stated
    physical guesses for drones of one model (motor speed within ~5% with load and
    battery, build tolerances of ~15% in the vibration amplitudes), not fits."""

    speed: float = 0.05
    frequency: float = 0.02
    amplitude: float = 0.15
    gamma: float = 0.15
    skew: float = 0.01
    width: float = 1.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float, np.number)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"SpecimenSpread.{f.name} must be a finite number >= 0, got {v!r}")

    @classmethod
    def exact(cls) -> "SpecimenSpread":
        """No spread at all: every specimen is the vector itself."""
        return cls(speed=0.0, frequency=0.0, amplitude=0.0, gamma=0.0, skew=0.0, width=0.0)

    def replace(self, **kw) -> "SpecimenSpread":
        return dataclasses.replace(self, **kw)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def apply(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """One specimen per row of x (n, 13E): the rows varied by the model (module doc)."""
        x = np.asarray(x, dtype=np.float64)
        n = x.shape[0]
        e = x.reshape(n, -1, N_PARAMS).copy()
        m = self.width
        speed = np.maximum(1.0 + m * self.speed * rng.standard_normal((n, 1)), 0.2)
        for cols, spread, common in ((["w_a", "w_b"], self.frequency, speed),
                                     (["A_a", "A_b", "A_p", "A_m"], self.amplitude, 1.0),
                                     (["Gamma"], self.gamma, 1.0),
                                     (["C_p", "C_m"], self.skew, 1.0)):
            idx = [IDX[c] for c in cols]
            factor = 1.0 + m * spread * rng.standard_normal((n, e.shape[1], len(idx)))
            e[..., idx] = np.abs(e[..., idx] * factor * (common[..., None] if np.ndim(common) else common))
        return e.reshape(x.shape)
