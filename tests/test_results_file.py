"""results.json is strict JSON (null for NaN and inf) with paths relative to the study folder."""
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from mdaug.reports.results_file import plain, write_results


def _strict(text):
    def refuse(token):
        raise ValueError(f"not strict JSON: {token}")

    return json.loads(text, parse_constant=refuse)


def _strings(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _strings(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _strings(v)
    elif isinstance(obj, str):
        yield obj


def test_results_json_is_strict_and_its_paths_are_relative(tmp_path):
    study = tmp_path / "study"
    (study / "data").mkdir(parents=True)
    given = tmp_path / "inputs" / "new.npz"
    given.parent.mkdir()
    given.write_bytes(b"x")
    results = {
        "balanced_accuracy": float("nan"), "ci": [np.float64("nan"), float("inf")], "low": -np.inf,
        "arr": np.array([0.5, np.nan]), "n": np.int64(3), "ok": 0.75,
        "data": {"new": {"path": str(study / "data" / "new.npz")}},
        "profiles_figure": study / "figures" / "profiles.png",
        "model_path": str(study / "models" / "cnn_x_run{run}.zip"),  # a template, not a file yet
        "config": {"data": {"test": {"new": str(given)}}, "source": "defaults"},
        "invocation": f"mdaug run --out {study}",  # the command as typed stays as typed
    }
    with pytest.raises(ValueError):
        _strict(json.dumps(float("nan")))  # the check itself refuses NaN
    text = write_results(results, study).read_text()
    back = _strict(text)
    assert back["balanced_accuracy"] is None and back["ci"] == [None, None] and back["low"] is None
    assert back["arr"] == [0.5, None] and back["n"] == 3 and back["ok"] == 0.75
    assert back["data"]["new"]["path"] == os.path.join("data", "new.npz")
    assert back["profiles_figure"] == os.path.join("figures", "profiles.png")
    assert back["model_path"] == os.path.join("models", "cnn_x_run{run}.zip")
    assert back["config"]["data"]["test"]["new"] == os.path.join("..", "inputs", "new.npz")
    assert (study / back["config"]["data"]["test"]["new"]).resolve() == given.resolve()
    assert back["config"]["source"] == "defaults"
    assert not any(os.path.isabs(s) for k, s in back.items() if k != "invocation" and isinstance(s, str))
    assert not any(os.path.isabs(s) for s in _strings({k: v for k, v in back.items() if k != "invocation"}))


def test_plain_keeps_finite_numbers_and_plain_strings(tmp_path):
    out = plain({"a": [1, 2.5, "HELI", "/not/a/path/here"], "b": {"c": np.float32(0.25)}}, tmp_path)
    assert out == {"a": [1, 2.5, "HELI", "/not/a/path/here"], "b": {"c": 0.25}}
    assert math.isfinite(out["b"]["c"])


def test_a_study_folder_given_relative_gives_paths_relative_to_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "study" / "data").mkdir(parents=True)
    back = _strict(write_results({"data": {"new": {"path": os.path.join("study", "data", "new.npz")}},
                                  "other": "studying"}, Path("study")).read_text())
    assert back["data"]["new"]["path"] == os.path.join("data", "new.npz") and back["other"] == "studying"
