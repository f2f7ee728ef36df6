"""What the measurements identify, and the space the networks and samplers work in.

A drone's physics (the shared block of a :class:`~mdaug.inference.space.layout.Layout`: per
engine ``A_a, A_b, A_p, A_m, w_a, w_b, C_p, C_m`` and Gamma ratios) is seen by a
profile only through its vibration lines: which line is the roll, the pitch or a
mixing term is a labelling that no profile fixes (:mod:`mdaug.inference.space.priors`).
The label-free quantities ``q`` are, per engine (engines ordered by brightness,
Gamma decreasing), the four line frequencies sorted (rad/s) and their amplitudes (m)
in the same order, and for engines k >= 1 ``lnG`` = ln(Gamma_k / Gamma_0) <= 0 (relative
to the brightest). The networks see them unbounded (``u``): log of the lowest line,
log of the three gaps (keeps the order), logit of each amplitude over the largest
amplitude bound, and log of the gaps between successive lnG (keeps their order).

Why brightness: the prior draws each Gamma ratio over two decades either side, so in a
typical several-engine drone one engine dominates the profile and the faint ones are
barely seen. Ordered by brightness, "engine 0" is the one the measurements identify;
ordered by lowest line (the first version of this target, ``TARGET`` 1) it is most
often a faint engine, and a network learns little about any engine (on 20,000
simulated QUADs at K = 32, a direct regression from the mean log-profile explains
R^2 0.34-0.72 of the brightest engine's log line frequencies and -0.09 to 0.17 of
every quantity in the lowest-line order: ``tests/benchmarks/identifiability.py``).

:class:`DroneSpace` is the drone's block of a one-measurement marginal layout: prior
draws, the exact prior density with its ordering constraints, the line-relabelling
move, and the class vectors, which the emcee path samples in.
"""
from __future__ import annotations

import numpy as np

from ...generator import IDX, N_PARAMS
from ..space.layout import Layout
from ..space.priors import PERMUTATIONS, Priors, align_lines, brightness_order, engine_lines, label_free_lines

_PERMS = np.asarray(PERMUTATIONS)
_EPS = 1e-9
TARGET = 2  # the definition of q (module doc); stored in every estimator file


class LabelFree:
    """Label-free quantities of one class's drones (module doc).

    n_engines: E; priors: the calibration prior (amplitude bound for the logit,
    Gamma_0, and the box that mapped-back vectors must satisfy); reference: (13E,)
    class vector whose labelling mapped-back vectors take where the prior allows."""

    def __init__(self, n_engines: int, priors: Priors, reference: np.ndarray):
        self.E, self.priors = int(n_engines), priors
        self.reference = np.asarray(reference, float).reshape(-1)[: self.E * N_PARAMS]
        b = priors.bounds
        self.a_max = float(max(b["A_a"][1], b["A_p"][1], b["A_m"][1]))
        self.dim = 8 * self.E + (self.E - 1)

    @property
    def names(self) -> list[str]:
        out = []
        for k in range(self.E):
            out += [f"line {j + 1} w[{k}]" for j in range(4)] + [f"line {j + 1} A[{k}]" for j in range(4)]
            if k:
                out.append(f"lnG[{k}]")
        return out

    @property
    def gamma_columns(self) -> list[int]:
        """Columns of q (and u) holding lnG[1..E-1], the ratios to the brightest engine."""
        return [self.engine_start(e) + 8 for e in range(1, self.E)]

    def engine_start(self, k: int) -> int:
        """Column of engine k's first line in q (and u): engine k >= 1 follows engine k - 1's
        lnG; its four lines, then their four amplitudes."""
        return 8 * k + max(k - 1, 0)

    @property
    def kinds(self) -> list[str]:
        """'w' (rad/s), 'A' (m) or 'lnG' per quantity."""
        return [n.split()[-1][0] if n.startswith("line") else "lnG" for n in self.names]

    # ---- vectors -> q -> u ----------------------------------------------------------------
    def quantities(self, x: np.ndarray) -> np.ndarray:
        """Class vectors (n, 13E) -> q (n, dim): the label-free quantities."""
        x = np.atleast_2d(np.asarray(x, float))
        n = len(x)
        xe = x.reshape(n, self.E, N_PARAMS)
        lines = label_free_lines(xe, by_brightness=True)  # (n, E, 4, 2), the brightest engine first
        w, a = lines[..., 0], lines[..., 1]
        lng = np.log(np.take_along_axis(xe[..., IDX["Gamma"]], brightness_order(xe), 1))
        cols = []
        for k in range(self.E):
            cols += [w[:, k], a[:, k]]
            if k:
                cols.append((lng[:, k] - lng[:, 0])[:, None])
        return np.concatenate(cols, axis=1)

    def to_unbounded(self, q: np.ndarray) -> np.ndarray:
        """q (n, dim) -> u (n, dim)."""
        q = np.atleast_2d(np.asarray(q, float))
        u = np.empty_like(q)
        j = 0
        for k in range(self.E):
            w = q[:, j: j + 4]
            u[:, j] = np.log(np.maximum(w[:, 0], _EPS))
            u[:, j + 1: j + 4] = np.log(np.maximum(np.diff(w, axis=1), _EPS))
            r = np.clip(q[:, j + 4: j + 8] / self.a_max, _EPS, 1 - _EPS)
            u[:, j + 4: j + 8] = np.log(r) - np.log1p(-r)
            j += 8
            if k:  # lnG decreasing from 0: log of each step down
                prev = q[:, j - 9] if k > 1 else np.zeros(len(q))
                u[:, j] = np.log(np.maximum(prev - q[:, j], _EPS))
                j += 1
        return u

    def log_jacobian(self, u: np.ndarray) -> np.ndarray:
        """log |det dq/du| (n,) of :meth:`from_unbounded` at u (n, d): per engine the
        line coordinates (the cumulated exp is triangular with diagonal exp u), the
        amplitudes' logistic slopes A_max s (1 - s) and the lnG steps (exp u)."""
        u = np.clip(np.atleast_2d(np.asarray(u, float)), -50, 50)
        out = np.zeros(len(u))
        j = 0
        for k in range(self.E):
            v = u[:, j + 4: j + 8]
            out += u[:, j: j + 4].sum(1) + (np.log(self.a_max) - np.logaddexp(0, -v) - np.logaddexp(0, v)).sum(1)
            j += 8
            if k:
                out += u[:, j]
                j += 1
        return out

    def ordered(self, q: np.ndarray) -> np.ndarray:
        """(n,) True where q (n, d) is a point of the label-free space: each engine's
        lines positive and increasing, amplitudes in (0, A_max), lnG below 0 and
        decreasing engine by engine (the image of :meth:`from_unbounded`)."""
        q = np.atleast_2d(np.asarray(q, float))
        ok = np.all(np.isfinite(q), axis=1)
        j, prev = 0, np.zeros(len(q))
        for k in range(self.E):
            w, a = q[:, j: j + 4], q[:, j + 4: j + 8]
            ok &= (w[:, 0] > 0) & np.all(np.diff(w, axis=1) > 0, axis=1) & np.all((a > 0) & (a < self.a_max), axis=1)
            j += 8
            if k:
                ok &= q[:, j] < prev
                prev = q[:, j]
                j += 1
        return ok

    def from_unbounded(self, u: np.ndarray) -> np.ndarray:
        """u (n, dim) -> q (n, dim)."""
        u = np.atleast_2d(np.asarray(u, float))
        q = np.empty_like(u)
        j = 0
        for k in range(self.E):
            q[:, j: j + 4] = np.cumsum(np.exp(np.clip(u[:, j: j + 4], -50, 50)), axis=1)
            q[:, j + 4: j + 8] = self.a_max / (1.0 + np.exp(-np.clip(u[:, j + 4: j + 8], -50, 50)))
            j += 8
            if k:
                prev = q[:, j - 9] if k > 1 else np.zeros(len(u))
                q[:, j] = prev - np.exp(np.clip(u[:, j], -50, 50))
                j += 1
        return q

    def _labellings(self, w: np.ndarray, a: np.ndarray):
        """Every labelling of an engine's sorted lines w, a (n, 4): frequencies and
        amplitudes in role order a, b, p, m (n, 24, 4), S = w_a + w_b, D = w_b - w_a,
        C_p, C_m (n, 24) and whether the prior allows it (w_a < w_b, every bound)."""
        b = self.priors.bounds
        inside = lambda v, name: (v >= b[name][0]) & (v <= b[name][1])  # noqa: E731
        wp, ap = w[:, _PERMS], a[:, _PERMS]
        s, d = wp[..., 0] + wp[..., 1], wp[..., 1] - wp[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            cp, cm = wp[..., 2] / s, wp[..., 3] / d
            valid = ((d > 0) & inside(cp, "C_p") & inside(cm, "C_m") & inside(wp[..., 0], "w_a")
                     & inside(wp[..., 1], "w_b") & inside(ap[..., 0], "A_a") & inside(ap[..., 1], "A_b")
                     & inside(ap[..., 2], "A_p") & inside(ap[..., 3], "A_m"))
        return wp, ap, s, d, cp, cm, valid

    # ---- q -> class vectors ---------------------------------------------------------------------
    def vectors(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q (n, dim) -> (class vectors (n, 13E), ok (n,)). Each engine's lines get the
        labelling closest to the reference's among those the prior allows (w_a < w_b,
        C_p and C_m and every amplitude and frequency inside its bounds); engines are
        put in the prior's order (w_a increasing) with Gamma_0 fixed. ``ok`` is False
        where no labelling of some engine fits the prior, or where the Gamma ratios are
        too spread for any engine to have been the prior's reference (the support of
        :meth:`log_prior_u`): such a q lies outside the prior's support (phases are 0)."""
        q = np.atleast_2d(np.asarray(q, float))
        n = len(q)
        out = np.zeros((n, self.E, N_PARAMS))
        ok = np.ones(n, bool)
        w_ref, _, _ = engine_lines(self.reference.reshape(self.E, N_PARAMS))
        j, lng = 0, np.zeros((n, self.E))
        for k in range(self.E):
            w, a = q[:, j: j + 4], q[:, j + 4: j + 8]
            j += 8
            if k:
                lng[:, k] = q[:, j]
                j += 1
            wp, ap, s, d, cp, cm, valid = self._labellings(w, a)
            with np.errstate(divide="ignore"):
                cost = np.abs(np.log(np.maximum(wp, 1e-300)) - np.log(w_ref[k % len(w_ref)])).sum(-1)
            pick = np.argmin(np.where(valid, cost, np.inf), axis=1)
            ok &= valid.any(axis=1)
            r = np.arange(n)
            for role, col in enumerate("abpm"):
                out[:, k, IDX[f"A_{col}"]] = ap[r, pick, role]
            out[:, k, IDX["w_a"]], out[:, k, IDX["w_b"]] = wp[r, pick, 0], wp[r, pick, 1]
            out[:, k, IDX["C_p"]], out[:, k, IDX["C_m"]] = cp[r, pick], cm[r, pick]
        if self.E > 1:  # Gamma ratios no engine of the prior could have as reference: outside its support
            ok &= self._references(lng) > 0
        order = np.argsort(out[:, :, IDX["w_a"]], axis=1, kind="stable")
        out = np.take_along_axis(out, order[..., None], 1)
        lng = np.take_along_axis(lng, order, 1)
        lng = lng - lng[:, :1]
        out[:, :, IDX["Gamma"]] = self.priors.gamma0 * np.exp(lng)
        x = out.reshape(n, self.E * N_PARAMS)
        x[~ok] = np.nan_to_num(x[~ok])
        return x, ok

    def log_prior_u(self, u: np.ndarray) -> np.ndarray:
        """Log density of the calibration prior in u (n, d), the pushforward of the
        uniform box of the drone's physics (w_a < w_b) through the label-free map:
        per engine the sum over the labellings the prior allows of 1 / (S D) (the
        Jacobian from (w_a, w_b, C_p, C_m) to line frequencies, S = w_a + w_b,
        D = w_b - w_a) over the box volume, times the Jacobian from q to u; -inf
        where no labelling fits; the Gamma ratios by :meth:`_log_gamma_density`.
        With several engines the prior's cut applies (:meth:`_lines_given_cut`): the
        prior re-references the Gamma ratios to the engine of the lowest roll frequency
        w_a and keeps a drone only where they stay in range, so a labelling counts only
        where its lowest-w_a engine is one the ratios allow as reference. Without it (the
        release before) an MCMC run on this density started from 200 prior draws drifted
        to fainter engines (lnG[3] median -4.6 against the prior's -4.1). Normalised for
        one engine; with several, up to the cut's acceptance (a constant)."""
        u = np.atleast_2d(np.asarray(u, float))
        q = self.from_unbounded(u)
        b = self.priors.bounds
        width = lambda name: b[name][1] - b[name][0]  # noqa: E731
        log_vol = (np.log(width("w_a")) + np.log(width("w_b")) - np.log(2.0) + np.log(width("C_p"))
                   + np.log(width("C_m")) + sum(np.log(width(f"A_{r}")) for r in "abpm"))
        out = np.zeros(len(u))
        j = 0
        weights, roll = [], []  # per engine (n, 24): each labelling's density 1 / (S D) (0 where not allowed), its w_a
        for k in range(self.E):
            w, a = q[:, j: j + 4], q[:, j + 4: j + 8]
            wp, _, s, d, _, _, valid = self._labellings(w, a)
            with np.errstate(divide="ignore", invalid="ignore"):
                weights.append(np.where(valid, 1.0 / (s * d), 0.0))
            roll.append(wp[..., 0])
            out -= log_vol
            r = a / self.a_max  # Jacobian of q -> u: w1, the gaps, A (1 - A / A_max)
            out += (np.log(w[:, 0]) + np.log(np.diff(w, axis=1)).sum(1) + np.log(a * (1 - r)).sum(1))
            j += 8
            if k:
                j += 1
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.E == 1:
                out += np.log(weights[0].sum(axis=1))
            else:
                lng = np.concatenate([np.zeros((len(q), 1)), q[:, self.gamma_columns]], axis=1)
                out += np.log(self._lines_given_cut(np.stack(weights, 1), np.stack(roll, 1),
                                                    self._reference_mask(lng)))
                out += self._log_gamma_density(q[:, self.gamma_columns])
        out[~np.isfinite(out)] = -np.inf
        return out

    @staticmethod
    def _lines_given_cut(weights: np.ndarray, roll: np.ndarray, refs: np.ndarray) -> np.ndarray:
        """The engines' line density (n,) under the prior's cut: the sum over labellings of
        the product of each engine's 1 / (S D) (``weights`` (n, E, 24), 0 where not
        allowed), kept where the engine of the lowest roll frequency w_a (``roll``
        (n, E, 24)), the prior's new engine 0, is one the others' Gamma ratios allow as
        reference (``refs`` (n, E)): sum over such engines j and their labellings l of
        c(j, l) prod_{k != j} sum_m c(k, m) [w_a(k, m) > w_a(j, l)]. Without the cut (every
        engine allowed) it is prod_k sum_l c(k, l)."""
        n, e, _ = weights.shape
        total = np.zeros(n)
        for j in range(e):
            if not refs[:, j].any():
                continue
            term = weights[:, j].copy()  # (n, 24): c(j, l) times the others' share above w_a(j, l)
            for k in range(e):
                if k != j:
                    above = roll[:, k, None, :] > roll[:, j, :, None]  # (n, 24 of j, 24 of k)
                    term *= np.einsum("nlm,nm->nl", above, weights[:, k])
            total += np.where(refs[:, j], term.sum(axis=1), 0.0)
        return total

    def _log_gamma_density(self, r: np.ndarray) -> np.ndarray:
        """Log density, in u, of the Gamma ratios r (n, E-1) to the brightest engine
        (decreasing, <= 0). The prior draws E-1 ratios uniform on [lo, hi] against a
        reference engine whose place in the brightness order is unknown, so the density
        of r is (E-1)! / (hi - lo)^(E-1) times the number of engines that could have
        been the reference (every other ratio to it inside [lo, hi]); times the
        Jacobian of the log-steps. The prior's further cut (ratios re-referenced to the
        engine of the lowest w_a must stay inside [lo, hi]) couples them with the lines:
        :meth:`log_prior_u` applies it."""
        lo, hi = self.priors.bounds["lnG"]
        full = np.concatenate([np.zeros((len(r), 1)), r], axis=1)  # (n, E), decreasing
        count = self._references(full)
        steps = -np.diff(full, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (np.log(count) + np.sum(np.log(np.arange(1, self.E))) - (self.E - 1) * np.log(hi - lo)
                    + np.log(steps).sum(axis=1))

    def _references(self, lng: np.ndarray) -> np.ndarray:
        """How many engines of each row of ln Gamma values (n, E) could be the prior's
        reference engine: every other engine's ratio to it inside the prior's lnG range
        (0: outside the prior's support)."""
        return self._reference_mask(lng).sum(1)

    def _reference_mask(self, lng: np.ndarray) -> np.ndarray:
        """(n, E): which engines of each row of ln Gamma values (n, E) every other
        engine's ratio to lies inside the prior's lnG range."""
        lo, hi = self.priors.bounds["lnG"]
        return (lng.max(axis=1, keepdims=True) - lng <= hi) & (lng.min(axis=1, keepdims=True) - lng >= lo)

    def aligned(self, x: np.ndarray) -> np.ndarray:
        """Vectors relabelled to the reference's labelling (:func:`align_lines`)."""
        return align_lines(x, self.reference)


class DroneSpace:
    """The drone's physics block (shared columns) of a one-measurement marginal
    :class:`Layout`: what the emcee path samples (module doc)."""

    def __init__(self, n_engines: int, priors: Priors):
        self.layout = Layout(n_engines, 1, priors, marginal=True)
        self.dim = self.layout.n_shared
        lo, hi = self.layout.z_bounds()
        t_lo, t_hi = self.layout.tail_bounds
        self._pad = np.concatenate([0.5 * (lo + hi)[self.dim:], [0.5 * (t_lo + t_hi)]])
        self.names = self.layout.shared_names

    def _full(self, s: np.ndarray) -> np.ndarray:
        s = np.atleast_2d(s)
        return np.concatenate([s, np.broadcast_to(self._pad, (len(s), len(self._pad)))], axis=1)

    def sample_prior(self, n: int, rng) -> np.ndarray:
        """n prior draws (n, dim)."""
        return self.layout.sample_prior(n, rng)[:, : self.dim]

    def log_prior(self, s: np.ndarray) -> np.ndarray:
        """0 inside the prior's support (box and ordering constraints), -inf outside."""
        return self.layout.log_prior(self._full(s))

    def random_relabel(self, s: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """The exact line-relabelling move (:meth:`Layout.random_relabel`)."""
        t, lj = self.layout.random_relabel(self._full(s), rng)
        return t[:, : self.dim], lj

    def vectors(self, s: np.ndarray) -> np.ndarray:
        """Class vectors (n, 13E) of draws s (n, dim) (phases 0)."""
        return self.layout.shared_physics(self._full(s))

    def from_vectors(self, x: np.ndarray) -> np.ndarray:
        """Draws s (n, dim) of class vectors (n, 13E) in the prior's order."""
        x = np.atleast_2d(x)
        return np.stack([self.layout.z_from_physics(v)[: self.dim] for v in x])
