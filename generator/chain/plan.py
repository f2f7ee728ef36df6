"""The reduced chain path's plan: what every block of one call shares (frames and MTI
weights, the rows around the true range bin, the angle tables, the receiver-noise
basis, the range window), and the scratch arrays its blocks reuse. The method is
described in :mod:`.path`."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ...radar.chain import angle_fft, angle_grid_deg

NOISE_TOL = 1e-8  # noise basis: largest relative variance left out per bin


# ---- the reduced computation ------------------------------------------------------
class Work(dict):
    """Scratch arrays reused across the blocks of one call (a fresh page costs a page
    fault: ~1 ms per K = 32 acquisition if every large temporary were new)."""

    def buf(self, name: str, shape, dtype) -> np.ndarray:
        a = self.get(name)
        if a is None or a.shape != tuple(shape) or a.dtype != np.dtype(dtype):
            a = self[name] = np.empty(shape, dtype)
        return a


@dataclass(frozen=True)
class Plan:
    """What every block of one call shares: frames rendered (J,) and their MTI weights
    (J,); the block's rows, ``rel`` (rows,) FFT bins relative to the true range bin:
    the search window +- search plus the profile's reach on both sides; angle tables
    (:func:`_angle_tables`), the angle-from-antenna matrix steer (n_a, A) and the
    half-width ``near`` of the detection's angle bins; the noise basis transposed
    (r, rows) and the conjugate of its phase ramp (rows,) (:func:`_noise_basis`), or
    None; the range window (N_s,) or None; whether the target may be sampled coarser
    and interpolated (:func:`_choose_step`); real and complex dtypes."""

    frames: np.ndarray
    weights: np.ndarray
    search: int
    reach: int
    rel: np.ndarray
    angles: tuple
    steer: np.ndarray
    near: int
    basis: np.ndarray | None
    deramp: np.ndarray | None
    taper: np.ndarray | None
    decimate: bool
    rdt: np.dtype
    cdt: np.dtype


def make_plan(scene, radar, chain, search, decimate=True) -> Plan:
    f, depth, n_ant = scene.frames(radar), radar.mti_depth, scene.antennas(radar)
    frames = np.arange(f) if scene.snr_db is not None else np.arange(f - depth - 1, f)  # all F for the noise power
    reach = radar.slice_length // 2 + 3  # profile rows: peak - reach .. peak + reach
    rel = np.arange(-(search + reach), search + reach + 1)
    angles = _angle_tables(max(chain.n_angle, n_ant), n_ant, radar.integration_width_deg)
    rdt = np.dtype(scene.dtype)
    cdt = np.result_type(rdt, np.complex64)
    basis = deramp = None
    if scene.snr_db is not None:
        basis, ramp = _noise_basis(len(rel), radar.samples_per_chirp, radar.fft_points, chain.window, scene.dtype)
        basis, deramp = basis.T.copy(), np.conj(ramp).astype(cdt)
    # detection angle bins: nearest to the azimuth +- near; beyond, the array gain at the
    # target is >= ~6% lower (n_a = 64, A = 8: the 3rd-nearest bin is >= 1.5 bins away)
    near = max(1, int(np.ceil(len(angles[0]) / (8 * n_ant))))
    taper = None if chain.window is None else _taper(chain.window, radar.samples_per_chirp).astype(rdt)
    return Plan(frames=frames, weights=_mti_weights(frames, f, depth), search=search, reach=reach, rel=rel,
                 angles=angles, steer=angles[1].T.astype(cdt), near=near, basis=basis, deramp=deramp,
                 taper=taper, decimate=decimate, rdt=rdt, cdt=cdt)


def _mti_weights(frames: np.ndarray, f: int, depth: int) -> np.ndarray:
    """Weights a_j (J,) of the last MTI frame over ``frames``: 1 for frame F-1, -1/depth
    for the depth frames before, 0 for earlier ones."""
    a = np.where(frames >= f - 1 - depth, -1.0 / depth, 0.0)
    a[frames == f - 1] = 1.0
    return a


@lru_cache(maxsize=8)
def _noise_basis(n_rows: int, ns: int, n_fft: int, window, dtype: str):
    """Factor of the covariance of the range spectrum of unit white noise on n_rows
    consecutive bins: C[b, b'] = sum_t w_t^2 exp(-2 pi i t (b - b') / N) (Toeplitz: the
    same for any first bin). Returns (basis (n_rows, r), ramp): C = D B B^H D^H with
    D = diag(ramp) (n_rows,). Without a range window the kernel is real up to the ramp
    exp(-i pi (N_s - 1) b / N) (the samples are symmetric about their centre), so B is
    real (half the work per product); with a window, B is complex and ramp is ones.
    r is the smallest rank that leaves out at most NOISE_TOL of any bin's variance."""
    from scipy.linalg import eigh, toeplitz

    taper = np.ones(ns) if window is None else _taper(window, ns)
    t = np.arange(ns) - (0.5 * (ns - 1) if window is None else 0.0)
    kernel = np.exp(-2j * np.pi * np.arange(n_rows)[:, None] * t / n_fft) @ taper ** 2  # C[b + lag, b], lag >= 0
    cov = toeplitz(kernel, np.conj(kernel))  # Hermitian (rows, rows)
    m = min(n_rows, int(n_rows * ns / n_fft) + 48)  # the spectrum's degrees of freedom, and a margin
    lam, vec = eigh(cov.real if window is None else cov, subset_by_index=[n_rows - m, n_rows - 1])
    lam, vec = np.maximum(lam[::-1], 0.0), vec[:, ::-1]
    tail = np.cumsum((np.abs(vec) ** 2 * lam)[:, ::-1], axis=1)[:, ::-1].max(axis=0)  # left out from rank i on
    ok = np.flatnonzero(tail <= NOISE_TOL * np.sum(taper ** 2))
    r = int(ok[0]) if ok.size else len(lam)
    basis = vec[:, :r] * np.sqrt(lam[:r])
    ramp = np.exp(-1j * np.pi * (ns - 1) * np.arange(n_rows) / n_fft) if window is None else np.ones(n_rows)
    rdt = np.dtype(dtype)
    return basis.astype(rdt if window is None else np.result_type(rdt, np.complex64)), ramp


def _taper(window: str, ns: int) -> np.ndarray:
    from scipy.signal import get_window

    return get_window(window, ns)


@lru_cache(maxsize=8)
def _angle_tables(n_angle: int, n_ant: int, width_deg: float):
    """Angle grid (n_a,) deg, antenna-to-angle matrix V (A, n_a) of the chain's angle FFT,
    and the integration sets of every theta_hat bin: indices (n_a, P) and weights (n_a, P)
    (the rule of :func:`mdaug.radar.chain.integrate_direction`, padded with weight 0)."""
    v = angle_fft(np.eye(n_ant, dtype=np.complex128), n_angle, axis=-2)  # row n: antenna n
    n_a = v.shape[1]
    grid = angle_grid_deg(n_a)
    sets = []
    for m in range(n_a):
        sel = np.abs(grid - grid[m]) <= 0.5 * width_deg + 1e-9
        sel[int(np.argmin(np.abs(grid - grid[m])))] = True
        sets.append(np.flatnonzero(sel))
    p = max(len(s) for s in sets)
    idx = np.array([np.pad(s, (0, p - len(s)), mode="edge") for s in sets])
    wts = np.array([np.r_[np.full(len(s), 1.0 / len(s)), np.zeros(p - len(s))] for s in sets])
    return grid, v, idx, wts
