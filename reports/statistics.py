"""The study's statistics: every classifier scored on the same resamples.

Each test set gets one set of bootstrap resamples and one set of training-run picks,
both from the study's seed and the set's name (:func:`resamples`). Where the set says
which drone made each acquisition (``truth[set]["drones"]``), a resample draws drones
(clusters) with replacement within each class and then acquisitions within them, so
the intervals cover other drones, not only other acquisitions of these few; otherwise
it resamples the acquisitions. Every strategy's CNN (several training runs: seeds) and every
ceiling model is scored on those same resamples, so that

* a classifier's figure is the mean over its runs and its 95% interval covers the
  test sample and the training randomness (:func:`mdaug.classify.metrics.evaluate_runs`:
  one run picked at random per resample; the interval holds every run's own score);
* a difference between two classifiers is paired: the same resamples of the test
  acquisitions and, in each, the same picks of runs, averaged
  (:func:`mdaug.classify.metrics.paired_difference`), so identical predictions give a
  difference of exactly 0 [0, 0] and shared test noise cancels.

Predictions are stored in ``results.json`` (one string of class indices per run and
set, :func:`encode`) with the true labels (``truth``), so the report can recompute all
of this from the file alone.
"""
from __future__ import annotations

import numpy as np

from ..classify.metrics import evaluate_runs, paired_difference, resample_indices, run_scores, seed_uniforms
from ..radar.seeds import child_seed

MAX_RUNS = 64
"""Columns of the run picks (a result may have at most this many training runs)."""


def encode(labels, classes) -> str:
    """Predicted labels as one string of class indices ('0110...'; classes < 10)."""
    index = {c: str(i) for i, c in enumerate(classes)}
    if len(index) > 10:
        raise ValueError("predictions are stored as digits: at most 10 classes")
    return "".join(index[str(v)] for v in np.asarray(labels).astype(str))


def decode(text: str, classes) -> np.ndarray:
    classes = np.asarray(list(classes))
    return classes[np.frombuffer(text.encode(), dtype=np.uint8) - ord("0")]


def truth(y, classes, drones=None) -> dict:
    """A test set's true labels as stored in results.json, and the drone of each
    acquisition (``drones``: ids within its class, None when the set does not say) as
    ``"CLASS/id"``: the clusters of the bootstrap."""
    out = {"classes": list(classes), "y": encode(y, classes)}
    if drones is not None:
        if len(drones) != len(y):
            raise ValueError(f"drones has {len(drones)} entries for {len(y)} acquisitions")
        out["drones"] = [f"{c}/{d}" for c, d in zip(np.asarray(y).astype(str), np.asarray(drones).astype(str))]
    return out


def clusters(truth_set: dict):
    """The drone of each acquisition of a stored set (None: not known, each its own)."""
    return truth_set.get("drones")


def resamples(seed: int, set_name: str, n: int, n_boot: int, drones=None, y=None):
    """(indices (n_boot, n), run picks (n_boot, MAX_RUNS)) of test set ``set_name``: the
    same for every classifier scored on it. With ``drones`` (and the true classes ``y``)
    the resamples are two-stage: drones, then acquisitions within them
    (:func:`mdaug.classify.metrics.resample_indices`)."""
    idx = resample_indices(n, n_boot, child_seed(seed, "bootstrap", set_name), drones, y)
    picks = seed_uniforms(n_boot, MAX_RUNS, child_seed(seed, "bootstrap-runs", set_name))
    return idx, picks


def score(truth_set: dict, predictions: list[str], set_name: str, seed: int, n_boot: int, seeds=None) -> dict:
    """The metrics of one classifier's runs (``predictions``: one encoded string per run)
    on one test set, on the study's shared resamples of that set."""
    classes = truth_set["classes"]
    y = decode(truth_set["y"], classes)
    preds = np.stack([decode(p, classes) for p in predictions])
    drones = clusters(truth_set)
    if n_boot:
        idx, picks = resamples(seed, set_name, len(y), n_boot, drones, y)
    else:
        idx, picks = None, None
    return evaluate_runs(y, preds, labels=classes, n_boot=n_boot, resamples=idx, uniforms=picks, seeds=seeds,
                         clusters=drones)


def differences(truth_set: dict, entries: dict, set_name: str, seed: int, n_boot: int) -> dict:
    """Paired differences in mean balanced accuracy between every two classifiers of
    ``entries`` ({name: [encoded predictions per run]}) on one test set:
    {"A|B": {"difference": A - B, "ci": [lo, hi]}} for every ordered pair A != B."""
    classes = truth_set["classes"]
    y = decode(truth_set["y"], classes)
    if not n_boot or not entries:
        return {}
    idx, picks = resamples(seed, set_name, len(y), n_boot, clusters(truth_set), y)
    point, boot = {}, {}
    for name, preds in entries.items():
        p = np.stack([decode(x, classes) for x in preds])
        point[name] = run_scores(y, p, classes, np.arange(len(y))[None, :])[:, 0]
        boot[name] = run_scores(y, p, classes, idx)
    out = {}
    for a in entries:
        for b in entries:
            if a != b:
                out[f"{a}|{b}"] = paired_difference(point[a], point[b], boot[a], boot[b], picks)
    return out


def score_study(results: dict) -> dict:
    """Fill ``results`` (as the study assembles it) with the scores and the paired
    differences: each strategy's ``tests`` and each ceiling model's, from their stored
    predictions, and ``comparisons`` {set: {"A|B": ...}} between the strategies and the
    ceiling models (named ``ceiling:<model>``). Returns ``results``."""
    seed = int(results["config"]["seed"])
    n_boot = int(results["config"]["protocol"]["n_boot"])
    sets = results["truth"]
    entries: dict[str, dict] = {s: {} for s in sets}
    for name, s in results["strategies"].items():
        s["tests"] = {t: score(sets[t], preds, t, seed, n_boot, seeds=s.get("seeds"))
                      for t, preds in s["predictions"].items()}
        for t, preds in s["predictions"].items():
            entries[t][name] = preds
    for model, m in ((results.get("ceiling") or {}).get("models") or {}).items():
        m["tests"] = {t: score(sets[t], preds, t, seed, n_boot, seeds=m.get("seeds"))
                      for t, preds in m["predictions"].items()}
        for t, preds in m["predictions"].items():
            entries[t][f"ceiling:{model}"] = preds
    results["comparisons"] = {t: differences(sets[t], e, t, seed, n_boot) for t, e in entries.items()}
    return results
