"""How sharp must a calibration be for its synthetic training set to classify new drones?

python tests/benchmarks/calibration_gap.py STUDY_DIR [--n 1000] [--shrink 1,0.5,0.3] [--models xgb,svm] \
    [--smc QUAD=FILE] [--jitter 0.1]

STUDY_DIR: a finished simulated study (``mdaug run --out STUDY_DIR``). Its drones are
drawn around the packaged class references, so the reference is what a perfect
calibration of its calibration drone would find, up to the specimen spread. For each
source of class vectors, a training set of N profiles per class is rendered through
the scene and the chain under each class's measured acquisition, the fast classifiers
are trained on it and scored (balanced accuracy, per-class recall) on the study's
'select' and 'new_large' sets:

* ``reference``: the class reference drone only (what the whole method can reach);
* ``best fit``: the study's best fit only (the ``sigma_p_fit`` strategy's source at
  sigma_P = 0: the smc median of the summary likelihood where the estimator has one);
* ``posterior``: the study's posterior draws (the ``posterior`` strategy's source, each
  draw once here, where the strategy resamples them);
* ``posterior, kernel jitter J`` (with --jitter J): the draws resampled with a Gaussian
  jitter of J x each parameter's posterior sd (``PosteriorSource(jitter=J)``; 0.1 was the
  ``posterior`` strategy's default before this release);
* ``the smc route's draws`` (with --smc): the summary likelihood's posterior, where a class's
  posterior is the amortized one the draws kept beside it (``mdaug calibrate --check-route``
  of the same measurements): what the study would train on if that route were its posterior;
* ``posterior at the reference, x s``: the posterior's spread in the label-free
  coordinates u, scaled by s and moved onto the reference (an honest posterior of the
  same width, s = 1, or s times as sharp, centred on the truth).

The gap between the rows says whether the calibration loses the class by its centre or
by its width. 1 thread.
"""
from __future__ import annotations

import argparse
import json
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

CLASSES = ("HELI", "QUAD")
SMC_ROW = "the smc route's draws"


def label_free(ref):
    from mdaug.inference.amortized.target import LabelFree
    from mdaug.inference.space.priors import Priors
    from mdaug.radar import RadarConfig

    return LabelFree(ref.n_engines, Priors.from_reference(ref, RadarConfig()), ref.to_array())


def vector_sources(study: str, shrinks, smc_files: dict | None = None, jitter: float = 0.0, seed: int = 0) -> dict:
    """{row name: {class: vectors (n, 13E)}}; with smc_files ({class: posterior file kept
    with ``--check-route``}) the row of every class's smc draws; with jitter > 0 the row of
    the draws resampled with that kernel jitter."""
    from mdaug.generator import load_reference
    from mdaug.inference.result.augment import PosteriorSource, load_posterior

    rows = {"reference": {}, "best fit": {}, "posterior": {}}
    jitter_row = f"posterior, kernel jitter {jitter:g}"
    if jitter > 0:
        rows[jitter_row] = {}
    rng = np.random.default_rng(seed)
    if smc_files is not None:
        rows[SMC_ROW] = {}
    rows.update({f"posterior at the reference, x {s:g}": {} for s in shrinks})
    for cls in CLASSES:
        ref = load_reference(cls)
        lf = label_free(ref)
        post = load_posterior(os.path.join(study, "posteriors", f"{cls}.nc"), cls)
        x = np.concatenate([post.draws(measurement=m) for m in range(post.n_measurements)])
        rows["reference"][cls] = ref.to_array()[None]
        rows["best fit"][cls] = post.best_fit[None]
        rows["posterior"][cls] = x
        if jitter > 0:
            rows[jitter_row][cls] = PosteriorSource(post, label=cls, jitter=jitter).draw(len(x), rng)
        if smc_files is not None:
            rows[SMC_ROW][cls] = smc_draws(post, smc_files.get(cls), cls)
        u = lf.to_unbounded(lf.quantities(x))
        u = u[np.all(np.isfinite(u), axis=1)]
        u_ref = lf.to_unbounded(lf.quantities(ref.to_array()[None]))[0]
        for s in shrinks:
            moved, ok = lf.vectors(lf.from_unbounded(u_ref + s * (u - np.median(u, axis=0))))
            rows[f"posterior at the reference, x {s:g}"][cls] = moved[ok]
    return rows


def smc_draws(post, path: str | None, cls: str) -> np.ndarray:
    """The smc route's draws of a class: the study's posterior where its route is smc, else
    the ``other_route`` group of ``path`` (a calibration of the same measurements with
    ``--check-route``)."""
    from mdaug.inference.result.augment import load_posterior

    if post.diagnostics.get("route") == "smc":
        return post.route_draws("smc")
    if path is None:
        raise SystemExit(f"--smc: {cls}'s posterior is the {post.diagnostics.get('route')} route's; give "
                         f"{cls}=FILE, a calibration of its measurements with --check-route")
    try:
        return load_posterior(path, cls).route_draws("smc")
    except ValueError as e:
        raise SystemExit(f"{path}: {e} (calibrate with --check-route)") from None


def smc_file_map(text: str) -> dict:
    """{class: file} from 'CLASS=FILE,...' (--smc), each class one of CLASSES."""
    out = {}
    for kv in filter(None, text.split(",")):
        cls, sep, path = kv.partition("=")
        if not sep or cls not in CLASSES or not path:
            raise SystemExit(f"--smc: expected CLASS=FILE with CLASS one of {', '.join(CLASSES)}, got {kv!r}")
        out[cls] = path
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("study")
    p.add_argument("--n", type=int, default=1000, help="training profiles per class")
    p.add_argument("--shrink", default="1,0.5,0.3")
    p.add_argument("--models", default="xgb,svm")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--smc", nargs="?", const="", default=None, metavar="CLASS=FILE,...",
                   help="add the row of the smc route's draws (the posterior's where its route is smc, else "
                        "those kept beside it in FILE by `mdaug calibrate --check-route`)")
    p.add_argument("--jitter", type=float, default=0.0, metavar="J",
                   help="add the row of the draws resampled with a kernel jitter of J x each parameter's posterior sd")
    a = p.parse_args(argv)
    if not (np.isfinite(a.jitter) and a.jitter >= 0):
        p.error(f"--jitter: expected a number >= 0, got {a.jitter}")

    from sklearn.metrics import balanced_accuracy_score, recall_score

    from mdaug.classify.models import make_classifier
    from mdaug.generator import make_dataset
    from mdaug.generator.acquisition import Acquisition
    from mdaug.generator.augment import FixedSource, ModelAugmenter, Renderer

    results = json.load(open(os.path.join(a.study, "results.json")))
    if not results.get("simulated"):
        raise SystemExit(f"{a.study}: results.json field 'simulated' is not true; this benchmark needs a simulated "
                         "study (its drones are drawn around the class references)")

    tests = {name: np.load(os.path.join(a.study, "data", f"{name}.npz"), allow_pickle=False)
             for name in ("select", "new_large")}
    acq = {}
    for cls in CLASSES:
        with np.load(os.path.join(a.study, "data", f"calibration_{cls}.npz"), allow_pickle=False) as z:
            acq[cls] = Acquisition.from_dict(json.loads(str(z["acquisition"])))
    shrinks = [float(s) for s in a.shrink.split(",")]
    print(f"{a.study}: {a.n} training profiles per class through the scene and the chain; balanced accuracy "
          "[recall HELI, QUAD]")
    print(f"{'source of class vectors':36s} {'model':5s} {'select':>20s} {'new_large':>20s}")
    shuffle = np.random.default_rng(a.seed)
    smc_files = None if a.smc is None else smc_file_map(a.smc)
    for row, per_class in vector_sources(a.study, shrinks, smc_files, a.jitter, a.seed).items():  # each pool in random order, cycled
        augs = [ModelAugmenter(FixedSource(shuffle.permutation(per_class[c]), c),
                               Renderer(acq[c], "peak", through_chain=True)) for c in CLASSES]
        ds = make_dataset(augs, a.n, a.seed, progress=False)
        labels = np.asarray(ds.labels)
        y = np.asarray(CLASSES)[labels] if np.issubdtype(labels.dtype, np.integer) else labels
        for model in a.models.split(","):
            clf = make_classifier(model, random_state=a.seed).fit(ds.profiles, y)
            cells = []
            for t in tests.values():
                pred = clf.predict(t["profiles"])
                rec = recall_score(t["labels"], pred, average=None, labels=list(CLASSES))
                cells.append(f"{balanced_accuracy_score(t['labels'], pred):.3f} [{rec[0]:.2f} {rec[1]:.2f}]")
            print(f"{row:36s} {model:5s} {cells[0]:>20s} {cells[1]:>20s}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
