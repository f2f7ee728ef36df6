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
    ``out/figures/`` (the corner with ``truth``, the drone's true class vector, where
    the study knows it); returns the stage's summary (plain data)."""
    from pathlib import Path

    from ..inference import calibrate
    from ..inference.population.result import calibrate_population
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
            # every drone by the estimator's default route; beside it, for the first drone only, the
            # smc run whose median is sigma_p_fit's centre (where the file has a summary likelihood)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                res = calibrate_amortized(X[drones == drone], cls, acquisition=job["acquisition"],
                                          settings=job["settings"], random_state=seed,
                                          fit=k == 0).record_specimens([drone])
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
        res.plot_corner(corner_png, truths=job.get("truth"))
        if amortized:
            trace_png = None  # no chain in the file: the amortized posterior's draws are exact
        else:
            res.plot_trace(trace_png)
    return {"posterior": str(nc), "corner": str(corner_png), "trace": None if trace_png is None else str(trace_png),
            **calibration_record(res), "n_profiles": int(np.sum(drones == ids[0])),
            "population": str(pop_path), "population_report": pop.report(), "population_spreads": pop.summary(),
            "population_assumed": bool(pop.assumed), "population_converged": bool(pop.converged),
            "drones": ids, "drones_converged": [bool(r.converged) for r in results],
            "seconds": time.perf_counter() - t0}


@announced(lambda job: f"data: {job['cls']} {job['part']}")
def campaign(job: dict) -> tuple:
    """One simulated campaign of the study's data (``cls``, ``n_specimens``, ``n``
    acquisitions, ``scene``, ``seed``): (profiles, labels, specimen)."""
    from ..generator.chain import simulate_campaign

    _threads(job.get("threads", 1))
    camp = simulate_campaign(job["cls"], job["n_specimens"], job["n"], job["seed"], scene=job["scene"])
    return camp.profiles, camp.labels, camp.specimen


def calibration_record(res) -> dict:
    """What the study keeps of one calibration result in ``results.json`` (beside its
    files): convergence, diagnostics, the status in the one vocabulary
    (:func:`mdaug.inference.result.status.calibration_status`, its stored SBC in it), the
    summary table, the acquisition and the label-free lines' quantiles."""
    from ..inference.result.status import calibration_status
    from ..inference.space.priors import engine_lines

    status = calibration_status(res)
    lines = res.lines()  # (n, E, 4, 2): frequency rad/s, amplitude m
    w_ref, _, _ = engine_lines(res.priors.centres)
    return {"converged": bool(res.converged), "diagnostics": res.diagnostics, "status": status.to_dict(),
            "summary": res.summary(), "acquisition": res.acquisition.to_dict(),
            "measured_acquisition": res.measured_acquisition().to_dict(),
            "lines": {"frequency_q": np.quantile(lines[..., 0], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "amplitude_q": np.quantile(lines[..., 1], [0.05, 0.5, 0.95], axis=0).tolist(),
                      "reference_frequency": np.sort(w_ref, axis=-1).tolist()}}


@announced(lambda job: job.get("label") or f"{job['model']} (seed {job['seed']})")
def fit_predict(job: dict) -> dict:
    """Train one classifier (``model``, ``seed``, ``params``) on (``X``, ``y``; ``groups``
    when given, the CNN's validation split by drone) and predict every set of
    ``tests``; saved to ``model_path`` when given. Returns {train_seconds, epochs_run,
    predictions (encoded)}."""
    from ..classify import make_classifier, save_model
    from ..radar.progress import echo
    from .statistics import encode

    _threads(job.get("threads", 1))
    clf = make_classifier(job["model"], random_state=job["seed"], **dict(job.get("params", {})))
    groups = job.get("groups")
    t0 = time.perf_counter()
    clf.fit(job["X"], job["y"], **({} if groups is None else {"groups": groups}))
    seconds = time.perf_counter() - t0
    if job.get("model_path"):
        save_model(clf, job["model_path"])
    if job.get("run_label"):
        echo(f"{job['run_label']} trained in {seconds:.1f} s")
    return {"train_seconds": seconds, "epochs_run": (getattr(clf, "split_scores_", None) or {}).get("epochs_run"),
            "predictions": {n: encode(clf.predict(np.asarray(Xt)), job["classes"])
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


def stage_data(job: dict) -> dict:
    """The training set of a training stage (:mod:`.study_training`): a strategy's CNN
    (``kind`` "cnn": its set from ``seed``) or the separability ceiling (``kind``
    "ceiling": the scene simulator's own drones through the chain). Returns {X, y,
    groups, seconds}."""
    _threads(job.get("threads", 1))
    t0 = time.perf_counter()
    if job["kind"] == "cnn":
        X, y, groups = training_set(job["spec"], job["classes"], job["n_per_class"], job["seed"])
    else:
        X, y, groups = _ceiling_set(job)
    return {"X": X, "y": y, "groups": groups, "seconds": time.perf_counter() - t0}


@announced(lambda job: f"{job['stage']}: training set")
def stage_data_job(job: dict) -> dict:
    """:func:`stage_data` as a worker job (it logs its start and end there)."""
    return stage_data(job)


def _ceiling_set(job: dict):
    from ..generator import load_reference
    from ..generator.chain import SceneConfig, draw_specimens, render_through_chain
    from ..radar.seeds import child_seed
    from ..radar.seeds import rng as seeded_rng

    scene = SceneConfig().with_acquisition(ramps=job["ramps"])
    n, parts, labels = job["per_class"], [], []
    for c in job["classes"]:
        rng = seeded_rng(child_seed(job["seed"], "ceiling", c))
        specimens = draw_specimens(load_reference(c).to_array(), job["n_specimens"], scene, rng)
        x = specimens[np.arange(n) % len(specimens)]
        parts.append(render_through_chain(x, scene, random_state=child_seed(job["seed"], "ceiling-chain", c)).profiles)
        labels.append(np.full(n, c))
    return np.concatenate(parts), np.concatenate(labels), None


def stage_fits(job: dict, data: dict) -> list[dict]:
    """The training runs of a stage as :func:`fit_predict` jobs, each with its own seed:
    a CNN stage's ``run_seeds`` (model saved per run), or the ceiling's ``fits``
    ((model, seed, params) each)."""
    classes = sorted(job["classes"])
    common = {"X": data["X"], "y": data["y"], "tests": job["tests"], "classes": classes}
    if job["kind"] == "ceiling":
        return [{**common, "model": m, "seed": seed, "params": params, "label": f"ceiling: {m} (seed {seed})"}
                for m, seed, params in job["fits"]]
    seeds = job.get("run_seeds") or [job["seed"]]
    return [{**common, "groups": data["groups"], "model": job["model"], "seed": seed,
             "params": job.get("model_params", {}), "label": f"{job['stage']} run {i + 1}/{len(seeds)}",
             "run_label": f"[{job['stage']}] run {i + 1}/{len(seeds)}",
             "model_path": str(job["model_path"]).format(run=i) if job.get("model_path") else None}
            for i, seed in enumerate(seeds)]


def stage_result(job: dict, data: dict, fits: list[dict], done: list[dict]) -> dict:
    """A stage's record from its runs' results (``done``, in the order of ``fits``):
    predictions of every run, not their scores (the study scores all runs of all
    classifiers on the same resamples)."""
    if job["kind"] == "ceiling":
        result = {"n_train": int(len(data["y"])), "models": {}, "what": job["what"]}
        for fit, res in zip(fits, done):
            m = result["models"].setdefault(fit["model"], {"train_seconds": 0.0, "seeds": [],
                                                           "predictions": {n: [] for n in job["tests"]}})
            m["train_seconds"] += res["train_seconds"]
            m["seeds"].append(fit["seed"])
            for n in job["tests"]:
                m["predictions"][n].append(res["predictions"][n])
        return result
    spec = job["spec"].to_dict()
    return {"strategy": job["name"], "model": job["model"], "spec": spec, "sigma_p": spec.get("sigma_p"),
            "width": spec.get("width"), "seeds": [f["seed"] for f in fits], "n_train": int(len(data["y"])),
            "data_seconds": data["seconds"], "train_seconds": float(sum(r["train_seconds"] for r in done)),
            "runs": [{"seed": int(f["seed"]), "train_seconds": r["train_seconds"], "epochs_run": r["epochs_run"]}
                     for f, r in zip(fits, done)],
            "predictions": {t: [r["predictions"][t] for r in done] for t in job["tests"]}}


@announced(lambda job: job["stage"])
def train_stage(job: dict) -> dict:
    """A whole training stage in one process: its training set once, then every run
    (:func:`stage_fits`), then its record (:func:`stage_result`)."""
    from ..radar.progress import echo

    data = stage_data(job)
    fits = stage_fits(job, data)
    echo(f"[{job['stage']}] training set of {len(data['y'])} profiles in {data['seconds']:.1f} s; "
         f"{len(fits)} training run(s)")
    return stage_result(job, data, fits, [fit_predict(f) for f in fits])
