"""The reduced chain path's range-angle image, formed only where the chain looks:
the receiver noise as range spectra on the block's rows, the detection, theta_hat
and the integrated profile (steps 3 and 4 of :mod:`.path`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...radar.seeds import rng as as_generator
from ..model import TWO_PI
from .plan import Plan, Work
from .target import mti_spectra

class _Noise:
    """Receiver noise after the MTI as range spectra on the block's rows: antenna a, ramp k
    sees sigma B zeta[a, k] (times the basis' phase ramp, moved onto the target instead:
    magnitudes do not change), B (rows, r) the basis, zeta (n, A, K, r) circular
    standard normal; beamformed on demand. Outputs are complex (n, M, K, B) or, for a
    real basis, real and imaginary parts (n, 2, M, K, B)."""

    def __init__(self, seeds, sigma, plan: Plan, n_ramps: int, work: Work):
        r, n_ant = plan.basis.shape[0], plan.steer.shape[1]
        self.work = work
        rngs = (as_generator(ss) for ss in seeds)
        self.zeta = np.stack([_complex_normal(rng, (n_ant, n_ramps, r), plan.rdt) for rng in rngs])
        self.zeta *= sigma.astype(plan.rdt)[:, None, None, None]
        self.basis_t, self.vt, self.k = plan.basis, plan.steer, n_ramps  # (r, rows), (n_a, A)

    def _basis_rows(self, rows) -> np.ndarray:
        """Basis^T columns: rows a slice (the same for all) or (start (n,), length)."""
        if isinstance(rows, slice):
            return self.basis_t[:, rows]
        start, length = rows
        r, total = self.basis_t.shape
        view = np.lib.stride_tricks.as_strided(self.basis_t, (r, total - length + 1, length),
                                               self.basis_t.strides + self.basis_t.strides[-1:], writeable=False)
        return np.moveaxis(view[:, start], 1, 0)  # (n, r, length)

    def angles_first(self, rows, angles, name: str) -> np.ndarray:
        """At block rows ``rows`` (see _basis_rows), angle bins (n, M)."""
        n, n_ant, _, r = self.zeta.shape
        m, bt = angles.shape[1], self._basis_rows(rows)
        eta = np.matmul(self.vt[angles], self.zeta.reshape(n, n_ant, -1)).reshape(n, m * self.k, r)
        if np.iscomplexobj(self.basis_t):
            out = self.work.buf(name, (n, m * self.k, bt.shape[-1]), eta.dtype)
            return np.matmul(eta, bt, out=out).reshape(n, m, self.k, -1)
        parts = self.work.buf(name + "eta", (n, 2, m * self.k, r), bt.dtype)  # one real product for both parts
        parts[:, 0], parts[:, 1] = eta.real, eta.imag
        out = self.work.buf(name, (n, 2, m * self.k, bt.shape[-1]), bt.dtype)
        np.matmul(parts, bt if bt.ndim == 2 else bt[:, None], out=out)
        return out.reshape(n, 2, m, self.k, -1)

    def antennas_first(self, start, length) -> np.ndarray:
        """At block rows start .. start + length - 1 (start (n,)), all angle bins; complex."""
        n, n_ant, _, r = self.zeta.shape
        bt = self._basis_rows((start, length)).astype(self.zeta.dtype)
        ant = np.matmul(self.zeta.reshape(n, -1, r), bt)  # (n, A K, B)
        out = np.matmul(self.vt, ant.reshape(n, n_ant, -1))  # (n, n_a, K B)
        return out.reshape(n, self.vt.shape[0], self.k, -1)


def _complex_normal(rng: np.random.Generator, shape, dtype) -> np.ndarray:
    """Circular complex standard normals (E|z|^2 = 1) by Box-Muller: sqrt(-ln u1) e^{2 pi i u2}
    (|z|^2 ~ Exp(1), uniform phase); ~3x faster than two standard_normal draws. float32
    uniforms cap |z|^2 at 16.6 (P = 6e-8 beyond)."""
    radius = np.sqrt(-np.log1p(-rng.random(shape, dtype=np.float32)))  # u1 in [0, 1): 1 - u1 > 0
    angle = np.float32(TWO_PI) * rng.random(shape, dtype=np.float32)
    z = np.empty(shape, np.result_type(dtype, np.complex64))
    z.real = radius * np.cos(angle)
    z.imag = radius * np.sin(angle)
    return z


def _ramp_mean_mag(tp, tm, gp, gm, noise, work, name) -> np.ndarray:
    """Ramp-averaged |I_MTI| (n, M, B): tp, tm (n, K, B) spectra Z(b), conj Z(-b); gp, gm
    (n, M) angle responses of e^{+-i psi} / 2; noise (n, M, K, B) complex, or its real and
    imaginary parts (n, 2, M, K, B), or None."""
    shape = (tp.shape[0], gp.shape[1]) + tp.shape[1:]
    img, tmp = work.buf(name, shape, tp.dtype), work.buf(name + "+", shape, tp.dtype)
    np.multiply(tp[:, None], gp[:, :, None, None], out=img)
    img += np.multiply(tm[:, None], gm[:, :, None, None], out=tmp)
    if noise is not None and np.iscomplexobj(noise):
        img += noise
    elif noise is not None:
        img.real += noise[:, 0]
        img.imag += noise[:, 1]
    return np.abs(img, out=work.buf(name + "|", shape, tp.real.dtype)).mean(axis=2)


def _windows(arr: np.ndarray, start: np.ndarray, length: int) -> np.ndarray:
    """(n, K, length) copy of arr[i, :, start[i]: start[i] + length] for arr (n, K, R)."""
    n, k, r = arr.shape
    view = np.lib.stride_tricks.as_strided(arr, (n, k, r - length + 1, length), arr.strides + arr.strides[-1:],
                                           writeable=False)
    return view[np.arange(n), :, start]


@dataclass
class _Block:
    """One block's image ingredients: tp, tm (n, K, rows) Z(b) and conj Z(-b) on the block's
    rows; gp, gm (n, n_a) angle responses of e^{+-i psi_n} / 2; first (n,) absolute bin
    of row 0; s (n,) sin(azimuth); noise (:class:`_Noise`) or None."""

    tp: np.ndarray
    tm: np.ndarray
    gp: np.ndarray
    gm: np.ndarray
    first: np.ndarray
    s: np.ndarray
    noise: "_Noise | None"

    def mag(self, rows, angles, work, name) -> np.ndarray:
        """Ramp-averaged |I_MTI| (n, M, B): rows a slice or (start (n,), length); angles
        (n, M) bins, or None for all (the noise then goes through the antennas first)."""
        if isinstance(rows, slice):
            tp, tm = self.tp[..., rows], self.tm[..., rows]
        else:
            tp, tm = _windows(self.tp, *rows), _windows(self.tm, *rows)
        if angles is None:
            noise = None if self.noise is None else self.noise.antennas_first(*rows)
            return _ramp_mean_mag(tp, tm, self.gp, self.gm, noise, work, name)
        ii = np.arange(len(angles))[:, None]
        noise = None if self.noise is None else self.noise.angles_first(rows, angles, "noise " + name)
        return _ramp_mean_mag(tp, tm, self.gp[ii, angles], self.gm[ii, angles], noise, work, name)


def _make_block(d, sl, plan: Plan, scene, radar, noise_seeds, step, work) -> _Block:
    base = np.rint(d.range_m[sl][:, -1] / radar.bin_m).astype(np.int64)  # true range bin (n,)
    n, n_fft = len(base), radar.fft_points
    spec, power = mti_spectra(d, sl, plan, scene, radar, base, step, work)
    first = base + plan.rel[0]
    mirror = (-(first[:, None] + np.arange(len(plan.rel))) - base[:, None]) % n_fft  # -b, shifted down by base
    tm = work.buf("tm", (n, spec.shape[1], len(plan.rel)), spec.dtype)
    np.conjugate(spec[np.arange(n)[:, None, None], np.arange(spec.shape[1])[:, None], mirror[:, None]], out=tm)
    s = np.sin(np.radians(d.azimuth_deg[sl]))
    steer = np.exp(1j * np.pi * np.arange(plan.steer.shape[1]) * s[:, None])  # (n, A)
    noise = None
    if power is not None:
        sigma = np.sqrt(power / 10 ** (scene.snr_db / 10) * np.sum(plan.weights ** 2))  # MTI'd noise, per sample
        noise = _Noise(noise_seeds, sigma, plan, scene.acquisition.ramps, work)
    tp = np.take(spec, plan.rel % n_fft, axis=2, out=work.buf("tp", tm.shape, tm.dtype))
    if noise is not None:  # the noise basis' phase ramp, moved onto the target (|.| unchanged)
        tp *= plan.deramp
        tm *= plan.deramp
    return _Block(tp=tp, tm=tm, gp=(0.5 * steer @ plan.steer.T).astype(plan.cdt),
                  gm=(0.5 * steer.conj() @ plan.steer.T).astype(plan.cdt), first=first, s=s, noise=noise)


def _detect(blk: _Block, plan: Plan, nb: int, work) -> tuple[np.ndarray, np.ndarray]:
    """Block row (n,) of the detection peak: max over the angle bins nearest the azimuth
    of the ramp-averaged |I_MTI|, argmax over the search window (never bin 0 or nb - 1);
    and whether it sits on the window's edge (n,) bool (the true maximum may lie beyond)."""
    n_a = len(plan.angles[0])
    m0 = np.rint(blk.s * n_a / 2).astype(np.int64) + n_a // 2
    near = (m0[:, None] + np.arange(-plan.near, plan.near + 1)) % n_a
    rows = slice(plan.reach, plan.reach + 2 * plan.search + 1)
    det = blk.mag(rows, near, work, "det").max(axis=1)
    bins = blk.first[:, None] + np.arange(rows.start, rows.stop)
    det[(bins < 1) | (bins > nb - 2)] = -np.inf
    at = np.argmax(det, axis=1)
    at_edge = ((at == 0) & (bins[:, 0] >= 1)) | ((at == det.shape[1] - 1) & (bins[:, -1] <= nb - 2))
    return plan.reach + at, at_edge


def _direction(blk: _Block, pk: np.ndarray, nb: int, work) -> np.ndarray:
    """theta_hat's angle bin (n,): argmax over all angle bins of |I_MTI| summed over the
    peak +- 2 bins inside the spectrum (:func:`mdaug.radar.chain.estimate_direction`)."""
    mag = blk.mag((pk - 2, 5), None, work, "dir")  # (n, n_a, 5)
    bins = (blk.first + pk)[:, None] + np.arange(-2, 3)
    return np.argmax((mag * ((bins >= 0) & (bins < nb))[:, None]).sum(axis=2), axis=1)


def _profile(blk: _Block, plan: Plan, pk, m_hat, radar, work) -> dict:
    """Integrated profile over theta_hat +- width/2 (angle sets of the chain's rule),
    centre refined to its maximum within peak +- 3 bins, then the zero-filled window."""
    length, nb, reach = radar.slice_length, radar.n_bins, plan.reach
    half, (sel_idx, sel_w) = length // 2, plan.angles[2:]
    mag = blk.mag((pk - reach, 2 * reach + 1), sel_idx[m_hat], work, "prof")  # (n, P, rows)
    prof = np.matmul(sel_w[m_hat][:, None].astype(mag.dtype), mag)[:, 0]  # weighted mean over the set
    bins = (blk.first + pk - reach)[:, None] + np.arange(2 * reach + 1)
    inside = (bins >= 0) & (bins < nb)
    c = half + np.argmax(np.where(inside[:, half:half + 7], prof[:, half:half + 7], -np.inf), axis=1)
    ii, widx = np.arange(len(c))[:, None], c[:, None] - half + np.arange(length)
    return {"profiles": np.where(inside, prof, 0)[ii, widx].astype(np.float32), "peak_bin": bins[ii[:, 0], c],
            "n_missing": length - inside[ii, widx].sum(axis=1)}


def reduced_block(d, sl, plan: Plan, scene, radar, noise_seeds, step, work) -> dict:
    """Profiles and chain estimates of acquisitions ``sl`` (a slice or row indices) by the
    reduced computation, the target sampled every ``step``-th sample."""
    blk = _make_block(d, sl, plan, scene, radar, noise_seeds, step, work)
    pk, at_edge = _detect(blk, plan, radar.n_bins, work)
    m_hat = _direction(blk, pk, radar.n_bins, work)
    out = _profile(blk, plan, pk, m_hat, radar, work)
    out["direction_deg"] = plan.angles[0][m_hat].astype(np.float64)
    out["at_edge"] = at_edge
    return out
