"""The sigma_P sweep (mdaug.classify.protocol) and the classify CLI verbs."""
import json
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from mdaug.classify import PUBLISHED_SIGMA_PS, sigma_p_sweep
from mdaug.cli import main
from mdaug.radar import atomic_savez


def toy_train(sigma_p, seed):
    """Toy make_train: the class sidebands blur as sigma_p grows (picklable, top level)."""
    rng = np.random.default_rng(seed)
    n = 100
    y = np.repeat(np.array(["HELI", "QUAD"]), n)
    off = np.where(y == "HELI", 9.0, 15.0) * (1 + sigma_p * rng.standard_normal(2 * n))
    x = np.arange(400)[None, :] - 200
    p = np.exp(-0.5 * (x / 2) ** 2) + 0.4 * np.exp(-0.5 * ((np.abs(x) - off[:, None]) / 2) ** 2)
    return p + 0.05 * rng.random(p.shape), y


@pytest.fixture(scope="module")
def tests_sets():
    xa, ya = toy_train(0.0, 101)
    xb, yb = toy_train(0.3, 102)
    return {"old": (xa[::4], ya[::4]), "new": (xb[::2], yb[::2])}


def test_published_grid():
    assert PUBLISHED_SIGMA_PS == (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.40, 0.50, 0.60)


def test_sweep_table_reproducible_and_executor_independent(tmp_path, tests_sets):
    kw = dict(sigma_ps=(0.0, 0.3), models=("nb", "xgb"), random_state=4, n_boot=100)
    a = sigma_p_sweep(toy_train, tests_sets, **kw)
    with ThreadPoolExecutor(2) as ex:
        b = sigma_p_sweep(toy_train, tests_sets, executor=ex, **kw)
    strip = [{k: v for k, v in r.items() if k != "train_seconds"} for r in a.rows]
    assert strip == [{k: v for k, v in r.items() if k != "train_seconds"} for r in b.rows]
    assert len(a.rows) == 2 * 2 * 2
    assert {(r["sigma_p"], r["model"], r["test_set"]) for r in a.rows} == {
        (s, m, t) for s in (0.0, 0.3) for m in ("nb", "xgb") for t in ("old", "new")}
    for r in a.rows:
        assert r["accuracy_lo"] <= r["accuracy"] <= r["accuracy_hi"]
        assert r["min_recall"] == min(r["recall_HELI"], r["recall_QUAD"])
        assert r["n_train"] == 200 and r["n_test"] == (50 if r["test_set"] == "old" else 100)
    best = a.best("xgb", "old")
    assert best["accuracy"] == max(a.column("accuracy", "xgb", "old"))
    with pytest.raises(ValueError, match="no rows for model 'svm'"):
        a.best("svm", "old")
    a.to_csv(tmp_path / "t.csv")
    lines = (tmp_path / "t.csv").read_text().splitlines()
    assert lines[0].startswith("sigma_p,model,test_set,accuracy,balanced_accuracy,min_recall")
    assert len(lines) == 9
    md = a.to_markdown()
    assert "| sigma_P | NB old | NB new | XGB old | XGB new |" in md and "| 0.30 |" in md
    a.plot(tmp_path / "t.png")
    assert (tmp_path / "t.png").stat().st_size > 1000


def test_sweep_resumes_from_cache(tmp_path, tests_sets):
    calls = []

    def counting(sigma_p, seed):
        calls.append(sigma_p)
        return toy_train(sigma_p, seed)

    counting.cache_key = "toy-v1"
    kw = dict(sigma_ps=(0.0, 0.1), models=("nb",), random_state=1, n_boot=50, cache_dir=tmp_path / "jobs")
    a = sigma_p_sweep(counting, tests_sets, **kw)
    b = sigma_p_sweep(counting, tests_sets, **kw)
    assert calls == [0.0, 0.1] and b.settings["resumed_jobs"] == 2
    assert a.rows == b.rows
    sigma_p_sweep(counting, tests_sets, **{**kw, "random_state": 2})  # other seed: recomputed
    assert calls == [0.0, 0.1, 0.0, 0.1]


def test_sweep_rejects_unknown_test_labels(tests_sets):
    x, y = tests_sets["old"]
    bad = {"odd": (x, np.where(y == "HELI", "PLANE", y))}
    with pytest.raises(ValueError, match=r"test set odd: labels \['PLANE'\] are unknown"):
        sigma_p_sweep(toy_train, bad, sigma_ps=(0.1,), models=("nb",), n_boot=0)
    with pytest.raises(ValueError, match="sigma_p values must be in"):
        sigma_p_sweep(toy_train, tests_sets, sigma_ps=(1.5,))


# -- CLI ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cls")
    x, y = toy_train(0.05, 1)
    xt, yt = toy_train(0.05, 2)
    atomic_savez(d / "train.npz", profiles=x, labels=y)
    atomic_savez(d / "test.npz", profiles=xt, labels=yt)
    atomic_savez(d / "short.npz", profiles=xt[:, :300], labels=yt)
    atomic_savez(d / "odd.npz", profiles=xt, labels=np.where(yt == "HELI", "PLANE", yt))
    return d


def test_cli_train_evaluate(files, capsys):
    d = files
    assert main(["train", str(d / "train.npz"), "--model", "xgb", "--out", str(d / "m.zip"), "--seed", "3"]) == 0
    assert main(["evaluate", str(d / "m.zip"), str(d / "test.npz"), "--json", str(d / "m.json"),
                 "--plot", str(d / "cm.png"), "--n-boot", "200"]) == 0
    out = capsys.readouterr().out
    assert "accuracy" in out and "confusion matrix" in out
    m = json.loads((d / "m.json").read_text())
    for key in ("accuracy", "balanced_accuracy", "confusion_matrix", "labels", "per_class", "ci", "n"):
        assert key in m
    assert m["labels"] == ["HELI", "QUAD"] and m["accuracy"] > 0.9
    assert set(m["per_class"]["HELI"]) == {"precision", "recall", "n"}
    assert (d / "cm.png").stat().st_size > 1000


def test_cli_evaluate_errors_name_the_file(files, capsys):
    d = files
    assert main(["train", str(d / "train.npz"), "--model", "nb", "--out", str(d / "nb.zip")]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(d / "nb.zip"), str(d / "short.npz")]) == 2
    err = capsys.readouterr().err
    assert "short.npz" in err and "300 bins" in err and "400-bin" in err
    assert main(["evaluate", str(d / "nb.zip"), str(d / "odd.npz")]) == 2
    err = capsys.readouterr().err
    assert "odd.npz" in err and "PLANE" in err
    assert main(["evaluate", str(d / "train.npz"), str(d / "test.npz")]) == 2
    assert "train.npz" in capsys.readouterr().err


def test_cli_sweep_on_generator_profiles(tmp_path, capsys):
    from mdaug.generator import SigmaPAugmenter, make_dataset

    ds = make_dataset([SigmaPAugmenter("HELI", 0.1), SigmaPAugmenter("QUAD", 0.1)], 20, 9)
    atomic_savez(tmp_path / "meas.npz", profiles=ds.profiles, labels=ds.labels)
    atomic_savez(tmp_path / "short.npz", profiles=ds.profiles[:, :200], labels=ds.labels)
    out = tmp_path / "sweep"
    args = ["sweep", "--sigma-p", "0,0.2", "--models", "nb,xgb", "--test", str(tmp_path / "meas.npz"),
            "--out", str(out), "--n-per-class", "100", "--n-boot", "50", "--seed", "1"]
    assert main(args) == 0
    for name in ("sweep.csv", "sweep.md", "sweep.png", "settings.json"):
        assert (out / name).is_file()
    lines = (out / "sweep.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * 2
    assert main(args + ["--test", str(tmp_path / "short.npz"), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "short.npz" in err and "200-bin" in err


def test_cli_baseline_cross_validates_and_saves(files, capsys):
    d = files
    args = ["baseline", str(d / "test.npz"), "--folds", "2", "--n-per-class", "40", "--epochs", "1",
            "--batch-size", "32", "--out", str(d / "tsaug.zip"), "--test", str(d / "train.npz"),
            "--json", str(d / "tsaug.json"), "--allow-degenerate"]  # one epoch: a toy model
    assert main(args) == 0
    report = json.loads((d / "tsaug.json").read_text())
    assert report["cross_validation"]["n"] == 200
    assert report[str(d / "train.npz")]["labels"] == ["HELI", "QUAD"]
    from mdaug.classify import load_model

    assert load_model(d / "tsaug.zip").name == "cnn"
    assert main(["baseline", str(d / "test.npz")]) == 2
    assert "--out MODEL" in capsys.readouterr().err


@pytest.mark.slow
def test_sweep_in_worker_processes_matches_serial():
    from concurrent.futures import ProcessPoolExecutor

    from mdaug.cli.sweep import SyntheticTrainSet
    from mdaug.generator import SigmaPAugmenter, make_dataset

    ds = make_dataset([SigmaPAugmenter("HELI", 0.1), SigmaPAugmenter("QUAD", 0.1)], 30, 5)
    tests = {"t": (ds.profiles, ds.labels)}
    make_train = SyntheticTrainSet(("HELI", "QUAD"), 200)
    kw = dict(sigma_ps=(0.05, 0.2), models=("svm", "xgb"), random_state=3, n_boot=100)
    serial = sigma_p_sweep(make_train, tests, **kw)
    with ProcessPoolExecutor(2) as ex:
        pooled = sigma_p_sweep(make_train, tests, executor=ex, **kw)
    drop = [{k: v for k, v in r.items() if k != "train_seconds"} for r in serial.rows]
    assert drop == [{k: v for k, v in r.items() if k != "train_seconds"} for r in pooled.rows]


@pytest.mark.slow
def test_cnn_learns_generator_profiles():
    from mdaug.classify import make_classifier
    from mdaug.generator import SigmaPAugmenter, make_dataset

    tr = make_dataset([SigmaPAugmenter("HELI", 0.1), SigmaPAugmenter("QUAD", 0.1)], 2000, 1)
    te = make_dataset([SigmaPAugmenter("HELI", 0.1), SigmaPAugmenter("QUAD", 0.1)], 500, 2)
    m = make_classifier("cnn", random_state=0, epochs=15, progress=False).fit(tr.profiles, tr.labels)
    assert m.score(te.profiles, te.labels) > 0.8
    assert m.split_scores_["test_accuracy"] > 0.8
