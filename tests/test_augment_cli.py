"""`mdaug augment` end to end: the dataset file, its settings, and its failures."""
import json

import numpy as np
import pytest

from mdaug.cli import main
from mdaug.generator import load_dataset, profiles


def test_augment_writes_a_complete_dataset(tmp_path, capsys):
    out, png = tmp_path / "train.npz", tmp_path / "train.png"
    rc = main(["augment", "--classes", "HELI,QUAD", "--n-per-class", "40", "--sigma-p", "0.2",
               "--seed", "1", "--out", str(out), "--plot", str(png)])
    assert rc == 0 and png.stat().st_size > 1000
    assert "80 profiles x 400 bins" in capsys.readouterr().out
    with np.load(out, allow_pickle=False) as f:
        assert f["profiles"].shape == (80, 400) and f["labels"].dtype.kind == "U"
        assert f["params_HELI"].shape == (40, 13) and f["params_QUAD"].shape == (40, 52)
        settings = json.loads(str(f["settings"]))
    assert settings["strategy"] == "sigma_p" and settings["sigma_p"] == 0.2 and settings["seed"] == 1
    assert settings["radar"]["fft_points"] == 4096 and settings["normalisation"] == "peak"
    assert "package_version" in settings
    ds = load_dataset(out)
    # each stored profile is f(x) of its stored vector (no jitter here)
    for label in ("HELI", "QUAD"):
        rows = np.flatnonzero(ds.labels == label)
        again = profiles(ds.params[label][ds.param_row[rows]], dtype="float32")
        np.testing.assert_array_equal(again, ds.profiles[rows])


def test_same_seed_same_file_bytes(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    for path in (a, b):
        assert main(["augment", "--classes", "QUAD", "--n-per-class", "30", "--seed", "9",
                     "--phases", "uniform", "--range-jitter", "1", "--allow-one-class", "--out", str(path)]) == 0
    with np.load(a) as fa, np.load(b) as fb:
        for key in fa.files:
            assert fa[key].tobytes() == fb[key].tobytes(), key


@pytest.mark.parametrize("args, match", [
    (["--classes", "HELI,BLIMP"], "unknown class 'BLIMP'"),
    (["--sigma-p", "-0.1"], "argument --sigma-p: expected a number in [0, 1]"),
    (["--n-per-class", "0"], "argument --n-per-class: expected a positive integer"),
])
def test_augment_errors(tmp_path, capsys, args, match):
    out = tmp_path / "x.npz"
    assert main(["augment", "--out", str(out), "--n-per-class", "5", *args]) == 2
    assert match in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_unwritable_output_fails_before_any_work(tmp_path, capsys):
    out = tmp_path / "missing" / "x.npz"
    assert main(["augment", "--out", str(out), "--n-per-class", "5"]) == 2
    assert f"{out}: cannot write, folder" in capsys.readouterr().err


def test_outputs_get_the_usual_file_mode(tmp_path):
    import os

    out = tmp_path / "m.npz"
    assert main(["augment", "--classes", "HELI", "--n-per-class", "3", "--allow-one-class", "--out", str(out)]) == 0
    mask = os.umask(0)
    os.umask(mask)
    assert (out.stat().st_mode & 0o777) == (0o666 & ~mask)
