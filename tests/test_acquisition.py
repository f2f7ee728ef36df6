"""The acquisition object (SPEC 3.2): its renderer, its draws for the likelihood,
what data files say about it, the specimen model and the augmenter interface."""
import json

import numpy as np
import pytest
import scipy.fft

from mdaug.generator import (Acquisition, FixedSource, MixtureAugmenter, ModelAugmenter, Renderer, SigmaPAugmenter,
                             SpecimenSpread, load_reference, profiles, spectra)
from mdaug.generator.acquisition import (acquisition_from_file, noise_sigma, ramp_signals, render,
                                         resolve_acquisition)
from mdaug.generator.synthetic import SyntheticDraws
from mdaug.radar import RadarConfig

HELI = load_reference("HELI").to_array()
QUAD = load_reference("QUAD").to_array()
RADAR = RadarConfig()


def test_published_acquisition_is_f_of_x():
    x = np.stack([HELI, HELI * 1.01])
    assert Acquisition().is_published and Acquisition.published() == Acquisition()
    got = render(x, Acquisition(), 0, dtype="float64")
    np.testing.assert_array_equal(got, profiles(x, dtype="float64"))


@pytest.mark.parametrize("k", [2, 8])
def test_fixed_phase_ramps_are_the_ramp_averaged_f_of_x(k):
    got = render(HELI[None], Acquisition(ramps=k), 0, dtype="float64")
    mag = spectra(HELI, n_ramps=k)
    want = np.take(mag[0], np.argmax(mag[0]) + np.arange(-200, 200))
    np.testing.assert_allclose(got[0], want / want.max(), atol=1e-9)


def test_the_likelihood_draws_are_the_renderer_on_the_same_draws():
    """SyntheticDraws renders exactly what ramp_signals renders for the same draws
    (MTI residual, yaw, carrier return and ramp advance included)."""
    for x in (HELI, QUAD):
        e = x.size // 13
        acq = Acquisition.measured(32)
        sd = SyntheticDraws(acq, e, n_acquisitions=4, ramps_drawn=6, seed=3)
        spec, gsum = sd.spectra(x)
        d = sd.acquisition_draws(x, 0.2, None)
        sig = ramp_signals(d, acq, RADAR, np.arange(sd.I), dtype="float64")
        want = scipy.fft.rfft(sig, n=RADAR.fft_points, axis=-1)[..., sd.band]
        mine = spec[0] + 0.2 * gsum[0] * sd.tone_spectra[:, None, :]
        assert np.abs(mine - want).max() < 1e-5 * np.abs(want).max()


def test_likelihood_profiles_are_continuous_in_the_offset_and_centred():
    sd = SyntheticDraws(Acquisition.measured(8), 1, n_acquisitions=4, ramps_drawn=4, seed=1)
    offsets = np.linspace(-0.6, 0.6, 61)
    p = sd.profiles(np.repeat(HELI[None], len(offsets), 0), np.full((len(offsets), 1), 0.1),
                    np.full((len(offsets), 1), -45.0), offsets[:, None], stride=8)
    centre = np.flatnonzero(sd.window_offsets(8) == 0)[0]
    np.testing.assert_allclose(p[..., centre], 1.0, rtol=1e-6)
    steps = np.abs(np.diff(p[:, 0], axis=0)).max()
    assert steps < 0.02  # no argmax jumps: a 0.02-bin step moves no bin by more than 2% of the peak
    with pytest.raises(ValueError, match="offset must be within"):
        sd.profiles(HELI[None], [[0.1]], [[-45.0]], [[sd.margin]])


def test_fast_path_noise_floor_and_carrier_return():
    acq = Acquisition(ramps=1, phases="uniform", noise_db=(-30.0, -30.0))
    x = np.repeat(HELI[None], 200, 0)
    noisy = render(x, acq, 1, normalisation="none", dtype="float64")
    quiet = render(x, acq.replace(noise_db=None), 1, normalisation="none", dtype="float64")  # the same draws
    # white noise adds its power to every bin: E|S + N|^2 - |S|^2 = N_s sigma^2, sigma from noise_sigma
    sigma = noise_sigma(-30.0, HELI[0], RADAR)
    added = np.mean(noisy[:, :100] ** 2 - quiet[:, :100] ** 2)
    assert added == pytest.approx(RADAR.samples_per_chirp * sigma**2, rel=0.1)
    # a carrier return at a random phase adds its power at the carrier: E|C + b e^{i beta}|^2 = |C|^2 + |b|^2
    body = render(x, acq.replace(noise_db=None, carrier=(0.5, 0.5)), 1, normalisation="none", dtype="float64")
    line = 0.5 * HELI[0] * RADAR.samples_per_chirp / 2
    assert np.mean(body[:, 200] ** 2 - quiet[:, 200] ** 2) == pytest.approx(line**2, rel=0.15)


def test_files_state_their_acquisition_and_conflicts_name_both():
    assert acquisition_from_file({}, "f.npz") is None
    acq = acquisition_from_file({"ramps_per_frame": np.array(32)}, "f.npz")
    assert acq == Acquisition.measured(32)
    table = Acquisition.measured(8, yaw_deg=5.0)
    got = acquisition_from_file({"acquisition": np.array(json.dumps(table.to_dict()))}, "f.npz")
    assert got == table
    with pytest.raises(ValueError, match="f.npz: field 'ramps_per_frame' = 32 disagrees with field 'acquisition'"):
        acquisition_from_file({"acquisition": np.array(json.dumps(table.to_dict())),
                               "ramps_per_frame": np.array(32)}, "f.npz")
    with pytest.raises(ValueError, match="f.npz: field 'ramps_per_frame' must be one integer >= 1"):
        acquisition_from_file({"ramps_per_frame": np.array(0)}, "f.npz")
    with pytest.raises(ValueError, match="f.npz: field 'acquisition': unknown acquisition field"):
        acquisition_from_file({"acquisition": np.array(json.dumps({"ramp": 3}))}, "f.npz")
    with pytest.raises(ValueError, match="a.npz says 32 ramp\\(s\\) per frame but --ramps says 4"):
        resolve_acquisition(Acquisition.measured(32), Acquisition(ramps=4), "a.npz", "--ramps")
    assert resolve_acquisition(None, None, "a", "b") == Acquisition()


def test_specimen_model():
    x = np.repeat(QUAD[None], 2000, 0)
    same = SpecimenSpread(width=0.0).apply(x, np.random.default_rng(0))
    np.testing.assert_array_equal(same, x)
    speed_only = SpecimenSpread(frequency=0.0, amplitude=0.0, gamma=0.0, skew=0.0, speed=0.05)
    y = speed_only.apply(x, np.random.default_rng(1)).reshape(2000, 4, 13)
    factor = y[..., 2] / QUAD.reshape(4, 13)[:, 2]  # w_a of every engine
    np.testing.assert_allclose(factor, factor[:, :1] * np.ones((1, 4)), rtol=1e-12)  # one factor per drone
    np.testing.assert_allclose(y[..., 5] / QUAD.reshape(4, 13)[:, 5], factor, rtol=1e-12)  # w_b follows
    assert factor[:, 0].std() == pytest.approx(0.05, rel=0.1)
    with pytest.raises(ValueError, match="SpecimenSpread.width"):
        SpecimenSpread(width=-1)


def test_one_augmenter_interface_and_mixtures():
    a = SigmaPAugmenter("HELI", 0.1, random_state=0)
    b = ModelAugmenter(FixedSource(HELI[None], "HELI"), Renderer(Acquisition(ramps=2, phases="uniform")))
    mix = MixtureAugmenter([a, b], weights=[3, 1], random_state=4)
    batch = mix.sample(400)
    assert batch.profiles.shape == (400, 400) and (batch.labels == "HELI").all() and batch.params.shape == (400, 13)
    n_fixed = int(np.sum(np.all(batch.params == HELI, axis=1)))
    assert 60 < n_fixed < 140  # about a quarter from the fixed source
    assert mix.settings()["strategy"] == "mixture" and len(mix.settings()["components"]) == 2
    with pytest.raises(ValueError, match="share a class label"):
        MixtureAugmenter([a, SigmaPAugmenter("QUAD", 0.1)])
    with pytest.raises(ValueError, match="weights"):
        MixtureAugmenter([a, b], weights=[1, -1])


def test_chain_path_renderer_is_the_chain():
    from mdaug.generator.chain import SceneConfig, render_through_chain

    r = Renderer(Acquisition.measured(4), through_chain=True, scene=SceneConfig(snr_db=None, quantise=False))
    got = r.render(np.repeat(HELI[None], 3, 0), np.random.default_rng(2))
    want = render_through_chain(np.repeat(HELI[None], 3, 0), r.scene_config(), random_state=np.random.default_rng(2))
    np.testing.assert_allclose(got, want.profiles / want.profiles.max(axis=1, keepdims=True), rtol=1e-5)
    assert r.scene_config().acquisition.ramps == 4 and r.settings()["path"] == "chain"


@pytest.mark.slow
def test_fast_path_matches_the_chain_in_distribution():
    """The fast path (with its MTI residual model) against the literal scene + chain, HELI
    reference at K = 32: mean profile within 0.025 of the peak near the target, spread
    within 30%."""
    from mdaug.generator.chain import SceneConfig, simulate_campaign
    from mdaug.radar import normalise

    camp = simulate_campaign("HELI", 1, 60, 2, scene=SceneConfig().with_acquisition(ramps=32).with_specimens(width=0.0))
    data = normalise(camp.profiles.astype(float), "peak")
    fast = render(np.repeat(HELI[None], 300, 0), Acquisition.measured(32), 0)
    s = slice(120, 280)
    assert np.abs(data.mean(0) - fast.mean(0))[s].max() < 0.025
    assert fast.std(0)[s].mean() == pytest.approx(data.std(0)[s].mean(), rel=0.3)


def test_k_beyond_the_radars_ramps_per_frame_is_refused_on_both_paths():
    """The radar runs at most RadarConfig.max_ramps_per_frame ramps in a frame: an
    acquisition asking more is refused by name, on the fast path and in the chain; a
    radar table of older files (the field's earlier name) still reads."""
    from mdaug.generator import load_reference
    from mdaug.generator.acquisition import draw_acquisitions
    from mdaug.generator.chain import SceneConfig, render_through_chain

    x = load_reference("HELI").to_array()[None]
    small = RadarConfig(max_ramps_per_frame=8)
    draw_acquisitions(x, Acquisition.measured(8), np.random.default_rng(0), small)  # at the bound: fine
    with pytest.raises(ValueError, match=r"Acquisition\.ramps = 32: .*max_ramps_per_frame is 8"):
        draw_acquisitions(x, Acquisition.measured(32), np.random.default_rng(0), small)
    scene = SceneConfig().with_acquisition(ramps=32)
    with pytest.raises(ValueError, match=r"SceneConfig\.acquisition\.ramps = 32: .*max_ramps_per_frame is 8"):
        render_through_chain(x, scene, small, random_state=0)
    old = {**RadarConfig().to_dict(), "ramps_per_frame": 500}
    del old["max_ramps_per_frame"]
    assert RadarConfig.from_dict(old).max_ramps_per_frame == 500
    with pytest.raises(ValueError, match=r"unknown radar field\(s\) \['ramps'\]"):
        RadarConfig.from_dict({**RadarConfig().to_dict(), "ramps": 4})
