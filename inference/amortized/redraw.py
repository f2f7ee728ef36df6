"""The smc route's moves across the likelihood's golf course: one label-free quantity
redrawn (:class:`QuantityRedraw`), one line moved (:class:`LineMove`), two engines
swapped (:class:`EngineSwap`). Off in the route by default (the SMC plugin's
``route_moves``; :mod:`.tempered` says why).

Why: the summary likelihood is a golf course in each line frequency (a line pays off only
within about a bin of its place, and a sideband at |w_i +- w_j| fits nearly as well as the
line), and the amortized posterior the route starts from is several times wider than
that hole. On 60 fresh HELI K = 32 prior drones whose summaries were drawn from the
file's own likelihood (``tests/benchmarks/route_selfcheck.py``), six of the route's
particle clouds had settled in a hole 3-35 particle sd from the truth while the truth's
log posterior stood 0.4-26 nats above every particle's: the differential-evolution
moves slide within a hole and do not jump to another. Redrawing one quantity, the rest
held, puts a line at a distant place in one step.

Each move is a Metropolis-Hastings proposal (a ``kernel`` of
:func:`mdaug.inference.samplers.tempering.de_sweep`) that returns its log correction.
:class:`QuantityRedraw`: each particle picks one
quantity q_c of the label-free q (a sorted line frequency, a line amplitude or a Gamma
ratio) and draws it afresh from a fixed one-dimensional density g_c, the others held.
In q the move is an independence proposal along q_c; a particle's state is u, so the
log correction it returns is log g_c(q_c) - log g_c(q_c') plus the change of log |dq/du|
(:meth:`LabelFree.log_jacobian`): the chain in q, with the target's density in q, is
the chain in u. g_c: a mixture of Gaussian kernel densities (on log w, logit A, lnG) over
the starting draws and over prior draws, so it is positive everywhere and reaches where
the amortized posterior does not (on three of the six drones above the truth's lowest
line lay below the amortized 5% quantile). A draw that breaks the lines' order or the
Gamma ratios' order is refused (log correction -inf).
"""
from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from .target import LabelFree


MAX_POINTS = 500
"""Rows of each source the kernel densities keep (evenly spaced): a density's cost is linear in them."""


def _rows(u, d: int, who: str) -> np.ndarray:
    u = np.atleast_2d(np.asarray(u, float))
    if u.shape[1] != d or len(u) < 2:
        raise ValueError(f"{who}: each source must be (n >= 2, {d}), got {u.shape}")
    return u[np.unique(np.linspace(0, len(u) - 1, min(len(u), MAX_POINTS)).astype(int))]


def _shares(weights, sources, who: str) -> np.ndarray:
    """The sources' mixing weights, normalised: one non-negative weight per source, not all 0."""
    w = np.asarray(weights, float)
    if len(sources) != len(w) or not len(w) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"{who}: one non-negative weight per source, not all 0")
    return w / w.sum()


def _to_line(kind: str, q: np.ndarray, a_max: float) -> np.ndarray:
    """The 1-D coordinate the kernel density lives on: log w, logit(A / A_max), lnG."""
    if kind == "w":
        return np.log(np.maximum(q, 1e-300))
    if kind == "A":
        r = np.clip(q / a_max, 1e-12, 1 - 1e-12)
        return np.log(r) - np.log1p(-r)
    return np.asarray(q, float)


def _from_line(kind: str, t: np.ndarray, a_max: float) -> np.ndarray:
    if kind == "w":
        return np.exp(np.clip(t, -700, 700))
    if kind == "A":
        return a_max / (1.0 + np.exp(-np.clip(t, -700, 700)))
    return np.asarray(t, float)


def _log_slope(kind: str, q: np.ndarray, a_max: float) -> np.ndarray:
    """log |dt/dq| of :func:`_to_line` (the kernel density carried to q)."""
    if kind == "w":
        return -np.log(q)
    if kind == "A":
        with np.errstate(divide="ignore"):
            return np.log(1.0 / q + 1.0 / (a_max - q))
    return np.zeros_like(q)


def _back_to_u(lf: LabelFree, u: np.ndarray, q_new: np.ndarray, log_corr: np.ndarray):
    """Proposals in q (n, d) back to u, with the change of log |dq/du| added to the log
    corrections (n,) (the chain in q, with the target's density in q, is the chain in u);
    a proposal outside the label-free space (:meth:`LabelFree.ordered`) is refused (-inf)
    and left at u."""
    ok = lf.ordered(q_new)
    u_new = u.copy()
    u_new[ok] = lf.to_unbounded(q_new[ok])
    with np.errstate(invalid="ignore"):
        log_corr = log_corr + lf.log_jacobian(u) - lf.log_jacobian(u_new)
    log_corr[~ok | ~np.isfinite(log_corr)] = -np.inf
    return u_new, log_corr


class QuantityRedraw:
    """Redraw one label-free quantity (module doc). label_free: the class's
    :class:`LabelFree`; sources: arrays u (n_i, d) whose kernel densities g_c mixes;
    weights: their shares (normalised); columns: the quantities a particle may pick
    (default all). Bandwidth per source and quantity: Silverman's rule; at most
    :data:`MAX_POINTS` rows of a source are kept."""

    def __init__(self, label_free: LabelFree, sources, weights, columns=None):
        self.lf = label_free
        self.kinds = label_free.kinds
        d = label_free.dim
        self.columns = np.arange(d) if columns is None else np.asarray(columns, int)
        self.weights = _shares(weights, sources, "QuantityRedraw")
        self.points, self.bandwidth = [], []
        for u in sources:
            q = label_free.from_unbounded(_rows(u, d, "QuantityRedraw"))
            t = np.column_stack([_to_line(self.kinds[c], q[:, c], label_free.a_max) for c in range(d)])
            sd = t.std(axis=0)
            iqr = np.subtract(*np.quantile(t, [0.75, 0.25], axis=0)) / 1.349
            spread = np.minimum(sd, np.where(iqr > 0, iqr, sd))
            self.points.append(t)
            self.bandwidth.append(0.9 * spread * len(t) ** -0.2 + 1e-9)

    def log_density(self, c: int, t: np.ndarray) -> np.ndarray:
        """log g_c (n,) at points t (n,) of quantity c's line (:func:`_to_line`)."""
        parts = []
        for pts, bw, w in zip(self.points, self.bandwidth, self.weights):
            z = (t[:, None] - pts[None, :, c]) / bw[c]
            parts.append(np.log(w) + logsumexp(-0.5 * z * z, axis=1) - np.log(len(pts) * bw[c] * np.sqrt(2 * np.pi)))
        return np.logaddexp.reduce(np.array(parts), axis=0)

    def _draw(self, c: np.ndarray, rng) -> np.ndarray:
        src = rng.choice(len(self.points), size=len(c), p=self.weights)
        t = np.empty(len(c))
        for s, (pts, bw) in enumerate(zip(self.points, self.bandwidth)):
            i = np.flatnonzero(src == s)
            if i.size:
                t[i] = pts[rng.integers(len(pts), size=i.size), c[i]] + bw[c[i]] * rng.standard_normal(i.size)
        return t

    def __call__(self, u: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """Proposals u' (n, d) for particles u (n, d) and each one's log correction (n,)
        (log q(u | u') - log q(u' | u), the Jacobian included; -inf where refused)."""
        u = np.atleast_2d(np.asarray(u, float))
        n, a_max = len(u), self.lf.a_max
        q = self.lf.from_unbounded(u)
        c = self.columns[rng.integers(len(self.columns), size=n)]
        t_new = self._draw(c, rng)
        q_new, log_corr = q.copy(), np.zeros(n)
        for col in np.unique(c):
            i = np.flatnonzero(c == col)
            kind, old = self.kinds[col], q[i, col]
            new = _from_line(kind, t_new[i], a_max)
            q_new[i, col] = new
            log_corr[i] = (self.log_density(col, _to_line(kind, old, a_max)) + _log_slope(kind, old, a_max)
                           - self.log_density(col, t_new[i]) - _log_slope(kind, new, a_max))
        return _back_to_u(self.lf, u, q_new, log_corr)


class LineMove:
    """Move one line of an engine, frequency and amplitude together, to anywhere in the
    band: the engine's four lines are a set (q keeps them sorted), and a line whose
    place the sampler got wrong is often another line's partner (drone 17 of the self-check:
    the bright line at 8.8 krad/s where the truth had it at 8.9 and a faint one at 8.3),
    which single-quantity redraws cannot cross with the lines' order held.

    Each particle picks an engine and one of its four lines uniformly, draws a new (w, A)
    from g (a product-kernel density on (log w, logit A) pooled over the engine's four
    lines of every source, mixed by ``weights``) and re-sorts. The reverse move picks the
    new line (also 1 in 4) and draws the old one, so the log correction is log g(old) -
    log g(new) (both carried to q) plus the change of log |dq/du|. Refused where two lines
    would share a frequency."""

    def __init__(self, label_free: LabelFree, sources, weights):
        self.lf = label_free
        self.weights = _shares(weights, sources, "LineMove")
        self.points, self.bandwidth = [], []  # per source: (E, n * 4, 2) points, (E, 2) bandwidths
        for u in sources:
            q = label_free.from_unbounded(_rows(u, label_free.dim, "LineMove"))
            pts, bws = [], []
            for k in range(label_free.E):
                j = self.lf.engine_start(k)
                t = np.column_stack([_to_line("w", q[:, j: j + 4].ravel(), label_free.a_max),
                                     _to_line("A", q[:, j + 4: j + 8].ravel(), label_free.a_max)])
                pts.append(t)
                bws.append(0.9 * t.std(axis=0) * len(t) ** (-1 / 6) + 1e-9)  # Scott-like for 2-D
            self.points.append(pts)
            self.bandwidth.append(bws)

    def log_density(self, k: int, t: np.ndarray) -> np.ndarray:
        """log g (n,) of engine k's line density at t (n, 2) = (log w, logit A)."""
        parts = []
        for pts, bws, w in zip(self.points, self.bandwidth, self.weights):
            a, b = t / bws[k], pts[k] / bws[k]  # squared distances by one product: (n, m)
            sq = (a * a).sum(1)[:, None] - 2.0 * a @ b.T + (b * b).sum(1)[None]
            parts.append(np.log(w) + logsumexp(-0.5 * np.maximum(sq, 0.0), axis=1)
                         - np.log(len(pts[k]) * 2 * np.pi * bws[k].prod()))
        return np.logaddexp.reduce(np.array(parts), axis=0)

    def __call__(self, u: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """Proposals u' (n, d) and log corrections (n,) (-inf where refused)."""
        u = np.atleast_2d(np.asarray(u, float))
        n, a_max = len(u), self.lf.a_max
        q = self.lf.from_unbounded(u)
        eng = rng.integers(self.lf.E, size=n)
        slot = rng.integers(4, size=n)
        src = rng.choice(len(self.points), size=n, p=self.weights)
        t_new = np.empty((n, 2))
        for s in range(len(self.points)):
            for k in range(self.lf.E):
                i = np.flatnonzero((src == s) & (eng == k))
                if i.size:
                    pts, bw = self.points[s][k], self.bandwidth[s][k]
                    t_new[i] = pts[rng.integers(len(pts), size=i.size)] + bw * rng.standard_normal((i.size, 2))
        q_new, log_corr = q.copy(), np.zeros(n)
        for k in range(self.lf.E):
            i = np.flatnonzero(eng == k)
            if not i.size:
                continue
            j = self.lf.engine_start(k)
            w_old, a_old = q[i, j + slot[i]], q[i, j + 4 + slot[i]]
            w_new, a_new = _from_line("w", t_new[i, 0], a_max), _from_line("A", t_new[i, 1], a_max)
            old_t = np.column_stack([_to_line("w", w_old, a_max), _to_line("A", a_old, a_max)])
            log_corr[i] = (self.log_density(k, old_t) + _log_slope("w", w_old, a_max) + _log_slope("A", a_old, a_max)
                           - self.log_density(k, t_new[i]) - _log_slope("w", w_new, a_max)
                           - _log_slope("A", a_new, a_max))
            lines_w, lines_a = q[i, j: j + 4].copy(), q[i, j + 4: j + 8].copy()
            lines_w[np.arange(i.size), slot[i]], lines_a[np.arange(i.size), slot[i]] = w_new, a_new
            order = np.argsort(lines_w, axis=1)
            q_new[i, j: j + 4] = np.take_along_axis(lines_w, order, 1)
            q_new[i, j + 4: j + 8] = np.take_along_axis(lines_a, order, 1)
        return _back_to_u(self.lf, u, q_new, log_corr)


class EngineSwap:
    """Exchange two engines' lines and amplitudes, the Gamma ratios held: which engine is
    the brightest is a labelling the measurements may not fix when two engines are nearly
    as bright (lnG near 0), and no move of one quantity or one line crosses between those
    labellings. A pair of engines is picked uniformly. Each engine's lines and amplitudes
    map to u by the same function, so the swap permutes coordinates of u: it is its own
    inverse and keeps volume, and its log correction is 0. Needs two engines or more."""

    def __init__(self, label_free: LabelFree):
        if label_free.E < 2:
            raise ValueError("EngineSwap needs two engines or more")
        self.pairs = np.array([(i, j) for i in range(label_free.E) for j in range(i + 1, label_free.E)])
        self.blocks = np.array([np.arange(8) + label_free.engine_start(k) for k in range(label_free.E)])

    def __call__(self, u: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
        """Proposals u' (n, d) and log corrections (n,) (zeros)."""
        u = np.atleast_2d(np.asarray(u, float))
        pick = self.pairs[rng.integers(len(self.pairs), size=len(u))]
        rows = np.arange(len(u))[:, None]
        out = u.copy()
        out[rows, self.blocks[pick[:, 0]]] = u[rows, self.blocks[pick[:, 1]]]
        out[rows, self.blocks[pick[:, 1]]] = u[rows, self.blocks[pick[:, 0]]]
        return out, np.zeros(len(u))
