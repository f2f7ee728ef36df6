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
"""
from __future__ import annotations

import numpy as np

from ..radar.seeds import child_seed
from ..radar.seeds import rng as seeded_rng
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

    def cnns(self, cnn_jobs: dict, executor) -> dict:
        """Every strategy's stage result (cached; uncached strategies go to the executor together)."""
        todo = [j for name, j in cnn_jobs.items() if not self.cache.has(f"cnn_{name}", self._cnn_key(j), CNN_NEEDS)]
        if len(todo) > 1 and self.cfg.workers > 1:
            for job in todo:
                self.cache.started(f"cnn_{job['name']}")
            for job, res in zip(todo, executor.map(jobs.train_and_test, todo)):
                self.cache.store(f"cnn_{job['name']}", self._cnn_key(job), res,
                                 res["data_seconds"] + res["train_seconds"], " in a worker (data and training)")
        return {name: self.cache.run(f"cnn_{name}", self._cnn_key(j), lambda j=j: jobs.train_and_test(j), CNN_NEEDS)
                for name, j in cnn_jobs.items()}

    # ---- stage 6: separability ceiling --------------------------------------------------------------
    def ceiling(self, tests: dict, select, executor=None) -> dict:
        """Classifiers trained on the scene simulator's own data (other specimens): the
        fast models once, the CNN ``cnn_seeds`` times (like the strategies' CNNs), all
        on the whole set; every fit is a job of ``executor``
        (None: in this process). Predictions only; scored and chosen (on the selection
        set) with everything else."""
        from ..generator import load_reference
        from ..generator.chain import SceneConfig, draw_specimens, render_through_chain

        sim, p = self.cfg.simulation, self.cfg.protocol
        classes = sorted(self.cfg.classes)

        def compute():
            scene = SceneConfig().with_acquisition(ramps=sim.ramps)
            parts, labels = [], []
            for c in self.cfg.classes:
                rng = seeded_rng(child_seed(self.cfg.seed, "ceiling", c))  # as before: same specimens
                specimens = draw_specimens(load_reference(c).to_array(), 2 * sim.new_specimens, scene, rng)
                x = specimens[np.arange(sim.ceiling_per_class) % len(specimens)]
                parts.append(render_through_chain(x, scene, random_state=child_seed(self.cfg.seed, "ceiling-chain",
                                                                                    c)).profiles)
                labels.append(np.full(sim.ceiling_per_class, c))
            X, y = np.concatenate(parts), np.concatenate(labels)
            sel_name, sel_data, _ = select
            sets = {sel_name: sel_data, **tests}
            result = {"n_train": int(len(y)), "models": {}, "what": "trained on the scene simulator's own data "
                      f"({sim.ceiling_per_class} acquisitions per class of {2 * sim.new_specimens} other specimens, "
                      f"through the chain's reduced computation; the CNN {p.cnn_seeds} times, like the strategies')"}
            work = []
            for model in CEILING_MODELS:  # the CNN: like for like with the strategies' CNNs
                first = child_seed(self.cfg.seed, "ceiling", model)
                params = {"epochs": p.cnn_epochs, "patience": p.cnn_patience, "device": self.cfg.device,
                          "precision": p.cnn_precision} \
                    if model == "cnn" else {}
                for seed in run_seeds(first, self.cfg.seed, p.cnn_seeds if model == "cnn" else 1, "ceiling", model):
                    work.append({"model": model, "seed": seed, "params": params, "X": X, "y": y, "tests": sets,
                                 "classes": classes})
            done = executor.map(jobs.fit_predict, work) if executor is not None else map(jobs.fit_predict, work)
            for job, res in zip(work, done):
                m = result["models"].setdefault(job["model"], {"train_seconds": 0.0, "seeds": [],
                                                               "predictions": {n: [] for n in sets}})
                m["train_seconds"] += res["train_seconds"]
                m["seeds"].append(job["seed"])
                for n in sets:
                    m["predictions"][n].append(res["predictions"][n])
            return result
        return self.cache.run("ceiling", settings_key(self.key, sim.ceiling_per_class, p.cnn_seeds, p.cnn_epochs,
                                                      p.cnn_patience, p.cnn_precision), compute)
