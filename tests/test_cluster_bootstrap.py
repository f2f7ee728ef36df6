"""Honest intervals: the bootstrap resamples drones (clusters), then acquisitions
within them (classify/metrics.py resample_indices; reports/statistics.py), for every
quoted interval and every paired comparison."""
import numpy as np
import pytest

from mdaug.classify.metrics import evaluate, resample_indices
from mdaug.reports import statistics

CLASSES = ["HELI", "QUAD"]
DRONES, PER_DRONE = 4, 30


def _drone_set():
    """4 drones per class, 30 acquisitions each; every acquisition of a drone is
    predicted alike: 3 drones of each class recognised, 1 missed (balanced accuracy 0.75)."""
    y = np.repeat(CLASSES, DRONES * PER_DRONE)
    drones = np.tile(np.repeat(np.arange(DRONES), PER_DRONE), 2)
    missed = drones == 3
    p = np.where(missed, np.where(y == "HELI", "QUAD", "HELI"), y)
    return y, p, drones


def _width(ci):
    return ci[1] - ci[0]


def test_identical_acquisitions_of_a_drone_widen_the_interval_to_the_drone_level_spread():
    y, p, drones = _drone_set()
    old = evaluate(y, p, labels=CLASSES, n_boot=4000, random_state=0)["ci"]["balanced_accuracy"]
    m = evaluate(y, p, labels=CLASSES, n_boot=4000, random_state=0, clusters=drones)
    new = m["ci"]["balanced_accuracy"]
    assert m["balanced_accuracy"] == pytest.approx(0.75)
    # the drone-level spread: each class's recall is the share of 4 drones drawn with replacement
    # that are recognised (each 3 in 4), the balanced accuracy their mean
    rng = np.random.default_rng(1)
    per_class = rng.binomial(DRONES, 0.75, size=(200_000, 2)) / DRONES
    drone_level = np.percentile(per_class.mean(axis=1), [2.5, 97.5])
    # a discrete spread (steps of 1/8): the percentile may land one step off
    assert new == pytest.approx(list(drone_level), abs=0.125 + 1e-9)
    assert _width(old) < 0.15 and _width(new) > 3 * _width(old)
    # the whole distribution: the resamples' balanced accuracy spreads as the drones' does
    idx = resample_indices(y.size, 4000, 0, drones, y)
    right = p[idx] == y[idx]
    bal = np.mean([right[:, y == c].mean(axis=1) for c in CLASSES], axis=0)
    assert bal.std() == pytest.approx(per_class.mean(axis=1).std(), rel=0.08)  # sqrt(3/16 / 4 / 2) = 0.153
    items = resample_indices(y.size, 4000, 0)
    right, cls = p[items] == y[items], y[items]
    recalls = [(right & (cls == c)).sum(axis=1) / (cls == c).sum(axis=1) for c in CLASSES]
    assert np.mean(recalls, axis=0).std() < 0.04  # acquisitions alone: about 0.028
    assert "8 drones" in m["ci"]["method"]
    assert "drones" not in evaluate(y, p, labels=CLASSES, n_boot=50)["ci"]["method"]


def test_the_study_scores_and_paired_differences_resample_drones():
    y, p, drones = _drone_set()
    other = np.where(drones == 2, np.where(y == "HELI", "QUAD", "HELI"), p)  # also misses drone 2
    runs = [statistics.encode(p, CLASSES)]
    with_drones = statistics.truth(y, CLASSES, drones)
    without = statistics.truth(y, CLASSES)
    assert with_drones["drones"][0] == "HELI/0" and "drones" not in without
    a = statistics.score(with_drones, runs, "new", 3, 2000)
    b = statistics.score(without, runs, "new", 3, 2000)
    assert _width(a["ci"]["balanced_accuracy"]) > 3 * _width(b["ci"]["balanced_accuracy"])
    assert "drones (clusters)" in a["ci"]["method"] and "drones" not in b["ci"]["method"]
    entries = {"a": runs, "b": [statistics.encode(other, CLASSES)]}
    d_drones = statistics.differences(with_drones, entries, "new", 3, 2000)["a|b"]
    d_items = statistics.differences(without, entries, "new", 3, 2000)["a|b"]
    assert d_drones["difference"] == d_items["difference"] == pytest.approx(0.25)
    assert _width(d_drones["ci"]) > 3 * _width(d_items["ci"])
    assert d_drones["ci"][0] <= 0 < d_items["ci"][0]  # 2 drones' worth of difference: not significant


def test_cluster_resamples_keep_the_class_counts_and_stay_inside_a_drone_slot():
    y, _, drones = _drone_set()
    idx = resample_indices(y.size, 300, 5, drones, y)
    assert idx.shape == (300, y.size)
    assert np.array_equal(idx, resample_indices(y.size, 300, 5, drones, y))
    assert (y[idx] == y[None, :]).all()  # a class's positions take items of that class
    slot = np.flatnonzero((y == "QUAD") & (drones == 1))
    picked = drones[idx[:, slot]]
    assert (picked == picked[:, :1]).all()  # a slot is filled from one drawn drone
    assert len(np.unique(picked[:, 0])) == DRONES
    with pytest.raises(ValueError, match="one entry per item"):
        resample_indices(y.size, 10, 0, drones[:-1], y)
