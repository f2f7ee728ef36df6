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

from ..generator import IDX, N_PARAMS, ClassParams
from ..radar import RadarConfig

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


class Layout:
    """Index bookkeeping between three vectors.

    * ``z`` (fit space, a box): shared block, then per measurement [4E phases (rad),
      offset (bins) if fitted];
    * ``theta`` (sampler space): z followed by ln sigma of every measurement;
    * physics: (M, 13E) vectors with Gamma_0 fixed, plus offsets (M,) in bins.
    """

    def __init__(self, n_engines: int, n_meas: int, priors: Priors, range_offset: bool = True):
        self.E, self.M, self.priors, self.range_offset = int(n_engines), int(n_meas), priors, bool(range_offset)
        self.shared_names = [f"{n}[{k}]" for k in range(self.E) for n in SHARED + (("lnG",) if k else ())]
        self.n_shared = len(self.shared_names)
        self.n_meas_z = 4 * self.E + int(self.range_offset)
        self.dim_z = self.n_shared + self.M * self.n_meas_z
        self.dim = self.dim_z + self.M
        # column of every shared physical parameter (engine k, name) in z / theta
        self._shared_col = {}
        j = 0
        for k in range(self.E):
            for n in SHARED + (("lnG",) if k else ()):
                self._shared_col[(k, n)] = j
                j += 1

    # ---- names and bounds ---------------------------------------------------
    def z_names(self) -> list[str]:
        names = list(self.shared_names)
        for m in range(self.M):
            names += [f"{p}[{k}]@{m}" for k in range(self.E) for p in PHASE_NAMES]
            if self.range_offset:
                names.append(f"offset@{m}")
        return names

    def z_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        b = self.priors.bounds
        lo = [b[n.split("[")[0]][0] for n in self.shared_names]
        hi = [b[n.split("[")[0]][1] for n in self.shared_names]
        per_lo = [-np.pi] * (4 * self.E) + ([self.priors.offset_bins[0]] if self.range_offset else [])
        per_hi = [np.pi] * (4 * self.E) + ([self.priors.offset_bins[1]] if self.range_offset else [])
        return np.array(lo + per_lo * self.M, float), np.array(hi + per_hi * self.M, float)

    def shared_col(self, k: int, name: str) -> int:
        return self._shared_col[(k, name)]

    # ---- z <-> theta ----------------------------------------------------------
    def _z_meas(self, m: int) -> slice:
        s = self.n_shared + m * self.n_meas_z
        return slice(s, s + self.n_meas_z)

    @property
    def phase_cols(self) -> np.ndarray:
        """Columns of z (and theta) holding phases (rad, wrapped to [-pi, pi))."""
        return np.array([self.n_shared + m * self.n_meas_z + j for m in range(self.M) for j in range(4 * self.E)],
                        dtype=int)

    def theta_from_z(self, z: np.ndarray, ln_sigma: np.ndarray) -> np.ndarray:
        """z (W, dim_z) and ln sigma (W, M) -> theta (W, dim) = [z, ln sigma]."""
        z = np.atleast_2d(z)
        ln_sigma = np.broadcast_to(np.asarray(ln_sigma, float).reshape(z.shape[0], -1), (z.shape[0], self.M))
        return np.concatenate([z, ln_sigma], axis=1)

    def split_theta(self, theta: np.ndarray):
        """theta (W, dim) -> (z (W, dim_z) with phases wrapped, ln_sigma (W, M))."""
        theta = np.atleast_2d(theta)
        z = theta[:, : self.dim_z].copy()
        z[:, self.phase_cols] = wrap(z[:, self.phase_cols])
        return z, theta[:, self.dim_z:]

    # ---- physics ----------------------------------------------------------------
    def physics(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z (W, dim_z) -> parameter vectors (W, M, 13E) and range offsets (W, M) in bins."""
        z = np.atleast_2d(z)
        w = z.shape[0]
        x = np.empty((w, self.M, self.E, N_PARAMS))
        for k in range(self.E):
            for n in SHARED:
                x[:, :, k, IDX[n]] = z[:, [self.shared_col(k, n)]]
            x[:, :, k, IDX["Gamma"]] = (self.priors.gamma0 if k == 0 else
                                        self.priors.gamma0 * np.exp(z[:, [self.shared_col(k, "lnG")]]))
        offsets = np.zeros((w, self.M))
        for m in range(self.M):
            zm = z[:, self._z_meas(m)]
            for k in range(self.E):
                for j, p in enumerate(PHASE_NAMES):
                    x[:, m, k, IDX[p]] = zm[:, 4 * k + j]
            if self.range_offset:
                offsets[:, m] = zm[:, 4 * self.E]
        return x.reshape(w, self.M, self.E * N_PARAMS), offsets

    def z_from_physics(self, x: np.ndarray, offsets=None) -> np.ndarray:
        """Inverse of :meth:`physics`: x (M, 13E) (or (13E,) for all measurements) -> z (dim_z,).
        Gamma ratios are taken relative to engine 0's Gamma."""
        x = np.asarray(x, float)
        x = np.broadcast_to(x.reshape(-1, self.E, N_PARAMS), (self.M, self.E, N_PARAMS))
        z = np.empty(self.dim_z)
        g0 = x[0, 0, IDX["Gamma"]]
        for k in range(self.E):
            for n in SHARED:
                z[self.shared_col(k, n)] = x[0, k, IDX[n]]
            if k:
                ratio = x[0, k, IDX["Gamma"]] / g0 if g0 > 0 else 1.0
                z[self.shared_col(k, "lnG")] = np.log(max(ratio, 1e-300))
        for m in range(self.M):
            zm = np.empty(self.n_meas_z)
            for k in range(self.E):
                zm[4 * k: 4 * k + 4] = wrap(x[m, k, [IDX[p] for p in PHASE_NAMES]])
            if self.range_offset:
                zm[4 * self.E] = 0.0 if offsets is None else np.asarray(offsets, float).reshape(-1)[m]
            z[self._z_meas(m)] = zm
        return z

    # ---- symmetries ----------------------------------------------------------------
    def canonical(self, z: np.ndarray) -> np.ndarray:
        """The mirror image of z that satisfies the ordering constraints (w_a < w_b in
        every engine, w_a increasing over engines, Gamma ratios to the new engine 0);
        f(x) is unchanged by construction."""
        z = np.array(np.atleast_2d(z), dtype=float)
        x, off = self.physics(z)
        x = x.reshape(z.shape[0], self.M, self.E, N_PARAMS)
        a = [IDX["A_a"], IDX["w_a"], IDX["phi_a"]]
        b = [IDX["A_b"], IDX["w_b"], IDX["phi_b"]]
        swap = x[..., IDX["w_a"]] > x[..., IDX["w_b"]]  # (W, M, E), equal over M
        xa, xb = x[..., a].copy(), x[..., b].copy()
        x[..., a] = np.where(swap[..., None], xb, xa)
        x[..., b] = np.where(swap[..., None], xa, xb)
        order = np.argsort(x[:, 0, :, IDX["w_a"]], axis=1, kind="stable")  # (W, E)
        x = np.take_along_axis(x, order[:, None, :, None], axis=2)
        out = np.empty_like(z)
        for i in range(z.shape[0]):
            out[i] = self.z_from_physics(x[i].reshape(self.M, -1), off[i])
        return out

    def relabel(self, theta: np.ndarray, engine: np.ndarray, perm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Give engine ``engine[i]``'s four lines to the roles (a, b, p, m) in the order
        ``PERMUTATIONS[perm[i]]`` (role r takes line PERMUTATIONS[.][r]) in row i of
        theta (n, dim): amplitudes, frequencies and every measurement's phases follow
        their line, C_p and C_m are recomputed so each line keeps its frequency.
        f(x) is unchanged (see the module docstring). Returns (theta' (n, dim),
        log |Jacobian| (n,) of the map, log(S D) - log(S' D') with S = w_a + w_b and
        D = |w_b - w_a|, for the Metropolis-Hastings ratio)."""
        theta = np.array(np.atleast_2d(theta), dtype=float)
        n = len(theta)
        rows = np.arange(n)
        order = np.asarray(PERMUTATIONS)[np.asarray(perm, int)]  # (n, 4)
        cols = np.array([[self.shared_col(k, f"A_{r}") for r in "abpm"] for k in range(self.E)])[engine]
        wa_c = np.array([self.shared_col(k, "w_a") for k in range(self.E)])[engine]
        wb_c = np.array([self.shared_col(k, "w_b") for k in range(self.E)])[engine]
        cp_c = np.array([self.shared_col(k, "C_p") for k in range(self.E)])[engine]
        cm_c = np.array([self.shared_col(k, "C_m") for k in range(self.E)])[engine]
        wa, wb = theta[rows, wa_c], theta[rows, wb_c]
        s, d = wa + wb, np.abs(wb - wa)
        lines_w = np.column_stack([wa, wb, theta[rows, cp_c] * s, theta[rows, cm_c] * d])
        lines_a = theta[rows[:, None], cols]
        new_w = np.take_along_axis(lines_w, order, axis=1)
        theta[rows[:, None], cols] = np.take_along_axis(lines_a, order, axis=1)
        s2, d2 = new_w[:, 0] + new_w[:, 1], np.abs(new_w[:, 1] - new_w[:, 0])
        theta[rows, wa_c], theta[rows, wb_c] = new_w[:, 0], new_w[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            theta[rows, cp_c] = new_w[:, 2] / s2
            theta[rows, cm_c] = new_w[:, 3] / d2
            log_jac = np.log(s * d) - np.log(s2 * d2)
        for m in range(self.M):
            base = self.n_shared + m * self.n_meas_z + 4 * np.asarray(engine, int)
            pc = base[:, None] + np.arange(4)[None, :]  # phase columns in PHASE_NAMES order (a, b, p, m)
            theta[rows[:, None], pc] = np.take_along_axis(theta[rows[:, None], pc], order, axis=1)
        bad = ~np.isfinite(theta).all(axis=1) | ~np.isfinite(log_jac)
        log_jac[bad] = -np.inf  # w_a' = w_b': C_m' undefined (measure zero), rejected
        return theta, log_jac

    def random_relabel(self, theta: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`relabel` of every row to a labelling drawn uniformly among the other
        labellings of a uniformly drawn engine that the prior allows (rows with none
        stay put). Symmetric: which labellings the prior allows depends on the lines
        only, so from the new point the old one is drawn with the same probability.
        rng: numpy Generator or legacy RandomState (emcee's). Returns (theta', log
        |Jacobian|)."""
        theta = np.atleast_2d(theta)
        n, k = len(theta), len(PERMUTATIONS) - 1
        draw = rng.integers if hasattr(rng, "integers") else rng.randint
        engine = draw(0, self.E, size=n)
        cand, log_jac = self.relabel(np.repeat(theta, k, axis=0), np.repeat(engine, k),
                                     np.tile(np.arange(1, k + 1), n))
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(log_jac) & np.isfinite(self.log_prior(cand, (1e-300, 1e300)))).reshape(n, k)
        count = ok.sum(axis=1)
        pick = np.minimum((rng.uniform(size=n) * np.maximum(count, 1)).astype(int), np.maximum(count - 1, 0))
        col = np.argmax(np.cumsum(ok, axis=1) > pick[:, None], axis=1)
        rows = np.arange(n) * k + col
        out, lj = cand[rows].copy(), log_jac[rows].copy()
        none = count == 0
        out[none], lj[none] = theta[none], 0.0
        return out, lj

    # ---- prior ----------------------------------------------------------------------
    def log_prior(self, theta: np.ndarray, sigma_bounds: tuple[float, float]) -> np.ndarray:
        """Log prior density of theta (W, dim): 0 inside the support, -inf outside (phases
        are unbounded: the density is periodic in them)."""
        theta = np.atleast_2d(theta)
        z, ln_sigma = theta[:, : self.dim_z], theta[:, self.dim_z:]
        lo, hi = self.z_bounds()
        box = np.ones(self.dim_z, bool)
        box[self.phase_cols] = False
        ok = np.all((z[:, box] >= lo[box]) & (z[:, box] <= hi[box]), axis=1)
        ok &= np.all((ln_sigma >= np.log(sigma_bounds[0])) & (ln_sigma <= np.log(sigma_bounds[1])), axis=1)
        wa = z[:, [self.shared_col(k, "w_a") for k in range(self.E)]]
        wb = z[:, [self.shared_col(k, "w_b") for k in range(self.E)]]
        ok &= np.all(wa < wb, axis=1) & np.all(np.diff(wa, axis=1) > 0, axis=1)
        return np.where(ok, 0.0, -np.inf)

    def sample_prior(self, n: int, rng: np.random.Generator, sigma_bounds=(1e-4, 1.0)) -> np.ndarray:
        """n draws of theta from the prior (the mirror image of a box draw satisfies the
        ordering constraints and has the same density, so no rejection is needed)."""
        lo, hi = self.z_bounds()
        out = np.empty((0, self.dim))
        while len(out) < n:  # with several engines the re-referenced Gamma ratios can leave their box
            z = self.canonical(rng.uniform(lo, hi, size=(n, self.dim_z)))
            ls = rng.uniform(np.log(sigma_bounds[0]), np.log(sigma_bounds[1]), size=(n, self.M))
            th = self.theta_from_z(z, ls)
            out = np.concatenate([out, th[np.isfinite(self.log_prior(th, sigma_bounds))]])
        return out[:n]


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


def wrap(phi):
    """Phases to [-pi, pi)."""
    return (np.asarray(phi) + np.pi) % TWO_PI - np.pi
