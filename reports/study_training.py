"""The study's training stages: each strategy's CNN (several training runs, stage
``cnn_<strategy>``) and the separability ceiling (stage ``ceiling``). A mixin of
:class:`mdaug.reports.study.Study` (it uses the study's config, cache and folder).

Training runs: every CNN is trained ``protocol.cnn_seeds`` times on its strategy's one
training set (drawn once, from ``child_seed(seed, "cnn", strategy)``); run ``i`` takes
its weights, validation split and shuffles from its own seed: run 0 from that same
seed (so it is the single CNN of a one-run study), run ``i`` > 0 from
``child_seed(seed, "cnn", strategy, i)`` (the one seed helper), so runs do not depend
on the order or process they run in. The stages store predictions; :mod:`.statistics`
scores them.

With workers, the uncached stages are one pool of jobs (:meth:`TrainingStages.training`):
their training sets, then every run of every stage as a job of its own
(:func:`mdaug.reports.jobs.fit_predict`), the longest first; a stage is stored when its
last run is in. The records are those of the one-process path
(:func:`mdaug.reports.jobs.train_stage`), run for run.
"""
from __future__ import annotations


from ..radar.seeds import child_seed
from ..strategies import TrainingSpec
from . import jobs
from .cache import settings_key

CEILING_MODELS = ("svm", "xgb", "nb", "cnn")
CNN_NEEDS = ("predictions", "runs", "seeds", "spec")  # what a stored CNN stage must hold to be used


def chosen_spec(specs: list[TrainingSpec], choice: dict | None) -> TrainingSpec:
    """The spec at the chosen value of its setting (a strategy without one: its only spec)."""
    if choice is None:
        return specs[0]
    return next(s for s in specs if s.setting == choice["value"])


def run_seeds(first: int, seed: int, n: int, *keys) -> list[int]:
    """The seeds of ``n`` training runs: ``first`` (the one-run study's seed), then
    ``child_seed(seed, *keys, i)`` for i = 1 .. n - 1."""
    return [int(first)] + [child_seed(seed, *keys, i) for i in range(1, n)]


class TrainingStages:
    # ---- stage 5: CNN per strategy, several runs ------------------------------------------------
    def cnn_jobs(self, specs: dict, choice: dict, select, tests: dict) -> dict[str, dict]:
        """{strategy: job}: its CNN's training runs at its chosen setting."""
        p = self.cfg.protocol
        sel_name, sel_data, _ = select
        out = {}
        for name, ss in specs.items():
            spec = chosen_spec(ss, choice.get(name))
            tsaug = name == "tsaug"
            sets = {sel_name: sel_data, **tests}
            if tsaug:  # tsaug copies the calibration measurements: never scored on them
                sets = {k: v for k, v in sets.items() if k != "calibration"}
            seed = child_seed(self.cfg.seed, "cnn", name)
            out[name] = {"name": name, "model": "cnn", "classes": list(self.cfg.classes), "spec": spec,
                         "n_per_class": p.tsaug_n_per_class if tsaug else p.cnn_n_per_class, "tests": sets,
                         "seed": seed, "run_seeds": run_seeds(seed, self.cfg.seed, p.cnn_seeds, "cnn", name),
                         "model_params": {"epochs": p.tsaug_epochs if tsaug else p.cnn_epochs,
                                          "patience": p.cnn_patience, "normalisation": p.normalisation,
                                          "precision": p.cnn_precision,
                                          "device": self.cfg.device},
                         "model_path": str(self.out / "models" / f"cnn_{name}_run{{run}}.zip")}
        return out

    def _cnn_key(self, job: dict) -> str:
        # the spec's files by their place in the study folder: a moved folder, or another working directory, resumes
        return settings_key(self.cnn_key, job["name"], self.cache.relative(job["spec"].to_dict()), job["run_seeds"])

    # ---- stage 6: separability ceiling --------------------------------------------------------------
    def ceiling_job(self, tests: dict, select) -> dict:
        """The ceiling's stage job: classifiers trained on the scene simulator's own data
        (other specimens): the fast models once, the CNN ``cnn_seeds`` times (like the
        strategies' CNNs), all on the whole set. Predictions only; scored and chosen (on
        the selection set) with everything else."""
        sim, p = self.cfg.simulation, self.cfg.protocol
        sel_name, sel_data, _ = select
        fits = []
        for model in CEILING_MODELS:  # the CNN: like for like with the strategies' CNNs
            first = child_seed(self.cfg.seed, "ceiling", model)
            params = {"epochs": p.cnn_epochs, "patience": p.cnn_patience, "device": self.cfg.device,
                      "precision": p.cnn_precision} if model == "cnn" else {}
            fits += [(model, seed, params)
                     for seed in run_seeds(first, self.cfg.seed, p.cnn_seeds if model == "cnn" else 1, "ceiling", model)]
        return {"kind": "ceiling", "stage": "ceiling", "seed": self.cfg.seed, "classes": list(self.cfg.classes),
                "ramps": self.cfg.scene_ramps, "n_specimens": 2 * sim.new_specimens, "per_class": sim.ceiling_per_class,
                "tests": {sel_name: sel_data, **tests}, "fits": fits,
                "key": settings_key(self.key, sim.ceiling_per_class, p.cnn_seeds, p.cnn_epochs, p.cnn_patience,
                                    p.cnn_precision),
                "what": "trained on the scene simulator's own data "
                        f"({sim.ceiling_per_class} acquisitions per class of {2 * sim.new_specimens} other specimens, "
                        f"through the chain's reduced computation; the CNN {p.cnn_seeds} times, like the strategies')"}

    # ---- stages 5 and 6 together -----------------------------------------------------------------------
    def training(self, cnn_jobs: dict, ceiling_job: dict | None, executor) -> tuple[dict, dict | None]:
        """Every strategy's CNN stage and the ceiling (None: none), each cached. With
        workers, the uncached stages run as one pool of jobs: their training sets first,
        then every training run of every stage, the longest first (a stage's runs are
        separate jobs, so two workers share out six strategies' eighteen runs evenly)."""
        stages = [(f"cnn_{name}", self._cnn_key(j), CNN_NEEDS, {**j, "kind": "cnn", "stage": f"cnn_{name}"})
                  for name, j in cnn_jobs.items()]
        if ceiling_job is not None:
            stages.append(("ceiling", ceiling_job["key"], (), ceiling_job))
        todo = [s for s in stages if not self.cache.has(s[0], s[1], s[2])]
        if len(todo) > 1 and self.cfg.workers > 1:
            self._train_in_workers(todo, executor)
        done = {name: self.cache.run(name, key, lambda j=job: jobs.train_stage(j), needs)
                for name, key, needs, job in stages}
        strategies = {name: done[f"cnn_{name}"] for name in cnn_jobs}
        return strategies, done.get("ceiling")

    def _train_in_workers(self, todo: list, executor) -> None:
        for name, *_ in todo:
            self.cache.started(name)
        data = list(executor.map(jobs.stage_data_job, [job for *_, job in todo]))
        per_stage = [jobs.stage_fits(job, data[k]) for k, (*_, job) in enumerate(todo)]
        queue = sorted(((k, i, f) for k, fits in enumerate(per_stage) for i, f in enumerate(fits)),
                       key=lambda kif: -_cost(kif[2]))  # the longest first: the last jobs to end are short
        results = [[None] * len(fits) for fits in per_stage]
        from ..radar.progress import progress_bar

        with progress_bar(total=len(queue), desc="training runs", unit="run", leave=False) as bar:
            for (k, i, _), res in zip(queue, executor.map(jobs.fit_predict, [f for *_, f in queue])):
                results[k][i] = res
                bar.update(1)
                if all(r is not None for r in results[k]):
                    name, key, _, job = todo[k]
                    seconds = data[k]["seconds"] + sum(r["train_seconds"] for r in results[k])
                    self.cache.store(name, key, jobs.stage_result(job, data[k], per_stage[k], results[k]), seconds,
                                     " in a worker (data and training)")


def _cost(fit: dict) -> float:
    """A training run's rough cost, to hand out the longest first: profiles x epochs."""
    epochs = fit.get("params", {}).get("epochs", 1) if fit["model"] == "cnn" else 0.2
    return len(fit["y"]) * epochs
