"""Static tables of the closed-form line moments (:mod:`.line_moments`): the kernel
table K_r(theta) = sum_s (s / N)^r e^{i theta s} (:data:`TABLE_OVERSAMPLE` points
per FFT bin) and its Taylor step between points, the line vectors n of one order and
the dense code of their differences, the Bessel envelope polynomials, and the Fejer
weights |F_K|^2 of K ramps. The small compiled helpers (numba, ``cache=True``) are
called from the compiled kernel of :func:`.line_moments.line_sums`.
"""
from __future__ import annotations

import functools
import math

import numpy as np

try:  # numba compiles the helpers and line_sums' kernel; without it line_sums refuses (a clear error)
    import numba
except ImportError:  # pragma: no cover - numba is a dependency
    numba = None

TABLE_OVERSAMPLE = 8  # kernel table points per FFT bin
TAYLOR_TERMS = 4  # Taylor steps between table points (|N d| <= 0.048 rad: error < 1e-8)
MAX_DEGREE = 40  # polynomial degree of a line's envelope (beta up to ~6 rad)
FEJER_POINTS = 16384  # table of |F_K|^2 over one period (interpolation error ~1e-5)


@functools.lru_cache(maxsize=4)
def kernel_table(n_samples: int, fft_points: int, degree: int) -> np.ndarray:
    """K_r(theta_j) = sum_s (s / N)^r e^{i theta_j s}, theta_j = 2 pi j / (fft_points x
    TABLE_OVERSAMPLE), for r = 0 .. degree: (points, degree + 1) complex128."""
    n_t = fft_points * TABLE_OVERSAMPLE
    u = np.arange(n_samples) / n_samples
    seq = np.zeros((degree + 1, n_t))
    seq[:, :n_samples] = u[None, :] ** np.arange(degree + 1)[:, None]
    return np.ascontiguousarray((np.fft.ifft(seq, axis=1) * n_t).T)


@functools.lru_cache(maxsize=8)
def line_vectors(order: int) -> np.ndarray:
    """Integer vectors n (L, 4) with 1 <= sum |n_j| <= order, the zero vector excluded."""
    r = np.arange(-order, order + 1)
    grid = np.stack(np.meshgrid(r, r, r, r, indexing="ij"), -1).reshape(-1, 4)
    l1 = np.abs(grid).sum(1)
    keep = (l1 >= 1) & (l1 <= order)
    g = grid[keep]
    return g[np.lexsort((g[:, 3], g[:, 2], g[:, 1], g[:, 0], np.abs(g).sum(1)))].astype(np.int64)


def order_for(beta_max: float, tol: float = 1e-6) -> int:
    """The smallest line order whose Bessel factor |J_n(beta_max)| drops below tol."""
    from scipy.special import jv

    for n in range(1, 40):
        if abs(jv(n, beta_max)) < tol and n > beta_max:
            return n
    return 40


class LineTables:
    """Static tables for :func:`line_sums`: the line vectors of one order, their
    negatives and the dense code of index differences (one code space per engine)."""

    def __init__(self, order: int):
        self.order = int(order)
        self.vectors = line_vectors(self.order)
        self.base = 4 * self.order + 1
        off = 2 * self.order
        powers = self.base ** np.arange(4)
        self.codes = ((self.vectors + off) * powers).sum(1).astype(np.int64)
        self.line_of_code = np.full(self.base ** 4, -1, np.int64)
        self.line_of_code[self.codes] = np.arange(len(self.vectors))
        neg_codes = ((-self.vectors + off) * powers).sum(1)
        self.neg = self.line_of_code[neg_codes].astype(np.int64)
        self.powers = powers.astype(np.int64)


@functools.lru_cache(maxsize=8)
def line_tables(order: int) -> LineTables:
    return LineTables(order)


@functools.lru_cache(maxsize=8)
def fejer_table(ramps: int) -> np.ndarray:
    """|F_K(x)|^2 at x = 2 pi j / FEJER_POINTS, j = 0 .. FEJER_POINTS + 1."""
    x = 2.0 * np.pi * np.arange(FEJER_POINTS + 2) / FEJER_POINTS
    if ramps <= 1:
        return np.ones_like(x)
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.sin(ramps * x / 2) / (ramps * np.sin(x / 2))
    v[np.abs(np.sin(x / 2)) < 1e-9] = 1.0
    return v * v


def bessel_poly_py(beta, nmax, degree):  # pragma: no cover - compiled below
    """Coefficients (nmax + 1, degree + 1) of J_m(beta u) as polynomials in u."""
    out = np.zeros((nmax + 1, degree + 1))
    for m in range(nmax + 1):
        s = 0
        while 2 * s + m <= degree:
            p = 2 * s + m
            lg = p * math.log(beta / 2.0) - math.lgamma(s + 1) - math.lgamma(s + m + 1) if beta > 0 else 0.0
            if beta > 0:
                out[m, p] = (-1.0) ** s * math.exp(lg)
            elif p == 0:
                out[m, p] = 1.0
            s += 1
    return out


def fejer_at_py(ftab, x):  # pragma: no cover - compiled below
    """|F_K(x)|^2 from its table over one period (linear interpolation)."""
    n = ftab.shape[0] - 2
    u = (x / (2.0 * math.pi)) % 1.0 * n
    j = int(u)
    f = u - j
    return ftab[j] * (1.0 - f) + ftab[j + 1] * f


def table_at_py(table, jf, r, n_samples):  # pragma: no cover - compiled below
    """K_r at fractional table position jf (Taylor step from the nearest point)."""
    n_t = table.shape[0]
    j0 = math.floor(jf + 0.5)
    d = (jf - j0) * 2.0 * math.pi / n_t * n_samples
    idx = j0 % n_t
    v = 0.0 + 0.0j
    f = 1.0 + 0.0j
    fact = 1.0
    top = table.shape[1] - 1
    for q in range(TAYLOR_TERMS + 1):
        if r + q > top:
            break
        if q > 0:
            fact *= q
        v += f / fact * table[idx, r + q]
        f *= 1j * d
    return v


if numba is not None:
    bessel_poly = numba.njit(cache=True)(bessel_poly_py)
    fejer_at = numba.njit(cache=True)(fejer_at_py)
    table_at = numba.njit(cache=True)(table_at_py)
else:  # pragma: no cover
    bessel_poly = fejer_at = table_at = None
