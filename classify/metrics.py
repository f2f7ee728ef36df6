"""Honest classification metrics: confusion matrix, accuracy, balanced accuracy,
per-class precision and recall, each with a bootstrap 95% interval.

The published per-class "precision" is the share of each true class classified
correctly, i.e. per-class *recall*; both are reported. Test sets of ~136 profiles
are small, so every figure carries a percentile bootstrap interval (test profiles
resampled with replacement, ``n_boot`` times, from ``random_state``).

Undefined is not zero: a class never predicted has precision None (``null`` in
JSON, "–" on screen; scikit-learn's ``zero_division=0`` would say 0), a class absent
from ``y_true`` has recall None; balanced accuracy is the mean recall over the
classes present in ``y_true``. Over several training runs a figure is the mean over
the runs that define it, with their count (``precision_runs``). In a bootstrap
resample where a class is absent (recall undefined) or never predicted (precision
undefined) that resample is left out of the interval.

A **degenerate** result (:func:`degenerate`, the one rule the study's verdicts and the
verbs share): a class that no training run recognises (its recall 0 in every run).
"""
from __future__ import annotations

import numpy as np

from ..radar.seeds import rng as seeded_rng

LEVEL = 0.95


def _encode(y_true, y_pred, labels):
    y_true = np.asarray(y_true).astype(str).ravel()
    y_pred = np.asarray(y_pred).astype(str).ravel()
    if y_true.shape != y_pred.shape:
        raise ValueError(f"y_true has {y_true.size} entries but y_pred has {y_pred.size}")
    if y_true.size == 0:
        raise ValueError("cannot evaluate an empty test set")
    if labels is None:
        labels = sorted(set(y_true.tolist()) | set(y_pred.tolist()))
    labels = [str(lab) for lab in labels]
    index = {lab: i for i, lab in enumerate(labels)}
    unknown = sorted((set(y_true.tolist()) | set(y_pred.tolist())) - set(index))
    if unknown:
        raise ValueError(f"labels {unknown} are not in the given labels {labels}")
    t = np.array([index[v] for v in y_true])
    p = np.array([index[v] for v in y_pred])
    return t, p, labels


def _confusions(t: np.ndarray, p: np.ndarray, k: int, idx: np.ndarray) -> np.ndarray:
    """Confusion matrices (B, k, k) of resamples idx (B, n): rows true, columns predicted."""
    b = idx.shape[0]
    code = (np.arange(b)[:, None] * k * k + t[idx] * k + p[idx]).ravel()
    return np.bincount(code, minlength=b * k * k).reshape(b, k, k)


def _rates(cm: np.ndarray):
    """accuracy (B,), balanced accuracy (B,), precision (B, k), recall (B, k); NaN = undefined."""
    diag = np.diagonal(cm, axis1=-2, axis2=-1).astype(float)
    support = cm.sum(axis=-1)
    predicted = cm.sum(axis=-2)
    n = cm.sum(axis=(-2, -1))
    with np.errstate(invalid="ignore", divide="ignore"):
        recall = np.where(support > 0, diag / support, np.nan)
        precision = np.where(predicted > 0, diag / predicted, np.nan)
        accuracy = diag.sum(axis=-1) / n
        balanced = np.nanmean(recall, axis=-1) if recall.shape[-1] else np.nan
    return accuracy, balanced, precision, recall


def _interval(values: np.ndarray) -> list[float] | None:
    v = values[np.isfinite(values)]
    if v.size == 0:
        return None
    lo, hi = np.percentile(v, [50 * (1 - LEVEL), 100 - 50 * (1 - LEVEL)])
    return [float(lo), float(hi)]


def evaluate(y_true, y_pred, labels=None, n_boot: int = 1000, random_state=0, clusters=None) -> dict:
    """Metrics of predictions ``y_pred`` (N,) against ``y_true`` (N,).

    Returns a JSON-serialisable dict: ``accuracy``, ``balanced_accuracy``,
    ``confusion_matrix`` (rows true, columns predicted, in ``labels`` order),
    ``labels``, ``n``, ``per_class`` {label: {precision, recall, n}} (recall is the
    paper's per-class "precision"; ``n`` the true-class count; precision None for a
    class never predicted, recall None for a class absent from ``y_true``) and ``ci``:
    {accuracy: [lo, hi], balanced_accuracy: [lo, hi], per_class: {label:
    {precision: [lo, hi] | None, recall: [lo, hi] | None}}}, 95% percentile
    bootstrap intervals; ``n_boot`` = 0 skips them (``ci`` = {}). ``clusters`` (N,): the
    drone of each test item: the resamples are two-stage, drones then their items
    (:func:`resample_indices`); ``ci["method"]`` says which.
    """
    t, p, labels = _encode(y_true, y_pred, labels)
    k = len(labels)
    cm = _confusions(t, p, k, np.arange(t.size)[None, :])
    acc, bal, prec, rec = _rates(cm)
    support = cm[0].sum(axis=1)
    per_class = {lab: {"precision": None if np.isnan(prec[0, i]) else float(prec[0, i]),
                       "recall": float(np.nan_to_num(rec[0, i], nan=0.0)) if support[i] else None,
                       "n": int(support[i])}
                 for i, lab in enumerate(labels)}
    out = {"accuracy": float(acc[0]), "balanced_accuracy": float(bal[0]),
           "confusion_matrix": cm[0].tolist(), "labels": labels, "n": int(t.size),
           "per_class": per_class, "ci": {}}
    if n_boot:
        rng = seeded_rng(random_state)
        ci_acc, ci_bal = [], []
        ci_prec, ci_rec = [], []
        drawn = None if clusters is None else resample_indices(t.size, n_boot, rng, clusters, t)
        for lo in range(0, n_boot, 500):  # bounded memory: (500, n) indices at a time
            idx = rng.integers(0, t.size, size=(min(500, n_boot - lo), t.size)) if drawn is None \
                else drawn[lo:lo + 500]
            a, b, pr, rc = _rates(_confusions(t, p, k, idx))
            ci_acc.append(a), ci_bal.append(b), ci_prec.append(pr), ci_rec.append(rc)
        pr, rc = np.concatenate(ci_prec), np.concatenate(ci_rec)
        out["ci"] = {"level": LEVEL, "n_boot": int(n_boot), "method": bootstrap_method(clusters, t),
                     "accuracy": _interval(np.concatenate(ci_acc)),
                     "balanced_accuracy": _interval(np.concatenate(ci_bal)),
                     "per_class": {lab: {"precision": _interval(pr[:, i]), "recall": _interval(rc[:, i])}
                                   for i, lab in enumerate(labels)}}
    return out


def resample_indices(n: int, n_boot: int, random_state=0, clusters=None, strata=None) -> np.ndarray:
    """(n_boot, n) bootstrap resamples of n test items (with replacement), from
    ``random_state``; the same arguments give the same resamples, so results scored
    on one set with one ``random_state`` are paired.

    ``clusters`` (n,): the drone of each item (any hashable ids; None: every item
    resampled on its own). Then the resample is two-stage, within each stratum
    (``strata`` (n,), the true class: a drone is one class; None: one stratum): every
    drone slot of the stratum is filled by a drone drawn with replacement, and the
    slot's number of items is drawn with replacement from that drone's items. The
    class counts and the number of items stay as in the set; when a drone's items are
    alike, the interval reflects how few drones there are (the drone-level spread),
    not how many acquisitions."""
    n, n_boot = int(n), int(n_boot)
    rng = seeded_rng(random_state)
    if clusters is None:
        return rng.integers(0, n, size=(n_boot, n))
    clusters = np.asarray(clusters).astype(str)
    strata = np.zeros(n, dtype=int) if strata is None else np.asarray(strata)
    if clusters.shape != (n,) or strata.shape != (n,):
        raise ValueError(f"clusters and strata must have one entry per item ({n}), got {clusters.shape}, "
                         f"{strata.shape}")
    out = np.empty((n_boot, n), dtype=np.int64)
    for stratum in np.unique(strata):
        rows = np.flatnonzero(strata == stratum)
        ids, inverse = np.unique(clusters[rows], return_inverse=True)
        members = [rows[inverse == k] for k in range(ids.size)]  # each drone's items, in order
        flat = np.concatenate(members)
        start = np.cumsum([0] + [m.size for m in members[:-1]])
        size = np.array([m.size for m in members])
        for slot in members:  # the slot's positions in the resample take items of a drawn drone
            drone = rng.integers(0, ids.size, size=n_boot)
            pos = (rng.random((n_boot, slot.size)) * size[drone][:, None]).astype(np.int64)
            out[:, slot] = flat[start[drone][:, None] + np.minimum(pos, size[drone][:, None] - 1)]
    return out


def bootstrap_method(clusters, strata=None) -> str:
    """What the resamples of :func:`resample_indices` resample, in words."""
    if clusters is None:
        return "percentile bootstrap over the test items"
    pairs = np.asarray(clusters).astype(str) if strata is None else \
        np.char.add(np.char.add(np.asarray(strata).astype(str), "/"), np.asarray(clusters).astype(str))
    return (f"percentile bootstrap over the {np.unique(pairs).size} drones (clusters) and then the acquisitions "
            "within them, per class")


def seed_uniforms(n_boot: int, n_runs: int, random_state=0) -> np.ndarray:
    """(n_boot, n_runs) uniforms in [0, 1) that pick training runs in every resample
    (``floor(u * S)`` for a result of S runs): results with as many runs get the same picks."""
    return seeded_rng(random_state).random((int(n_boot), max(int(n_runs), 1)))


def _point(cm: np.ndarray, labels) -> dict:
    acc, bal, prec, rec = _rates(cm[None])
    support = cm.sum(axis=1)
    return {"accuracy": float(acc[0]), "balanced_accuracy": float(bal[0]),
            "recall": {lab: (float(rec[0, i]) if support[i] else None) for i, lab in enumerate(labels)},
            "precision": {lab: (None if np.isnan(prec[0, i]) else float(prec[0, i])) for i, lab in enumerate(labels)}}


def evaluate_runs(y_true, y_preds, labels=None, n_boot: int = 1000, resamples=None, uniforms=None,
                  random_state=0, seeds=None, clusters=None) -> dict:
    """Metrics of S training runs (seeds) of one classifier on one test set.

    ``y_preds`` (S, N): each run's predictions of the N test items ``y_true``. Every
    figure is the mean over the runs (``runs`` holds each run's own); the confusion
    matrix is summed over the runs (S x N predictions). The 95% interval covers both
    the test sample and the training randomness: each of ``n_boot`` bootstrap
    resamples of the test items (``resamples``, (n_boot, N), e.g. from
    :func:`resample_indices`; drawn from ``random_state`` when None) is scored with one
    run picked at random (``uniforms``, from :func:`seed_uniforms`): the percentile
    interval of that mixture is where one training run scores on a test sample of
    this size, so it holds every run's own score (each run is 1/S of the mixture).
    With S = 1 it is the ordinary percentile bootstrap. Same ``resamples`` and
    ``uniforms`` for several classifiers: paired intervals. ``clusters`` (N,): the drone
    of each test item: the resamples drawn here are two-stage (drones, then their
    acquisitions: :func:`resample_indices`), and ``ci["method"]`` says so (give it with
    ``resamples`` drawn that way).

    Returns :func:`evaluate`'s layout plus ``runs`` (per run: accuracy, balanced
    accuracy, recall and precision per class), ``per_class[c]["precision_runs"]`` (the
    runs that predict c at all: the precision is their mean, None when there are
    none), ``n_runs``, ``seeds`` and
    ``seed_spread`` ({balanced_accuracy: [min, max], sd}); ``ci`` also says
    ``method``.
    """
    y_preds = np.asarray(y_preds)
    if y_preds.ndim == 1:
        y_preds = y_preds[None]
    t, _, labels = _encode(y_true, y_preds[0], labels)
    p = np.stack([_encode(y_true, row, labels)[1] for row in y_preds])
    s, n, k = p.shape[0], t.size, len(labels)
    cms = np.stack([_confusions(t, row, k, np.arange(n)[None, :])[0] for row in p])  # (S, k, k)
    runs = [_point(cm, labels) for cm in cms]
    if seeds is not None:
        for r, sd in zip(runs, seeds):
            r["seed"] = int(sd)
    support = cms[0].sum(axis=1)

    def mean(values):
        v = [x for x in values if x is not None]
        return float(np.mean(v)) if v else None

    bal = np.array([r["balanced_accuracy"] for r in runs])
    per_class = {}
    for i, lab in enumerate(labels):
        precisions = [r["precision"][lab] for r in runs]
        per_class[lab] = {"precision": mean(precisions),  # over the runs that predict the class (None: none)
                          "precision_runs": sum(v is not None for v in precisions),
                          "recall": mean([r["recall"][lab] for r in runs]) if support[i] else None,
                          "n": int(support[i])}
    out = {"accuracy": float(np.mean([r["accuracy"] for r in runs])), "balanced_accuracy": float(bal.mean()),
           "confusion_matrix": cms.sum(axis=0).tolist(), "labels": labels, "n": int(n), "n_runs": int(s),
           "seeds": None if seeds is None else [int(x) for x in seeds], "per_class": per_class, "runs": runs,
           "seed_spread": {"balanced_accuracy": [float(bal.min()), float(bal.max())],
                           "sd": float(bal.std(ddof=1)) if s > 1 else 0.0},
           "ci": {}}
    if not n_boot:
        return out
    if resamples is None:
        resamples = resample_indices(n, n_boot, random_state, clusters, None if clusters is None else t)
    resamples = np.asarray(resamples)
    if resamples.ndim != 2 or resamples.shape[1] != n:
        raise ValueError(f"resamples must be (n_boot, {n}) indices, got shape {resamples.shape}")
    if uniforms is None:
        uniforms = seed_uniforms(len(resamples), s, random_state)
    pick = np.minimum((np.asarray(uniforms)[: len(resamples), 0] * s).astype(int), s - 1)
    acc_b, bal_b, prec_b, rec_b = [], [], [], []
    for lo in range(0, len(resamples), 500):  # bounded memory
        idx, who = resamples[lo:lo + 500], pick[lo:lo + 500]
        b = idx.shape[0]
        code = (np.arange(b)[:, None] * k * k + t[idx] * k + p[who[:, None], idx]).ravel()
        a, bb, pr, rc = _rates(np.bincount(code, minlength=b * k * k).reshape(b, k, k))
        acc_b.append(a), bal_b.append(bb), prec_b.append(pr), rec_b.append(rc)
    pr, rc = np.concatenate(prec_b), np.concatenate(rec_b)
    out["ci"] = {"level": LEVEL, "n_boot": int(len(resamples)),
                 "method": f"{bootstrap_method(clusters, t)}, one training run picked at random per resample "
                           f"({s} run(s))",
                 "accuracy": _interval(np.concatenate(acc_b)),
                 "balanced_accuracy": _interval(np.concatenate(bal_b)),
                 "per_class": {lab: {"precision": _interval(pr[:, i]), "recall": _interval(rc[:, i])}
                               for i, lab in enumerate(labels)}}
    return out


def run_scores(y_true, y_preds, labels, resamples: np.ndarray) -> np.ndarray:
    """Balanced accuracy (S, n_boot) of each run on each resample of the test items."""
    y_preds = np.asarray(y_preds)
    t, _, labels = _encode(y_true, y_preds[0], labels)
    k = len(labels)
    return np.stack([_rates(_confusions(t, _encode(y_true, row, labels)[1], k, resamples))[1] for row in y_preds])


def paired_difference(point_a, point_b, scores_a: np.ndarray, scores_b: np.ndarray, uniforms: np.ndarray) -> dict:
    """Mean-over-runs balanced accuracy of A minus B and its 95% interval, paired.

    point_a, point_b: each run's balanced accuracy on the whole test set; scores_a (S_a, n_boot), scores_b (S_b, n_boot): each run's balanced accuracy on the
    same resamples of one test set (:func:`run_scores`). In each resample the runs of
    each classifier are themselves resampled with replacement (``uniforms``
    (n_boot, >= max S): the same picks for classifiers with as many runs) and averaged:
    the interval covers the test sample and the training runs of both."""
    def boot_mean(sc):
        s = sc.shape[0]
        pick = np.minimum((uniforms[:, :s] * s).astype(int), s - 1)  # (B, S)
        return np.take_along_axis(sc.T, pick, axis=1).mean(axis=1)

    uniforms = np.asarray(uniforms)
    d = boot_mean(np.asarray(scores_a)) - boot_mean(np.asarray(scores_b))
    return {"difference": float(np.mean(point_a) - np.mean(point_b)), "ci": _interval(d)}


def degenerate(m: dict, classes=None) -> dict:
    """The degenerate rule on metrics of :func:`evaluate` or :func:`evaluate_runs`:
    ``degenerate`` when a class of ``classes`` (default: the labels) is recognised by
    no training run (recall 0 in every run); ``zero_recall`` those classes,
    ``never_predicted`` the classes no run predicts, ``degenerate_runs`` {class: runs
    with recall 0} for the classes only some runs miss, ``n_runs``."""
    labels = list(m["labels"])
    classes = labels if classes is None else list(classes)
    cm = np.asarray(m["confusion_matrix"])
    never = [labels[j] for j in range(len(labels)) if cm[:, j].sum() == 0]
    zero = [c for c in classes if (m["per_class"].get(c) or {}).get("recall") == 0.0]
    runs = m.get("runs") or []
    partly = {c: sum(1 for r in runs if (r["recall"] or {}).get(c) == 0.0) for c in classes if c not in zero}
    return {"degenerate": bool(zero), "zero_recall": zero, "never_predicted": never,
            "degenerate_runs": {c: k for c, k in partly.items() if k}, "n_runs": len(runs) or 1}


def degenerate_words(v: dict) -> list[str]:
    """:func:`degenerate`'s verdict in words: ['degenerate: recognises no HELI (never
    predicts HELI)'] and/or ['recognises no QUAD in 1 of 3 runs']; [] when none."""
    parts = []
    if v["degenerate"]:
        never = [c for c in v["never_predicted"] if c in v["zero_recall"]]
        parts.append(f"degenerate: recognises no {', '.join(v['zero_recall'])}"
                     + (f" (never predicts {', '.join(never)})" if never else ""))
    parts += [f"recognises no {c} in {k} of {v['n_runs']} runs" for c, k in v.get("degenerate_runs", {}).items()]
    return parts


def format_metrics(m: dict) -> str:
    """A short human-readable report of :func:`evaluate`'s dict."""
    ci = m.get("ci") or {}

    def fmt(v, interval):
        if v is None:
            return "  n/a"
        s = f"{v:6.1%}"
        return s + (f" [{interval[0]:.1%}, {interval[1]:.1%}]" if interval else "")

    words = degenerate_words(degenerate(m))
    # a degenerate model's balanced accuracy (often 50.0% [50.0%, 50.0%]) is not a score: say so on its line
    flag = f"  ({words[0]}: not a score)" if words and words[0].startswith("degenerate") else ""
    lines = [f"n = {m['n']}",
             f"accuracy          {fmt(m['accuracy'], ci.get('accuracy'))}",
             f"balanced accuracy {fmt(m['balanced_accuracy'], ci.get('balanced_accuracy'))}{flag}",
             "per class (recall = the paper's per-class 'precision'):"]
    predicted = np.asarray(m["confusion_matrix"]).sum(axis=0)  # per column: how often each class was predicted
    undefined = False
    for j, (lab, pc) in enumerate(m["per_class"].items()):
        cc = ci.get("per_class", {}).get(lab, {})
        never = pc.get("precision") is None or (m["labels"][j] == lab and predicted[j] == 0)
        undefined |= bool(never)
        precision = "     –" if never else fmt(pc["precision"], cc.get("precision"))
        lines.append(f"  {lab:>8s} n={pc['n']:<5d} recall {fmt(pc['recall'], cc.get('recall'))}"
                     f"  precision {precision}")
    width = max(len(lab) for lab in m["labels"])
    lines.append("confusion matrix (rows true, columns predicted):")
    lines.append(" " * (width + 2) + " ".join(f"{lab:>{max(width, 6)}s}" for lab in m["labels"]))
    for lab, row in zip(m["labels"], m["confusion_matrix"]):
        lines.append(f"  {lab:>{width}s} " + " ".join(f"{v:>{max(width, 6)}d}" for v in row))
    if undefined:
        lines.append("precision – = undefined: the class is never predicted")
    if words:
        lines.append("verdict: " + "; ".join(words))
    if ci:
        lines.append(f"[..] = {ci['level']:.0%} intervals: {ci.get('method', 'percentile bootstrap')} "
                     f"({ci['n_boot']} resamples)")
    return "\n".join(lines)


def plot_confusion(m: dict, title: str = ""):
    """A matplotlib figure of the confusion matrix (counts and row shares)."""
    import matplotlib.pyplot as plt

    cm = np.asarray(m["confusion_matrix"], dtype=float)
    share = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
    k = len(m["labels"])
    fig, ax = plt.subplots(figsize=(1.6 * k + 2, 1.4 * k + 1.6))
    ax.imshow(share, vmin=0, vmax=1, cmap="Blues")
    for i in range(k):
        for j in range(k):
            ax.text(j, i, f"{int(cm[i, j])}\n{share[i, j]:.0%}", ha="center", va="center",
                    color="white" if share[i, j] > 0.6 else "black")
    ax.set_xticks(range(k), m["labels"])
    ax.set_yticks(range(k), m["labels"])
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title(title or f"accuracy {m['accuracy']:.1%}, balanced {m['balanced_accuracy']:.1%}")
    fig.tight_layout()
    return fig
