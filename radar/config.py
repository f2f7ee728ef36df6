"""The one radar configuration object of the toolkit.

Range convention (stated once, used everywhere):

* The vibration model (SPEC section 1) writes the IF signal of a scatterer at model
  range ``R0`` as ``cos(K * R0 * t)`` with ``K = 8*pi*mu/c0``: its beat tone sits at
  ``f = 4*mu*R0/c0``.
* The processing chain maps a beat frequency to range with ``R = c0*f/(2*mu)``.

So a model range ``R0`` appears at apparent range ``2*R0`` in chain coordinates.
:meth:`RadarConfig.model_range_to_frequency`, :meth:`frequency_to_range` and
friends are the only places that encode this.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

C0 = 299_792_458.0  # speed of light, m/s


@dataclass(frozen=True)
class RadarConfig:
    """FMCW MIMO radar settings, with the published platform's values as defaults.

    All frequencies in Hz, times in s, ranges in m, angles in degrees.
    """

    ramp_start_hz: float = 75e9
    ramp_stop_hz: float = 79e9
    slope_hz_per_s: float = 1.56e12
    sample_rate_hz: float = 200e3
    samples_per_chirp: int = 504
    fft_points: int = 4096
    n_rx: int = 8
    n_tx: int = 4
    mti_depth: int = 10
    adc_bits: int = 12
    integration_width_deg: float = 7.0
    slice_length: int = 400
    ramp_time_up_s: float = 2.56e-3
    ramp_time_down_s: float = 0.32e-3
    max_ramps_per_frame: int = 1000
    """The most ramps the platform runs in one frame: the bound on an acquisition's K
    (the ramps a frame's profile averages, ``Acquisition.ramps``; :meth:`check_ramps`)."""
    frame_interval_s: float = 0.2
    model_range_m: float = 3.0
    """Default model range R0 of the vibration model (m, model convention)."""

    def __post_init__(self) -> None:
        checks = {
            "slope_hz_per_s": self.slope_hz_per_s > 0,
            "sample_rate_hz": self.sample_rate_hz > 0,
            "samples_per_chirp": self.samples_per_chirp > 1,
            "fft_points": self.fft_points >= self.samples_per_chirp,
            "n_rx": self.n_rx >= 1,
            "n_tx": self.n_tx >= 1,
            "mti_depth": self.mti_depth >= 1,
            "adc_bits": 2 <= self.adc_bits <= 32,
            "integration_width_deg": self.integration_width_deg > 0,
            "slice_length": 2 <= self.slice_length <= self.fft_points // 2,
            "ramp_start_hz": 0 < self.ramp_start_hz < self.ramp_stop_hz,
            "model_range_m": self.model_range_m > 0,
            "max_ramps_per_frame": self.max_ramps_per_frame >= 1,
        }
        for field, ok in checks.items():
            if not ok:
                raise ValueError(
                    f"RadarConfig.{field} = {getattr(self, field)!r} is out of range "
                    "(need positive sizes, fft_points >= samples_per_chirp, "
                    "2 <= slice_length <= fft_points/2, ramp_start < ramp_stop)"
                )

    # ---- derived quantities -------------------------------------------------
    @property
    def n_bins(self) -> int:
        """Bins kept of the real signal's spectrum: 0 .. fft_points/2 - 1."""
        return self.fft_points // 2

    @property
    def bin_hz(self) -> float:
        """Spacing of FFT bins, Hz."""
        return self.sample_rate_hz / self.fft_points

    @property
    def bin_m(self) -> float:
        """Spacing of FFT bins in chain range (R = c0*f/(2*mu)), m."""
        return C0 * self.bin_hz / (2.0 * self.slope_hz_per_s)

    @property
    def centre_frequency_hz(self) -> float:
        return 0.5 * (self.ramp_start_hz + self.ramp_stop_hz)

    @property
    def wavelength_m(self) -> float:
        return C0 / self.centre_frequency_hz

    @property
    def bandwidth_hz(self) -> float:
        return self.ramp_stop_hz - self.ramp_start_hz

    @property
    def max_range_m(self) -> float:
        """Largest unambiguous chain range (beat frequency fs/2), m."""
        return self.frequency_to_range(self.sample_rate_hz / 2.0)

    @property
    def ramp_period_s(self) -> float:
        """Time from one ramp's start to the next (up + down), s."""
        return self.ramp_time_up_s + self.ramp_time_down_s

    @property
    def chirp_duration_s(self) -> float:
        """Sampled part of a chirp, N_s / fs, s."""
        return self.samples_per_chirp / self.sample_rate_hz

    @property
    def model_k(self) -> float:
        """K = 8*pi*mu/c0 of the vibration model, rad/(m*s)."""
        return 8.0 * math.pi * self.slope_hz_per_s / C0

    # ---- conversions (the range convention lives here) ------------------------
    def frequency_to_range(self, f_hz):
        """Chain range R = c0*f/(2*mu) of a beat frequency (m)."""
        return C0 * f_hz / (2.0 * self.slope_hz_per_s)

    def range_to_frequency(self, r_m):
        return 2.0 * self.slope_hz_per_s * r_m / C0

    def model_range_to_frequency(self, r0_m):
        """Beat frequency 4*mu*R0/c0 of a scatterer at model range R0 (Hz)."""
        return 4.0 * self.slope_hz_per_s * r0_m / C0

    def model_range_to_bin(self, r0_m):
        """Fractional FFT bin of model range R0."""
        return self.model_range_to_frequency(r0_m) / self.bin_hz

    def model_range_per_bin(self) -> float:
        """Change of model range R0 that moves the tone by one bin, m."""
        return C0 * self.bin_hz / (4.0 * self.slope_hz_per_s)

    def check_ramps(self, k: int, what: str = "Acquisition.ramps") -> None:
        """Refuse K ramps per frame beyond what the radar runs (``what`` names the setting)."""
        if k > self.max_ramps_per_frame:
            raise ValueError(f"{what} = {k}: more ramps per frame than the radar runs (its max_ramps_per_frame "
                             f"is {self.max_ramps_per_frame})")

    def replace(self, **changes) -> "RadarConfig":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict, source: str = "radar config") -> "RadarConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        if "ramps_per_frame" in d and "max_ramps_per_frame" not in d:  # its earlier name, in the shipped estimators and older files
            d = {("max_ramps_per_frame" if k == "ramps_per_frame" else k): v for k, v in d.items()}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"{source}: unknown radar field(s) {unknown}; known: {sorted(known)}")
        return cls(**d)
