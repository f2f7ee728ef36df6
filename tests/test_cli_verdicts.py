"""The verbs say what the study says: an undefined precision is "–" on screen and null
in JSON, and an always-one-class model is called degenerate by train, evaluate and
baseline (the study's one rule, mdaug.classify.metrics.degenerate)."""
import json

import numpy as np
import pytest

from mdaug.cli import main
from mdaug.radar import atomic_savez


def _peaks(n, offsets, rng):
    x = np.arange(400)[None, :] - 200
    p = np.exp(-0.5 * (x / 2) ** 2) + 0.4 * np.exp(-0.5 * ((np.abs(x) - np.asarray(offsets)[:, None]) / 2) ** 2)
    return p + 0.05 * rng.random((n, 400))


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    d = tmp_path_factory.mktemp("verdicts")
    rng = np.random.default_rng(0)
    y = np.repeat(np.array(["HELI", "QUAD"]), 60)
    atomic_savez(d / "train.npz", profiles=_peaks(120, np.where(y == "HELI", 9.0, 15.0), rng), labels=y)
    yt = np.repeat(np.array(["HELI", "QUAD"]), 20)
    atomic_savez(d / "test.npz", profiles=_peaks(40, np.where(yt == "HELI", 9.0, 15.0), rng), labels=yt)
    # every profile the same: any model answers one class for all of them
    same = np.tile(_peaks(1, [12.0], rng), (40, 1))
    atomic_savez(d / "same.npz", profiles=same, labels=yt)
    return d


def _verdicts(text):
    return [ln for ln in text.splitlines() if ln.startswith("verdict")]


def test_evaluate_calls_an_always_one_class_model_degenerate_and_writes_null(d, capsys):
    assert main(["train", str(d / "train.npz"), "--model", "nb", "--out", str(d / "nb.zip")]) == 0
    out = capsys.readouterr().out
    (line,) = _verdicts(out)
    assert "not degenerate" in line and "of its training profiles" in line

    assert main(["evaluate", str(d / "nb.zip"), str(d / "test.npz"), "--n-boot", "50",
                 "--json", str(d / "good.json")]) == 0
    out = capsys.readouterr().out
    assert not _verdicts(out) and "degenerate" not in out
    good = json.loads((d / "good.json").read_text())
    assert all(isinstance(pc["precision"], float) for pc in good["per_class"].values())

    assert main(["evaluate", str(d / "nb.zip"), str(d / "same.npz"), "--n-boot", "50",
                 "--json", str(d / "m.json")]) == 0
    out = capsys.readouterr().out
    m = json.loads((d / "m.json").read_text())
    never = [c for c, pc in m["per_class"].items() if pc["recall"] == 0.0]
    (cls,) = never
    (line,) = _verdicts(out)
    assert line == f"verdict: degenerate: recognises no {cls} (never predicts {cls})"
    assert m["per_class"][cls]["precision"] is None  # undefined, not 0
    assert m["ci"]["per_class"][cls]["precision"] is None
    row = next(ln for ln in out.splitlines() if ln.strip().startswith(f"{cls} n="))
    assert row.endswith("precision      –")


def test_train_calls_a_model_of_identical_profiles_degenerate(d, capsys):
    same = np.load(d / "same.npz")
    atomic_savez(d / "same_train.npz", profiles=same["profiles"], labels=same["labels"])
    assert main(["train", str(d / "same_train.npz"), "--model", "nb", "--out", str(d / "same.zip"),
                 "--allow-degenerate"]) == 0
    (line,) = _verdicts(capsys.readouterr().out)
    assert line.startswith("verdict on 40 of its training profiles: degenerate: recognises no ")
    assert (d / "same.zip").is_file()


@pytest.mark.parametrize("model", ["nb", "svm"])
def test_train_refuses_a_degenerate_model_unless_allowed(d, tmp_path, model, refused):
    """Issue 39 item 3: a model that recognises one class only of its own training data is
    not a success: exit 2, one line naming the file, the reason and the option; no model."""
    same = np.load(d / "same.npz")
    inputs = tmp_path / "in"
    inputs.mkdir()
    atomic_savez(inputs / "same_train.npz", profiles=same["profiles"], labels=same["labels"])
    out = tmp_path / "out"
    out.mkdir()
    line = refused(["train", str(inputs / "same_train.npz"), "--model", model, "--out", str(out / "m.zip")],
                   inputs, out, [f"{inputs / 'same_train.npz'}: the {model} model trained on it is degenerate: "
                                 "recognises no ", "on 40 of its training profiles", "--allow-degenerate",
                                 "nothing written"], seconds=60)
    assert "recall HELI" in line and not (out / "m.zip").exists()


def test_baseline_calls_its_degenerate_model_so(d, capsys):
    out = d / "bl"
    out.mkdir()
    argv = ["baseline", str(d / "same.npz"), "--n-per-class", "20", "--epochs", "1", "--out", str(out / "b.zip"),
            "--test", str(d / "same.npz"), "--json", str(out / "b.json"), "--out-set", str(out / "b.npz")]
    assert main(argv) == 2  # refused after training, before any file: nothing left behind
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "same.npz: the tsaug-baseline CNN made from it is degenerate" in err
    assert "--allow-degenerate" in err and list(out.iterdir()) == []
    assert main(argv + ["--allow-degenerate"]) == 0
    lines = _verdicts(capsys.readouterr().out)
    assert len(lines) == 2  # on the measured profiles it was made from, and on the --test file
    assert "of the measured profiles of" in lines[0] and "degenerate: recognises no" in lines[0]
    assert lines[1].startswith("verdict: degenerate: recognises no ")
    report = json.loads((out / "b.json").read_text())
    (m,) = report.values()
    assert None in [pc["precision"] for pc in m["per_class"].values()]
