"""The vibration model against closed forms (SPEC section 1)."""
import numpy as np
import pytest
import scipy.fft
from scipy.special import jv

from mdaug.generator import IDX, N_PARAMS, if_signal, load_reference, profiles, spectra
from mdaug.radar import C0, RadarConfig

RADAR = RadarConfig()
T = np.arange(RADAR.samples_per_chirp) / RADAR.sample_rate_hz


def single_term(gamma=1.0, amp=0.0, w=0.0, phi=0.0):
    """One engine whose only vibration is the roll term (a)."""
    x = np.zeros(N_PARAMS)
    x[IDX["Gamma"]], x[IDX["A_a"]], x[IDX["w_a"]], x[IDX["phi_a"]] = gamma, amp, w, phi
    x[IDX["w_b"]] = w  # no b, p, m amplitude: their frequencies do not matter
    return x


@pytest.mark.parametrize("r0", [1.0, 2.2, 3.0, 4.1])
def test_static_tone_sits_at_the_conventions_bin(r0):
    mag = spectra(single_term(), RADAR, r0=r0)[0]
    expected_hz = 4 * RADAR.slope_hz_per_s * r0 / C0
    assert abs(np.argmax(mag) - expected_hz / RADAR.bin_hz) <= 0.5 + 1e-9
    # through the chain's mapping the model range shows at twice the range
    apparent = RADAR.frequency_to_range(np.argmax(mag) * RADAR.bin_hz)
    assert abs(apparent - 2 * r0) <= RADAR.bin_m


def test_frozen_bracket_matches_jacobi_anger_series():
    """With the bracket's t frozen at T0: cos(K R0 t + beta cos(w t + phi)),
    beta = K A T0 = sum_n J_n(beta) cos(K R0 t + n (w t + phi) + n pi / 2)."""
    r0, amp, w, phi, t0 = 3.0, 2.05e-3, 2.69e3, 1.04, 1.3e-3
    k = RADAR.model_k
    beta = k * amp * t0
    series = sum(jv(n, beta) * np.cos(k * r0 * T + n * (w * T + phi) + n * np.pi / 2) for n in range(-25, 26))
    expected = np.abs(scipy.fft.rfft(series, RADAR.fft_points))[: RADAR.n_bins]
    got = spectra(single_term(amp=amp, w=w, phi=phi), RADAR, r0=r0, bracket_time=t0)[0]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9 * expected.max())


def test_frozen_bracket_line_heights_are_bessel_values():
    """Lines placed on bin centres and far apart: |X| at line n is ~ Gamma |J_n(beta)| N_s / 2."""
    k = RADAR.model_k
    tone_bin, spacing = 900, 150
    r0 = tone_bin * RADAR.model_range_per_bin()
    w = 2 * np.pi * spacing * RADAR.bin_hz
    t0 = 1.26e-3
    amp = 1.8 / (k * t0)  # beta = 1.8: lines n = 0..3 all visible
    mag = spectra(single_term(gamma=0.7, amp=amp, w=w), RADAR, r0=r0, bracket_time=t0)[0]
    half = RADAR.samples_per_chirp / 2
    for n in range(-3, 4):
        measured = mag[tone_bin + n * spacing] / (0.7 * half)
        # neighbours 150 bins away leak ~2% through the rectangular window's sidelobes
        assert measured == pytest.approx(abs(jv(n, 1.8)), abs=0.03), n


def test_small_modulation_matches_first_order_ramp_envelope():
    """For K A T << 1: s ~ cos(K R0 t) - K A t cos(w t + phi) sin(K R0 t): the sidebands
    at +-w carry the transform of a linear ramp envelope, not of a constant one."""
    r0, amp, w, phi = 3.0, 2e-5, 2.0e4, 0.4  # sidebands ~65 bins out, clear of the tone
    k = RADAR.model_k
    tone = np.cos(k * r0 * T)

    def first_order(envelope):
        term = -k * amp * envelope * np.cos(w * T + phi) * np.sin(k * r0 * T)
        return np.abs(scipy.fft.rfft(term, RADAR.fft_points))[: RADAR.n_bins]

    signal = if_signal(single_term(amp=amp, w=w, phi=phi), RADAR, r0=r0, dtype="float64")[0]
    got = np.abs(scipy.fft.rfft(signal - tone, RADAR.fft_points))[: RADAR.n_bins]
    ramp, constant = first_order(T), first_order(np.full_like(T, T.mean()))
    side = int(round(RADAR.model_range_to_bin(r0) + w / (2 * np.pi) / RADAR.bin_hz))
    band = slice(side - 24, side + 25)
    scale = ramp[band].max()
    np.testing.assert_allclose(got, ramp, atol=1e-2 * scale)  # error is O((K A T)^2)
    assert np.max(np.abs(got[band] - constant[band])) > 0.2 * scale  # the envelope's shape shows


def test_sideband_distance_and_phase_excursion_scale():
    """SPEC scale sanity: w = 2.69e3 rad/s is ~8.8 bins; K A T ~ 0.66 rad for A = 2 mm."""
    assert 2.69e3 / (2 * np.pi) / RADAR.bin_hz == pytest.approx(8.77, abs=0.05)
    assert RADAR.model_k * 2e-3 * RADAR.chirp_duration_s == pytest.approx(0.66, abs=0.01)


def test_float32_path_keeps_the_carrier_phase():
    quad = load_reference("QUAD").to_array()
    p64 = profiles(quad, dtype="float64")
    p32 = profiles(quad, dtype="float32")
    assert np.argmax(p32) == np.argmax(p64) == RADAR.slice_length // 2
    assert np.max(np.abs(p32 - p64)) < 1e-5


def test_batch_equals_one_by_one_and_engines_add_linearly():
    quad = load_reference("QUAD").to_array()
    sig = if_signal(quad, RADAR, dtype="float64")[0]
    parts = sum(if_signal(quad[k * N_PARAMS:(k + 1) * N_PARAMS], RADAR, dtype="float64")[0] for k in range(4))
    np.testing.assert_allclose(sig, parts, atol=1e-12)
    batch = np.stack([quad, quad * np.r_[[1.0] * 51, 2.0]])
    one = np.concatenate([profiles(b, dtype="float64") for b in batch])
    np.testing.assert_array_equal(profiles(batch, dtype="float64"), one)
