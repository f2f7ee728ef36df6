"""Sampling in line space: each engine's four vibration lines, sorted by frequency.

With random phases every moment of the spectrum depends only on the set of (A, w)
pairs of an engine's four lines (a, b, p, m), so giving the lines to the roles in
another order is an exact symmetry: a sampler in role space sees up to 24 mirror
modes per engine. Here the shared block holds, per engine k, the amplitudes
``A1..A4`` (m) and frequencies ``w1 < w2 < w3 < w4`` (rad/s) of its lines, sorted,
and for k >= 1 ``lnG``; engines are ordered by their lowest line. There are no
mirror modes left.

The prior is the role-space prior of :class:`.priors.Priors` (uniform on the
amplitudes, w_a < w_b, C_p and C_m), carried to line space: a sorted line set has
density sum over the labellings sigma that put it inside the role box of
1 / ((w_a + w_b) |w_b - w_a|) (the Jacobian of C_p = w_p / (w_a + w_b),
C_m = w_m / |w_b - w_a|). :meth:`LineLayout.sample_prior` draws in role space and
sorts, so prior draws follow exactly this density.

To the rest of the toolkit a point is a class vector as before
(:meth:`LineLayout.shared_physics`): its lines given to the roles by the most
likely labelling under the prior (any labelling gives the same profiles under
random phases).
"""
from __future__ import annotations

import numpy as np

from ...generator import IDX, N_PARAMS
from .layout import Layout
from .priors import PERMUTATIONS, engine_lines

ROLE_AMP = ("A_a", "A_b", "A_p", "A_m")
LINE_NAMES = ("A1", "A2", "A3", "A4", "w1", "w2", "w3", "w4")
_PERMS = np.asarray(PERMUTATIONS)  # (24, 4): role r takes line _PERMS[s, r]


class LineLayout(Layout):
    """A marginal :class:`Layout` whose shared block is each engine's sorted lines."""

    labelled = False  # no labelling to move between (the samplers' relabel move is off)

    def __init__(self, n_engines: int, n_meas: int, priors, **kw):
        kw["marginal"] = True
        super().__init__(n_engines, n_meas, priors, **kw)
        self.shared_names = [f"{n}[{k}]" for k in range(self.E) for n in LINE_NAMES + (("lnG",) if k else ())]
        self.n_shared = len(self.shared_names)
        self.dim_z = self.n_shared + self.M * self.n_meas_z
        self.dim = self.dim_z + self.M
        self._shared_col = {}
        for j, name in enumerate(self.shared_names):
            base, k = name[:-1].split("[")
            self._shared_col[(int(k), base)] = j
        b = priors.bounds
        self.amp_hi = max(b[n][1] for n in ROLE_AMP)
        self.w_lo = 0.0
        self.w_hi = b["C_p"][1] * 2.0 * b["w_a"][1]

    # ---- bounds ------------------------------------------------------------------------------
    def z_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = super().z_bounds_meas()
        shared_lo, shared_hi = [], []
        for name in self.shared_names:
            base = name.split("[")[0]
            if base.startswith("A"):
                shared_lo.append(0.0), shared_hi.append(self.amp_hi)
            elif base.startswith("w"):
                shared_lo.append(self.w_lo), shared_hi.append(self.w_hi)
            else:
                shared_lo.append(self.priors.bounds["lnG"][0]), shared_hi.append(self.priors.bounds["lnG"][1])
        return np.array(shared_lo + lo, float), np.array(shared_hi + hi, float)

    # ---- lines <-> class vectors -----------------------------------------------------------
    def lines(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """z (W, dim_z) -> amplitudes (W, E, 4), frequencies (W, E, 4), Gamma (W, E)."""
        z = np.atleast_2d(z)
        amp = np.stack([z[:, [self.shared_col(k, f"A{j}") for j in range(1, 5)]] for k in range(self.E)], 1)
        freq = np.stack([z[:, [self.shared_col(k, f"w{j}") for j in range(1, 5)]] for k in range(self.E)], 1)
        gam = np.full((z.shape[0], self.E), self.priors.gamma0)
        for k in range(1, self.E):
            gam[:, k] = self.priors.gamma0 * np.exp(z[:, self.shared_col(k, "lnG")])
        return amp, freq, gam

    def _labellings(self, amp: np.ndarray, freq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Prior weight (..., 24) of every labelling of lines (..., 4) and whether it is
        inside the role box; weight 1 / ((w_a + w_b)(w_b - w_a)) where valid, else 0."""
        b = self.priors.bounds
        a_r = amp[..., _PERMS]  # (..., 24, 4) amplitudes by role
        w_r = freq[..., _PERMS]
        wa, wb, wp, wm = (w_r[..., i] for i in range(4))
        s, d = wa + wb, wb - wa
        with np.errstate(divide="ignore", invalid="ignore"):
            cp, cm = wp / s, wm / d
            ok = (d > 0) & (wa >= b["w_a"][0]) & (wb <= b["w_b"][1])
            ok &= (cp >= b["C_p"][0]) & (cp <= b["C_p"][1]) & (cm >= b["C_m"][0]) & (cm <= b["C_m"][1])
            for i, name in enumerate(ROLE_AMP):
                ok &= (a_r[..., i] >= b[name][0]) & (a_r[..., i] <= b[name][1])
            weight = np.where(ok, 1.0 / (s * d), 0.0)
        return weight, ok

    def shared_physics(self, z: np.ndarray) -> np.ndarray:
        """z (W, dim_z) -> class vectors (W, 13E), phases 0: each engine's lines given to
        the roles by its most likely labelling (the first, sorted, where none is valid)."""
        amp, freq, gam = self.lines(z)
        weight, _ = self._labellings(amp, freq)
        pick = _PERMS[np.argmax(weight, axis=-1)]  # (W, E, 4)
        a = np.take_along_axis(amp, pick, -1)
        w = np.take_along_axis(freq, pick, -1)
        x = np.zeros(amp.shape[:2] + (N_PARAMS,))
        x[..., IDX["Gamma"]] = gam
        for i, name in enumerate(ROLE_AMP):
            x[..., IDX[name]] = a[..., i]
        x[..., IDX["w_a"]], x[..., IDX["w_b"]] = w[..., 0], w[..., 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            x[..., IDX["C_p"]] = w[..., 2] / np.abs(w[..., 0] + w[..., 1])
            x[..., IDX["C_m"]] = np.nan_to_num(w[..., 3] / np.abs(w[..., 1] - w[..., 0]), posinf=0.0)
        return x.reshape(len(x), -1)

    def _fill_shared(self, z: np.ndarray, x: np.ndarray) -> None:
        """The shared block from vectors x (E, 13): lines sorted within engines, engines by
        their lowest line, Gamma ratios to the new engine 0."""
        w, a, _ = engine_lines(x)  # (E, 4)
        self._write_lines(z[None], *_sorted_lines(a[None], w[None], x[None, :, IDX["Gamma"]]))

    def _write_lines(self, z: np.ndarray, amp: np.ndarray, freq: np.ndarray, gam: np.ndarray) -> None:
        """Write sorted lines (W, E, 4) and Gamma (W, E) into the shared block of z (W, dim_z)."""
        for k in range(self.E):
            for j in range(4):
                z[:, self.shared_col(k, f"A{j + 1}")] = amp[:, k, j]
                z[:, self.shared_col(k, f"w{j + 1}")] = freq[:, k, j]
            if k:
                with np.errstate(divide="ignore", invalid="ignore"):
                    ratio = np.log(np.maximum(gam[:, k], 1e-300) / gam[:, 0])
                z[:, self.shared_col(k, "lnG")] = np.where(gam[:, 0] > 0, ratio, 0.0)

    def role_layout(self) -> Layout:
        """The role-space layout of the same problem (its z has the same columns per
        measurement; the shared block holds roles instead of sorted lines)."""
        return Layout(self.E, self.M, self.priors, marginal=True, noise_db_bounds=self.tail_bounds,
                      carrier_bounds=self.carrier_bounds, carrier_name=self.carrier_name)

    def from_roles(self, z_role: np.ndarray, role: Layout) -> np.ndarray:
        """Role-space z (W, dim_z) -> line-space z (W, dim_z), vectorised."""
        z_role = np.atleast_2d(z_role)
        x = role.shared_physics(z_role).reshape(len(z_role), self.E, N_PARAMS)
        w, a, _ = engine_lines(x)
        out = z_role.copy()
        self._write_lines(out, *_sorted_lines(a, w, x[..., IDX["Gamma"]]))
        return out

    def canonical(self, z: np.ndarray) -> np.ndarray:
        """Lines sorted within each engine, engines by their lowest line (Gamma ratios to
        the new engine 0)."""
        z = np.array(np.atleast_2d(z), dtype=float)
        out = z.copy()
        self._write_lines(out, *_sorted_lines(*self.lines(z)))
        return out

    # ---- prior -------------------------------------------------------------------------------
    def log_prior(self, theta: np.ndarray, sigma_bounds=None, *, any_tail: bool = False) -> np.ndarray:
        """Log density (up to a constant) of the role-space prior carried to sorted lines
        (module doc); -inf outside the box, unsorted, or where no labelling is valid."""
        theta = np.atleast_2d(theta)
        z, tail = theta[:, : self.dim_z], theta[:, self.dim_z:]
        lo, hi = self.z_bounds()
        ok = np.all((z >= lo) & (z <= hi), axis=1)
        if not any_tail:
            ok &= np.all((tail >= self.tail_bounds[0]) & (tail <= self.tail_bounds[1]), axis=1)
        amp, freq, _ = self.lines(z)
        ok &= np.all(np.diff(freq, axis=-1) > 0, axis=(1, 2)) & np.all(np.diff(freq[..., 0], axis=1) > 0, axis=1)
        weight, _ = self._labellings(amp, freq)
        total = weight.sum(axis=-1)  # (W, E)
        ok &= np.all(total > 0, axis=1)
        with np.errstate(divide="ignore"):
            lp = np.sum(np.log(np.where(total > 0, total, 1.0)), axis=1)
        return np.where(ok, lp, -np.inf)

    def sample_prior(self, n: int, rng: np.random.Generator, sigma_bounds=None) -> np.ndarray:
        """n prior draws: role-space draws (:class:`Layout`) with their lines sorted."""
        role = self.role_layout()
        out = np.empty((0, self.dim))
        while len(out) < n:  # re-referenced to the lowest engine, a Gamma ratio can leave its box
            th = role.sample_prior(n, rng)
            z_role, tail = role.split_theta(th)
            x, extra = role.physics(z_role)
            carriers = role.carriers(z_role)
            z = np.stack([self.z_from_physics(x[i, 0], extra[i], carriers[i]) for i in range(n)])
            th = self.theta_from_z(z, tail)
            out = np.concatenate([out, th[np.isfinite(self.log_prior(th))]])
        return out[:n]

    def random_relabel(self, theta: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """No labellings to move between: the identity."""
        theta = np.atleast_2d(theta)
        return theta.copy(), np.zeros(len(theta))


def _sorted_lines(amp: np.ndarray, freq: np.ndarray, gam: np.ndarray):
    """Lines (W, E, 4) sorted by frequency within each engine, engines by their lowest line;
    Gamma (W, E) follows its engine."""
    order = np.argsort(freq, axis=-1)
    amp, freq = np.take_along_axis(amp, order, -1), np.take_along_axis(freq, order, -1)
    eng = np.argsort(freq[..., 0], axis=-1, kind="stable")
    return (np.take_along_axis(amp, eng[..., None], 1), np.take_along_axis(freq, eng[..., None], 1),
            np.take_along_axis(gam, eng, 1))
