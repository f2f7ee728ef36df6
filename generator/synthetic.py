"""Common-random-number draws of an acquisition, for synthetic likelihoods.

The calibration marginalises what an :class:`~.acquisition.Acquisition`
randomises (phases, MTI residual, carrier-return phase, sub-bin range, yaw,
noise) by simulation: for a class vector it renders O acquisitions of I ramps
each, always with the same random draws (common random numbers, so the result is
a smooth function of the vector), and the likelihood is a Gaussian whose mean and
covariance are those of the rendered profiles (:mod:`mdaug.inference.likelihood.synthetic`).

What is drawn here follows :func:`~.acquisition.draw_acquisitions` term by term
(tested equal to :func:`~.acquisition.ramp_signals` on the same draws), with two
differences that make it fast:

* all O x I ramps of one class vector share its frequencies, so every term's
  displacement is a small matrix product with a table of cos(w t), sin(w t);
* the carrier return and the receiver noise enter linearly in the complex
  spectrum, so they are added per measurement (amplitude and level are the
  measurement's parameters) to spectra computed once: the carrier return as the
  spectrum of a unit tone at the acquisition's range and phase, the noise as the
  spectrum of fixed unit white noise.

Each measurement's sub-bin position is its own parameter (the offset of its centre
bin from the carrier tone, :meth:`SyntheticDraws.profiles`), so it is not drawn.

An acquisition's I ramps are consecutive ramps of the acquisition (phases advance
by w x ramp period between them), I = min(K, ``ramps_drawn``): with I < K the
spread of the I-ramp averages is a little larger than the data's K-ramp averages
(measured for HELI at K = 32: +12% at I = 8), which errs on the side of wider
posteriors.
"""
from __future__ import annotations

import numpy as np
import scipy.fft

from ..radar import RadarConfig
from ..radar.seeds import rng as as_generator
from .acquisition import (Acquisition, AcquisitionDraws, frame_phases, noise_sigma, phase_columns, residual_offsets,
                          yaw_mix)
from .model import wrap_phase
from .params import IDX, N_PARAMS, validate_vectors


class SyntheticDraws:
    """O acquisitions x I ramps of fixed random draws (see the module doc).

    acq: the acquisition; n_engines: E; n_acquisitions: O; ramps_drawn: I_max;
    margin: the largest offset (bins) of a profile's centre from the carrier tone;
    seed: int or SeedSequence (the common random numbers). The window of a profile
    is the ``radar.slice_length`` bins centred on its peak, as f(x) and the chain do.
    """

    def __init__(self, acq: Acquisition, n_engines: int, radar: RadarConfig = RadarConfig(), *,
                 n_acquisitions: int = 16, ramps_drawn: int = 8, margin: int = 40, seed=0,
                 dtype: str = "float32"):
        if n_acquisitions < 2:
            raise ValueError(f"n_acquisitions must be >= 2 (a spread needs two), got {n_acquisitions}")
        self.acq, self.E, self.radar, self.dtype = acq, int(n_engines), radar, np.dtype(dtype)
        self.O, self.I = int(n_acquisitions), int(min(acq.ramps, max(1, ramps_drawn)))
        rng = as_generator(seed)
        o, e = self.O, self.E
        half = radar.slice_length // 2
        self.centre = int(round(radar.model_range_to_bin(radar.model_range_m)))
        self.margin = int(margin)
        lo = self.centre - half - self.margin
        if lo < 0 or self.centre + half + self.margin > radar.n_bins:
            raise ValueError(f"model range {radar.model_range_m} m puts the profile window outside the spectrum")
        self.band = np.arange(lo, self.centre + half + self.margin)
        self.t = np.arange(radar.samples_per_chirp) / radar.sample_rate_hz
        # unit draws, in the order of draw_acquisitions (yaw, phases, range, carrier, noise, residual)
        self.yaw = np.radians(rng.uniform(-acq.yaw_deg, acq.yaw_deg, o)) if acq.yaw_deg else np.zeros(o)
        # uniform: the phase rule's draws; fixed: None, the vectors' own phases
        self.phases = frame_phases(np.zeros((o, e * N_PARAMS)), 1, "uniform", rng)[:, 0] \
            if acq.phases == "uniform" else None
        rng.uniform(size=o)  # (the sub-bin position is each measurement's offset parameter, not drawn)
        self.r0 = np.full(o, radar.model_range_m)
        self.carrier_u = rng.uniform(size=o)  # unused (the amplitude is a parameter); keeps streams aligned
        self.carrier_phase = rng.uniform(-np.pi, np.pi, o)
        self.noise_u = rng.uniform(size=o)
        if acq.mti_depth:
            self.residual_offset = residual_offsets((o, e, 4), acq.phases, rng)
            self.residual_r0 = self.r0 + acq.drift_bins * rng.standard_normal(o) * radar.model_range_per_bin()
            self.residual_phase = rng.uniform(-np.pi, np.pi, o)
        noise = rng.standard_normal((o, self.I, radar.samples_per_chirp))
        noise_spectra = scipy.fft.rfft(noise, n=radar.fft_points, axis=-1)[..., self.band].astype(np.complex64)
        ph = radar.model_k * self.r0[:, None] * self.t + self.carrier_phase[:, None]
        self.tone_spectra = scipy.fft.rfft(np.cos(ph), n=radar.fft_points, axis=-1)[:, self.band].astype(np.complex64)
        self.ramp_times = np.arange(self.I) * radar.ramp_period_s
        self._noise_t = np.ascontiguousarray(noise_spectra.reshape(o * self.I, -1).T)  # (band, O I)
        self._tone_t = np.ascontiguousarray(self.tone_spectra.T)  # (band, O)

    # ---- the draws as AcquisitionDraws (for checks against the renderer) ------------------
    def acquisition_draws(self, x, carrier, noise_db) -> AcquisitionDraws:
        """The draws of vector x (13E,) with carrier-return ratio and noise level as
        :class:`AcquisitionDraws` (O rows), for :func:`.acquisition.ramp_signals`."""
        x = validate_vectors(x, self.E, physical=False)[0]
        seen = self._seen(x[None])[0]
        gsum = x.reshape(self.E, N_PARAMS)[:, IDX["Gamma"]].sum()
        d = AcquisitionDraws(x=seen, r0=self.r0.copy(), carrier=np.full(self.O, carrier * gsum),
                             carrier_phase=self.carrier_phase.copy(),
                             noise_sigma=np.full(self.O, 0.0 if noise_db is None else float(noise_sigma(noise_db, gsum, self.radar))),
                             yaw_deg=np.degrees(self.yaw))
        if self.acq.mti_depth:
            res = seen.copy()
            cols = phase_columns(self.E)
            res[:, cols] = seen[:, cols] + self.residual_offset.reshape(self.O, -1)
            d.residual_x, d.residual_r0, d.residual_phase = res, self.residual_r0.copy(), self.residual_phase.copy()
        return d

    def _seen(self, x: np.ndarray) -> np.ndarray:
        """(W, 13E) -> (W, O, 13E): yaw-mixed, with the draws' phases."""
        w = x.shape[0]
        rows = np.repeat(x, self.O, axis=0)
        if self.acq.yaw_deg:
            rows = yaw_mix(rows, np.tile(self.yaw, w))
        rows = rows.reshape(w, self.O, -1)
        if self.phases is not None:
            rows[..., phase_columns(self.E)] = self.phases.reshape(1, self.O, -1)
        return rows

    # ---- rendering ----------------------------------------------------------------------------
    def _signals(self, x: np.ndarray) -> np.ndarray:
        """IF samples (W, O, I, N_s) of target minus MTI residual for vectors x (W, 13E)."""
        seen = self._seen(x)  # (W, O, 13E)
        w_n, o, e = x.shape[0], self.O, self.E
        xe = seen.reshape(w_n, o, e, N_PARAMS)
        wa, wb = xe[..., IDX["w_a"]], xe[..., IDX["w_b"]]
        freq = np.stack([wa, wb, xe[..., IDX["C_p"]] * np.abs(wa + wb), xe[..., IDX["C_m"]] * np.abs(wa - wb)],
                        axis=-1)[:, 0]  # (W, E, 4): the same for every acquisition
        amp = xe[..., [IDX["A_a"], IDX["A_b"], IDX["A_p"], IDX["A_m"]]]  # (W, O, E, 4)
        phi = xe[..., [IDX["phi_a"], IDX["phi_b"], IDX["phi_p"], IDX["phi_m"]]]
        gam = xe[..., IDX["Gamma"]]  # (W, O, E)
        advance = freq[:, None, None] * self.ramp_times[None, None, :, None, None]  # (W, 1, I, E, 4)
        arg = np.multiply.outer(freq, self.t)  # (W, E, 4, Ns)
        trig = np.concatenate([np.cos(arg), np.sin(arg)], axis=2).astype(self.dtype)  # (W, E, 8, Ns)
        k = self.radar.model_k
        kt = (k * self.t).astype(self.dtype)

        def frame(phases, r0, carrier):
            ph = phases[:, :, None] + advance  # (W, O, I, E, 4)
            # d(t) = sum_j A_j cos(w_j t + phi_j) = sum_j A_j (cos phi_j cos w_j t - sin phi_j sin w_j t):
            # one (O I, 8) @ (8, N_s) product per walker and engine
            coef = np.concatenate([amp[:, :, None] * np.cos(ph), -amp[:, :, None] * np.sin(ph)], axis=-1)
            coef = np.moveaxis(coef.astype(self.dtype), 3, 1).reshape(w_n, e, o * self.I, 8)
            disp = np.matmul(coef, trig)  # (W, E, O I, N_s)
            base = k * r0[:, None] * self.t + carrier[:, None]  # (O, Ns) float64
            base = wrap_phase(base).astype(self.dtype)
            total = np.repeat(base, self.I, axis=0)[None, None] + kt * disp
            np.cos(total, out=total)
            g = np.moveaxis(np.repeat(gam.astype(self.dtype), self.I, axis=1), 2, 1)  # (W, E, O I)
            return np.einsum("weq,weqn->wqn", g, total).reshape(w_n, o, self.I, -1)

        sig = frame(phi, self.r0, np.zeros(o))
        if self.acq.mti_depth:
            sig -= frame(phi + self.residual_offset[None], self.residual_r0, self.residual_phase) * \
                self.dtype.type(1.0 / np.sqrt(self.acq.mti_depth))
        return sig

    def spectra(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Complex band spectra (W, O, I, B) of target minus MTI residual (no carrier
        return, no noise) and sum(Gamma) (W,) of vectors x (W, 13E) or (13E,)."""
        x = validate_vectors(x, self.E, physical=False)
        sig = self._signals(x)
        spec = scipy.fft.rfft(sig, n=self.radar.fft_points, axis=-1)[..., self.band]
        gsum = x.reshape(x.shape[0], self.E, N_PARAMS)[..., IDX["Gamma"]].sum(axis=1)
        return spec, gsum

    def profiles(self, x, carrier, noise_db, offset, stride: int = 1) -> np.ndarray:
        """I-ramp-averaged profiles (W, M, O, B) of vectors x (W, 13E) for M
        measurements, each with its carrier-return ratio, noise floor (dB,
        :func:`.acquisition.noise_sigma`) and offset (bins: where the measured
        profile's centre bin sits relative to the carrier tone), all (W, M).

        A profile is sampled at its centre + every ``stride``-th bin
        (:meth:`window_offsets`) and normalised to 1 at the centre, as a measured
        profile centred on its peak is. The fractional positions are read off the
        complex spectrum by cubic (Keys) interpolation, which the 8-fold oversampled
        spectrum makes accurate to ~1e-4 of the peak: unlike an argmax centring, the
        result is a continuous function of the offset and the vector."""
        spec, gsum = self.spectra(x)
        carrier = np.atleast_2d(np.asarray(carrier, float))
        w_n, m_n = carrier.shape
        offset = np.broadcast_to(np.asarray(offset, float), (w_n, m_n))
        amp_c = (carrier * gsum[:, None]).astype(np.float32)  # (W, M)
        sig_n = np.zeros((w_n, m_n), np.float32) if noise_db is None else \
            noise_sigma(np.atleast_2d(noise_db), gsum[:, None], self.radar).astype(np.float32)
        offsets = self.window_offsets(stride)
        c0 = self.centre - self.band[0]
        taps = np.arange(-1, 3)
        if np.any(np.abs(offset) > self.margin - 2):
            raise ValueError(f"offset must be within +-{self.margin - 2} bins, got {offset.min()}..{offset.max()}")
        out = np.empty((w_n, m_n, self.O, offsets.size), np.float32)
        # band axis first, so that reading a bin copies O I contiguous values (a gather along the
        # last axis copies one value at a time and cost a third of the evaluation)
        o_i = self.O * self.I
        spec_t = np.ascontiguousarray(np.moveaxis(spec.reshape(w_n, o_i, -1), -1, 1))  # (W, band, O I)
        walkers = np.arange(w_n)[:, None]
        for m in range(m_n):
            pos = c0 + offset[:, m]  # (W,)
            base = np.floor(pos).astype(int)
            f = (pos - base)[:, None]
            wts = np.concatenate([(-f**3 + 2 * f**2 - f) / 2, (3 * f**3 - 5 * f**2 + 2) / 2,
                                  (-3 * f**3 + 4 * f**2 + f) / 2, (f**3 - f**2) / 2], axis=1).astype(np.float32)
            flat = (base[:, None, None] + offsets[None, :, None] + taps[None, None, :]).reshape(w_n, -1)  # (W, B*4)
            z = spec_t[walkers, flat]  # (W, B*4, O I)
            by_ramp = z.reshape(w_n, -1, self.O, self.I)  # a view of z
            by_ramp += amp_c[:, m, None, None, None] * self._tone_t[flat][..., None]
            z += sig_n[:, m, None, None] * self._noise_t[flat]
            z = np.einsum("wbtq,wt->wbq", z.reshape(w_n, offsets.size, 4, o_i), wts)  # (W, B, O I)
            mag = np.abs(z).reshape(w_n, offsets.size, self.O, self.I).mean(axis=-1).transpose(0, 2, 1)  # (W, O, B)
            centre = mag[..., np.flatnonzero(offsets == 0)[0], None]
            out[:, m] = mag / np.where(centre > 0, centre, 1)
        return out

    def window_offsets(self, stride: int = 1) -> np.ndarray:
        """Bins (relative to the peak) that :meth:`profiles` samples."""
        half = self.radar.slice_length // 2
        return np.arange(-(half // stride) * stride, half, stride)
