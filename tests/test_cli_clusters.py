"""Drones are the clusters of every interval the verbs print (issue 39, item 5):
``evaluate`` (and ``baseline``, ``sweep``) resample drones when the test file carries
``specimen`` and say which bootstrap they used; a degenerate result says so on its
balanced-accuracy line instead of a bare "50.0% [50.0%, 50.0%]"."""
import json

import numpy as np
import pytest

from mdaug.cli import main
from mdaug.radar import atomic_savez

DRONES, PER_DRONE = 4, 10


def _peaks(where, rng):
    x = np.arange(400)[None, :] - 200
    p = np.exp(-0.5 * (x / 2) ** 2) + 0.6 * np.exp(-0.5 * ((np.abs(x) - np.asarray(where)[:, None]) / 2) ** 2)
    return p + 0.02 * rng.random((len(where), 400))


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    """A clean training file; a test file of 4 drones per class, 10 acquisitions each,
    whose drone 3 of each class looks like the other class (so every acquisition of a
    drone is predicted alike: 3 of 4 drones recognised per class)."""
    d = tmp_path_factory.mktemp("clusters")
    rng = np.random.default_rng(0)
    y = np.repeat(np.array(["HELI", "QUAD"]), 60)
    atomic_savez(d / "train.npz", profiles=_peaks(np.where(y == "HELI", 9.0, 15.0), rng), labels=y)
    yt = np.repeat(np.array(["HELI", "QUAD"]), DRONES * PER_DRONE)
    drone = np.tile(np.repeat(np.arange(DRONES), PER_DRONE), 2)
    look = np.where((yt == "HELI") ^ (drone == 3), 9.0, 15.0)
    x = _peaks(look, rng)
    atomic_savez(d / "drones.npz", profiles=x, labels=yt, specimen=drone)
    atomic_savez(d / "items.npz", profiles=x, labels=yt)
    assert main(["train", str(d / "train.npz"), "--model", "nb", "--out", str(d / "nb.zip")]) == 0
    return d


def _balanced_line(text):
    return next(ln for ln in text.splitlines() if ln.startswith("balanced accuracy"))


def test_evaluate_resamples_drones_when_the_file_names_them(d, tmp_path, capsys):
    capsys.readouterr()
    assert main(["evaluate", str(d / "nb.zip"), str(d / "drones.npz"), "--n-boot", "2000",
                 "--json", str(tmp_path / "drones.json")]) == 0
    out = capsys.readouterr().out
    assert "95% intervals: percentile bootstrap over the 8 drones (clusters)" in out
    m = json.loads((tmp_path / "drones.json").read_text())
    assert m["balanced_accuracy"] == pytest.approx(0.75)
    assert "8 drones" in m["ci"]["method"]
    assert main(["evaluate", str(d / "nb.zip"), str(d / "items.npz"), "--n-boot", "2000",
                 "--json", str(tmp_path / "items.json")]) == 0
    out = capsys.readouterr().out
    assert "percentile bootstrap over the test items" in out and "names no drones, field 'specimen'" in out
    items = json.loads((tmp_path / "items.json").read_text())
    lo, hi = m["ci"]["balanced_accuracy"]
    ilo, ihi = items["ci"]["balanced_accuracy"]
    # 3 of 4 drones per class: the drone-level spread (binomial over 4 drones per class: [0.5, 1.0]) is
    # more than twice the one of 80 acquisitions taken as independent (about 0.19)
    assert hi - lo >= 0.4 and ihi - ilo < 0.25 and hi - lo > 2 * (ihi - ilo)


def test_a_degenerate_result_says_degenerate_on_its_line(d, tmp_path, capsys):
    rng = np.random.default_rng(1)
    same = np.tile(_peaks([12.0], rng), (20, 1))
    atomic_savez(tmp_path / "same.npz", profiles=same, labels=np.repeat(np.array(["HELI", "QUAD"]), 10),
                 specimen=np.tile(np.repeat(np.arange(2), 5), 2))
    capsys.readouterr()
    assert main(["evaluate", str(d / "nb.zip"), str(tmp_path / "same.npz"), "--n-boot", "200"]) == 0
    line = _balanced_line(capsys.readouterr().out)
    assert line.startswith("balanced accuracy  50.0% [50.0%, 50.0%]  (degenerate: recognises no ")
    assert line.endswith(": not a score)")


def test_baseline_cross_validation_resamples_drones(d, capsys):
    capsys.readouterr()
    assert main(["baseline", str(d / "drones.npz"), "--folds", "2", "--n-per-class", "8", "--epochs", "1"]) == 0
    assert "percentile bootstrap over the 8 drones (clusters)" in capsys.readouterr().out


def test_sweep_says_which_bootstrap_each_test_set_used(d, tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", "--test", f"{d / 'drones.npz'},{d / 'items.npz'}", "--models", "nb", "--sigma-p", "0",
                 "--n-per-class", "10", "--n-boot", "50", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    settings = json.loads((out / "settings.json").read_text())
    assert settings["intervals"]["drones"].startswith("percentile bootstrap over the 8 drones (clusters)")
    assert "names no drones" in settings["intervals"]["items"]
    assert "95% intervals on drones: percentile bootstrap over the 8 drones" in text
    assert "95% intervals on drones" in (out / "sweep.md").read_text()
