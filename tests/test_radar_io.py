"""Measured-profile readers: every error names the file and the field."""
import numpy as np
import pytest
from scipy.io import savemat

from mdaug.radar import DataFileError, load_profiles


def test_npz_csv_and_mat_read_alike(tmp_path, rng):
    profiles = rng.random((5, 400))
    labels = np.array(["HELI", "QUAD", "QUAD", "HELI", "QUAD"])
    np.savez(tmp_path / "p.npz", profiles=profiles, labels=labels)
    savemat(tmp_path / "p.mat", {"profiles": profiles, "labels": labels})
    with open(tmp_path / "p.csv", "w") as fh:
        fh.write(",".join([f"b{i}" for i in range(400)] + ["label"]) + "\n")
        for row, lab in zip(profiles, labels):
            fh.write(",".join(repr(float(v)) for v in row) + f",{lab}\n")
    for name in ("p.npz", "p.mat", "p.csv"):
        ps = load_profiles(tmp_path / name)
        np.testing.assert_array_equal(ps.profiles, profiles)
        assert ps.labels.tolist() == labels.tolist() and ps.classes == ["HELI", "QUAD"]
        assert ps.select("HELI").shape == (2, 400)
    with pytest.raises(DataFileError, match="p.npz: field 'labels' holds no profile of class 'DRONE'"):
        load_profiles(tmp_path / "p.npz").select("DRONE")


@pytest.mark.parametrize("arrays, match", [
    ({"labels": np.array(["A"])}, "missing field 'profiles'"),
    ({"profiles": np.ones((2, 400))}, "missing field 'labels'"),
    ({"profiles": np.ones((2, 400)), "labels": np.array(["A"])}, "field 'labels' has 1 entries for 2 profiles"),
    ({"profiles": np.full((2, 400), np.nan), "labels": np.array(["A", "B"])}, "field 'profiles' holds NaN"),
    ({"profiles": np.ones((2, 3, 4)), "labels": np.array(["A", "B"])}, "field 'profiles' must be a non-empty"),
    ({"profiles": np.array(["x", "y"]), "labels": np.array(["A", "B"])}, "field 'profiles' must be a numeric"),
])
def test_bad_npz_fields(tmp_path, arrays, match):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(DataFileError, match=f"bad.npz: .*{match}"):
        load_profiles(path)


def test_missing_empty_pickled_and_headerless_files(tmp_path):
    with pytest.raises(DataFileError, match="none.npz: file not found"):
        load_profiles(tmp_path / "none.npz")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(DataFileError, match="empty.npz: file is empty"):
        load_profiles(tmp_path / "empty.npz")
    np.savez(tmp_path / "obj.npz", profiles=np.array([{"a": 1}], dtype=object), labels=np.array(["A"]))
    with pytest.raises(DataFileError, match="obj.npz: field .profiles. holds Python objects; refusing to unpickle"):
        load_profiles(tmp_path / "obj.npz")
    (tmp_path / "h.csv").write_text("1,2,3\n4,5,6\n")
    with pytest.raises(DataFileError, match="h.csv: CSV header has no 'label' column"):
        load_profiles(tmp_path / "h.csv")
    (tmp_path / "t.csv").write_text("a,b,label\n1,x,HELI\n")
    with pytest.raises(DataFileError, match="t.csv: line 2: field 'profiles' is not numeric"):
        load_profiles(tmp_path / "t.csv")
    savemat(tmp_path / "m.mat", {"other": np.ones(3)})
    with pytest.raises(DataFileError, match="m.mat: missing field 'profiles'"):
        load_profiles(tmp_path / "m.mat")
