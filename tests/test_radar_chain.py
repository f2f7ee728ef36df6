"""The published chain (radar/chain.py), raw readers and ``mdaug process``."""
import numpy as np
import pytest
import scipy.fft
from scipy.io import savemat

from mdaug import cli
from mdaug.radar import DataFileError, RadarConfig, load_profiles
from mdaug.radar.chain import (ChainConfig, angle_fft, angle_grid_deg, angle_spacing_deg, extract_signatures,
                               integrate_direction, mti, mti_magnitude, process_cube, range_fft)
from mdaug.radar.raw import read_raw

RADAR = RadarConfig()
T = np.arange(RADAR.samples_per_chirp) / RADAR.sample_rate_hz


def tones(ranges_m, azimuths_deg, amps, carrier, n_ant=8):
    """Cube (F, A, N_s) of point targets: cos(2 pi f t + carrier[f, j] + pi n sin(theta_j))."""
    carrier = np.atleast_2d(carrier)
    out = np.zeros((carrier.shape[0], n_ant, T.size))
    n = np.arange(n_ant)[:, None]
    for j, (r, az, a) in enumerate(zip(ranges_m, azimuths_deg, amps)):
        fb = RADAR.range_to_frequency(r)
        spatial = np.pi * n * np.sin(np.radians(az))
        out += a * np.cos(2 * np.pi * fb * T[None, None] + spatial[None] + carrier[:, j, None, None])
    return out


def hover(rng, n_targets, frames=11):
    return rng.uniform(-np.pi, np.pi, (frames, n_targets))


@pytest.mark.parametrize("r_m,az", [(2.003, 0.0), (4.5117, 20.0), (6.2, -33.0), (8.1, 47.0)])
def test_point_target_range_bin_and_direction(rng, r_m, az):
    res = process_cube(tones([r_m], [az], [1.0], hover(rng, 1)))
    assert len(res) == 1
    assert abs(res.peak_bin[0] - r_m / RADAR.bin_m) <= 1.0
    assert abs(res.range_m[0] - r_m) <= RADAR.bin_m
    assert abs(res.direction_deg[0] - az) <= angle_spacing_deg(az, 64)
    assert res.signatures.shape == (1, RADAR.slice_length)
    assert np.argmax(res.signatures[0]) == RADAR.slice_length // 2


def test_angle_grid_is_uniform_in_sine_and_matches_the_fft():
    grid = angle_grid_deg(64)
    assert grid.shape == (64,) and grid[32] == 0.0
    np.testing.assert_allclose(np.diff(np.sin(np.radians(grid))), 2 / 64, atol=1e-12)
    assert angle_spacing_deg(0.0, 64) == pytest.approx(np.degrees(2 / 64), rel=1e-12)
    # a steering vector at grid angle k peaks in bin k; the shortcut equals fftshift(fft)
    k = 41
    steer = np.exp(1j * np.pi * np.arange(8) * np.sin(np.radians(grid[k])))
    img = angle_fft(steer[:, None], 64)
    assert np.argmax(np.abs(img[0])) == k
    ref = scipy.fft.fftshift(scipy.fft.fft(steer, 64))
    np.testing.assert_allclose(img[0], ref, atol=1e-5)


def test_mti_closed_form_and_orders_agree(rng):
    x = rng.normal(size=(13, 3, 5)) + 1j * rng.normal(size=(13, 3, 5))
    out = mti(x, 10)
    assert out.shape == (3, 3, 5)
    for i in range(3):
        np.testing.assert_allclose(out[i], x[10 + i] - x[i:10 + i].mean(axis=0), atol=1e-12)
    with pytest.raises(ValueError, match="at least depth \\+ 1 = 11 frames"):
        mti(x[:10], 10)
    cube = rng.normal(size=(12, 2, 8, 504)).astype(np.float32)
    fast = mti_magnitude(cube, RADAR, ChainConfig(order="fast"))
    image = mti_magnitude(cube, RADAR, ChainConfig(order="image"))
    assert fast.shape == (2, RADAR.n_bins, 64)
    np.testing.assert_allclose(fast, image, rtol=0, atol=1e-5 * image.max())


def quantise(cube, bits=12, fill=0.7):
    full = 2 ** (bits - 1)
    return np.clip(np.rint(cube * fill * (full - 1) / np.abs(cube).max()), -full, full - 1).astype(np.int16)


def test_mti_suppresses_static_clutter_and_keeps_a_hovering_target(rng):
    """Three static clutter scatterers 20 dB above a hovering target, 12-bit ADC codes.

    Measured over 5 seeds: clutter down by 63-71 dB at its bins (what remains there is
    the hovering target's own range sidelobes, so this is a lower bound), ending
    43-45 dB below the target; the target's peak moves by -0.8..+0.9 dB. Asserted:
    > 55 dB suppression and a target change > -6 dB."""
    clutter_r, target_r = [1.5, 3.0, 8.5], 5.0
    carrier = np.concatenate([np.zeros((11, 3)), hover(rng, 1)], axis=1)
    cube = quantise(tones(clutter_r + [target_r], [-20, 10, 40, 5], [10, 10, 10, 1], carrier))
    raw = np.abs(angle_fft(range_fft(cube[-1:].astype(np.float32)), 64))[0]  # current frame, no MTI
    after = mti_magnitude(cube)[0]
    peak = lambda img, r: img[int(round(r / RADAR.bin_m)) - 2: int(round(r / RADAR.bin_m)) + 3].max()  # noqa: E731
    supp = [20 * np.log10(peak(raw, r) / peak(after, r)) for r in clutter_r]
    target_change = 20 * np.log10(peak(after, target_r) / peak(raw, target_r))
    assert min(supp) > 55.0, supp
    assert target_change > -6.0
    res = process_cube(cube)
    assert len(res) == 1 and abs(res.range_m[0] - target_r) <= RADAR.bin_m
    # without the hover drift the target is cancelled like clutter
    static = quantise(tones(clutter_r + [target_r], [-20, 10, 40, 5], [10, 10, 10, 1], np.zeros((11, 4))))
    assert peak(mti_magnitude(static)[0], target_r) < 1e-2 * peak(raw, target_r)


def test_several_targets_sorted_and_separated(rng):
    ranges, az, amps = [2.0, 4.0, 4.0 + 100 * RADAR.bin_m, 7.0], [-10, 15, 15, 30], [0.6, 1.0, 0.9, 0.5]
    res = process_cube(tones(ranges, az, amps, hover(rng, 4)))
    # the target 100 bins from a stronger one (< min separation 200) is not a separate signature
    assert len(res) == 3
    np.testing.assert_allclose(res.range_m, [4.0, 2.0, 7.0], atol=RADAR.bin_m)
    assert np.all(np.diff(res.signatures.max(axis=1)) <= 0)  # strongest first
    np.testing.assert_allclose(res.direction_deg, [15, -10, 30], atol=angle_spacing_deg(30, 64))
    # a weaker one below -12 dB of the strongest is not significant
    weak = process_cube(tones([2.0, 6.0], [0, 0], [1.0, 0.1], hover(rng, 2)))
    assert len(weak) == 1 and abs(weak.range_m[0] - 2.0) <= RADAR.bin_m
    # max_targets and a tighter separation
    assert len(process_cube(tones(ranges, az, amps, hover(rng, 4)), chain=ChainConfig(max_targets=2))) == 2
    close = process_cube(tones(ranges, az, amps, hover(rng, 4)), chain=ChainConfig(min_separation_bins=50))
    assert len(close) == 4


def test_extraction_near_the_ends_zero_fills_never_shifts(rng):
    r_near = 60 * RADAR.bin_m  # peak at bin 60: 140 bins of the window before bin 0
    res = process_cube(tones([r_near, 6.0], [0, 0], [1.0, 0.8], hover(rng, 2)))
    near = int(np.argmin(np.abs(res.range_m - r_near)))
    c = RADAR.slice_length // 2
    assert abs(res.peak_bin[near] - 60) <= 1
    assert res.n_missing[near] == c - res.peak_bin[near]
    assert np.all(res.signatures[near, : res.n_missing[near]] == 0)
    assert np.argmax(res.signatures[near]) == c
    np.testing.assert_array_equal(res.signatures[near, res.n_missing[near]:],
                                  res.profiles[near, : RADAR.slice_length - res.n_missing[near]])
    dropped = process_cube(tones([r_near, 6.0], [0, 0], [1.0, 0.8], hover(rng, 2)), chain=ChainConfig(edge="drop"))
    assert len(dropped) == 1 and abs(dropped.range_m[0] - 6.0) <= RADAR.bin_m
    # the pure function, both ends
    prof = np.arange(1.0, 2049.0)
    win, miss = extract_signatures(prof, [10, 2040], 400)
    assert miss.tolist() == [190, 192] and win[0, 200] == 11.0 and win[1, 200] == 2041.0
    assert np.all(win[0, :190] == 0) and np.all(win[1, 400 - 192:] == 0) and win[1, 207] == 2048.0


def test_integration_width_selects_the_stated_angles():
    angles = angle_grid_deg(64)
    mag = np.zeros((4, 64))
    mag[:, :] = np.arange(64)[None, :]
    prof = integrate_direction(mag, angles, 0.0, 7.0)
    sel = np.abs(angles) <= 3.5
    assert sel.sum() == 3  # -1.79, 0, +1.79 deg on the 64-point grid
    np.testing.assert_allclose(prof, np.arange(64)[sel].mean())


def test_ramps_axis_averages_mti_magnitudes_incoherently(rng):
    cubes = [tones([5.0], [0], [1.0], hover(rng, 1)) for _ in range(3)]
    stacked = np.stack(cubes, axis=1)  # (F, K, A, S)
    mag = mti_magnitude(stacked)
    each = np.stack([mti_magnitude(c) for c in cubes])
    np.testing.assert_allclose(mag, each.mean(axis=0), rtol=1e-5, atol=1e-6 * mag.max())


# ---- raw readers and bad input ----------------------------------------------------
def good_cube(rng, frames=11):
    return quantise(tones([5.0], [10], [1.0], hover(rng, 1, frames)))


@pytest.mark.parametrize("name,cube,match", [
    ("rank.npz", np.zeros((11, 504)), "rank 2"),
    ("nan.npz", np.full((11, 8, 504), np.nan), "NaN"),
    ("short.npz", np.zeros((10, 8, 504), dtype=np.int16), "10 frame\\(s\\).*mti_depth \\+ 1 = 11"),
    ("long.npz", np.zeros((11, 8, 5000)), "5000 samples"),
    ("empty_cube.npz", np.zeros((0, 8, 504)), "is empty"),
])
def test_bad_cubes_name_the_file(tmp_path, name, cube, match):
    path = tmp_path / name
    np.savez(path, cube=cube)
    with pytest.raises(DataFileError, match=match) as err:
        read_raw(path)
    assert str(path) in str(err.value)


def test_missing_variable_empty_file_and_mat(tmp_path, rng):
    mat = tmp_path / "novar.mat"
    savemat(mat, {"other": np.zeros((11, 8, 504))})
    with pytest.raises(DataFileError, match="missing field 'cube'") as err:
        read_raw(mat)
    assert str(mat) in str(err.value)
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(DataFileError, match="empty") as err:
        read_raw(empty)
    assert str(empty) in str(err.value)
    good = tmp_path / "good.mat"
    cube = good_cube(rng)
    savemat(good, {"cube": cube, "label": "HELI"})
    raw = read_raw(good)
    assert raw.cubes.shape == (1, 11, 1, 8, 504) and raw.labels.tolist() == ["HELI"]
    np.testing.assert_array_equal(raw.cubes[0, :, 0], cube)


def test_process_cli_writes_measured_profile_format(tmp_path, rng, capsys):
    a, b = tmp_path / "a.npz", tmp_path / "b.mat"
    np.savez(a, cube=good_cube(rng), label="QUAD")
    savemat(b, {"cube": good_cube(rng, frames=12).astype(np.float64)})
    out = tmp_path / "profiles.npz"
    assert cli.main(["process", str(a), str(b), "--out", str(out), "--label", "HELI"]) == 0
    ps = load_profiles(out)
    # a: one MTI frame; b: 12 frames -> two MTI frames; one target each
    assert ps.profiles.shape == (3, 400) and ps.labels.tolist() == ["HELI"] * 3
    assert ps.extra["mti_profiles"].shape == (3, RADAR.n_bins)
    np.testing.assert_allclose(ps.extra["range_m"], 5.0, atol=RADAR.bin_m)
    assert ps.extra["source"].tolist() == [str(a), str(b), str(b)]
    assert ps.extra["frame"].tolist() == [10, 10, 11]
    assert ps.settings()["simulated"] is False
    # without --label the file's own label is used; a file without one is an error naming it
    assert cli.main(["process", str(a), "--out", str(out)]) == 2  # no silent overwrite
    assert f"{out}: --out: the file exists" in capsys.readouterr().err
    assert cli.main(["process", str(a), "--out", str(out), "--overwrite"]) == 0
    assert load_profiles(out).labels.tolist() == ["QUAD"]
    assert cli.main(["process", str(b), "--out", str(tmp_path / "x.npz")]) == 2
    assert str(b) in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()
