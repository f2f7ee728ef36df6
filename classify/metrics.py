"""Honest classification metrics: confusion matrix, accuracy, balanced accuracy,
per-class precision and recall, each with a bootstrap 95% interval.

The published per-class "precision" is the share of each true class classified
correctly, i.e. per-class *recall*; both are reported. Test sets of ~136 profiles
are small, so every figure carries a percentile bootstrap interval (test profiles
resampled with replacement, ``n_boot`` times, from ``random_state``).

Conventions (as scikit-learn with ``zero_division=0``): a class never predicted has
precision 0; balanced accuracy is the mean recall over the classes present in
``y_true``. In a bootstrap resample where a class is absent (recall undefined) or
never predicted (precision undefined) that resample is left out of the interval.
"""
from __future__ import annotations

import numpy as np

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


def evaluate(y_true, y_pred, labels=None, n_boot: int = 1000, random_state=0) -> dict:
    """Metrics of predictions ``y_pred`` (N,) against ``y_true`` (N,).

    Returns a JSON-serialisable dict: ``accuracy``, ``balanced_accuracy``,
    ``confusion_matrix`` (rows true, columns predicted, in ``labels`` order),
    ``labels``, ``n``, ``per_class`` {label: {precision, recall, n}} (recall is the
    paper's per-class "precision"; ``n`` the true-class count) and ``ci``:
    {accuracy: [lo, hi], balanced_accuracy: [lo, hi], per_class: {label:
    {precision: [lo, hi] | None, recall: [lo, hi] | None}}}, 95% percentile
    bootstrap intervals; ``n_boot`` = 0 skips them (``ci`` = {}).
    """
    t, p, labels = _encode(y_true, y_pred, labels)
    k = len(labels)
    cm = _confusions(t, p, k, np.arange(t.size)[None, :])
    acc, bal, prec, rec = _rates(cm)
    support = cm[0].sum(axis=1)
    per_class = {lab: {"precision": float(np.nan_to_num(prec[0, i], nan=0.0)),
                       "recall": float(np.nan_to_num(rec[0, i], nan=0.0)) if support[i] else None,
                       "n": int(support[i])}
                 for i, lab in enumerate(labels)}
    out = {"accuracy": float(acc[0]), "balanced_accuracy": float(bal[0]),
           "confusion_matrix": cm[0].tolist(), "labels": labels, "n": int(t.size),
           "per_class": per_class, "ci": {}}
    if n_boot:
        rng = np.random.default_rng(random_state)
        ci_acc, ci_bal = [], []
        ci_prec, ci_rec = [], []
        for lo in range(0, n_boot, 500):  # bounded memory: (500, n) indices at a time
            idx = rng.integers(0, t.size, size=(min(500, n_boot - lo), t.size))
            a, b, pr, rc = _rates(_confusions(t, p, k, idx))
            ci_acc.append(a), ci_bal.append(b), ci_prec.append(pr), ci_rec.append(rc)
        pr, rc = np.concatenate(ci_prec), np.concatenate(ci_rec)
        out["ci"] = {"level": LEVEL, "n_boot": int(n_boot),
                     "accuracy": _interval(np.concatenate(ci_acc)),
                     "balanced_accuracy": _interval(np.concatenate(ci_bal)),
                     "per_class": {lab: {"precision": _interval(pr[:, i]), "recall": _interval(rc[:, i])}
                                   for i, lab in enumerate(labels)}}
    return out


def format_metrics(m: dict) -> str:
    """A short human-readable report of :func:`evaluate`'s dict."""
    ci = m.get("ci") or {}

    def fmt(v, interval):
        if v is None:
            return "  n/a"
        s = f"{v:6.1%}"
        return s + (f" [{interval[0]:.1%}, {interval[1]:.1%}]" if interval else "")

    lines = [f"n = {m['n']}",
             f"accuracy          {fmt(m['accuracy'], ci.get('accuracy'))}",
             f"balanced accuracy {fmt(m['balanced_accuracy'], ci.get('balanced_accuracy'))}",
             "per class (recall = the paper's per-class 'precision'):"]
    predicted = np.asarray(m["confusion_matrix"]).sum(axis=0)  # per column: how often each class was predicted
    undefined = False
    for j, (lab, pc) in enumerate(m["per_class"].items()):
        cc = ci.get("per_class", {}).get(lab, {})
        never = m["labels"][j] == lab and predicted[j] == 0
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
    if ci:
        lines.append(f"[..] = {ci['level']:.0%} bootstrap intervals ({ci['n_boot']} resamples)")
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
