"""The study's independent jobs as picklable top-level functions.

Each job takes one dict (its settings and its own seed) and returns plain data, so
any executor (serial, processes, dask) gives the same results. A training-set
strategy at one setting is a :class:`mdaug.strategies.TrainingSpec` (``spec``); its
set comes from :func:`mdaug.strategies.training_set`, the registry's one builder.
"""
from __future__ import annotations

import dataclasses
import functools
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..strategies import STRATEGIES, TrainingSpec, training_set


def announced(label):
    """Decorator of a job function: in a worker process, a status line when the job
    starts and when it ends (``label(job)`` names it, as the study's stage log does);
    in the study's own process the stage cache logs the stage instead."""
    def wrap(fn):
        @functools.wraps(fn)
        def run(job):
            from ..radar.progress import echo, in_worker

            if not in_worker():
                return fn(job)
            name = label(job)
            echo(f"[{name}] started in worker {os.getpid()}")
            t0 = time.perf_counter()
            out = fn(job)
            echo(f"[{name}] done in {time.perf_counter() - t0:.1f} s in worker {os.getpid()}")
            return out
        return run
    return wrap


def _threads(n: int = 1) -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)


@announced(lambda job: f"calibrate_{job['cls']}")
def calibrate_class(job: dict) -> dict:
    """One class calibrated from its measurements (``profiles``, of the drones
    ``drones``) under ``acquisition``: each drone on its own (the first drone's posterior
    is the single-drone calibration the posterior strategies use, saved to
    ``out/posteriors/<cls>.nc``, the others beside it as ``<cls>.drone-<id>.nc``), then
    the class's population over the drones (``<cls>.population.npz``; from one drone
    its spreads are the stated prior); corner and trace plots of the first drone in
    ``out/figures/``; returns the stage's summary (plain data)."""
    from pathlib import Path

    from ..inference import calibrate
    from ..inference.population.result import calibrate_population
    from ..inference.space.priors import engine_lines
    from ..radar.seeds import child_seed
    from .style import figure_style

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    cls, out, X = job["cls"], Path(job["out"]), job["profiles"]
    amortized = job.get("method", "likelihood") == "amortized"
    if amortized:
        from ..inference.amortized.calibrate import calibrate_amortized
    drones = np.asarray(job.get("drones", np.full(len(X), "0"))).astype(str)
    ids = list(dict.fromkeys(drones.tolist()))
    results = []
    for k, drone in enumerate(ids):
        name = cls if k == 0 else f"{cls}.drone-{drone}"
        checkpoint = out / "posteriors" / f"{name}.chain.h5"
        seed = job["seed"] if k == 0 else child_seed(job["seed"], "drone", drone)
        if amortized:  # an out-of-range warning lands in the diagnostics, which the report shows
            with warnings.catch_warnings():  # the emcee route beside the first drone's only: the population
                warnings.simplefilter("ignore", UserWarning)  # and the strategies use the amortized draws
                res = calibrate_amortized(X[drones == drone], cls, acquisition=job["acquisition"],
                                          settings=job["settings"], random_state=seed,
                                          emcee=k == 0).record_specimens([drone])
        else:
            res = calibrate(X[drones == drone], cls, acquisition=job["acquisition"], settings=job["settings"],
                            random_state=seed, backend_path=checkpoint).record_specimens([drone])
        res.save(out / "posteriors" / f"{name}.nc")
        for f in checkpoint.parent.glob(checkpoint.name + "*"):
            f.unlink()  # only needed to resume an interrupted run
        results.append(res)
    res, nc = results[0], out / "posteriors" / f"{cls}.nc"
    pop = calibrate_population(results, ids, random_state=child_seed(job["seed"], "population"))
    pop_path = pop.save(out / "posteriors" / f"{cls}.population.npz")
    corner_png, trace_png = out / "figures" / f"corner_{cls}.png", out / "figures" / f"trace_{cls}.png"
    with figure_style():
        res.plot_corner(corner_png)
        if amortized:
            trace_png = None  # no chain in the file: the amortized posterior's draws are exact
        else:
            res.plot_trace(trace_png)
    lines = res.lines()  # (n, E, 4, 2): frequency rad/s, amplitude m
    w_ref, _, _ = engine_lines(res.priors.centres)
    return {"posterior": str(nc), "corner": str(corner_png), "trace": None if trace_png is None else str(trace_png),
            "converged": bool(res.converged), "diagnostics": res.diagnostics, "summary": res.summary(),
            "n_profiles": int(np.sum(drones == ids[0])), "acquisition": res.acquisition.to_dict(),
            "measured_acquisition": res.measured_acquisition().to_dict(),
            "lines": {"frequency_q": np.quantile(lines[..., 0], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "amplitude_q": np.quantile(lines[..., 1], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "reference_frequency": np.sort(w_ref, axis=-1).tolist()},
            "sbc": _estimator_sbc(res) if amortized else None,
            "population": str(pop_path), "population_report": pop.report(), "population_spreads": pop.summary(),
            "population_assumed": bool(pop.assumed), "population_converged": bool(pop.converged),
            "drones": ids, "drones_converged": [bool(r.converged) for r in results],
            "seconds": time.perf_counter() - t0}


def _estimator_sbc(res) -> dict | None:
    """The SBC the calibration's estimator passed (stored in its file): the amortized
    route's outer share, pooled rank p and truths."""
    sbc = res.diagnostics.get("estimator", {}).get("sbc", {}).get("amortized")
    return None if not sbc else {"outer_share": sbc.get("outer_share"), "pooled_p": sbc.get("pooled_p"),
                                 "n_replicates": sbc.get("n_replicates")}


@announced(lambda job: f"ceiling: {job['model']} (seed {job['seed']})")
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


@dataclass(frozen=True)
class StrategySets:
    """Picklable ``make_train(value, seed) -> (X, y)`` of the sweep job
    (:class:`mdaug.classify.protocol.SweepJob`): ``spec``'s training set with its
    setting at ``value``."""

    spec: TrainingSpec
    classes: tuple
    n_per_class: int

    def __call__(self, value, seed):
        param = STRATEGIES[self.spec.strategy].parameter
        spec = self.spec if param is None else dataclasses.replace(self.spec, **{param: value})
        X, y, _ = training_set(spec, list(self.classes), self.n_per_class, seed)
        return X, y


@announced(lambda job: f"candidates: {job['spec'].strategy}"
                      + ("" if job["spec"].setting is None else f" at {job['spec'].setting:g}"))
def candidate(job: dict) -> list[dict]:
    """One choice candidate (a strategy at one sigma_P or width): the sweep's job
    (:func:`mdaug.classify.protocol.run_sweep_job`: its training set, the fast
    classifiers trained on it and scored on every set given; the selection set ranks
    the candidates, the test sets are only reported), all from the job's one seed.
    Its rows: the sweep's (the setting's value under ``sigma_p``)."""
    from ..classify.protocol import SweepJob, run_sweep_job

    _threads(job.get("threads", 1))
    spec, seed = job["spec"], job["seed"]
    sweep = SweepJob(index=0, sigma_p=spec.setting, train_seed=seed, model_seeds={m: seed for m in job["models"]},
                     make_train=StrategySets(spec, tuple(job["classes"]), job["n_per_class"]),
                     test_sets=job["tests"], models=tuple(job["models"]),
                     model_params={m: {"normalisation": spec.normalisation} for m in job["models"]},
                     n_boot=job["n_boot"], boot_seed=seed)
    return run_sweep_job(sweep)


@announced(lambda job: f"cnn_{job['name']}")
def train_and_test(job: dict) -> dict:
    """A strategy's training runs: make its training set once (from ``seed``), train one
    classifier per run seed (``run_seeds``: weights, validation split and shuffles) on
    it, predict every set given. Returns the runs' predictions (one string of class
    indices per run and set, :func:`mdaug.reports.statistics.encode`), not their scores:
    the study scores all runs of all classifiers on the same resamples."""
    from ..classify import make_classifier, save_model
    from ..radar.progress import echo
    from .statistics import encode

    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    X, y, groups = training_set(job["spec"], job["classes"], job["n_per_class"], job["seed"])
    t_data = time.perf_counter() - t0
    classes = sorted(job["classes"])
    runs = []
    seeds = job.get("run_seeds") or [job["seed"]]
    echo(f"[cnn_{job.get('name', job['model'])}] training set of {len(y)} profiles in {t_data:.1f} s; "
         f"{len(seeds)} training run(s)")
    for i, seed in enumerate(seeds):
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
        echo(f"[cnn_{job.get('name', job['model'])}] run {i + 1}/{len(seeds)} trained in {t_train:.1f} s")
    spec = job["spec"].to_dict()
    return {"strategy": job["name"], "model": job["model"], "spec": spec, "sigma_p": spec.get("sigma_p"),
            "width": spec.get("width"), "seeds": [r["seed"] for r in runs], "n_train": int(len(y)),
            "data_seconds": t_data, "train_seconds": float(sum(r["train_seconds"] for r in runs)),
            "runs": [{k: v for k, v in r.items() if k != "predictions"} for r in runs],
            "predictions": {t: [r["predictions"][t] for r in runs] for t in runs[0]["predictions"]}}
