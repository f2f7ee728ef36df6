"""The published sigma_P protocol: train the fast classifiers on synthetic sets over a
grid of sigma_P and test each on measured sets (the paper's Table IV and Fig. 13).

The caller supplies ``make_train(sigma_p, seed) -> (X, y)`` (the CLI and the study
build it with :mod:`mdaug.generator`; this module only sees arrays). One job per
sigma_P builds the training set once and trains every model on it. Seeds: job i
gets ``SeedSequence(random_state).spawn``-style child i for its training set and its
models, so results do not depend on the executor or the order jobs finish.

Training size (the CLI default, ``--n-per-class 4000``, i.e. 8,000 profiles per
sigma_P, against the paper's 32,000): measured on one thread here
(tests/benchmarks/classify.py), going from 8,000 to 32,000 synthetic training
profiles moves held-out synthetic accuracy by <= 2 points (LinearSVC 0.854 -> 0.875,
XGBoost 0.976 -> 0.985), far inside the +-7-8 point 95% interval of a 136-profile
measured test set, while the RBF SVC's fit grows super-linearly (3.8 s at 8,000,
16.6 s at 16,000, ~1 min at 32,000). The default sweep (10 sigma_P x svm, nb, xgb)
takes ~1 min at 8,000; the published size needs ``--n-per-class 16000`` (with
``--kernel linear`` to stay within minutes).

With ``cache_dir`` each finished job's rows are written there (JSON, atomically) and
reused on a rerun with the same settings: an interrupted sweep resumes.
"""
from __future__ import annotations

import csv
import io
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..radar.keys import cache_key
from ..radar.seeds import child_seed
from .metrics import evaluate
from .models import make_classifier

PUBLISHED_SIGMA_PS = (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.40, 0.50, 0.60)
"""The published sigma_P grid (the toolkit's one copy)."""
FAST_MODELS = ("svm", "nb", "xgb")
METRICS = ("accuracy", "balanced_accuracy", "min_recall")
TIE = 0.01
"""Scores within this of the best are tied (the study's choices: mean balanced accuracy)."""
PREFER = {"sigma_p": "smaller", "width": "larger"}
"""Which tied setting wins: the smaller sigma_P (the published rule), the larger
specimen width (the selection set holds only the calibrated drone, which cannot tell
how much new drones differ: among equals, assume more variation)."""


def ties(scores: dict, tie: float = TIE) -> list:
    """The keys whose score is within ``tie`` of the best (and 1e-12 of float noise),
    best first (then in the given order); [] when there are no scores."""
    if not scores:
        return []
    top = max(scores.values())
    return sorted((n for n, s in scores.items() if s >= top - tie - 1e-12), key=lambda n: -scores[n])


def choose(scores: dict, prefer: str = "smaller", tie: float = TIE) -> tuple:
    """(value, tied): the one choice rule of a setting. THE TIE RULE: the values whose
    score is within ``tie`` of the best are tied (:func:`ties`), and the tie goes to the
    smallest of them (``prefer="smaller"``) or the largest (``"larger"``). The study
    chooses on the mean over the fast classifiers with ``tie`` = :data:`TIE`; the
    sweep's per-classifier pick (:meth:`SweepResult.best`) with ``tie`` = 0 (exact
    ties to the smaller sigma_P, as published)."""
    tied = sorted(ties(scores, tie))
    return (min(tied) if prefer == "smaller" else max(tied)), tied



@dataclass
class SweepJob:
    """One sigma_P point (or one value of another setting: the study's candidates):
    everything a worker needs (picklable when make_train is). ``boot_seed``: the
    bootstrap's seed (None: ``child_seed(train_seed, 7)``). ``test_sets``: {name: (X, y)
    or (X, y, drone of each item)}: with drones, the intervals resample drones first."""

    index: int
    sigma_p: float
    train_seed: int
    model_seeds: dict
    make_train: object
    test_sets: dict
    models: tuple
    model_params: dict
    n_boot: int
    boot_seed: int | None = None


def run_sweep_job(job: SweepJob, on_cell=None) -> list[dict]:
    """Build the sigma_P training set, train each model, score it on each test set.
    ``on_cell()`` is called after each model (one cell of the sweep's table)."""
    x, y = job.make_train(job.sigma_p, job.train_seed)
    rows = []
    for name in job.models:
        model = make_classifier(name, random_state=job.model_seeds[name], **job.model_params.get(name, {}))
        model.fit(x, y)
        for test_name, (xt, yt, *drones) in job.test_sets.items():  # (X, y) or (X, y, drone of each item)
            yt = model.check_labels(yt, source=f"test set {test_name}")
            model.check_input(xt, source=f"test set {test_name}")
            m = evaluate(yt, model.predict(xt), labels=model.classes_.tolist(), n_boot=job.n_boot,
                         random_state=child_seed(job.train_seed, 7) if job.boot_seed is None else job.boot_seed,
                         clusters=drones[0] if drones and drones[0] is not None else None)
            recalls = {lab: pc["recall"] for lab, pc in m["per_class"].items() if pc["recall"] is not None}
            ci = m["ci"] or {}
            row = {"sigma_p": job.sigma_p, "model": name, "test_set": test_name,
                   "accuracy": m["accuracy"], "balanced_accuracy": m["balanced_accuracy"],
                   "min_recall": min(recalls.values()),
                   "accuracy_lo": (ci.get("accuracy") or [None])[0],
                   "accuracy_hi": (ci.get("accuracy") or [None, None])[1],
                   "balanced_lo": (ci.get("balanced_accuracy") or [None])[0],
                   "balanced_hi": (ci.get("balanced_accuracy") or [None, None])[1],
                   "train_seconds": model.train_seconds_, "n_train": int(len(y)), "n_test": m["n"]}
            row.update({f"recall_{lab}": r for lab, r in recalls.items()})
            rows.append(row)
        if on_cell is not None:
            on_cell()
    return rows


def row_ci(row: dict, metric: str = "balanced") -> list | None:
    """A row's 95% interval of ``metric`` ("balanced" or "accuracy") as [lo, hi], or None."""
    lo, hi = row.get(f"{metric}_lo"), row.get(f"{metric}_hi")
    return None if lo is None else [lo, hi]


def _job_key(job: SweepJob) -> str:
    tests = {k: [np.asarray(v[0]).shape, cache_key(arrays=[v[0]], algorithm="sha1", length=None),
                 *(cache_key(text="|".join(np.asarray(a).astype(str).tolist()), algorithm="sha1", length=None)
                   for a in v[1:] if a is not None)]  # the labels (and the drones, when given)
             for k, v in job.test_sets.items()}
    desc = {"sigma_p": job.sigma_p, "seed": job.train_seed, "models": list(job.models),
            "params": job.model_params, "tests": tests, "n_boot": job.n_boot,
            "make_train": getattr(job.make_train, "cache_key", repr(job.make_train))}
    return cache_key(desc, algorithm="sha1")


@dataclass
class _CachedJob:
    job: SweepJob
    path: Path
    key: str


def _run_cached(c: _CachedJob, on_cell=None) -> list[dict]:
    from ..radar import atomic_write

    rows = run_sweep_job(c.job, on_cell)
    payload = json.dumps({"key": c.key, "rows": rows}).encode()
    atomic_write(c.path, lambda fh: fh.write(payload))
    return rows


@dataclass
class SweepResult:
    """Tidy table of a sweep: one row per (sigma_p, model, test set)."""

    rows: list[dict]
    settings: dict = field(default_factory=dict)

    COLUMNS = ("sigma_p", "model", "test_set", "accuracy", "balanced_accuracy", "min_recall",
               "accuracy_lo", "accuracy_hi", "balanced_lo", "balanced_hi", "train_seconds", "n_train", "n_test")

    @property
    def columns(self) -> list[str]:
        extra = sorted({k for r in self.rows for k in r} - set(self.COLUMNS))
        return list(self.COLUMNS) + extra

    @property
    def models(self) -> list[str]:
        return list(dict.fromkeys(r["model"] for r in self.rows))

    @property
    def test_sets(self) -> list[str]:
        return list(dict.fromkeys(r["test_set"] for r in self.rows))

    @property
    def sigma_ps(self) -> list[float]:
        return sorted({r["sigma_p"] for r in self.rows})

    def column(self, name: str, model: str, test_set: str) -> np.ndarray:
        """``name`` per sigma_P (sorted) for one model and test set."""
        sel = sorted((r for r in self.rows if r["model"] == model and r["test_set"] == test_set),
                     key=lambda r: r["sigma_p"])
        return np.array([np.nan if r.get(name) is None else r[name] for r in sel], dtype=float)

    def best(self, model: str, test_set: str, metric: str = "accuracy") -> dict:
        """The row with the highest ``metric`` (:func:`choose` with tie 0: exact ties to
        the smaller sigma_P)."""
        sel = [r for r in self.rows if r["model"] == model and r["test_set"] == test_set]
        if not sel:
            raise ValueError(f"no rows for model {model!r} and test set {test_set!r} "
                             f"(models {self.models}, test sets {self.test_sets})")
        if metric not in sel[0]:
            raise ValueError(f"unknown metric {metric!r}; columns: {self.columns}")
        by_value = {r["sigma_p"]: r for r in reversed(sel)}  # a repeated sigma_P: its first row
        value, _ = choose({v: r[metric] for v, r in by_value.items()}, PREFER["sigma_p"], tie=0.0)
        return by_value[value]

    def to_csv(self, path) -> Path:
        from ..radar import atomic_write

        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=self.columns, lineterminator="\n")
        writer.writeheader()
        for r in self.rows:
            writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in self.columns})
        return atomic_write(path, lambda fh: fh.write(buf.getvalue().encode()))

    def to_markdown(self, metric: str = "accuracy") -> str:
        """Table IV layout: rows sigma_P, columns classifier x test set (``metric`` in %),
        then the per-class worst recall, then the best sigma_P of each pair."""
        pairs = [(m, t) for m in self.models for t in self.test_sets]
        out = []
        for name, title in ((metric, metric.replace("_", " ")), ("min_recall", "worst per-class recall")):
            out.append(f"**{title}** (%)\n")
            out.append("| sigma_P | " + " | ".join(f"{m.upper()} {t}" for m, t in pairs) + " |")
            out.append("|---" * (len(pairs) + 1) + "|")
            cols = [self.column(name, m, t) for m, t in pairs]
            for i, s in enumerate(self.sigma_ps):
                out.append(f"| {s:.2f} | " + " | ".join(f"{100 * c[i]:.1f}" for c in cols) + " |")
            out.append("")
        out.append(f"**best sigma_P by {metric}, picked on each test set itself** (the published way: this peeks "
                   "at the test set, so these scores are optimistic; an honest choice is made on a selection set "
                   "disjoint from every test set, as `mdaug run` does)\n")
        out.append(f"| model | test set | sigma_P | {metric} | 95% CI | balanced | worst recall |")
        out.append("|---|---|---|---|---|---|---|")
        for m, t in pairs:
            b = self.best(m, t, metric)
            ci = (f"[{100 * b['accuracy_lo']:.1f}, {100 * b['accuracy_hi']:.1f}]"
                  if b.get("accuracy_lo") is not None else "-")
            out.append(f"| {m} | {t} | {b['sigma_p']:.2f} | {100 * b[metric]:.1f} | {ci} | "
                       f"{100 * b['balanced_accuracy']:.1f} | {100 * b['min_recall']:.1f} |")
        return "\n".join(out) + "\n"

    def figure(self, metric: str = "accuracy"):
        """Accuracy vs sigma_P per classifier, one panel per test set (paper Fig. 13),
        with the bootstrap 95% band (accuracy) and balanced accuracy dashed."""
        import matplotlib.pyplot as plt

        tests = self.test_sets
        fig, axes = plt.subplots(1, len(tests), figsize=(4.2 * len(tests), 3.6), sharey=True, squeeze=False)
        s = np.array(self.sigma_ps)
        for ax, t in zip(axes[0], tests):
            for k, m in enumerate(self.models):
                color = f"C{k}"
                ax.plot(s, self.column(metric, m, t), "o-", color=color, label=m.upper())
                if metric == "accuracy":
                    lo, hi = self.column("accuracy_lo", m, t), self.column("accuracy_hi", m, t)
                    if np.all(np.isfinite(lo)):
                        ax.fill_between(s, lo, hi, color=color, alpha=0.12, lw=0)
                    ax.plot(s, self.column("balanced_accuracy", m, t), "--", color=color, lw=1)
            ax.axhline(0.5, color="grey", lw=0.6, ls=":")
            ax.set_title(f"test: {t}")
            ax.set_xlabel("sigma_P")
            ax.set_ylim(0, 1.02)
            ax.grid(alpha=0.3)
        axes[0][0].set_ylabel(f"{metric.replace('_', ' ')} (dashed: balanced; band: 95% CI)")
        axes[0][-1].legend(loc="lower right", fontsize=8)
        fig.tight_layout()
        return fig

    def plot(self, path, metric: str = "accuracy") -> Path:
        from ..radar.plots import save_figure

        return save_figure(self.figure(metric), path, dpi=120)


def sigma_p_sweep(make_train, test_sets: dict, sigma_ps=PUBLISHED_SIGMA_PS, models=FAST_MODELS,
                  random_state=0, executor=None, model_params: dict | None = None, n_boot: int = 1000,
                  cache_dir=None, progress: bool | None = None) -> SweepResult:
    """Run the published protocol.

    make_train(sigma_p, seed) -> (X (N, L), y (N,)); test_sets {name: (X (M, L), y (M,))};
    models from ("svm", "nb", "xgb", "cnn"); model_params {model: {param: value}};
    executor: any object with ``map(fn, iterable)`` (concurrent.futures style) or None
    (serial); a process pool needs a picklable ``make_train`` (a top-level function,
    or an instance of a top-level class such as the CLI's ``SyntheticTrainSet``).
    cache_dir: folder for per-sigma_P results (resume); a cached job is reused only
    when its settings match, and ``make_train`` is identified by its ``cache_key``
    attribute (else its repr, which for a plain function changes between runs).
    progress: a bar of the sweep's cells (sigma_P x model) with an ETA; None shows it
    on a terminal (see :mod:`mdaug.radar.progress`).
    """
    from ..radar.progress import progress_bar

    sigma_ps = [float(s) for s in sigma_ps]
    bad = [s for s in sigma_ps if not 0.0 <= s <= 1.0]
    if bad or not sigma_ps:
        raise ValueError(f"sigma_p values must be in [0, 1], got {sigma_ps}")
    models = tuple(models)
    for m in models:
        make_classifier(m)  # fail early on an unknown name
    if not test_sets:
        raise ValueError("at least one test set is needed")
    model_params = model_params or {}
    jobs = [SweepJob(index=i, sigma_p=s, train_seed=child_seed(random_state, i),
                     model_seeds={m: child_seed(random_state, i, j + 1) for j, m in enumerate(models)},
                     make_train=make_train, test_sets=dict(test_sets), models=models,
                     model_params=model_params, n_boot=n_boot)
            for i, s in enumerate(sigma_ps)]
    results: list[list[dict] | None] = [None] * len(jobs)
    if cache_dir is not None:
        Path(cache_dir).mkdir(parents=True, exist_ok=True)
    todo = []
    for job in jobs:
        if cache_dir is None:
            todo.append((job.index, job))
            continue
        key = _job_key(job)
        path = Path(cache_dir) / f"sigma_{job.sigma_p:.4f}_{job.index}.json"
        if path.is_file():
            try:
                cached = json.loads(path.read_text())
                if cached.get("key") == key:
                    results[job.index] = cached["rows"]
                    continue
            except (json.JSONDecodeError, OSError):
                pass  # unreadable cache: recompute
        todo.append((job.index, _CachedJob(job, path, key)))
    fn = run_sweep_job if cache_dir is None else _run_cached
    t0 = time.perf_counter()
    bar = progress_bar(total=len(todo) * len(models), desc="sigma_P sweep cells", unit="cell", progress=progress)
    with bar:
        if executor is None or getattr(executor, "name", None) == "serial":  # one tick per trained model
            for i, job in todo:
                results[i] = fn(job, lambda: bar.update(1))
        else:  # workers: one tick per model as each sigma_P job comes back
            for (i, _), rows in zip(todo, executor.map(fn, [j for _, j in todo])):
                results[i] = rows
                bar.update(len(models))
    settings = {"sigma_ps": sigma_ps, "models": list(models), "random_state": random_state,
                "test_sets": {k: int(len(v[1])) for k, v in test_sets.items()}, "model_params": model_params,
                "n_boot": n_boot, "seconds": time.perf_counter() - t0, "resumed_jobs": len(jobs) - len(todo)}
    return SweepResult([r for rows in results for r in rows], settings)
