"""Bad values through the Python API: f(x) refuses what it cannot compute faithfully
(clear ValueError naming the parameter, its row and the range) instead of NaN bins
or silently inaccurate profiles; the loaders and memory checks say what is wrong."""
import numpy as np
import pytest

from mdaug.generator import IDX, N_PARAMS, SigmaPAugmenter, if_signal, load_reference, make_dataset, profiles
from mdaug.generator.model import AMPLITUDE_MAX, GAMMA_MAX, PHASE_MAX, nyquist_rad_s
from mdaug.radar import DataFileError, RadarConfig, atomic_savez, load_profiles
from mdaug.radar.raw import check_cube

HELI = load_reference("HELI").to_array()


def with_value(name, value, engine=0, x=HELI):
    y = np.array(x, dtype=float)
    y[engine * N_PARAMS + IDX[name]] = value
    return y


@pytest.mark.parametrize("r0", [np.nan, np.inf, -1.0, 0.0])
@pytest.mark.parametrize("fn", [profiles, if_signal])
def test_r0_must_be_finite_and_positive(fn, r0):
    with pytest.raises(ValueError, match=r"r0 = .* expected a finite model range > 0 m"):
        fn(HELI, r0=r0)


def test_r0_per_row_names_the_row():
    with pytest.raises(ValueError, match=r"r0 = nan \(row 2\)"):
        profiles(np.stack([HELI] * 3), r0=np.array([3.0, 3.0, np.nan]))


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("name, value, match", [
    ("Gamma", 1e300, r"Gamma\[0\] = 1e\+300 in row 0; expected \|Gamma\| <= 1e\+30"),
    ("A_a", 1e300, r"A_a\[0\] = 1e\+300 in row 0; expected \|A\| <= 1 m"),
    ("A_m", -2.0, r"A_m\[0\] = -2 in row 0; expected \|A\| <= 1 m"),
    ("phi_b", 1e16, r"phi_b\[0\] = 1e\+16 in row 0; expected \|phi\| <= 1e\+09 rad .*reduce it modulo 2 pi"),
    ("w_a", 1e12, r"w_a of engine 0 = 1e\+12 rad/s in row 0; expected at most the Nyquist frequency pi fs"),
    ("C_p", 1e6, r"w_p = C_p \|w_a \+ w_b\| of engine 0"),
])
def test_out_of_range_parameters_are_refused_not_nan(name, value, match, dtype):
    with pytest.raises(ValueError, match=match):
        profiles(with_value(name, value), dtype=dtype)


def test_limits_are_where_the_docs_say():
    assert GAMMA_MAX == 1e30 and AMPLITUDE_MAX == 1.0 and PHASE_MAX == 1e9
    assert nyquist_rad_s(RadarConfig()) == pytest.approx(np.pi * 200e3)
    # just inside every limit the float32 path is finite
    x = with_value("Gamma", 1e30)
    x = with_value("A_a", 1.0, x=x)
    x = with_value("phi_a", -1e9, x=x)
    assert np.all(np.isfinite(profiles(x, dtype="float32")))


def test_large_phases_are_reduced_exactly_enough():
    """A phase of 1e8 rad (many turns) gives the profile of its reduced value."""
    turns = 15_915_494  # 2 pi x turns ~ 1e8 rad
    big = with_value("phi_a", HELI[IDX["phi_a"]] + 2 * np.pi * turns)
    for dtype, tol in (("float64", 1e-6), ("float32", 1e-5)):
        np.testing.assert_allclose(profiles(big, dtype=dtype), profiles(HELI, dtype=dtype), atol=tol)


def test_the_quad_engine_is_named():
    quad = load_reference("QUAD").to_array()
    with pytest.raises(ValueError, match=r"A_b\[2\] = 5 in row 1"):
        profiles(np.stack([quad, with_value("A_b", 5.0, engine=2, x=quad)]))


def test_make_dataset_refuses_what_memory_cannot_hold():
    with pytest.raises(ValueError, match=r"n_per_class 1,000,000,000,000: 2 class\(es\) .* of memory"):
        make_dataset([SigmaPAugmenter("HELI"), SigmaPAugmenter("QUAD")], 10**12, 0)


def test_nan_in_a_3d_cube_is_reported_in_the_files_shape():
    cube = np.zeros((11, 8, 504), np.float32)
    cube[2, 5, 7] = np.inf
    with pytest.raises(DataFileError, match=r"first at index \(2, 5, 7\) of shape \(11, 8, 504\)"):
        check_cube(cube, "f.npz")


def test_all_zero_rows_are_named(tmp_path):
    prof = np.ones((5, 400))
    prof[[1, 4]] = 0
    atomic_savez(tmp_path / "z.npz", profiles=prof, labels=np.array(["A"] * 5))
    ps = load_profiles(tmp_path / "z.npz")
    with pytest.raises(DataFileError, match=r"z.npz: field 'profiles': 2 of 5 profile\(s\) are all zeros \(rows 1, 4\)"):
        ps.check_no_zero_rows()


def test_a_non_npz_file_is_not_called_a_pickle(tmp_path):
    (tmp_path / "t.npz").write_text("profiles,labels\n")
    with pytest.raises(DataFileError, match=r"t.npz: not a readable NPZ file \(not a ZIP archive\)") as exc:
        load_profiles(tmp_path / "t.npz")
    assert "allow_pickle" not in str(exc.value)
