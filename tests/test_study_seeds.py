"""tests/benchmarks/study_seeds.py: the seeds' table reads each study's own choice."""
import importlib.util
import json
from pathlib import Path

import pytest


def _bench():
    path = Path(__file__).parent / "benchmarks" / "study_seeds.py"
    spec = importlib.util.spec_from_file_location("study_seeds", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _study(d: Path, seed: int, scores: dict, tied: list, ceiling: float) -> Path:
    test = lambda ba: {"balanced_accuracy": ba, "ci": {"balanced_accuracy": [ba - 0.1, ba + 0.1]}}  # noqa: E731
    results = {"config": {"seed": seed},
               "strategies": {n: {"tests": {"new": test(v), "select": test(0.5)}} for n, v in scores.items()},
               "best_strategy": {"name": tied[0], "tied": tied},
               "ceiling": {"chosen": {"model": "svm"}, "models": {"svm": {"tests": {"new": test(ceiling)}}}}}
    d.mkdir()
    (d / "results.json").write_text(json.dumps(results))
    return d


def test_the_seeds_table_averages_each_studys_own_choice_and_refuses_a_missing_study(tmp_path, capsys):
    bench = _bench()
    a = _study(tmp_path / "s0", 0, {"fit": 0.70, "posterior": 0.60}, ["fit"], 0.90)
    b = _study(tmp_path / "s1", 1, {"fit": 0.80, "posterior": 0.86}, ["fit", "posterior"], 0.80)
    assert bench.main([str(a), str(b), "--tests", "new"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert "0.700* [0.60,0.80]" in lines[3] and "0.600  [0.50,0.70]" in lines[3]
    assert "0.800* [0.70,0.90]" in lines[4] and "0.860* [0.76,0.96]" in lines[4]
    mean = lines[5].split()
    assert mean[0] == "mean" and [float(x) for x in mean[1:]] == pytest.approx([0.75, 0.73, 0.85])
    # the chosen strategy: 0.70 on seed 0, the mean of the tied 0.80 and 0.86 on seed 1
    assert "the chosen strategy (tied ones averaged): mean 0.765, 0.700-0.830 over 2 studies" in out
    assert bench.main([str(a), str(tmp_path / "none")]) == 2
    assert "no results.json" in capsys.readouterr().err
