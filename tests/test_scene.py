"""The measurement-scene simulator (generator/chain/) and ``mdaug simulate``."""
import json

import numpy as np
import pytest

from mdaug import cli
from mdaug.generator import IDX, N_PARAMS, load_reference, profiles
from mdaug.generator.acquisition import yaw_mix
from mdaug.generator.chain import (Campaign, SceneConfig, as_profile_set, draw_acquisitions, draw_specimens,
                                   load_campaign, render_cubes, simulate_campaign)
from mdaug.radar import RadarConfig, load_profiles
from mdaug.radar.chain import angle_spacing_deg

RADAR = RadarConfig()


@pytest.mark.parametrize("cls,ramps", [("HELI", 1), ("QUAD", 2)])
def test_clean_fixed_phase_acquisition_is_the_generators_f_x(cls, ramps):
    """Noise-, clutter-, body-free, phases held fixed, drift only in the carrier phase:
    the MTI multiplies the whole target image by one complex number, so the peak-
    normalised signature is f(x) at model range R0 = R / 2. What is left (< 5e-3 of
    the peak, measured ~2.5e-3) is the real IF signal's mirror image leaking into the
    positive bins: its phase follows -carrier, not +carrier, so the MTI treats it
    differently (~1 / (pi * 2 * bin * N_s / N_fft) of the peak)."""
    ref = load_reference(cls).to_array()
    scene = SceneConfig.clean(drift_shifts_range=False, dtype="float64").with_acquisition(phases="fixed", ramps=ramps)
    scene = scene.with_specimens(width=0.0)
    camp = simulate_campaign(cls, 1, 3, seed=4, scene=scene)
    np.testing.assert_array_equal(camp.true_params, np.repeat(ref[None], 3, axis=0))
    fx, info = profiles(camp.true_params, r0=camp.range_true_m / 2, n_ramps=ramps, dtype="float64",
                        return_info=True)
    sig = camp.profiles / camp.profiles.max(axis=1, keepdims=True)
    assert np.abs(sig - fx).max() < 5e-3
    np.testing.assert_array_equal(np.rint(camp.range_m / RADAR.bin_m), info.peak_bin)
    # the check can fail: random phases per frame do not give f(x) at the stored phases
    moving = simulate_campaign(cls, 1, 3, seed=4, scene=scene.with_acquisition(phases="uniform"))
    fx_m = profiles(moving.true_params, r0=moving.range_true_m / 2, n_ramps=ramps, dtype="float64")
    assert np.abs(moving.profiles / moving.profiles.max(axis=1, keepdims=True) - fx_m).max() > 2e-2


def test_default_scene_finds_the_drone_where_it_is():
    camp = simulate_campaign("QUAD", 2, 12, seed=3)
    assert camp.profiles.shape == (12, 400) and camp.profiles.dtype == np.float32
    assert camp.on_target.all()
    tol = angle_spacing_deg(camp.azimuth_deg, 64)
    assert np.all(np.abs(camp.direction_deg - camp.azimuth_deg) <= tol)
    assert np.all(camp.peak_db > 25)
    assert np.all(np.argmax(camp.profiles, axis=1) == 200)
    assert camp.specimen.tolist() == [0] * 6 + [1] * 6


def test_same_seed_same_bytes_other_seed_differs():
    a = simulate_campaign("HELI", 2, 4, seed=11)
    b = simulate_campaign("HELI", 2, 4, seed=11)
    c = simulate_campaign("HELI", 2, 4, seed=12)
    for key in Campaign.ARRAYS:
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert not np.array_equal(a.profiles, c.profiles)


def test_specimens_share_a_motor_speed_factor():
    ref = load_reference("QUAD").to_array()
    scene = SceneConfig().with_specimens(speed=0.1, frequency=0.0, amplitude=0.0, gamma=0.0, skew=0.0)
    spec = draw_specimens(ref, 5, scene, np.random.default_rng(0))
    cols = [k * N_PARAMS + IDX[c] for k in range(4) for c in ("w_a", "w_b")]
    ratio = spec[:, cols] / ref[cols]
    np.testing.assert_allclose(ratio, ratio[:, :1] * np.ones_like(ratio), rtol=1e-12)  # common per specimen
    assert ratio[:, 0].std() > 0.03
    others = [i for i in range(ref.size) if i not in cols]
    np.testing.assert_array_equal(spec[:, others], np.repeat(ref[None, others], 5, axis=0))
    exact = draw_specimens(ref, 3, SceneConfig().with_specimens(width=0.0), np.random.default_rng(0))
    np.testing.assert_array_equal(exact, np.repeat(ref[None], 3, axis=0))


def test_yaw_mix_preserves_energy_and_swaps_at_90_degrees():
    x = load_reference("QUAD").to_array()[None].repeat(3, axis=0)
    yawed = yaw_mix(x, np.radians([0.0, 90.0, 37.0]))
    e, y = x.reshape(3, 4, 13), yawed.reshape(3, 4, 13)
    a, b = IDX["A_a"], IDX["A_b"]
    np.testing.assert_allclose(y[0], e[0])
    np.testing.assert_allclose(y[1][:, [a, b]], e[1][:, [b, a]])
    np.testing.assert_allclose(y[2, :, a] ** 2 + y[2, :, b] ** 2, e[2, :, a] ** 2 + e[2, :, b] ** 2)
    keep = [i for i in range(13) if i not in (a, b)]
    np.testing.assert_array_equal(y[..., keep], e[..., keep])


def _one_cube(scene, seed=0, cls="HELI"):
    spec = draw_specimens(load_reference(cls).to_array(), 1, scene, np.random.default_rng(seed))
    d = draw_acquisitions(spec, 1, scene, RADAR, np.random.default_rng(seed + 1))
    return render_cubes(d, slice(0, 1), scene, RADAR, [np.random.default_rng(seed + 2)])[0], d


def test_noise_level_matches_the_snr_and_adc_codes_fit_12_bits():
    base = SceneConfig.clean().with_acquisition(ramps=2)
    clean, _ = _one_cube(base)
    noisy, _ = _one_cube(base.replace(snr_db=6.0))
    p_s = np.mean(clean.astype(np.float64) ** 2)
    measured_db = 10 * np.log10(p_s / np.var(noisy - clean))
    assert measured_db == pytest.approx(6.0, abs=0.1)
    codes, _ = _one_cube(SceneConfig().with_acquisition(ramps=2))
    assert codes.dtype == np.int16 and codes.shape == (11, 2, 8, RADAR.samples_per_chirp)
    assert np.abs(codes).max() == round(0.7 * 2047)  # gain control: the largest sample at 70% of full scale


def test_hover_drift_moves_the_range_between_frames():
    _, d = _one_cube(SceneConfig(drift_step_m=5e-3))
    steps = np.diff(d.range_m[0])
    assert steps.shape == (10,) and np.all(steps != 0) and np.abs(steps).max() < 0.05
    _, still = _one_cube(SceneConfig(drift_step_m=0.0))
    assert np.all(still.range_m[0] == still.range_m[0, 0])


def test_save_load_and_measured_profile_reader(tmp_path):
    camp = simulate_campaign("HELI", 1, 3, seed=5, scene=SceneConfig().with_acquisition(ramps=1), keep_cubes=True)
    path = tmp_path / "camp.npz"
    camp.save(path)
    back = load_campaign(path)
    for key in Campaign.ARRAYS:
        np.testing.assert_array_equal(getattr(back, key), getattr(camp, key))
    assert back.cubes.shape == (3, 11, 1, 8, RADAR.samples_per_chirp) and back.cubes.dtype == np.int16
    ps = load_profiles(path)
    assert ps.profiles.shape == (3, 400) and ps.labels.tolist() == ["HELI"] * 3
    s = ps.settings()
    assert s["simulated"] is True and s["seed"] == 5 and s["scene"]["n_ramps"] == 1
    assert ps.extra["true_params"].shape == (3, 13)


def test_simulate_then_process_cli_round_trip(tmp_path, capsys):
    sim, proc = tmp_path / "q.npz", tmp_path / "p.npz"
    argv = ["simulate", "--class", "QUAD", "--specimens", "2", "--acquisitions", "4", "--seed", "7",
            "--ramps", "2", "--out", str(sim), "--keep-cubes"]
    assert cli.main(argv) == 0
    assert "4 simulated QUAD acquisitions" in capsys.readouterr().out
    camp = load_campaign(sim)
    assert json.loads(json.dumps(camp.settings))["class"] == "QUAD" and camp.true_params.shape == (4, 52)
    assert cli.main(["process", str(sim), "--out", str(proc), "--max-targets", "1"]) == 0
    ps = load_profiles(proc)
    np.testing.assert_allclose(ps.profiles, camp.profiles, rtol=1e-6)
    assert ps.labels.tolist() == ["QUAD"] * 4
    assert cli.main(["simulate", "--class", "PLANE", "--acquisitions", "2", "--out", str(tmp_path / "x.npz")]) == 2
    assert "PLANE" in capsys.readouterr().err


@pytest.mark.parametrize("kw,match", [
    ({"phases": "random"}, "phases"), ({"n_ramps": 0}, "n_ramps"), ({"range_m": (5.0, 2.0)}, "range_m"),
    ({"agc_fill": 1.5}, "agc_fill"), ({"drift_step_m": -1.0}, "drift_step_m"),
])
def test_bad_scene_settings(kw, match):
    """A file's scene table (its keys, K as n_ramps) is checked by key."""
    with pytest.raises(ValueError, match=match):
        SceneConfig.from_dict(kw)


def test_the_scene_has_one_spelling_of_k_and_its_file_table_round_trips():
    scene = SceneConfig().with_acquisition(ramps=3, yaw_deg=5.0).with_specimens(width=0.5).replace(n_clutter=2)
    table = json.loads(json.dumps(scene.to_dict()))  # as a campaign file stores it
    assert table["n_ramps"] == 3 and table["specimen_spread"] == 0.5 and table["yaw_deg"] == 5.0
    assert SceneConfig.from_dict(table) == scene
    assert not hasattr(scene, "n_ramps")  # K is scene.acquisition.ramps
    with pytest.raises(TypeError, match="acquisition's fields"):
        SceneConfig(n_ramps=2)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['ramps'\]"):
        SceneConfig.from_dict({"ramps": 2})


def test_bad_campaign_sizes():
    with pytest.raises(ValueError, match="n_acquisitions"):
        simulate_campaign("HELI", 1, 0)
    with pytest.raises(ValueError, match="n_specimens"):
        simulate_campaign("HELI", 0, 3)


def test_campaigns_merge_into_one_labelled_set():
    h = simulate_campaign("HELI", 1, 2, seed=1, scene=SceneConfig().with_acquisition(ramps=1))
    q = simulate_campaign("QUAD", 1, 3, seed=2, scene=SceneConfig().with_acquisition(ramps=1))
    ps = as_profile_set(h, q)
    assert ps.profiles.shape == (5, 400) and ps.labels.tolist() == ["HELI"] * 2 + ["QUAD"] * 3
    np.testing.assert_array_equal(ps.select("QUAD"), q.profiles.astype(np.float64))
    assert ps.extra["campaign"].tolist() == [0, 0, 1, 1, 1] and ps.extra["mti_profiles"].shape == (5, 2048)
