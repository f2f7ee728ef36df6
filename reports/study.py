"""The main job: calibrate under the acquisition, augment several ways, classify, compare.

Stages (each cached in ``DIR/stages`` so an interrupted run resumes):

1. ``data``: the measured sets. Simulated (default): a campaign of the
   class-reference drones (``calibration_<CLASS>``: the acquisitions calibrated on;
   ``select``: more of them, held out for the study's choices), a campaign of new
   drone specimens (``new``) and a larger one (``new_large``); every acquisition
   averages ``ramps`` ramps and goes through the radar chain. Or the
   files of a study config.
2. ``calibrate_<CLASS>``: each class calibrated from its measurements under the
   campaign's acquisition (the phases marginalised; :mod:`mdaug.inference`).
3. ``candidates``: every strategy at every value of its setting (sigma_P, the
   specimen width) trains the fast classifiers; they are scored on the selection set
   (the choice) and, for the report only, on the test sets.
4. ``choice``: each strategy's setting with the best balanced accuracy on the
   selection set (the choice never sees a test set; the published peeking choice
   of sigma_P is recorded beside it, labelled as such).
5. ``cnn_<strategy>``: the CNN trained on each strategy at its chosen setting,
   ``protocol.cnn_seeds`` times (training runs, :mod:`.study_training`), predicting
   the selection and test sets; the best strategy is the one with the best mean
   balanced accuracy on the selection set (strategies within a tie of it are reported
   as tied, :mod:`.verdicts`).
6. ``ceiling``: simulated scenes: classifiers trained on the scene simulator's own
   data (other specimens): the separability ceiling of the acquisition; its model is
   chosen on the selection set.
7. ``speed``: speed against error of the stages.

Then every classifier's runs are scored on the same resamples of each set
(:mod:`.statistics`: means over the runs, intervals covering the test sample and the
training runs, paired differences) and every verdict is made (:mod:`.verdicts`).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..radar import atomic_savez, load_profiles
from ..radar.seeds import child_seed
from ..strategies import DRAWS_REVISION, STRATEGIES, TrainingSpec, training_set
from . import jobs, statistics, verdicts
from .cache import StageCache, settings_key
from .config import StudyConfig
from .executor import SerialExecutor, make_executor
from .identity import check_study_folder, claim, study_key
from .results_file import jsonable as _jsonable
from .results_file import write_results
from .study_training import TrainingStages, chosen_spec



CALIBRATION_NEEDS = ("posterior", "population", "converged", "diagnostics", "drones")
"""What a stored calibration stage must hold to be used (else it is computed again)."""


def _stage_seed(cfg: StudyConfig, *keys) -> int:
    return child_seed(cfg.seed, *keys)


class Study(TrainingStages):
    """``invocation``: the command line as it was run (the report prints it)."""

    def __init__(self, cfg: StudyConfig, out: Path, log=print, invocation: str | None = None):
        self.cfg = cfg.validate(check_files=False)
        self.invocation = invocation
        self.out = Path(out).absolute()  # its records do not depend on the working directory
        check_study_folder(self.out, cfg)  # another study's folder: refused before anything is written
        self.out.mkdir(parents=True, exist_ok=True)
        for sub in ("data", "posteriors", "models", "figures"):
            (self.out / sub).mkdir(exist_ok=True)
        self.log = log
        self.cache = StageCache(self.out, log)
        claim(self.out, cfg)
        c, p = cfg.to_dict(), cfg.to_dict()["protocol"]
        self.key = study_key(cfg)
        self.calib_key = settings_key(self.key, c["quick"], p["calibration"])
        self.cand_key = settings_key(self.calib_key, [p[k] for k in ("sigma_p", "specimen_widths", "models",
                                                                     "sweep_n_per_class", "strategies",
                                                                     "through_chain", "normalisation", "n_boot")],
                                     DRAWS_REVISION)
        self.cnn_key = settings_key(self.cand_key, [p[k] for k in ("cnn_n_per_class", "cnn_epochs", "cnn_patience",
                                                                   "tsaug_n_per_class", "tsaug_epochs",
                                                                   "cnn_precision")])
        # the key without n_boot: the stages store predictions, scored afterwards

    # ---- stage 1: data -------------------------------------------------------------
    def data(self, executor=None) -> dict:
        """Stage 1 (cached); simulated campaigns are the executor's jobs (None: here)."""
        def compute():
            sets, acq = self._simulated_sets(executor) if self.cfg.simulated else self._file_sets()
            index = {"sets": {}, "acquisition": acq.to_dict()}
            for name, (X, y, *drones) in sets.items():
                path = self.out / "data" / f"{name}.npz"
                extra = {"specimen": np.asarray(drones[0]).astype(str)} if drones else {}
                atomic_savez(path, profiles=np.asarray(X, dtype=np.float64), labels=np.asarray(y).astype(str),
                             ramps_per_frame=np.array(acq.ramps), acquisition=np.array(json.dumps(acq.to_dict())),
                             **extra)
                index["sets"][name] = {"path": str(path), "n": int(len(y)),
                                       "per_class": {c: int(np.sum(np.asarray(y) == c)) for c in self.cfg.classes}}
            return index
        return self.cache.run("data", self.key, compute, needs=("sets", "acquisition"))

    def _file_sets(self):
        from ..generator.acquisition import Acquisition, acquisition_from_file

        sets, acqs = {}, []
        groups = [("calibration", "calibration_{}"), ("select", "select_{}")]
        for group, fmt in groups:
            for cls, path in getattr(self.cfg.data, group).items():
                ps = load_profiles(path)
                X = ps.select(cls)
                sets[fmt.format(cls)] = (X, np.full(len(X), cls), ps.specimens(cls))
                acqs.append((path, acquisition_from_file(ps.extra, path)))
        if self.cfg.data.select:
            parts = [sets.pop(f"select_{c}") for c in self.cfg.classes]
            sets["select"] = (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
        for name, path in self.cfg.data.test.items():
            ps = load_profiles(path)
            sets[name] = (ps.profiles, ps.labels, *([ps.extra["specimen"]] if "specimen" in ps.extra else []))
            acqs.append((path, acquisition_from_file(ps.extra, path)))
        from ..generator.acquisition import resolve_acquisition

        stated = [(p, a) for p, a in acqs if a is not None]
        k = self.cfg.ramps
        given = None if k is None else Acquisition.measured(k)
        for (p1, a1) in stated:  # the one file-against-setting rule: every file against the first, and the config
            resolve_acquisition(a1, stated[0][1], str(p1), str(stated[0][0]))
            resolve_acquisition(a1, given, str(p1), f"{self.cfg.source}: ramps (or --ramps)")
        acq = stated[0][1] if stated else Acquisition.measured(k or 1)
        return sets, acq

    def _simulated_sets(self, executor):
        from ..generator.chain import SceneConfig
        from ..generator.specimens import SpecimenSpread

        sim = self.cfg.simulation
        scene = SceneConfig().with_acquisition(ramps=self.cfg.scene_ramps)
        reference = scene.replace(specimens=SpecimenSpread.exact())
        d = sim.calibration_drones
        # 1 drone: the reference drone itself, its other acquisitions held out for the choices; more:
        # drones of the specimen model and one drone more, held out whole (no strategy is calibrated on it)
        n_drones = 1 if d == 1 else d + 1
        work = []
        for cls in self.cfg.classes:
            n = sim.n_new.get(cls, 44)
            work += [{"cls": cls, "part": "reference", "n_specimens": n_drones,
                      "n": n_drones * (sim.n_calibration + sim.n_select), "scene": reference if d == 1 else scene,
                      "seed": _stage_seed(self.cfg, "reference", cls)},
                     {"cls": cls, "part": "new", "n_specimens": sim.new_specimens, "n": n, "scene": scene,
                      "seed": _stage_seed(self.cfg, "new", cls)}]
            if sim.large_factor > 1:
                work.append({"cls": cls, "part": "new_large", "n_specimens": 2 * sim.new_specimens,
                             "n": n * sim.large_factor, "scene": scene, "seed": _stage_seed(self.cfg, "new_large", cls)})
        order = sorted(range(len(work)), key=lambda i: -work[i]["n"])  # the largest first, over the workers
        done = dict(zip(order, _imap(executor or SerialExecutor(), jobs.campaign, [work[i] for i in order])))
        camps = {(w["cls"], w["part"]): done[i] for i, w in enumerate(work)}
        sets, select, new, large = {}, {}, {}, {}
        for cls in self.cfg.classes:
            profiles, labels, specimen = camps[cls, "reference"]
            first = np.concatenate([np.flatnonzero(specimen == k)[: sim.n_calibration] for k in range(d)])
            rest = np.setdiff1d(np.arange(len(labels)), first) if d == 1 else np.flatnonzero(specimen == d)
            sets[f"calibration_{cls}"] = (profiles[first], labels[first], specimen[first])
            select[cls] = (profiles[rest], labels[rest], specimen[rest])
            new[cls] = camps[cls, "new"]
            if (cls, "new_large") in camps:
                large[cls] = camps[cls, "new_large"]

        def cat(parts):
            return tuple(np.concatenate([p[i] for p in parts.values()]) for i in range(len(next(iter(parts.values())))))

        sets["select"], sets["new"] = cat(select), cat(new)
        if large:
            sets["new_large"] = cat(large)
        return sets, scene.acquisition_for()

    def load_set(self, name: str):
        ps = load_profiles(self.out / "data" / f"{name}.npz")
        return ps.profiles, ps.labels

    def set_drones(self, name: str):
        """The drone id (within its class) of each acquisition of a stored set, None when
        the set does not say (the bootstrap's clusters, :mod:`.statistics`)."""
        path = self.out / "data" / f"{name}.npz"
        extra = load_profiles(path).extra if path.is_file() else {}
        return np.asarray(extra["specimen"]).astype(str) if "specimen" in extra else None

    def load_drones(self, name: str, cls: str) -> np.ndarray:
        """The drone id of each profile of class ``cls`` in a stored set ("0" when unknown)."""
        return load_profiles(self.out / "data" / f"{name}.npz").specimens(cls)

    def acquisition(self, index: dict):
        from ..generator.acquisition import Acquisition

        return Acquisition.from_dict(index["acquisition"], "study data")

    def selection_set(self, index: dict) -> tuple[str, tuple, str]:
        """(name, (X, y), what it is) of the set the study's choices are made on."""
        if "select" in index["sets"]:
            if self.cfg.simulated and self.cfg.simulation.calibration_drones > 1:
                return "select", self.load_set("select"), ("acquisitions of a drone no strategy was calibrated on "
                                                           "(one fold of leave-one-drone-out)")
            return "select", self.load_set("select"), "held-out acquisitions of the calibration drones"
        parts = [self.load_set(f"calibration_{c}") for c in self.cfg.classes]
        return "calibration", (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])), \
            "the calibration measurements themselves (no held-out set was given: the choices are optimistic)"

    def test_sets(self, index: dict) -> dict:
        return {name: self.load_set(name) for name in index["sets"]
                if not name.startswith("calibration_") and name != "select"}

    # ---- stage 2: calibration --------------------------------------------------------
    def _calibration_job(self, cls: str, acquisition) -> dict:
        settings = self.cfg.protocol.calibration.settings(self.cfg.quick)
        return {"cls": cls, "method": self.calibration_method(cls, acquisition),
                "profiles": self.load_set(f"calibration_{cls}")[0],
                "drones": self.load_drones(f"calibration_{cls}", cls), "acquisition": acquisition,
                "settings": settings, "seed": _stage_seed(self.cfg, "calibrate", cls), "out": str(self.out),
                "truth": self.calibration_truth(cls)}

    def calibration_truth(self, cls: str):
        """The calibrated drone's true class vector where the study knows it (simulated
        data from the reference drone itself, one calibration drone), else None; the
        corner plot draws it."""
        if not self.cfg.simulated or self.cfg.simulation.calibration_drones != 1:
            return None
        from ..generator import load_reference

        return load_reference(cls).to_array()

    def calibration_method(self, cls: str, acquisition) -> str:
        """'amortized' or 'likelihood' (protocol.calibration.method; auto: amortized for a
        measured acquisition when an estimator ships for the class and K)."""
        from ..inference.amortized.shipped import shipped_path

        method = self.cfg.protocol.calibration.method
        if method == "auto":
            ok = acquisition.phases == "uniform" and shipped_path(cls, acquisition.ramps).is_file()
            method = "amortized" if ok else "likelihood"
        return method

    def calibrate(self, cls: str, acquisition) -> dict:
        return self.cache.run(f"calibrate_{cls}", settings_key(self.calib_key, cls),
                              lambda: _jsonable(jobs.calibrate_class(self._calibration_job(cls, acquisition))),
                              needs=CALIBRATION_NEEDS)

    def calibrations(self, acquisition, executor) -> dict:
        """Every class calibrated (cached); with workers, the uncached classes at once."""
        todo = [c for c in self.cfg.classes
                if not self.cache.has(f"calibrate_{c}", settings_key(self.calib_key, c), CALIBRATION_NEEDS)]
        if len(todo) > 1 and self.cfg.workers > 1:
            work = [self._calibration_job(c, acquisition) for c in todo]
            for c in todo:
                self.cache.started(f"calibrate_{c}")
            for c, res in zip(todo, executor.map(jobs.calibrate_class, work)):
                self.cache.store(f"calibrate_{c}", settings_key(self.calib_key, c), _jsonable(res), res["seconds"])
        return {c: self.calibrate(c, acquisition) for c in self.cfg.classes}

    # ---- stages 3-4: candidates and the choice ---------------------------------------------
    def specs(self, calib: dict, tsaug_sources) -> dict[str, list[TrainingSpec]]:
        """{strategy: [spec, ...]}: every strategy at every value of its setting (the
        published one rendered as the published single chirp, never through the chain)."""
        p = self.cfg.protocol
        files = {"population": {c: calib[c]["population"] for c in self.cfg.classes}}
        posts = {c: calib[c]["posterior"] for c in self.cfg.classes}
        out = {}
        for name in p.strategies:
            s = STRATEGIES[name]
            if name == "tsaug":
                out[name] = [TrainingSpec(name, normalisation=p.normalisation, profiles=tsaug_sources[0],
                                          labels=tsaug_sources[1])]
                continue
            values = {"sigma_p": p.sigma_p, "width": p.specimen_widths, None: (None,)}[s.parameter]
            out[name] = [TrainingSpec(name, posteriors=files.get(name, posts), normalisation=p.normalisation,
                                      through_chain=bool(p.through_chain and s.study_chain),
                                      **({} if s.parameter is None else {s.parameter: float(v)}))
                         for v in values]
        return out

    def candidates(self, specs: dict, select, tests: dict, executor) -> dict:
        p = self.cfg.protocol
        sel_name, sel_data, _ = select
        sets = {n: (*xy, self.set_drones(n)) for n, xy in {sel_name: sel_data, **tests}.items()}

        def compute():
            todo = [(name, i, s) for name, ss in specs.items() if STRATEGIES[name].parameter is not None
                    for i, s in enumerate(ss)]
            job_list = [{"spec": s, "classes": list(self.cfg.classes), "n_per_class": p.sweep_n_per_class,
                         "seed": _stage_seed(self.cfg, "candidate", name, i), "models": list(p.models),
                         "tests": sets, "n_boot": p.n_boot} for name, i, s in todo]
            from ..radar.progress import progress_bar

            rows = []
            with progress_bar(total=len(job_list), desc="choice candidates", unit="candidate", leave=False) as bar:
                for (name, i, spec), res in zip(todo, _imap(executor, jobs.candidate, job_list)):
                    param = STRATEGIES[name].parameter
                    rows += [{"strategy": name, "parameter": param, "value": r.pop("sigma_p"), **r} for r in res]
                    bar.update(1)
            return {"rows": rows, "selection_set": sel_name}
        return self.cache.run("candidates", settings_key(self.cand_key, "rows of the sweep job"), compute,
                              needs=("rows", "selection_set"))

    @staticmethod
    def choose(rows: list[dict], strategy: str, on: str) -> dict:
        """The value of ``strategy``'s setting chosen on set ``on`` (:func:`.verdicts.choose_setting`)."""
        return verdicts.choose_setting(rows, strategy, STRATEGIES[strategy].parameter, on)

    # ---- figures -------------------------------------------------------------------------------
    def profiles_figure(self, specs: dict, choice: dict, tests: dict) -> str:
        """Measured (new-drone) profiles beside each model-based strategy's profiles."""
        from .figures import measured_vs_synthetic

        def compute():
            X, y = tests["new"] if "new" in tests else next(iter(tests.values()))
            synthetic = {}
            for name, ss in specs.items():
                if name == "tsaug":
                    continue
                spec = chosen_spec(ss, choice.get(name))
                Xs, ys, _ = training_set(spec, list(self.cfg.classes), 300 if not self.cfg.quick else 60,
                                              _stage_seed(self.cfg, "figure", name))
                synthetic[_label(name, spec)] = {c: Xs[ys == c] for c in self.cfg.classes}
            path = self.out / "figures" / "profiles.png"
            measured_vs_synthetic({c: X[y == c] for c in self.cfg.classes}, synthetic, path,
                                  self.cfg.protocol.normalisation)
            return str(path)
        return self.cache.run("profiles_figure", settings_key(self.cnn_key, sorted(
            (k, v.get("value")) for k, v in choice.items())), compute)

    # ---- stage 7: speed against error -----------------------------------------------------------------
    def speed(self, acquisition) -> dict:
        from .speed import stage_speed

        return self.cache.run("speed", settings_key(self.cfg.quick, acquisition.to_dict()),
                              lambda: stage_speed(acquisition, quick=self.cfg.quick))

    # ---- the whole study ----------------------------------------------------------------------------------
    def run(self) -> dict:
        t_start = time.perf_counter()
        executor = make_executor(self.cfg.workers, self.cfg.scheduler)
        try:
            index = self.data(executor)
            acq = self.acquisition(index)
            self.log(f"acquisition: {acq.describe()}")
            tests = self.test_sets(index)
            select = self.selection_set(index)
            calib = self.calibrations(acq, executor)
            tsaug_src = [self.load_set(f"calibration_{c}") for c in self.cfg.classes]
            specs = self.specs(calib, (np.concatenate([s[0] for s in tsaug_src]),
                                       np.concatenate([s[1] for s in tsaug_src])))
            cand = self.candidates(specs, select, tests, executor)
            sel_name = select[0]
            peek = "new" if "new" in tests else next(iter(tests))
            choice = {n: self.choose(cand["rows"], n, sel_name) for n in specs if STRATEGIES[n].parameter is not None}
            published_peeking = self.choose(cand["rows"], "sigma_p_published", peek) \
                if "sigma_p_published" in specs else None
            for n, c in choice.items():
                self.log(f"choice [{n}]: {c['parameter']} = {c['value']} (on '{sel_name}')")
            strategies, ceiling = self.training(self.cnn_jobs(specs, choice, select, tests),
                                                self.ceiling_job(tests, select) if self.cfg.simulated else None,
                                                executor)
            figure = self.profiles_figure(specs, choice, tests)
            speed = self.speed(acq)
        finally:
            executor.close()
        classes = list(self.cfg.classes)
        truth = {n: statistics.truth(yt, sorted(classes), self.set_drones(n))
                 for n, (_, yt) in {sel_name: select[1], **tests}.items()}
        results = {
            "config": self.cfg.to_dict(), "invocation": self.invocation, "simulated": self.cfg.simulated,
            "data": index["sets"], "acquisition": index["acquisition"], "acquisition_text": acq.describe(),
            "selection": {"set": sel_name, "what": select[2]},
            "calibration": calib, "candidates": cand, "choice": choice, "published_peeking_choice": published_peeking,
            "truth": truth, "strategies": _jsonable(strategies), "strategy_text": {n: STRATEGIES[n].text for n in strategies},
            "ceiling": _jsonable(ceiling), "speed": speed, "profiles_figure": figure,
            "timings": dict(self.cache.timings), "resumed_stages": list(self.cache.resumed),
            "total_seconds": time.perf_counter() - t_start,
        }
        statistics.score_study(results)
        results["best_strategy"] = verdicts.best_strategy(results["strategies"], sel_name)
        if ceiling is not None:
            results["ceiling"]["chosen"] = verdicts.ceiling_choice(results["ceiling"]["models"], sel_name)
        results["verdicts"] = verdicts.judge(results)
        write_results(results, self.out)  # strict JSON, paths relative to the study folder
        from .report import write_report

        write_report(results, self.out / "report.html")
        return results


def stage_names(cfg: StudyConfig) -> list[str]:
    """The stages a study of ``cfg`` runs, in order."""
    names = ["data", *(f"calibrate_{c}" for c in cfg.classes), "candidates",
             *(f"cnn_{s}" for s in cfg.protocol.strategies)]
    return names + (["ceiling"] if cfg.simulated else []) + ["profiles_figure", "speed"]


def _label(name: str, spec: TrainingSpec) -> str:
    param = STRATEGIES[name].parameter
    return name + ("" if param is None else f" ({param} {spec.setting:g})")


def _imap(executor, fn, items):
    """Results of fn over items in order: one at a time serially (so a progress bar
    moves), or the executor's map."""
    if executor.name == "serial":
        return (fn(item) for item in items)
    return executor.map(fn, items)
