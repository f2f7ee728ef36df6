"""Long work is never silent: every stage of `mdaug run` logs its start and end, the
stages computed in worker processes too (the parent when it sends them and when each
comes back, in order; the worker when it takes a job up and when it is done), and a
CNN stage logs each training run."""
import dataclasses
import re

import numpy as np

from mdaug.reports import jobs
from mdaug.reports.cache import StageCache
from mdaug.reports.executor import ProcessExecutor

CLASSES = ["HELI", "QUAD"]


def _toy(n=60, seed=0):
    rng = np.random.default_rng(seed)
    y = np.repeat(CLASSES, n // 2)
    x = np.abs(rng.normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    x[y == "QUAD", 215] += 0.6
    return x, y


def test_the_stage_cache_logs_start_and_end_of_every_stage(tmp_path):
    lines = []
    cache = StageCache(tmp_path, log=lines.append)
    cache.run("data", "k", lambda: {"a": 1})
    cache.started("cnn_x")
    cache.store("cnn_x", "k", {"b": 2}, 12.5)
    StageCache(tmp_path, log=lines.append).run("data", "k", lambda: {"a": 1})  # a rerun resumes: said so
    assert lines == ["[data] running ...", "[data] done in 0.0 s", "[cnn_x] running (sent to the workers) ...",
                     "[cnn_x] done in 12.5 s in a worker", "[data] cached (0.0 s when computed)"]


def test_worker_jobs_log_their_start_and_end_in_the_worker(capfd):
    x, y = _toy()
    work = [{"model": "nb", "seed": s, "params": {}, "X": x, "y": y, "tests": {"t": (x, y)}, "classes": CLASSES,
             "label": f"ceiling: nb (seed {s})"} for s in (1, 2, 3)]
    pool = ProcessExecutor(2)
    try:
        done = pool.map(jobs.fit_predict, work)
        assert not isinstance(done, list)  # an iterator: each result as it comes, in order
        results = list(done)
    finally:
        pool.close()
    assert len(results) == 3
    out = capfd.readouterr().out
    for s in (1, 2, 3):
        assert re.search(rf"\[ceiling: nb \(seed {s}\)\] started in worker \d+", out), out
        assert re.search(rf"\[ceiling: nb \(seed {s}\)\] done in [\d.]+ s in worker \d+", out), out
    # in the study's own process the stage cache logs instead: no second line
    jobs.fit_predict(work[0])
    assert "started in worker" not in capfd.readouterr().out


def test_cnn_stages_in_workers_log_start_runs_and_end(tmp_path, capfd):
    from mdaug.reports.config import StudyConfig
    from mdaug.reports.study import Study
    from mdaug.strategies import TrainingSpec

    cfg = StudyConfig(seed=7).quick_version()
    cfg.protocol = dataclasses.replace(cfg.protocol, cnn_n_per_class=60, cnn_epochs=1, cnn_seeds=2,
                                       tsaug_n_per_class=30, tsaug_epochs=1)
    lines = []
    study = Study(cfg, tmp_path, log=lines.append)
    x, y = _toy(40, 1)
    specs = {n: [TrainingSpec("sigma_p_published", sigma_p=v, normalisation="peak", through_chain=False)]
             for n, v in (("sigma_p_published", 0.2),)}
    specs["tsaug"] = [TrainingSpec("tsaug", normalisation="peak", profiles=x, labels=y)]
    cnn_jobs = study.cnn_jobs(specs, {"sigma_p_published": {"value": 0.2}}, ("select", (x, y), "x"),
                              {"new": (x, y)})
    pool = ProcessExecutor(2)
    try:
        study.training(cnn_jobs, None, pool)
    finally:
        pool.close()
    for name in ("sigma_p_published", "tsaug"):
        start = lines.index(f"[cnn_{name}] running (sent to the workers) ...")
        end = next(i for i, ln in enumerate(lines) if ln.startswith(f"[cnn_{name}] done in ")
                   and ln.endswith(" s in a worker (data and training)"))
        assert start < end
    out = capfd.readouterr().out
    for name in ("sigma_p_published", "tsaug"):
        # the stage's training set, then each run, each a job of its own that logs its start and end
        assert re.search(rf"\[cnn_{name}: training set\] started in worker \d+", out), out
        assert f"[cnn_{name}] run 1/2 trained in " in out and f"[cnn_{name}] run 2/2 trained in " in out
        for run in (1, 2):
            assert re.search(rf"\[cnn_{name} run {run}/2\] started in worker \d+", out), out
            assert re.search(rf"\[cnn_{name} run {run}/2\] done in [\d.]+ s in worker \d+", out), out


def test_training_in_workers_gives_the_one_process_records_run_for_run(tmp_path, monkeypatch, terminal):
    """The pool path (training sets, then every run of every stage as its own job, the
    longest first) stores what the one-process path stores: same seeds, same
    predictions, in the stage's own run order (the ceiling's runs are handed out in
    another order than they are recorded in); on a terminal the parent draws a bar
    of the runs as they come back."""
    import sys

    from mdaug.radar.progress import QUIET_ENV
    from mdaug.reports.config import StudyConfig
    from mdaug.reports.executor import SerialExecutor
    from mdaug.reports.study import Study
    from mdaug.strategies import TrainingSpec

    records = {}
    for workers in (1, 2):
        cfg = StudyConfig(seed=7, workers=workers).quick_version()
        cfg.protocol = dataclasses.replace(cfg.protocol, cnn_n_per_class=40, cnn_epochs=2, cnn_seeds=2,
                                           tsaug_n_per_class=30, tsaug_epochs=1)
        cfg.simulation = dataclasses.replace(cfg.simulation, ceiling_per_class=20, new_specimens=1)
        study = Study(cfg, tmp_path / f"w{workers}", log=lambda *_: None)
        x, y = _toy(40, 1)
        specs = {"sigma_p_published": [TrainingSpec("sigma_p_published", sigma_p=0.2, normalisation="peak",
                                                    through_chain=False)],
                 "tsaug": [TrainingSpec("tsaug", normalisation="peak", profiles=x, labels=y)]}
        cnn_jobs = study.cnn_jobs(specs, {"sigma_p_published": {"value": 0.2}}, ("select", (x, y), "x"),
                                  {"new": (x, y)})
        pool = ProcessExecutor(2) if workers == 2 else SerialExecutor()
        tty = terminal()
        monkeypatch.delenv(QUIET_ENV, raising=False)
        monkeypatch.setattr(sys, "stderr", tty)
        try:
            records[workers] = study.training(cnn_jobs, study.ceiling_job({"new": (x, y)}, ("select", (x, y), "x")),
                                              pool)
        finally:
            pool.close()
            monkeypatch.undo()
        # 2 strategies x 2 runs and the ceiling's 2 CNN runs + svm, xgb, nb: 9 runs, a bar in the pool path only
        assert ("training runs:" in tty.text and "/9 [" in tty.text) == (workers == 2), tty.text[-300:]
    (one, ceil_one), (pool_, ceil_pool) = records[1], records[2]
    for name in ("sigma_p_published", "tsaug"):
        assert one[name]["seeds"] == pool_[name]["seeds"] and len(one[name]["seeds"]) == 2
        assert one[name]["predictions"] == pool_[name]["predictions"]
    assert list(ceil_one["models"]) == list(ceil_pool["models"]) == ["svm", "xgb", "nb", "cnn"]
    for model, m in ceil_one["models"].items():
        assert m["seeds"] == ceil_pool["models"][model]["seeds"]
        assert m["predictions"] == ceil_pool["models"][model]["predictions"]
    assert ceil_one["n_train"] == ceil_pool["n_train"] == 40
