"""Index bookkeeping of the calibration: the fit space z, the sampler space theta
and the physics, for the two likelihoods.

* ``marginal=False`` (fitted phases, the published single-chirp case K = 1 with
  fixed phases): z = [shared block, then per measurement 4E phases (rad) and the
  range offset (bins) if fitted]; theta = [z, ln sigma_m per measurement] (the
  per-bin noise level of :class:`..likelihood.fitted_phases.LogPosterior`).
* ``marginal=True`` (the acquisition's phases marginalised,
  :class:`..likelihood.synthetic.SyntheticLikelihood`): z = [shared block, then per
  measurement its carrier return (ratio to sum Gamma) and its offset (bins: where
  the measured profile's centre bin sits relative to the carrier tone)]; theta =
  [z, noise floor per measurement (dB, :func:`mdaug.generator.acquisition.noise_sigma`)].

The shared block (the drone's physics) is the same in both: per engine k the
SHARED amplitudes, frequencies and skews, and for k >= 1 ``lnG`` = ln(Gamma_k /
Gamma_0) (Gamma_0 fixed: a peak-normalised profile cannot fix the scale).
The last M coordinates of theta are its "tail" (one per measurement); their
uniform prior bounds are ``tail_bounds``.
"""
from __future__ import annotations

import numpy as np

from ...generator import IDX, N_PARAMS
from ...generator.model import wrap_phase
from .priors import PERMUTATIONS, PHASE_NAMES, SHARED, Priors

DEFAULT_SIGMA_BOUNDS = (1e-4, 1.0)
DEFAULT_NOISE_DB = (-80.0, -10.0)
DEFAULT_CARRIER = (0.0, 1.0)
DEFAULT_STEADY = (0.0, 2.0)


class Layout:
    """Columns of z and theta for E engines and M measurements (module doc)."""

    labelled = True  # lines carry roles (a, b, p, m): the samplers' relabel move applies

    def __init__(self, n_engines: int, n_meas: int, priors: Priors, range_offset: bool = True, *,
                 marginal: bool = False, sigma_bounds=DEFAULT_SIGMA_BOUNDS, noise_db_bounds=DEFAULT_NOISE_DB,
                 carrier_bounds=DEFAULT_CARRIER, carrier_name: str = "carrier"):
        self.E, self.M, self.priors = int(n_engines), int(n_meas), priors
        self.carrier_name = str(carrier_name)
        self.marginal = bool(marginal)
        self.range_offset = bool(range_offset) and not self.marginal
        self.shared_names = [f"{n}[{k}]" for k in range(self.E) for n in SHARED + (("lnG",) if k else ())]
        self.n_shared = len(self.shared_names)
        self.n_meas_z = 2 if self.marginal else 4 * self.E + int(self.range_offset)
        self.dim_z = self.n_shared + self.M * self.n_meas_z
        self.dim = self.dim_z + self.M
        self.carrier_bounds = tuple(map(float, carrier_bounds))
        if self.marginal:
            self.tail_bounds = tuple(map(float, noise_db_bounds))
            self.tail_name = "noise_db"
        else:
            self.tail_bounds = (float(np.log(sigma_bounds[0])), float(np.log(sigma_bounds[1])))
            self.tail_name = "ln_sigma"
        if not self.tail_bounds[0] < self.tail_bounds[1] or not self.carrier_bounds[0] < self.carrier_bounds[1]:
            raise ValueError(f"Layout: need low < high bounds, got {self.tail_bounds} and {self.carrier_bounds}")
        self._shared_col = {}
        j = 0
        for k in range(self.E):
            for n in SHARED + (("lnG",) if k else ()):
                self._shared_col[(k, n)] = j
                j += 1

    # ---- names and bounds ---------------------------------------------------------
    def meas_names(self, m: int) -> list[str]:
        if self.marginal:
            return [f"{self.carrier_name}@{m}", f"offset@{m}"]
        names = [f"{p}[{k}]@{m}" for k in range(self.E) for p in PHASE_NAMES]
        return names + ([f"offset@{m}"] if self.range_offset else [])

    def z_names(self) -> list[str]:
        names = list(self.shared_names)
        for m in range(self.M):
            names += self.meas_names(m)
        return names

    def tail_names(self) -> list[str]:
        return [f"{self.tail_name}@{m}" for m in range(self.M)]

    def theta_names(self) -> list[str]:
        return self.z_names() + self.tail_names()

    def z_bounds_meas(self) -> tuple[list, list]:
        """Bounds of the per-measurement block of z, all M measurements (two lists)."""
        if self.marginal:
            per_lo = [self.carrier_bounds[0], self.priors.offset_bins[0]]
            per_hi = [self.carrier_bounds[1], self.priors.offset_bins[1]]
        else:
            per_lo = [-np.pi] * (4 * self.E) + ([self.priors.offset_bins[0]] if self.range_offset else [])
            per_hi = [np.pi] * (4 * self.E) + ([self.priors.offset_bins[1]] if self.range_offset else [])
        return per_lo * self.M, per_hi * self.M

    def z_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        b = self.priors.bounds
        lo = [b[n.split("[")[0]][0] for n in self.shared_names]
        hi = [b[n.split("[")[0]][1] for n in self.shared_names]
        per_lo, per_hi = self.z_bounds_meas()
        return np.array(lo + per_lo, float), np.array(hi + per_hi, float)

    def theta_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.z_bounds()
        return (np.concatenate([lo, np.full(self.M, self.tail_bounds[0])]),
                np.concatenate([hi, np.full(self.M, self.tail_bounds[1])]))

    def shared_col(self, k: int, name: str) -> int:
        return self._shared_col[(k, name)]

    def _z_meas(self, m: int) -> slice:
        s = self.n_shared + m * self.n_meas_z
        return slice(s, s + self.n_meas_z)

    @property
    def phase_cols(self) -> np.ndarray:
        """Columns of z (and theta) holding phases (rad, on the circle); none when marginal."""
        if self.marginal:
            return np.zeros(0, dtype=int)
        return np.array([self.n_shared + m * self.n_meas_z + j for m in range(self.M) for j in range(4 * self.E)],
                        dtype=int)

    # ---- z <-> theta ---------------------------------------------------------------
    def theta_from_z(self, z: np.ndarray, tail: np.ndarray) -> np.ndarray:
        """z (W, dim_z) and the tail (W, M) -> theta (W, dim) = [z, tail]."""
        z = np.atleast_2d(z)
        tail = np.broadcast_to(np.asarray(tail, float).reshape(z.shape[0], -1), (z.shape[0], self.M))
        return np.concatenate([z, tail], axis=1)

    def split_theta(self, theta: np.ndarray):
        """theta (W, dim) -> (z (W, dim_z) with phases wrapped, tail (W, M))."""
        theta = np.atleast_2d(theta)
        z = theta[:, : self.dim_z].copy()
        cols = self.phase_cols
        if cols.size:
            z[:, cols] = wrap_phase(z[:, cols])
        return z, theta[:, self.dim_z:]

    # ---- physics -------------------------------------------------------------------
    def shared_physics(self, z: np.ndarray) -> np.ndarray:
        """z (W, dim_z) -> the class vectors (W, 13E) with phases 0 (Gamma_0 fixed)."""
        z = np.atleast_2d(z)
        x = np.zeros((z.shape[0], self.E, N_PARAMS))
        for k in range(self.E):
            for n in SHARED:
                x[:, k, IDX[n]] = z[:, self.shared_col(k, n)]
            x[:, k, IDX["Gamma"]] = (self.priors.gamma0 if k == 0 else
                                     self.priors.gamma0 * np.exp(z[:, self.shared_col(k, "lnG")]))
        return x.reshape(z.shape[0], -1)

    def physics(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z (W, dim_z) -> parameter vectors (W, M, 13E) and each measurement's offset
        (W, M) in bins (0 when not fitted; marginal: the vectors' phases are 0 and the
        carrier returns are in :meth:`carriers`)."""
        z = np.atleast_2d(z)
        w = z.shape[0]
        x = np.repeat(self.shared_physics(z)[:, None], self.M, axis=1).reshape(w, self.M, self.E, N_PARAMS)
        extra = np.zeros((w, self.M))
        for m in range(self.M):
            zm = z[:, self._z_meas(m)]
            if self.marginal:
                extra[:, m] = zm[:, 1]
                continue
            for k in range(self.E):
                for j, p in enumerate(PHASE_NAMES):
                    x[:, m, k, IDX[p]] = zm[:, 4 * k + j]
            if self.range_offset:
                extra[:, m] = zm[:, 4 * self.E]
        return x.reshape(w, self.M, self.E * N_PARAMS), extra

    def carriers(self, z: np.ndarray) -> np.ndarray:
        """Carrier-return ratios (W, M) of a marginal layout's z (W, dim_z)."""
        z = np.atleast_2d(z)
        return z[:, [self._z_meas(m).start for m in range(self.M)]]

    def z_from_physics(self, x: np.ndarray, extra=None, carrier=None) -> np.ndarray:
        """Inverse of :meth:`physics`: x (M, 13E) (or (13E,) for all measurements), the
        offsets (M,) (default 0) and, marginal, the carrier returns (M,) (default the
        middle of their prior) -> z (dim_z,). Gamma ratios relative to engine 0."""
        x = np.asarray(x, float)
        x = np.broadcast_to(x.reshape(-1, self.E, N_PARAMS), (self.M, self.E, N_PARAMS))
        z = np.empty(self.dim_z)
        self._fill_shared(z, x[0])
        extra = None if extra is None else np.asarray(extra, float).reshape(-1)
        carrier = None if carrier is None else np.broadcast_to(np.asarray(carrier, float).reshape(-1), (self.M,))
        for m in range(self.M):
            if self.marginal:
                z[self._z_meas(m)] = [0.5 * sum(self.carrier_bounds) if carrier is None else carrier[m],
                                      0.0 if extra is None else extra[m]]
                continue
            zm = np.empty(self.n_meas_z)
            for k in range(self.E):
                zm[4 * k: 4 * k + 4] = wrap_phase(x[m, k, [IDX[p] for p in PHASE_NAMES]])
            if self.range_offset:
                zm[4 * self.E] = 0.0 if extra is None else extra[m]
            z[self._z_meas(m)] = zm
        return z

    def _fill_shared(self, z: np.ndarray, x: np.ndarray) -> None:
        """Write the shared block of z from one measurement's vectors x (E, 13)."""
        g0 = x[0, IDX["Gamma"]]
        for k in range(self.E):
            for n in SHARED:
                z[self.shared_col(k, n)] = x[k, IDX[n]]
            if k:
                ratio = x[k, IDX["Gamma"]] / g0 if g0 > 0 else 1.0
                z[self.shared_col(k, "lnG")] = np.log(max(ratio, 1e-300))

    # ---- symmetries --------------------------------------------------------------------
    def canonical(self, z: np.ndarray) -> np.ndarray:
        """The mirror image of z that satisfies the ordering constraints (w_a < w_b in
        every engine, w_a increasing over engines, Gamma ratios to the new engine 0);
        f(x) is unchanged by construction."""
        z = np.array(np.atleast_2d(z), dtype=float)
        x, extra = self.physics(z)
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
        carriers = self.carriers(z) if self.marginal else [None] * z.shape[0]
        for i in range(z.shape[0]):
            out[i] = self.z_from_physics(x[i].reshape(self.M, -1), extra[i], carriers[i])
        return out

    def relabel(self, theta: np.ndarray, engine: np.ndarray, perm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Give engine ``engine[i]``'s four lines to the roles (a, b, p, m) in the order
        ``PERMUTATIONS[perm[i]]`` (role r takes line PERMUTATIONS[.][r]) in row i of
        theta (n, dim): amplitudes, frequencies and every measurement's phases (when
        fitted) follow their line, C_p and C_m are recomputed so each line keeps its
        frequency. f(x) is unchanged (:mod:`.priors`). Returns (theta' (n, dim), log
        |Jacobian| (n,) of the map, log(S D) - log(S' D') with S = w_a + w_b and
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
        if not self.marginal:
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
            ok = (np.isfinite(log_jac) & np.isfinite(self.log_prior(cand, any_tail=True))).reshape(n, k)
        count = ok.sum(axis=1)
        pick = np.minimum((rng.uniform(size=n) * np.maximum(count, 1)).astype(int), np.maximum(count - 1, 0))
        col = np.argmax(np.cumsum(ok, axis=1) > pick[:, None], axis=1)
        rows = np.arange(n) * k + col
        out, lj = cand[rows].copy(), log_jac[rows].copy()
        none = count == 0
        out[none], lj[none] = theta[none], 0.0
        return out, lj

    # ---- prior ----------------------------------------------------------------------------
    def log_prior(self, theta: np.ndarray, sigma_bounds=None, *, any_tail: bool = False) -> np.ndarray:
        """Log prior density (up to a constant) of theta (W, dim): 0 inside the support,
        -inf outside (phases are unbounded: the density is periodic in them). The tail's
        bounds are ``tail_bounds`` (or, fitted phases, log of ``sigma_bounds`` when
        given); ``any_tail`` ignores them (used by moves that leave the tail alone)."""
        theta = np.atleast_2d(theta)
        z, tail = theta[:, : self.dim_z], theta[:, self.dim_z:]
        lo, hi = self.z_bounds()
        box = np.ones(self.dim_z, bool)
        box[self.phase_cols] = False
        ok = np.all((z[:, box] >= lo[box]) & (z[:, box] <= hi[box]), axis=1)
        if not any_tail:
            t_lo, t_hi = self.tail_bounds
            if sigma_bounds is not None and not self.marginal:
                t_lo, t_hi = np.log(sigma_bounds[0]), np.log(sigma_bounds[1])
            ok &= np.all((tail >= t_lo) & (tail <= t_hi), axis=1)
        wa = z[:, [self.shared_col(k, "w_a") for k in range(self.E)]]
        wb = z[:, [self.shared_col(k, "w_b") for k in range(self.E)]]
        ok &= np.all(wa < wb, axis=1) & np.all(np.diff(wa, axis=1) > 0, axis=1)
        return np.where(ok, 0.0, -np.inf)

    def sample_prior(self, n: int, rng: np.random.Generator, sigma_bounds=None) -> np.ndarray:
        """n draws of theta from the prior (the mirror image of a box draw satisfies the
        ordering constraints and has the same density, so no rejection is needed)."""
        lo, hi = self.z_bounds()
        t_lo, t_hi = self.tail_bounds
        if sigma_bounds is not None and not self.marginal:
            t_lo, t_hi = np.log(sigma_bounds[0]), np.log(sigma_bounds[1])
        out = np.empty((0, self.dim))
        while len(out) < n:  # with several engines the re-referenced Gamma ratios can leave their box
            z = self.canonical(rng.uniform(lo, hi, size=(n, self.dim_z)))
            tail = rng.uniform(t_lo, t_hi, size=(n, self.M))
            th = self.theta_from_z(z, tail)
            out = np.concatenate([out, th[np.isfinite(self.log_prior(th, sigma_bounds))]])
        return out[:n]
