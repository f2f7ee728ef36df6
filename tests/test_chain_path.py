"""The chain path of the augmentation renderer (generator/chain_path.py).

The reduced computation against the literal one (raw cubes through radar/chain.py) on
the same scene draws: equal to float32 rounding without noise and ADC, within the ADC's
rounding floor with it, and equal in distribution with receiver noise.
"""
import numpy as np
import pytest

from mdaug.generator import load_reference
from mdaug.generator.chain import ChainProfiles, SceneConfig, render_through_chain
from mdaug.radar import RadarConfig
from mdaug.radar.chain import ChainConfig

RADAR = RadarConfig()
NO_NOISE = dict(snr_db=None, quantise=False)  # clutter stays on (default scene: 6 scatterers)


def rows(cls, n):
    return np.repeat(load_reference(cls).to_array()[None], n, axis=0)


def both(x, scene, seed=0, chain=ChainConfig(), **kw):
    lit = render_through_chain(x, scene, RADAR, chain, random_state=seed, method="literal", **kw)
    red = render_through_chain(x, scene, RADAR, chain, random_state=seed, method="reduced", **kw)
    return lit, red


def peak_normalised(p):
    return p.profiles / p.profiles.max(axis=1, keepdims=True)


@pytest.mark.parametrize("cls", ["HELI", "QUAD"])
@pytest.mark.parametrize("ramps,n", [(1, 6), (4, 4), (32, 2)])
def test_reduced_equals_literal_on_the_same_draws(cls, ramps, n):
    """Clutter on, no noise, no ADC: the same numbers to float32 rounding (measured
    <= 3e-7 of the peak; the acceptance bound is 1e-3), same peak bin and direction,
    same absolute scale."""
    lit, red = both(rows(cls, n), SceneConfig(**NO_NOISE).with_acquisition(ramps=ramps), seed=ramps)
    assert red.profiles.shape == (n, RADAR.slice_length) and red.profiles.dtype == np.float32
    assert np.abs(peak_normalised(lit) - peak_normalised(red)).max() <= 1e-5
    assert np.abs(lit.profiles - red.profiles).max() <= 1e-5 * lit.profiles.max()
    np.testing.assert_array_equal(lit.peak_bin, red.peak_bin)
    np.testing.assert_array_equal(lit.direction_deg, red.direction_deg)
    np.testing.assert_array_equal(lit.true_params, red.true_params)
    assert lit.on_target.all() and red.on_target.all()


def test_every_sample_and_interpolated_paths_agree():
    """interpolate=False computes the return on every sample; the default samples it
    every 4th (2nd) sample where the derivative bound allows and interpolates: both equal
    the literal chain to float32 rounding, and each other to ~1e-7 of the peak."""
    x = rows("QUAD", 3)
    x[1, 1::13] *= 3.0  # larger amplitudes: a finer sampling (or every sample) is chosen
    scene = SceneConfig(**NO_NOISE).with_acquisition(ramps=3)
    lit = render_through_chain(x, scene, random_state=4, method="literal")
    for interpolate in (True, False):
        red = render_through_chain(x, scene, random_state=4, interpolate=interpolate)
        assert np.abs(peak_normalised(lit) - peak_normalised(red)).max() <= 1e-5
        np.testing.assert_array_equal(lit.peak_bin, red.peak_bin)


@pytest.mark.parametrize("name,scene,chain", [
    ("more frames than one MTI frame", dict(n_frames=13), {}),
    ("drift only in the carrier phase", dict(drift_shifts_range=False), {}),
    ("fixed phases", dict(acquisition=SceneConfig().acquisition.replace(phases="fixed")), {}),
    ("4 antennas, 32 angle bins", dict(n_antennas=4), dict(n_angle=32)),
    ("Hann range window", {}, dict(window="hann")),
    ("far azimuth", dict(azimuth_deg=(55.0, 80.0)), {}),
    ("window past bin 0", dict(range_m=(0.4, 0.6), clutter_range_m=(5.0, 9.0)), {}),
    ("window past the last bin", dict(range_m=(9.3, 9.55), clutter_range_m=(1.0, 5.0)), {}),
])
def test_reduced_equals_literal_in_other_scenes(name, scene, chain):
    lit, red = both(rows("QUAD", 3), SceneConfig(**NO_NOISE, **scene).with_acquisition(ramps=2), seed=5, chain=ChainConfig(**chain))
    assert np.abs(peak_normalised(lit) - peak_normalised(red)).max() <= 1e-5, name
    np.testing.assert_array_equal(lit.peak_bin, red.peak_bin)
    np.testing.assert_array_equal(lit.n_missing, red.n_missing)
    if "past" in name:
        assert red.n_missing.min() > 0


@pytest.mark.parametrize("cls", ["HELI", "QUAD"])
def test_adc_rounding_is_the_only_difference_when_quantised(cls):
    """With the 12-bit ADC, the clutter's rounding does not cancel in the MTI: a white
    floor of 1/sqrt(12) code per sample, i.e. sigma_q = sqrt(A N_s (1 + 1/D) / 12) codes
    per range-angle bin. The reduced path leaves it out; its error is a few sigma_q
    relative to the literal profile's peak (in codes): measured <= 3.2 sigma_q / peak,
    max ~3.5e-4 of the peak at K = 1 (less with more ramps)."""
    lit, red = both(rows(cls, 24), SceneConfig(snr_db=None).with_acquisition(ramps=1), seed=2)
    peak = lit.profiles.max(axis=1)
    err = np.abs(peak_normalised(lit) - peak_normalised(red)).max(axis=1)
    sigma_q = np.sqrt(8 * RADAR.samples_per_chirp * (1 + 1 / RADAR.mti_depth) / 12)
    assert np.all(err <= 5 * sigma_q / peak)
    assert err.max() <= 1e-3
    np.testing.assert_array_equal(lit.peak_bin, red.peak_bin)


def residuals(p, clean):
    """Profiles minus the noise-free ones, per clean peak; and whether the centre moved."""
    return (p.profiles - clean.profiles) / clean.profiles.max(axis=1, keepdims=True), p.peak_bin != clean.peak_bin


def noise_statistics(n, ramps, seed):
    """Paired noise statistics of literal and reduced profiles (same draws, independent
    noise), both classes: far-bin floor mean and spread per acquisition, near-peak
    spread, share of acquisitions whose centre bin moved, share whose direction moved."""
    stats = {"literal": [], "reduced": []}
    for cls in ("HELI", "QUAD"):
        scene = SceneConfig(snr_db=10.0, quantise=False).with_acquisition(ramps=ramps)
        x = rows(cls, n)
        clean = render_through_chain(x, scene.replace(snr_db=None), random_state=seed)
        for method in stats:
            p = render_through_chain(x, scene, random_state=seed, method=method)
            r, moved = residuals(p, clean)
            far = r[:, np.r_[0:100, 300:400]]
            stats[method].append((far.mean(axis=1), far.std(axis=1), r[~moved, 150:250].std(), moved,
                                  p.direction_deg != clean.direction_deg, np.abs(p.peak_bin - clean.peak_bin)))
    return {m: [np.concatenate([np.atleast_1d(s[i]) for s in v]) for i in range(6)] for m, v in stats.items()}


def check_same_distribution(stats, tol_mean, tol_sd, tol_near, tol_rate):
    (mean_l, sd_l, near_l, moved_l, dir_l, jump_l), (mean_r, sd_r, near_r, moved_r, dir_r, jump_r) = (
        stats["literal"], stats["reduced"])
    assert abs(np.mean(mean_r - mean_l)) < tol_mean * np.mean(mean_l)  # noise floor level, paired
    assert abs(np.mean(sd_r - sd_l)) < tol_sd * np.mean(sd_l)  # its spread
    assert np.all(np.abs(near_r / near_l - 1) < tol_near)  # spread next to the peak, per class
    assert abs(moved_r.mean() - moved_l.mean()) < tol_rate  # noise moves the centre bin as often
    assert abs(dir_r.mean() - dir_l.mean()) < tol_rate  # ... and theta_hat
    assert jump_l.max() <= 2 and jump_r.max() <= 2  # ... and only by a bin or two


def test_noise_on_gives_the_literal_distribution():
    """Receiver noise at 10 dB: the reduced path draws the MTI'd noise directly (other
    draws), so compare distributions on the same scene draws, 150 acquisitions per
    class at K = 1. Standard errors of the paired differences (measured over seeds):
    floor mean 3.2%, floor spread 1.0%, near-peak spread ~2.5% per class; the shares
    of moved centres and directions (~2%) differ by a binomial 1.1% s.e. Tolerances
    are ~4 standard errors (a 1500-acquisition run agrees to 1-2% on the floor)."""
    check_same_distribution(noise_statistics(150, 1, seed=7), tol_mean=0.13, tol_sd=0.05, tol_near=0.1,
                            tol_rate=0.045)


@pytest.mark.slow
def test_noise_on_gives_the_literal_distribution_more_ramps():
    check_same_distribution(noise_statistics(400, 4, seed=8), tol_mean=0.08, tol_sd=0.03, tol_near=0.06,
                            tol_rate=0.03)


def test_default_scene_both_paths_find_the_target():
    """Default scene (noise, clutter, ADC, K = 4): the literal chain's strongest
    signature is the drone's (on_target), and the reduced path's centre is within a
    bin or two of it (noise draws differ)."""
    lit, red = both(rows("QUAD", 12), SceneConfig(), seed=3)
    assert lit.on_target.all() and red.on_target.all()
    assert np.abs(lit.peak_bin - red.peak_bin).max() <= 2
    assert np.abs(peak_normalised(lit) - peak_normalised(red)).max() < 0.1


def test_seeds_chunks_and_shapes():
    x = rows("QUAD", 5)
    x[2, 1::13] *= 3.0  # this row is sampled finer than the others: blocks must not change its bytes
    scene = SceneConfig().with_acquisition(ramps=2)
    a = render_through_chain(x, scene, random_state=11)
    assert isinstance(a, ChainProfiles) and len(a) == 5 and a.method == "reduced"
    assert a.profiles.shape == (5, 400) and a.true_params.shape == (5, 52)
    for other in (render_through_chain(x, scene, random_state=11, chunk_size=1),
                  render_through_chain(x, scene, random_state=11, chunk_size=3),
                  render_through_chain(x, scene, random_state=np.random.SeedSequence(11))):
        assert other.profiles.tobytes() == a.profiles.tobytes()
        np.testing.assert_array_equal(other.peak_bin, a.peak_bin)
    assert not np.array_equal(render_through_chain(x, scene, random_state=12).profiles, a.profiles)
    g1 = render_through_chain(x, scene, random_state=np.random.default_rng(4))
    g2 = render_through_chain(x, scene, random_state=np.random.default_rng(4))
    assert g1.profiles.tobytes() == g2.profiles.tobytes()
    one = render_through_chain(x[0], scene, random_state=1)  # a single vector is one row
    assert one.profiles.shape == (1, 400)
    lit = [render_through_chain(x[:3], scene, random_state=2, method="literal", chunk_size=c).profiles
           for c in (1, None)]
    assert lit[0].tobytes() == lit[1].tobytes()
    assert a.settings["method"] == "reduced" and a.settings["scene"]["n_ramps"] == 2


@pytest.mark.parametrize("kwargs,match", [
    (dict(x=np.ones((2, 12))), "x .*multiple of 13"),
    (dict(x=np.full((1, 13), np.nan)), "x .*nan"),
    (dict(x=np.ones((0, 13))), "x .*no rows"),
    (dict(method="fast"), "method"),
    (dict(search_bins=1), "search_bins"),
    (dict(chain=ChainConfig(edge="drop")), "chain.edge"),
    (dict(scene={"n_ramps": 4}), "scene"),
    (dict(random_state="seven"), "random_state"),
])
def test_bad_input_names_the_argument(kwargs, match):
    args = {"x": rows("HELI", 1), **kwargs}
    x = args.pop("x")
    with pytest.raises(ValueError, match=match):
        render_through_chain(x, **args)
