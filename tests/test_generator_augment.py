"""sigma_P augmentation, nuisances, hard cases and bad input (SPEC sections 2-3)."""
import warnings

import numpy as np
import pytest
from scipy import stats

from mdaug.generator import (IDX, N_PARAMS, Acquisition, ClassParams, FixedParamsAugmenter, SigmaPAugmenter,
                             load_reference, profiles, spectra, validate_vectors)
from mdaug.generator.params import NONNEGATIVE, PHASES
from mdaug.radar import NORMALISATIONS, RadarConfig

HELI = load_reference("HELI")
QUAD = load_reference("QUAD")


def test_references_model_only_the_engines_present():
    assert (HELI.n_engines, HELI.size) == (1, 13)
    assert (QUAD.n_engines, QUAD.size) == (4, 52)
    assert "uncertain" in QUAD.note
    assert HELI.engines[0].w_p == pytest.approx(1.04 * (2.69e3 + 3.98e3))
    back = ClassParams.from_array(QUAD.to_array(), name="QUAD")
    np.testing.assert_array_equal(back.to_array(), QUAD.to_array())


def test_sigma_zero_reproduces_the_reference_exactly():
    batch = SigmaPAugmenter("HELI", 0.0, random_state=3).sample(4)
    ref = profiles(HELI.to_array(), dtype="float32")
    for row in batch.profiles:
        assert row.tobytes() == ref[0].tobytes()


@pytest.mark.parametrize("sigma", [0.05, 0.2])
def test_relative_spread_matches_sigma_p(sigma):
    n = 20000
    x = SigmaPAugmenter(QUAD, sigma, random_state=1).sample_params(n)
    ref = QUAD.to_array()
    nz = np.abs(ref) > 0
    rel_sd = x[:, nz].std(axis=0) / np.abs(ref[nz])
    # standard error of a standard deviation: sigma / sqrt(2 n); allow 5 of them
    assert np.all(np.abs(rel_sd - sigma) < 5 * sigma / np.sqrt(2 * n))
    assert np.all(np.abs(x[:, nz].mean(axis=0) - ref[nz]) < 5 * sigma * np.abs(ref[nz]) / np.sqrt(n))


def test_mixing_frequencies_follow_the_perturbed_roll_and_pitch():
    from mdaug.generator import vibration_terms

    x = SigmaPAugmenter(HELI, 0.3, random_state=2).sample_params(50)
    _, w, _ = vibration_terms(x)
    np.testing.assert_allclose(w[:, 0, 2], x[:, IDX["C_p"]] * np.abs(x[:, IDX["w_a"]] + x[:, IDX["w_b"]]))
    np.testing.assert_allclose(w[:, 0, 3], x[:, IDX["C_m"]] * np.abs(x[:, IDX["w_a"]] - x[:, IDX["w_b"]]))


def test_sign_policies():
    n, sigma = 40000, 1.0
    cols = [k * N_PARAMS + c for k in range(4) for c in NONNEGATIVE]
    reflect = SigmaPAugmenter(QUAD, sigma, random_state=5).sample_params(n)
    keep = SigmaPAugmenter(QUAD, sigma, sign_policy="keep", random_state=5).sample_params(n)
    trunc = SigmaPAugmenter(QUAD, sigma, sign_policy="truncate", random_state=5).sample_params(n)
    assert (reflect[:, cols] >= 0).all() and (trunc[:, cols] >= 0).all()
    # same draws, reflected: |keep| == reflect; a flip happens with probability Phi(-1/sigma)
    np.testing.assert_array_equal(np.abs(keep[:, cols]), reflect[:, cols])
    flipped = (keep[:, cols] < 0).mean()
    assert flipped == pytest.approx(stats.norm.cdf(-1 / sigma), abs=0.005)
    # truncate draws from N(x, |x|) truncated at 0: mean x + |x| phi(1)/Phi(1)
    ref = QUAD.to_array()[cols]
    want = ref * (1 + stats.norm.pdf(1) / stats.norm.cdf(1))
    np.testing.assert_allclose(trunc[:, cols].mean(axis=0), want, rtol=0.02)
    assert np.all(np.isfinite(SigmaPAugmenter(QUAD, sigma, sign_policy="keep", random_state=5).sample(64).profiles))


def test_uniform_phases_are_uniform_on_the_circle():
    from mdaug.generator.acquisition import draw_acquisitions

    x = draw_acquisitions(np.repeat(HELI.to_array()[None], 5000, 0), Acquisition(phases="uniform"),
                          np.random.default_rng(11)).x
    for c in PHASES:
        ks = stats.kstest(x[:, c], stats.uniform(loc=-np.pi, scale=2 * np.pi).cdf)
        assert ks.pvalue > 1e-3, (c, ks)
    # relative phases stay near the fitted value (phi_m = -0.04 is barely moved)
    rel = SigmaPAugmenter(HELI, 0.1, random_state=11).sample_params(5000)
    assert np.std(rel[:, IDX["phi_m"]]) < 0.01


def test_fixed_phases_are_untouched():
    x = SigmaPAugmenter(QUAD, 0.3, perturb_phases=False, random_state=1).sample_params(10)
    cols = [k * N_PARAMS + c for k in range(4) for c in PHASES]
    np.testing.assert_array_equal(x[:, cols], np.broadcast_to(QUAD.to_array()[cols], (10, len(cols))))


def test_ramp_average_converges_to_the_phase_averaged_profile():
    """K ramps (phases advancing by w x 2.88 ms) -> the average over uniform phases."""
    radar = RadarConfig()
    from mdaug.generator.acquisition import draw_acquisitions

    uniform = draw_acquisitions(np.repeat(HELI.to_array()[None], 6000, 0), Acquisition(phases="uniform"),
                                np.random.default_rng(0)).x
    reference = spectra(uniform, radar).mean(axis=0)
    errors = {}
    for k in (1, 16, 400):
        got = spectra(HELI.to_array(), radar, n_ramps=k)[0]
        errors[k] = np.linalg.norm(got - reference) / np.linalg.norm(reference)
    assert errors[400] < errors[16] < errors[1]
    assert errors[400] < 0.02


def test_range_jitter_moves_the_tone_within_the_requested_width():
    radar = RadarConfig()
    from mdaug.generator.acquisition import draw_acquisitions

    r0 = draw_acquisitions(np.repeat(HELI.to_array()[None], 4000, 0), Acquisition(range_jitter_bins=1.0),
                           np.random.default_rng(1)).r0
    offset_bins = (r0 - radar.model_range_m) / radar.model_range_per_bin()
    assert offset_bins.min() >= -0.5 and offset_bins.max() <= 0.5
    assert stats.kstest(offset_bins, stats.uniform(loc=-0.5, scale=1).cdf).pvalue > 1e-3


def test_same_seed_same_bytes():
    kw = dict(acquisition=Acquisition(phases="uniform", range_jitter_bins=1.0, ramps=2, carrier=(0, 0.3),
                                      noise_db=(-50, -40), mti_depth=10, yaw_deg=10.0))
    a = SigmaPAugmenter(QUAD, 0.2, random_state=7, **kw).sample(300)
    b = SigmaPAugmenter(QUAD, 0.2, random_state=7, **kw).sample(300)
    c = SigmaPAugmenter(QUAD, 0.2, random_state=8, **kw).sample(300)
    assert a.profiles.tobytes() == b.profiles.tobytes() and a.params.tobytes() == b.params.tobytes()
    assert a.profiles.tobytes() != c.profiles.tobytes()


@pytest.mark.parametrize("norm", NORMALISATIONS)
def test_hard_cases_are_finite(norm):
    base = HELI.to_array()
    equal_w = base.copy()
    equal_w[IDX["w_b"]] = equal_w[IDX["w_a"]]  # w_m = 0
    no_motion = base.copy()
    no_motion[[IDX[a] for a in ("A_a", "A_b", "A_p", "A_m")]] = 0.0
    silent = base.copy()
    silent[IDX["Gamma"]] = 0.0
    out = profiles(np.stack([equal_w, no_motion, silent]), normalisation=norm)
    assert np.all(np.isfinite(out))
    assert np.argmax(out[1]) == 200 and np.count_nonzero(out[1] == out[1].max()) == 1
    if norm in ("peak", "l2", "none"):
        assert np.all(out[2] == 0)
    big = SigmaPAugmenter(QUAD, 1.0, random_state=0, normalisation=norm).sample(500)
    assert np.all(np.isfinite(big.profiles))


def test_normalisations():
    p = {n: profiles(QUAD.to_array(), normalisation=n, dtype="float64")[0] for n in NORMALISATIONS}
    assert p["peak"].max() == pytest.approx(1.0)
    assert p["db"].max() == pytest.approx(0.0) and p["db"].min() >= -80.0
    assert np.linalg.norm(p["l2"]) == pytest.approx(1.0)
    np.testing.assert_allclose(p["none"] / p["none"].max(), p["peak"], rtol=1e-12)


def test_peak_near_the_end_is_zero_filled_not_shifted():
    radar = RadarConfig()
    r0_end = 2000 * radar.model_range_per_bin()  # tone at bin 2000 of 2048
    x = HELI.to_array()
    with pytest.warns(RuntimeWarning, match="zero-filled"):
        out, info = profiles(x, radar, r0=r0_end, return_info=True)
    peak = info.peak_bin[0]
    assert abs(peak - 2000) <= 1 and np.argmax(out[0]) == 200
    assert info.n_missing[0] == peak + 200 - 2048 and np.all(out[0, -info.n_missing[0]:] == 0)
    with pytest.raises(ValueError, match="spectrum's end"):
        profiles(x, radar, r0=r0_end, on_edge="error")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        profiles(x, radar, r0=r0_end, on_edge="pad")


def test_fixed_params_augmenter_cycles_its_vectors():
    x = np.stack([HELI.to_array(), HELI.to_array() * 1.01])
    got = FixedParamsAugmenter(x, label="HELI", random_state=0).sample(5)
    np.testing.assert_array_equal(got.params, x[[0, 1, 0, 1, 0]])


@pytest.mark.parametrize("bad, match", [
    (np.ones(12), "not a multiple of 13"),
    (np.r_[HELI.to_array()[:-1], np.nan], "phi_m\\[0\\] is nan"),
    (np.r_[-0.1, HELI.to_array()[1:]], "Gamma\\[0\\] = -0.1"),
])
def test_bad_vectors_are_named(bad, match):
    with pytest.raises(ValueError, match=match):
        validate_vectors(bad)
    with pytest.raises(ValueError, match="does not match 4 engine"):
        validate_vectors(HELI.to_array(), n_engines=4)


@pytest.mark.parametrize("kw, match", [
    (dict(centre="FOO"), "unknown class 'FOO'"),
    (dict(sigma_p=-0.1), "sigma_p must be a number in \\[0, 1\\]"),
    (dict(sigma_p=1.5), "sigma_p must be a number in \\[0, 1\\]"),
    (dict(sign_policy="wrap"), "sign_policy must be one of"),
])
def test_bad_augmenter_settings(kw, match):
    args = {"centre": "HELI", **kw}
    with pytest.raises(ValueError, match=match):
        SigmaPAugmenter(**args)


@pytest.mark.parametrize("n", [0, -5, 2.5])
def test_bad_sample_count(n):
    with pytest.raises(ValueError, match="positive integer"):
        SigmaPAugmenter("HELI", 0.1).sample(n)


def test_bad_acquisition():
    with pytest.raises(ValueError, match="phases must be one of"):
        Acquisition(phases="random")
    with pytest.raises(ValueError, match="ramps"):
        Acquisition(ramps=0)
    with pytest.raises(ValueError, match="range_jitter_bins"):
        Acquisition(range_jitter_bins=-1)
    with pytest.raises(ValueError, match="carrier"):
        Acquisition(carrier=(0.3, 0.1))
    with pytest.raises(ValueError, match="mti_depth"):
        Acquisition(mti_depth=-1)
