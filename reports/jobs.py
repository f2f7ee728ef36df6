"""The study's independent jobs as picklable top-level functions.

Each job takes one dict (its settings and its own seed) and returns plain data, so
any executor (serial, processes, dask) gives the same results.
"""
from __future__ import annotations

import time

import numpy as np

MIN_GROUPS = 5


def _threads(n: int = 1) -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)


def sigma_p_training_set(sigma_p: float, seed: int, *, classes, n_per_class: int, nuisance: dict,
                         normalisation: str):
    """(X, y) synthetic profiles of every class at one sigma_P (the sweep's make_train)."""
    from ..generator import Nuisance, SigmaPAugmenter, make_dataset

    augs = [SigmaPAugmenter(c, sigma_p, nuisance=Nuisance(**nuisance), normalisation=normalisation)
            for c in classes]
    ds = make_dataset(augs, n_per_class, seed, progress=False)
    return ds.profiles, ds.labels


def training_set(job: dict):
    """(X, y, groups) for one CNN strategy: sigma_p, sigma_p_matched, posterior or tsaug.

    groups (tsaug only) is each copy's source profile, so that the CNN's validation
    split never holds a copy of a profile it trains on; None for model-based sets."""
    from ..generator import Nuisance, SigmaPAugmenter, make_dataset

    kind, n, seed = job["strategy_kind"], job["n_per_class"], job["seed"]
    if kind == "tsaug":
        from ..classify import TsaugAugmenter

        aug = TsaugAugmenter(np.asarray(job["profiles"]), np.asarray(job["labels"]), random_state=seed,
                             normalisation=job["normalisation"])
        X, y, sources = aug.sample(n, return_sources=True)
        per_class = [np.unique(sources[y == c]).size for c in np.unique(y)]
        # a grouped 80/10/10 split needs a few sources per class; with fewer, the
        # validation split holds copies of training profiles (documented in the report)
        return X, y, (sources if min(per_class) >= MIN_GROUPS else None)
    nuisance = Nuisance(**job["nuisance"])
    if kind == "sigma_p":
        augs = [SigmaPAugmenter(c, job["sigma_p"], nuisance=nuisance, normalisation=job["normalisation"])
                for c in job["classes"]]
    elif kind == "posterior":
        from ..inference import PosteriorAugmenter

        augs = [PosteriorAugmenter(job["posteriors"][c], label=c, nuisance=nuisance,
                                   normalisation=job["normalisation"]) for c in job["classes"]]
    else:
        raise ValueError(f"unknown training strategy {kind!r}")
    ds = make_dataset(augs, n, seed, progress=False)
    return ds.profiles, ds.labels, None


def train_and_test(job: dict) -> dict:
    """Make a strategy's training set, train one classifier, test on every test set."""
    from ..classify import evaluate, make_classifier, save_model

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    X, y, groups = training_set(job)
    t_data = time.perf_counter() - t0
    params = dict(job.get("model_params", {}))
    clf = make_classifier(job["model"], random_state=job["seed"], **params)
    t1 = time.perf_counter()
    clf.fit(X, y, **({} if groups is None else {"groups": groups}))
    t_train = time.perf_counter() - t1
    if job.get("model_path"):
        save_model(clf, job["model_path"])
    tests = {}
    for name, (Xt, yt) in job["tests"].items():
        t2 = time.perf_counter()
        pred = clf.predict(np.asarray(Xt))
        m = evaluate(np.asarray(yt), pred, labels=sorted(job["classes"]), n_boot=job["n_boot"],
                     random_state=job["seed"])
        m["predict_seconds"] = time.perf_counter() - t2
        tests[name] = m
    return {"strategy": job["name"], "model": job["model"], "n_train": int(len(y)), "sigma_p": job.get("sigma_p"),
            "nuisance": job.get("nuisance"),
            "data_seconds": t_data, "train_seconds": t_train, "tests": tests}
