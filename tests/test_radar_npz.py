"""The checked NPZ reader (mdaug.radar.npz): the generic part every NPZ artefact uses
(population files now, trained estimators later): fields present with their dtype
kind, rank and shape (named axes agree across fields), finite; archives cut short,
pickles and single arrays refused; every error one DataFileError naming file and field."""
import numpy as np
import pytest

from mdaug.radar import atomic_savez
from mdaug.radar.npz import DataFileError, Field, read_checked

FIELDS = [Field("weights", "f", 2, ("inputs", 3)), Field("names", "U", 1, ("inputs",)),
          Field("steps", "iu", 0)]


def _save(path, **over):
    arrays = {"weights": np.ones((4, 3)), "names": np.array(list("abcd")), "steps": np.array(7)}
    arrays.update(over)
    atomic_savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


def test_a_good_artefact_reads_with_its_named_sizes(tmp_path):
    got = read_checked(_save(tmp_path / "e.npz"), FIELDS, "estimator file")
    assert got["weights"].shape == (4, 3) and int(got["steps"]) == 7
    with pytest.raises(DataFileError, match=r"e.npz: field 'weights' has shape \(4, 3\); expected 5 along axis 0"):
        read_checked(tmp_path / "e.npz", FIELDS, sizes={"inputs": 5})


@pytest.mark.parametrize("over, says", [
    ({"weights": None}, "missing field 'weights'"),
    ({"weights": np.array(["x"] * 3)}, "field 'weights' has dtype <U1"),
    ({"weights": np.ones(3)}, "field 'weights' has shape (3,)"),
    ({"names": np.array(list("abc"))}, "field 'names' has shape (3,); expected 4 along axis 0 (as its 'inputs'"),
    ({"weights": np.full((4, 3), np.inf)}, "field 'weights' holds NaN or infinite values"),
    ({"steps": np.array(7.5)}, "field 'steps' has dtype float64"),
])
def test_a_wrong_field_is_named(tmp_path, over, says):
    with pytest.raises(DataFileError) as e:
        read_checked(_save(tmp_path / "e.npz", **over), FIELDS, "estimator file")
    assert str(e.value).startswith(f"{tmp_path / 'e.npz'}: ") and says in str(e.value), str(e.value)


def test_broken_files_are_one_line_naming_the_file(tmp_path):
    raw = _save(tmp_path / "e.npz").read_bytes()
    mid = len(raw) // 3
    flipped = raw[:mid] + bytes(b ^ 0xFF for b in raw[mid: mid + 20]) + raw[mid + 20:]
    for name, data, says in (("cut.npz", raw[: len(raw) // 2], "not a readable NPZ file"),
                             ("tail.npz", raw[:-10], "not a readable NPZ file"),
                             ("flipped.npz", flipped, "flipped.npz: (field '[a-z]+' is cut short or corrupt|not a readable)"),
                             ("empty.npz", b"", "file is empty"),
                             ("pickle.npz", b"\x80\x04junk", "refusing to unpickle")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(DataFileError, match=says):
            read_checked(tmp_path / name, FIELDS, "estimator file")
    with pytest.raises(DataFileError, match="nowhere.npz: estimator file not found"):
        read_checked(tmp_path / "nowhere.npz", FIELDS, "estimator file")
    np.savez(tmp_path / "obj.npz", weights=np.array([{}], dtype=object))
    with pytest.raises(DataFileError, match="field 'weights' holds Python objects"):
        read_checked(tmp_path / "obj.npz", FIELDS)
