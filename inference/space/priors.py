"""Priors and the parametrisation the fit and the sampler work in.

What is sampled (per class with E engines and M measurements):

* shared by all measurements (the drone's physics), per engine k:
  ``A_a, A_b, A_p, A_m`` (m), ``w_a, w_b`` (rad/s), ``C_p, C_m`` and, for k >= 1,
  ``lnG`` = ln(Gamma_k / Gamma_0);
* per measurement m: the 4 vibration phases of every engine, the sub-bin range
  offset (FFT bins, optional) and the noise level ln(sigma_m).

Hazards, handled here:

* Scale: a peak-normalised profile is invariant to multiplying every Gamma by a
  constant, so Gamma_0 is *fixed* (to the largest reference Gamma) and only the
  ratios Gamma_k / Gamma_0 are fitted. Gamma_0 is reported as fixed, not inferred.
* Roll/pitch mirror: swapping an engine's (A_a, w_a, phi_a) with (A_b, w_b, phi_b)
  leaves f(x) unchanged (the mixing terms use |w_a + w_b| and |w_a - w_b|), so the
  prior requires w_a < w_b; A_a and A_b share bounds so the swap maps the prior
  onto itself. Engine permutation: the prior requires w_a[0] < w_a[1] < ...
* Line relabelling (exact): the model is a sum over the four vibration terms
  a, b, p, m, each a line (A, w, phi) with w_p = C_p (w_a + w_b) and
  w_m = C_m |w_a - w_b| the only ties between them. Giving the four lines of an
  engine to the four roles in another order (and recomputing C_p, C_m so that
  every line keeps its frequency) leaves f(x) unchanged, so every labelling
  whose C's fall inside the prior is an equally likely mode. Which line is the
  roll, the pitch or a mixing term is only told apart by the prior; the samplers
  move between labellings with :meth:`Layout.relabel` (measured: this, not
  noise, was most of the HELI posterior's multimodality).
* Phases live on the circle: uniform prior, no boundary. The fit works on angles
  in a [-pi, pi] box (nlopt needs a box); the sampler's moves are translations
  taken modulo 2 pi (:mod:`.sampler`), so walkers cross +-pi freely; summaries of
  phases are circular.

All priors are uniform on their box (log-uniform for Gamma ratios and sigma);
defaults derive from the class reference (:meth:`Priors.from_reference`) and
any bound can be overridden.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from ...generator import IDX, N_PARAMS, ClassParams
from ...radar import RadarConfig

SHARED = ("A_a", "A_b", "A_p", "A_m", "w_a", "w_b", "C_p", "C_m")
PERMUTATIONS = tuple(itertools.permutations(range(4)))
"""The 24 ways of giving an engine's four lines to the roles (a, b, p, m)."""
PHASE_NAMES = ("phi_a", "phi_b", "phi_p", "phi_m")
TWO_PI = 2.0 * np.pi
OFFSET_BINS = {"tone": (-4.0, 4.0), "peak": (-0.5, 0.5)}
"""Default prior of the per-measurement offset (FFT bins) for each alignment: with
``tone`` it is where the data window's maximum sits relative to the carrier tone,
with ``peak`` the sub-bin position only."""


@dataclass(frozen=True)
class Priors:
    """Uniform box priors of the shared parameters (the same for every engine).

    bounds: name -> (lo, hi) for every name in ``SHARED`` and ``lnG`` (natural log
    of Gamma_k / Gamma_0); gamma0: the fixed Gamma of engine 0; centres: (E_ref, 13)
    reference vectors (start points of the fit, not part of the prior).
    """

    bounds: dict
    gamma0: float
    centres: np.ndarray
    offset_bins: tuple = (-0.5, 0.5)

    def __post_init__(self) -> None:
        missing = [n for n in SHARED + ("lnG",) if n not in self.bounds]
        if missing:
            raise ValueError(f"prior bounds missing for {missing}")
        for name, (lo, hi) in self.bounds.items():
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ValueError(f"prior bounds of {name}: need finite lo < hi, got ({lo}, {hi})")
        for a, b in (("A_a", "A_b"), ("w_a", "w_b")):
            if tuple(self.bounds[a]) != tuple(self.bounds[b]):
                raise ValueError(f"prior bounds of {a} and {b} must be equal (the a<->b mirror "
                                 f"maps one onto the other), got {self.bounds[a]} and {self.bounds[b]}")
        if self.bounds["w_a"][0] <= 0 or self.bounds["A_a"][0] < 0:
            raise ValueError("prior bounds: frequencies must be > 0 and amplitudes >= 0")
        if not self.gamma0 > 0:
            raise ValueError(f"gamma0 must be > 0, got {self.gamma0}")

    @classmethod
    def from_reference(cls, ref: ClassParams, radar: RadarConfig = RadarConfig(), *,
                       amp_factor: float = 3.0, w_factors=(0.25, 3.0), c_bounds=(0.5, 1.5),
                       gamma_ratio_range: float = 100.0, alignment: str = "tone", **override) -> "Priors":
        """Default priors from a class reference.

        Amplitudes on [0, amp_factor x largest reference value] (A_a and A_b share
        theirs); w_a, w_b on [w_factors[0] x smallest, w_factors[1] x largest
        reference roll/pitch frequency], capped so the fastest mixing line
        (C_p_max x 2 w_hi) stays inside the profile window; C on ``c_bounds``;
        Gamma ratios within a factor ``gamma_ratio_range`` either way; the
        per-measurement tone offset on ``OFFSET_BINS[alignment]`` FFT bins.
        ``override``: name=(lo, hi) replaces any of them (also ``offset_bins``).
        """
        e = ref.to_array().reshape(-1, N_PARAMS)
        col = lambda *names: e[:, [IDX[n] for n in names]]  # noqa: E731
        a_ab = amp_factor * float(col("A_a", "A_b").max())
        w_ab = col("w_a", "w_b")
        w_visible = TWO_PI * radar.bin_hz * (radar.slice_length // 2)  # rad/s at the window's edge
        w_hi = min(w_factors[1] * float(w_ab.max()), 0.95 * w_visible / (2.0 * c_bounds[1]))
        bounds = {
            "A_a": (0.0, a_ab), "A_b": (0.0, a_ab),
            "A_p": (0.0, amp_factor * float(col("A_p").max())),
            "A_m": (0.0, amp_factor * float(col("A_m").max())),
            "w_a": (w_factors[0] * float(w_ab.min()), w_hi), "w_b": (w_factors[0] * float(w_ab.min()), w_hi),
            "C_p": tuple(c_bounds), "C_m": tuple(c_bounds),
            "lnG": (-np.log(gamma_ratio_range), np.log(gamma_ratio_range)),
        }
        offset = override.pop("offset_bins", OFFSET_BINS[alignment])
        unknown = sorted(set(override) - set(bounds))
        if unknown:
            raise ValueError(f"unknown prior override(s) {unknown}; known: {sorted(bounds)} and offset_bins")
        bounds.update({k: tuple(map(float, v)) for k, v in override.items()})
        gamma0 = float(e[:, IDX["Gamma"]].max())
        return cls(bounds=bounds, gamma0=gamma0 if gamma0 > 0 else 1.0, centres=e.copy(),
                   offset_bins=tuple(offset))

    def replace(self, **kw) -> "Priors":
        return dataclasses.replace(self, **kw)

    def to_dict(self) -> dict:
        return {"bounds": {k: list(v) for k, v in self.bounds.items()}, "gamma0": self.gamma0,
                "centres": self.centres.tolist(), "offset_bins": list(self.offset_bins)}

    @classmethod
    def from_dict(cls, d: dict) -> "Priors":
        return cls(bounds={k: tuple(v) for k, v in d["bounds"].items()}, gamma0=float(d["gamma0"]),
                   centres=np.asarray(d["centres"], dtype=float), offset_bins=tuple(d["offset_bins"]))


def engine_lines(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The four vibration lines of engine vectors x (..., 13) in role order (a, b, p, m):
    frequencies (..., 4) in rad/s (w_p = C_p |w_a + w_b|, w_m = C_m |w_a - w_b|),
    amplitudes (..., 4) in m and phases (..., 4) in rad."""
    col = lambda n: x[..., IDX[n]]  # noqa: E731
    w = np.stack([col("w_a"), col("w_b"), col("C_p") * np.abs(col("w_a") + col("w_b")),
                  col("C_m") * np.abs(col("w_b") - col("w_a"))], axis=-1)
    return w, x[..., [IDX[f"A_{r}"] for r in "abpm"]], x[..., [IDX[p] for p in PHASE_NAMES]]


def align_lines(x: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Parameter vectors x (n, 13E) relabelled, engine by engine, to the labelling of
    ``reference`` (13E,): each engine's four lines (A, w, phi) are given to the
    roles (a, b, p, m) in the order whose line frequencies are closest to the
    reference's (sum of |log w - log w_ref|), C_p and C_m recomputed. f(x) is
    unchanged (:meth:`Layout.relabel`); use it to read a posterior that moves
    between labellings in the labelling of a reference vector (label switching
    undone as in mixture models)."""
    x = np.array(np.atleast_2d(x), dtype=float)
    n, e = len(x), x.shape[1] // N_PARAMS
    xe = x.reshape(n, e, N_PARAMS)
    ref = np.asarray(reference, float).reshape(e, N_PARAMS)
    perms = np.asarray(PERMUTATIONS)
    w, a, ph = engine_lines(xe)
    w_ref, _, _ = engine_lines(ref)
    with np.errstate(divide="ignore"):
        cost = np.abs(np.log(np.maximum(w[:, :, perms], 1e-300)) - np.log(w_ref)[None, :, None, :]).sum(-1)
    best = perms[np.argmin(cost, axis=2)]  # (n, e, 4)
    w2, a2, ph2 = (np.take_along_axis(v, best, -1) for v in (w, a, ph))
    out = xe.copy()
    for j, r in enumerate("ab"):
        out[..., IDX[f"A_{r}"]], out[..., IDX[f"w_{r}"]], out[..., IDX[f"phi_{r}"]] = a2[..., j], w2[..., j], ph2[..., j]
    with np.errstate(divide="ignore", invalid="ignore"):
        out[..., IDX["C_p"]] = w2[..., 2] / np.abs(w2[..., 0] + w2[..., 1])
        out[..., IDX["C_m"]] = w2[..., 3] / np.abs(w2[..., 1] - w2[..., 0])
    for j, r in ((2, "p"), (3, "m")):
        out[..., IDX[f"A_{r}"]], out[..., IDX[f"phi_{r}"]] = a2[..., j], ph2[..., j]
    return out.reshape(n, e * N_PARAMS)


def brightness_order(xe: np.ndarray) -> np.ndarray:
    """Engine indices (n, E) of per-engine vectors xe (n, E, 13) ordered by brightness
    (Gamma decreasing, ties in their given order): the engine order of the label-free
    quantities (:mod:`mdaug.inference.amortized.target`), engine 0 the one the
    measurements identify."""
    return np.argsort(-np.asarray(xe)[..., IDX["Gamma"]], axis=1, kind="stable")


def label_free_lines(xe: np.ndarray, by_brightness: bool = False) -> np.ndarray:
    """Engine vectors xe (n, E, 13) -> their lines (n, E, 4, 2): (frequency rad/s,
    amplitude m) sorted by frequency; ``by_brightness``: engines ordered by
    :func:`brightness_order`, so engine 0 is the brightest."""
    xe = np.asarray(xe, float)
    w, a, _ = engine_lines(xe)
    order = np.argsort(w, axis=-1)
    out = np.stack([np.take_along_axis(w, order, -1), np.take_along_axis(a, order, -1)], axis=-1)
    if by_brightness:
        out = np.take_along_axis(out, brightness_order(xe)[..., None, None], 1)
    return out
