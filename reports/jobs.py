"""The study's independent jobs as picklable top-level functions.

Each job takes one dict (its settings and its own seed) and returns plain data, so
any executor (serial, processes, dask) gives the same results. A training-set
strategy is a small dict (``spec``) that :func:`augmenters` turns into one
augmenter per class; :func:`training_set` is the study's one way to build a set
(through :func:`mdaug.generator.make_dataset`, or tsaug's :func:`tsaug_set`).
"""
from __future__ import annotations

import time

import numpy as np

MIN_GROUPS = 5


def _threads(n: int = 1) -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)


def augmenters(spec: dict, classes) -> list:
    """One augmenter per class for a model-based strategy spec:

    ``strategy`` (sigma_p_published | sigma_p_fit | posterior | posterior_specimens),
    ``sigma_p``, ``width`` (specimen model), ``posteriors`` {class: NetCDF},
    ``acquisition`` (dict, for the model-based strategies other than the published
    one: None = each calibration's measured acquisition), ``through_chain``,
    ``normalisation``."""
    from ..generator import Acquisition, Renderer, SigmaPSource, SpecimenSource, SpecimenSpread
    from ..generator.augment import ModelAugmenter

    kind, norm = spec["strategy"], spec.get("normalisation", "peak")
    out = []
    for c in classes:
        if kind == "sigma_p_published":
            src = SigmaPSource(c, spec["sigma_p"], perturb_phases=True)
            acq = Acquisition()
        else:
            from ..inference.posterior_augment import PosteriorSource, load_posterior

            post = load_posterior(spec["posteriors"][c], c)
            acq = (post.measured_acquisition() if spec.get("acquisition") is None
                   else Acquisition.from_dict(spec["acquisition"]))
            if kind == "sigma_p_fit":
                src = SigmaPSource(post.best_fit, spec["sigma_p"], perturb_phases=False, label=c)
            elif kind in ("posterior", "posterior_specimens"):
                src = PosteriorSource(post, label=c)
                if kind == "posterior_specimens" and spec.get("width"):
                    src = SpecimenSource(src, SpecimenSpread(width=float(spec["width"])))
            else:
                raise ValueError(f"unknown training strategy {kind!r}")
        out.append(ModelAugmenter(src, Renderer(acq, norm, through_chain=bool(spec.get("through_chain")))))
    return out


def training_set(spec: dict, classes, n_per_class: int, seed):
    """(X, y, groups) for one strategy spec; groups (tsaug only) is each copy's source
    profile, so that the CNN's validation split never holds a copy of a profile it
    trains on; None for model-based sets."""
    if spec["strategy"] == "tsaug":
        from ..classify import tsaug_set

        X, y, sources = tsaug_set(np.asarray(spec["profiles"]), np.asarray(spec["labels"]), n_per_class, seed,
                                  normalisation=spec.get("normalisation", "peak"))
        per_class = [np.unique(sources[y == c]).size for c in np.unique(y)]
        # a grouped 80/10/10 split needs a few sources per class; with fewer, the
        # validation split holds copies of training profiles (documented in the report)
        return X, y, (sources if min(per_class) >= MIN_GROUPS else None)
    from ..generator import make_dataset

    ds = make_dataset(augmenters(spec, classes), n_per_class, seed, progress=False)
    return ds.profiles, ds.labels, None


def _evaluate_all(clf, tests: dict, classes, n_boot: int, seed) -> dict:
    from ..classify import evaluate

    out = {}
    for name, (Xt, yt) in tests.items():
        t0 = time.perf_counter()
        m = evaluate(np.asarray(yt), clf.predict(np.asarray(Xt)), labels=sorted(classes), n_boot=n_boot,
                     random_state=seed)
        m["predict_seconds"] = time.perf_counter() - t0
        out[name] = m
    return out


def calibrate_class(job: dict) -> dict:
    """One class calibrated from its measurements (``profiles``) under ``acquisition``:
    the posterior saved to ``out/posteriors/<cls>.nc``, its corner and trace plots to
    ``out/figures/``; returns the stage's summary (plain data)."""
    from pathlib import Path

    from ..inference import calibrate
    from ..inference.priors import engine_lines
    from .style import figure_style

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    cls, out, X = job["cls"], Path(job["out"]), job["profiles"]
    checkpoint = out / "posteriors" / f"{cls}.chain.h5"
    res = calibrate(X, cls, acquisition=job["acquisition"], settings=job["settings"], random_state=job["seed"],
                    backend_path=checkpoint)
    nc = out / "posteriors" / f"{cls}.nc"
    res.save(nc)
    for f in checkpoint.parent.glob(checkpoint.name + "*"):
        f.unlink()  # only needed to resume an interrupted run
    corner_png, trace_png = out / "figures" / f"corner_{cls}.png", out / "figures" / f"trace_{cls}.png"
    with figure_style():
        res.plot_corner(corner_png)
        res.plot_trace(trace_png)
    lines = res.lines()  # (n, E, 4, 2): frequency rad/s, amplitude m
    w_ref, _, _ = engine_lines(res.priors.centres)
    return {"posterior": str(nc), "corner": str(corner_png), "trace": str(trace_png),
            "converged": bool(res.converged), "diagnostics": res.diagnostics, "summary": res.summary(),
            "n_profiles": int(len(X)), "acquisition": res.acquisition.to_dict(),
            "measured_acquisition": res.measured_acquisition().to_dict(),
            "lines": {"frequency_q": np.quantile(lines[..., 0], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "amplitude_q": np.quantile(lines[..., 1], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "reference_frequency": np.sort(w_ref, axis=-1).tolist()},
            "seconds": time.perf_counter() - t0}


def fit_predict(job: dict) -> dict:
    """Train one classifier (``model``, ``seed``, ``params``) on (``X``, ``y``) and predict
    every set of ``tests``: {train_seconds, predictions (encoded)}."""
    from ..classify import make_classifier
    from .statistics import encode

    _threads(job.get("threads", 1))
    clf = make_classifier(job["model"], random_state=job["seed"], **job.get("params", {}))
    t0 = time.perf_counter()
    clf.fit(job["X"], job["y"])
    seconds = time.perf_counter() - t0
    return {"train_seconds": seconds, "predictions": {n: encode(clf.predict(np.asarray(Xt)), job["classes"])
                                                       for n, (Xt, _) in job["tests"].items()}}


def candidate(job: dict) -> dict:
    """One choice candidate (a strategy at one sigma_P or width): its training set, the
    fast classifiers trained on it and scored on every set given (the selection set
    ranks the candidates; the test sets are only reported)."""
    from ..classify import make_classifier

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    X, y, _ = training_set(job["spec"], job["classes"], job["n_per_class"], job["seed"])
    t_data = time.perf_counter() - t0
    models = {}
    for name in job["models"]:
        clf = make_classifier(name, random_state=job["seed"], normalisation=job["spec"].get("normalisation", "peak"))
        t1 = time.perf_counter()
        clf.fit(X, y)
        models[name] = {"train_seconds": time.perf_counter() - t1,
                        "tests": _evaluate_all(clf, job["tests"], job["classes"], job["n_boot"], job["seed"])}
    return {"spec": {k: v for k, v in job["spec"].items() if k not in ("profiles", "labels")},
            "data_seconds": t_data, "n_train": int(len(y)), "models": models}


def train_and_test(job: dict) -> dict:
    """A strategy's training runs: make its training set once (from ``seed``), train one
    classifier per run seed (``run_seeds``: weights, validation split and shuffles) on
    it, predict every set given. Returns the runs' predictions (one string of class
    indices per run and set, :func:`mdaug.reports.statistics.encode`), not their scores:
    the study scores all runs of all classifiers on the same resamples."""
    from ..classify import make_classifier, save_model
    from .statistics import encode

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    X, y, groups = training_set(job["spec"], job["classes"], job["n_per_class"], job["seed"])
    t_data = time.perf_counter() - t0
    classes = sorted(job["classes"])
    runs = []
    for i, seed in enumerate(job.get("run_seeds") or [job["seed"]]):
        clf = make_classifier(job["model"], random_state=seed, **dict(job.get("model_params", {})))
        t1 = time.perf_counter()
        clf.fit(X, y, **({} if groups is None else {"groups": groups}))
        t_train = time.perf_counter() - t1
        if job.get("model_path"):
            save_model(clf, str(job["model_path"]).format(run=i))
        runs.append({"seed": int(seed), "train_seconds": t_train,
                     "epochs_run": (getattr(clf, "split_scores_", None) or {}).get("epochs_run"),
                     "predictions": {name: encode(clf.predict(np.asarray(Xt)), classes)
                                     for name, (Xt, _) in job["tests"].items()}})
    spec = {k: v for k, v in job["spec"].items() if k not in ("profiles", "labels")}
    return {"strategy": job["name"], "model": job["model"], "spec": spec, "sigma_p": spec.get("sigma_p"),
            "width": spec.get("width"), "seeds": [r["seed"] for r in runs], "n_train": int(len(y)),
            "data_seconds": t_data, "train_seconds": float(sum(r["train_seconds"] for r in runs)),
            "runs": [{k: v for k, v in r.items() if k != "predictions"} for r in runs],
            "predictions": {t: [r["predictions"][t] for r in runs] for t in runs[0]["predictions"]}}
