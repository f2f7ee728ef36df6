"""Classifiers, metrics, persistence and the tsaug baseline (mdaug.classify)."""
import json
import zipfile

import numpy as np
import pytest

from mdaug.classify import (TsaugAugmenter, evaluate, load_model, make_classifier, preprocess,
                            save_model, tsaug_baseline)
from mdaug.classify.cnn import ProfileCNN, split_indices
from mdaug.radar import DataFileError, normalise

FAST = ("svm", "nb", "xgb")
CNN_FAST = {"epochs": 30, "batch_size": 32, "progress": False}


def toy(n_per_class, seed, labels=("HELI", "QUAD")):
    """Two classes of 400-bin profiles: a central peak with sidebands 9 or 15 bins out,
    random amplitude, sub-bin shift and additive noise (clearly separable)."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.array(labels), n_per_class)
    off = np.where(y == labels[0], 9.0, 15.0)[:, None] + rng.normal(0, 0.5, (y.size, 1))
    x = np.arange(400)[None, :] - 200 - rng.uniform(-0.5, 0.5, (y.size, 1))
    p = np.exp(-0.5 * (x / 2) ** 2) + 0.4 * np.exp(-0.5 * ((np.abs(x) - off) / 2) ** 2)
    p = p * rng.uniform(0.5, 20, (y.size, 1)) + 0.05 * rng.random(p.shape)
    return p, y


def balanced_shuffle(y, rng):
    """Labels independent of the class: half of each true class gets each label."""
    out = y.copy()
    labs = np.unique(y)
    for c in labs:
        idx = rng.permutation(np.flatnonzero(y == c))
        out[idx] = np.resize(labs, idx.size)
    return out


@pytest.fixture(scope="module")
def data():
    return toy(150, 0), toy(100, 1)


def params(name):
    return CNN_FAST if name == "cnn" else {}


# -- preprocessing -----------------------------------------------------------------------
def test_preprocess_is_radar_normalise_in_float32():
    x, _ = toy(5, 3)
    for method in ("peak", "db", "l2", "none"):
        p = preprocess(x, method)
        assert p.dtype == np.float32 and p.shape == x.shape
        np.testing.assert_allclose(p, normalise(x, method), rtol=1e-6, atol=1e-5)
    p = preprocess(x)
    np.testing.assert_allclose(p.max(axis=1), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(preprocess(p), p)  # peak normalisation is idempotent
    with pytest.raises(ValueError, match="unknown normalisation"):
        preprocess(x, "max")
    with pytest.raises(ValueError, match="NaN or inf"):
        preprocess(np.full((2, 10), np.nan))


# -- each classifier ---------------------------------------------------------------------
@pytest.mark.parametrize("name", FAST + ("cnn",))
def test_separable_problem_is_learned(name, data):
    (x, y), (xt, yt) = data
    model = make_classifier(name, random_state=0, **params(name)).fit(x, y)
    assert model.classes_.tolist() == ["HELI", "QUAD"] and model.n_features_in_ == 400
    assert model.score(xt, yt) >= 0.95
    proba = model.predict_proba(xt)
    assert proba.shape == (len(yt), 2)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(model.classes_[proba.argmax(axis=1)], model.predict(xt))


@pytest.mark.parametrize("name", FAST + ("cnn",))
def test_shuffled_labels_give_chance(name, data):
    (x, y), (xt, yt) = data
    ys = balanced_shuffle(y, np.random.default_rng(5))
    model = make_classifier(name, random_state=0, **params(name)).fit(x, ys)
    # labels that carry no information teach nothing that transfers: on test labels shuffled
    # the same way (independent of the profiles), 200 predictions score 0.5 +- 0.15 with
    # overwhelming probability (against the true classes a noise-trained model may land
    # anywhere: its arbitrary split of the profiles can follow the classes either way)
    acc = model.score(xt, balanced_shuffle(yt, np.random.default_rng(6)))
    assert abs(acc - 0.5) < 0.15


@pytest.mark.parametrize("name", FAST + ("cnn",))
def test_wrong_length_and_unknown_labels_fail_clearly(name, data):
    (x, y), _ = data
    model = make_classifier(name, random_state=0, **{**params(name), "epochs": 1} if name == "cnn" else {})
    with pytest.raises(ValueError, match="not trained yet"):
        model.predict(x)
    model.fit(x, y)
    with pytest.raises(ValueError, match=r"300 bins but this .* 400-bin"):
        model.predict(x[:, :300])
    with pytest.raises(ValueError, match=r"new.npz.*\['DRONE'\] are unknown"):
        model.check_labels(["HELI", "DRONE"], source="new.npz")


def test_unknown_classifier_and_bad_cnn_length():
    with pytest.raises(ValueError, match="unknown classifier 'rf'"):
        make_classifier("rf")
    x, y = toy(20, 0)
    with pytest.raises(ValueError, match="400-bin profiles"):
        make_classifier("cnn", epochs=1).fit(x[:, :256], y)


# -- the CNN -----------------------------------------------------------------------------
def test_cnn_layer_shapes_match_spec():
    net = ProfileCNN(n_classes=2)
    shapes = net.layer_shapes(batch=3)
    assert shapes == [("Conv2d", (3, 32, 18, 18)), ("ReLU", (3, 32, 18, 18)), ("MaxPool2d", (3, 32, 9, 9)),
                      ("Conv2d", (3, 64, 7, 7)), ("ReLU", (3, 64, 7, 7)), ("AvgPool2d", (3, 64, 1, 1)),
                      ("Flatten", (3, 64)), ("Linear", (3, 64)), ("ReLU", (3, 64)), ("Linear", (3, 2))]
    pool = net.features[5]
    assert pool.kernel_size == 7 and pool.stride == 7
    assert net.features[2].kernel_size == 2


def test_cnn_same_seed_same_model_and_best_validation_kept(data):
    (x, y), (xt, _) = data
    kw = {"epochs": 6, "batch_size": 32, "progress": False}
    a = make_classifier("cnn", random_state=7, **kw).fit(x, y)
    b = make_classifier("cnn", random_state=7, **kw).fit(x, y)
    c = make_classifier("cnn", random_state=8, **kw).fit(x, y)
    np.testing.assert_array_equal(a.predict_proba(xt), b.predict_proba(xt))
    assert not np.array_equal(a.predict_proba(xt), c.predict_proba(xt))
    losses = [h["val_loss"] for h in a.history_]
    assert a.best_epoch_ == int(np.argmin(losses)) + 1
    s = a.split_scores_
    assert (s["n_train"], s["n_val"], s["n_test"]) == (240, 30, 30)
    assert s["val_loss"] == pytest.approx(min(losses))


def test_cnn_early_stopping_stops():
    x, y = toy(40, 2)
    ys = balanced_shuffle(y, np.random.default_rng(0))  # nothing to learn: validation stalls
    m = make_classifier("cnn", random_state=0, epochs=60, batch_size=16, patience=3, progress=False).fit(x, ys)
    assert len(m.history_) < 60
    assert len(m.history_) == m.best_epoch_ + 3


def test_split_is_stratified_disjoint_and_grouped():
    y = np.repeat([0, 1], [60, 140])
    tr, va, te = split_indices(y, rng=0)
    assert len(np.intersect1d(tr, va)) == len(np.intersect1d(tr, te)) == len(np.intersect1d(va, te)) == 0
    assert len(tr) + len(va) + len(te) == 200
    assert np.sum(y[te] == 0) == 6 and np.sum(y[te] == 1) == 14
    groups = np.repeat(np.arange(20), 10)  # 20 source profiles, 10 copies each
    yg = (groups >= 8).astype(int)
    tr, va, te = split_indices(yg, groups=groups, rng=1)
    for a, b in ((tr, va), (tr, te), (va, te)):
        assert not set(groups[a]) & set(groups[b])
    assert set(yg[va]) == set(yg[te]) == {0, 1}


# -- metrics -----------------------------------------------------------------------------
def test_metrics_agree_with_scikit_learn():
    from sklearn import metrics as skm

    y_true = np.array(list("AAAAABBBBBBBCCCD"))
    y_pred = np.array(list("AAABCBBBBBACCCAA"))
    labels = ["A", "B", "C", "D"]
    m = evaluate(y_true, y_pred, labels=labels, n_boot=0)
    assert m["accuracy"] == pytest.approx(skm.accuracy_score(y_true, y_pred))
    assert m["balanced_accuracy"] == pytest.approx(skm.balanced_accuracy_score(y_true, y_pred))
    assert m["confusion_matrix"] == skm.confusion_matrix(y_true, y_pred, labels=labels).tolist()
    p, r, _, n = skm.precision_recall_fscore_support(y_true, y_pred, labels=labels, zero_division=0)
    for i, lab in enumerate(labels):
        if lab != "D":
            assert m["per_class"][lab]["precision"] == pytest.approx(p[i])
        assert m["per_class"][lab]["recall"] == pytest.approx(r[i])
        assert m["per_class"][lab]["n"] == n[i]
    assert m["per_class"]["D"]["precision"] is None  # never predicted: undefined, not scikit-learn's 0
    assert m["n"] == 16 and m["labels"] == labels


def test_bootstrap_intervals_cover_point_and_are_reproducible():
    rng = np.random.default_rng(3)
    y_true = np.repeat(["HELI", "QUAD"], [44, 92])  # the paper's New set
    y_pred = np.where(rng.random(136) < 0.75, y_true, np.where(y_true == "HELI", "QUAD", "HELI"))
    m = evaluate(y_true, y_pred, random_state=1)
    json.dumps(m)  # plain Python values
    ci = m["ci"]
    assert ci["accuracy"][0] <= m["accuracy"] <= ci["accuracy"][1]
    assert ci["balanced_accuracy"][0] <= m["balanced_accuracy"] <= ci["balanced_accuracy"][1]
    for lab, pc in m["per_class"].items():
        for key in ("precision", "recall"):
            lo, hi = ci["per_class"][lab][key]
            assert lo <= pc[key] <= hi and hi - lo > 0.02
    # binomial standard error sqrt(p(1-p)/n): the 95% interval is about +-1.96 of it
    se = np.sqrt(m["accuracy"] * (1 - m["accuracy"]) / 136)
    assert ci["accuracy"][1] - ci["accuracy"][0] == pytest.approx(2 * 1.96 * se, rel=0.2)
    assert evaluate(y_true, y_pred, random_state=1) == m
    with pytest.raises(ValueError, match=r"labels \['X'\] are not in"):
        evaluate(["A", "X"], ["A", "A"], labels=["A"])


# -- persistence -------------------------------------------------------------------------
@pytest.mark.parametrize("name,extra", [("svm", {}), ("svm", {"kernel": "linear"}), ("nb", {}),
                                        ("xgb", {}), ("cnn", {"epochs": 2, "progress": False})])
def test_save_load_round_trip(tmp_path, data, name, extra):
    (x, y), (xt, _) = data
    model = make_classifier(name, random_state=0, normalisation="db", **extra).fit(x, y)
    path = save_model(model, tmp_path / "m.zip")
    back = load_model(path)
    assert type(back) is type(model) and back.normalisation == "db"
    assert back.classes_.tolist() == model.classes_.tolist() and back.n_features_in_ == 400
    np.testing.assert_array_equal(back.predict_proba(xt), model.predict_proba(xt))
    np.testing.assert_array_equal(back.predict(xt), model.predict(xt))
    with zipfile.ZipFile(path) as zf:
        meta = json.loads(zf.read("meta.json"))
    assert meta["kind"] == name and meta["n_features"] == 400


def test_load_rejects_wrong_and_corrupted_files(tmp_path, data):
    (x, y), _ = data
    path = save_model(make_classifier("nb").fit(x, y), tmp_path / "m.zip")
    other = tmp_path / "data.npz"
    np.savez(other, profiles=x)
    with pytest.raises(DataFileError, match=r"data.npz.*meta.json"):
        load_model(other)
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(DataFileError, match=r"notes.txt: not an mdaug model file"):
        load_model(text)
    raw = path.read_bytes()
    bad = tmp_path / "bad.zip"
    bad.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(DataFileError, match="bad.zip"):
        load_model(bad)
    flipped = bytearray(raw)
    start = raw.find(b"model.skops") + 40  # inside the weights member's data
    flipped[start:start + 20] = bytes(20)
    bad.write_bytes(bytes(flipped))
    with pytest.raises(DataFileError, match="bad.zip"):
        load_model(bad)
    with pytest.raises(DataFileError, match="missing.zip: model file not found"):
        load_model(tmp_path / "missing.zip")


# -- tsaug baseline ----------------------------------------------------------------------
def test_tsaug_keeps_length_labels_and_draws_fresh_each_call():
    from mdaug.classify import tsaug_set

    x, y = toy(5, 4)  # a handful of "measured" profiles per class
    aug = TsaugAugmenter(x, y, "QUAD", random_state=3)
    a = aug.sample(50)
    assert a.profiles.shape == (50, 400) and a.profiles.dtype == np.float32 and a.params is None
    assert (a.labels == "QUAD").all() and (y[a.sources] == "QUAD").all()  # copies keep their source's class
    assert np.bincount(a.sources, minlength=10)[y == "QUAD"].tolist() == [10] * 5  # sources used equally
    b = aug.sample(50)
    assert not np.array_equal(a.profiles, b.profiles)  # a fresh tsaug seed per call
    again = TsaugAugmenter(x, y, "QUAD", random_state=3)
    np.testing.assert_array_equal(again.sample(50).profiles, a.profiles)  # same user seed, same sequence
    np.testing.assert_array_equal(again.sample(50).profiles, b.profiles)
    xs, ys, src = tsaug_set(x, y, 20, random_state=1)
    assert xs.shape == (40, 400) and (ys == "HELI").sum() == 20 and np.array_equal(ys, y[src])
    with pytest.raises(ValueError, match="no tsaug source profile of class 'BLIMP'"):
        TsaugAugmenter(x, y, "BLIMP")


def test_tsaug_baseline_trains_cnn_on_training_profiles_only():
    x, y = toy(10, 6)
    model = tsaug_baseline(x, y, n_per_class=100, random_state=0, epochs=2, batch_size=32, progress=False)
    assert model.name == "cnn" and model.classes_.tolist() == ["HELI", "QUAD"]
    assert model.augmenter_settings_["strategy"] == "tsaug"
    s = model.split_scores_
    assert s["n_train"] + s["n_val"] + s["n_test"] == 200
    # split by source profile: 10 sources per class -> 8 / 1 / 1 sources x 10 copies
    assert (s["n_train"], s["n_val"], s["n_test"]) == (160, 20, 20)


def test_tsaug_cross_validation_never_trains_on_its_test_fold(monkeypatch):
    import importlib

    tb = importlib.import_module("mdaug.classify.tsaug_baseline")  # the module, not the function

    x, y = toy(6, 8)
    seen = []

    class Echo:  # stands in for the CNN: predicts the first class, records its training rows
        def __init__(self, xtr):
            seen.append(xtr)

        def predict(self, xs):
            return np.full(len(xs), "HELI")

    monkeypatch.setattr(tb, "tsaug_baseline", lambda xtr, ytr, n, seed, epochs, **kw: Echo(xtr))
    pred, fold = tb.tsaug_cross_validate(x, y, n_splits=3, n_per_class=10, random_state=0, epochs=1)
    assert pred.shape == (12,) and sorted(np.bincount(fold).tolist()) == [4, 4, 4]
    for k, xtr in enumerate(seen):
        test_rows = x[fold == k]
        assert len(xtr) == 8
        assert not any(np.array_equal(r, t) for r in xtr for t in test_rows)


def test_undefined_precision_is_left_out_of_the_mean_over_runs():
    from mdaug.classify.metrics import degenerate, evaluate_runs

    y = np.array(["HELI"] * 4 + ["QUAD"] * 4)
    runs = [np.array(["HELI", "HELI", "QUAD", "QUAD", "QUAD", "QUAD", "QUAD", "HELI"]),  # HELI precision 2/3
            np.array(["QUAD"] * 8),                                                      # HELI never predicted
            np.array(["HELI", "QUAD", "QUAD", "QUAD", "QUAD", "QUAD", "QUAD", "QUAD"])]  # HELI precision 1
    m = evaluate_runs(y, np.stack(runs), labels=["HELI", "QUAD"], n_boot=200)
    heli = m["per_class"]["HELI"]
    assert heli["precision"] == pytest.approx((2 / 3 + 1) / 2)  # not (2/3 + 0 + 1) / 3
    assert heli["precision_runs"] == 2 and m["per_class"]["QUAD"]["precision_runs"] == 3
    lo, hi = m["ci"]["per_class"]["HELI"]["precision"]
    assert 0 <= lo < hi <= 1
    v = degenerate(m)
    assert not v["degenerate"] and v["degenerate_runs"] == {"HELI": 1} and v["n_runs"] == 3
    never = evaluate_runs(y, np.stack([runs[1], runs[1]]), labels=["HELI", "QUAD"], n_boot=50)
    assert never["per_class"]["HELI"]["precision"] is None and never["per_class"]["HELI"]["precision_runs"] == 0
    assert never["ci"]["per_class"]["HELI"]["precision"] is None
    json.dumps(never, allow_nan=False)
    v = degenerate(never)
    assert v["degenerate"] and v["zero_recall"] == ["HELI"] and v["never_predicted"] == ["HELI"]
