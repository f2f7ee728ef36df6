"""The main job: calibrate, augment two ways, classify, compare (``mdaug run``).

Stages (each cached in ``DIR/stages`` so an interrupted run resumes):

1. ``data``: the measured sets: calibration profiles per class and the test sets
   (``old``: other acquisitions of the calibration drones, ``new``: new drone
   specimens, ``mix``: both, ``new_large``: a bigger new-drone campaign). From the
   embedded scene simulator by default, or from the files of a study config.
2. ``calibrate_<CLASS>``: nlopt fit + emcee posterior of each class (mdaug.inference).
3. ``sweep_<nuisance>``: the published sigma_P protocol with the fast classifiers, for
   every nuisance treatment on the study's nuisance axis.
4. ``choice``: sigma_P picked the published way (best on the new-drone test set: it
   peeks at the test data) and without peeking (best on the ``old`` set, i.e. other
   acquisitions of the calibration drones; ties go to the smaller sigma_P).
5. ``cnn_<strategy>``: the CNN trained on each strategy's set (sigma_P at the
   non-peeking choice with published and uniform nuisances, posterior draws, tsaug
   on the calibration measurements) and tested on every test set.
6. ``ceiling``: for simulated campaigns, a classifier trained on the simulator's own
   data (other seeds and specimens): the separability ceiling of the setting.
7. ``speed``: speed against error of the generator's float32 and float64 paths.
"""
from __future__ import annotations

import dataclasses
import json
import time
from functools import partial
from pathlib import Path

import numpy as np

from ..radar import atomic_savez, atomic_write, load_profiles
from .cache import StageCache, settings_key
from .config import StudyConfig, nuisance_preset
from .executor import make_executor
from . import jobs

STRATEGY_NUISANCE = {"sigma_p": "published", "sigma_p_matched": "matched", "posterior": "matched", "tsaug": None}


def _seed(cfg: StudyConfig, *keys) -> int:
    """A child seed of the study's one seed, stable for a given stage name."""
    words = [sum(ord(ch) * 31 ** i for i, ch in enumerate(str(k))) % (2**31) for k in keys]
    return int(np.random.SeedSequence([cfg.seed, *words]).generate_state(1)[0])


class Study:
    def __init__(self, cfg: StudyConfig, out: Path, log=print):
        self.cfg = cfg.validate()
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        for sub in ("data", "posteriors", "models", "figures"):
            (self.out / sub).mkdir(exist_ok=True)
        self.log = log
        self.cache = StageCache(self.out, log)
        # each stage's cache key covers only what the stage depends on, so changing,
        # say, the CNN's epochs does not redo the calibration
        c, p = cfg.to_dict(), cfg.to_dict()["protocol"]
        self.key = settings_key(c["seed"], c["classes"], c["data"], c["simulation"])  # the measured sets
        self.calib_key = settings_key(self.key, c["quick"], {k: v for k, v in p.items() if k.startswith("calibration")})
        self.sweep_key = settings_key(self.key, [p[k] for k in ("sigma_p", "models", "sweep_n_per_class", "acquisition_ramps",
                                                                 "normalisation", "n_boot")])
        self.cnn_key = settings_key(self.calib_key, [p[k] for k in ("cnn_n_per_class", "cnn_epochs", "cnn_patience", "acquisition_ramps",
                                                                     "tsaug_n_per_class", "tsaug_epochs",
                                                                     "normalisation", "n_boot")])

    def nuisance(self, name: str):
        return nuisance_preset(name, self.cfg.protocol.acquisition_ramps)

    # ---- stage 1: data -----------------------------------------------------
    def data(self) -> dict:
        def compute():
            sets = self._simulated_sets() if self.cfg.simulated else self._file_sets()
            index = {}
            for name, (X, y) in sets.items():
                path = self.out / "data" / f"{name}.npz"
                atomic_savez(path, profiles=np.asarray(X, dtype=np.float64), labels=np.asarray(y).astype(str))
                index[name] = {"path": str(path), "n": int(len(y)),
                               "per_class": {c: int(np.sum(np.asarray(y) == c)) for c in self.cfg.classes}}
            return index
        return self.cache.run("data", self.key, compute)

    def _file_sets(self) -> dict:
        sets = {}
        for cls, path in self.cfg.data.calibration.items():
            ps = load_profiles(path)
            sets[f"calibration_{cls}"] = (ps.select(cls), np.full(len(ps.select(cls)), cls))
        for name, path in self.cfg.data.test.items():
            ps = load_profiles(path)
            unknown = sorted(set(ps.classes) - set(self.cfg.classes))
            if unknown:
                raise ValueError(f"{path}: field 'labels' holds class(es) {unknown} not in the study's "
                                 f"classes {list(self.cfg.classes)}")
            sets[name] = (ps.profiles, ps.labels)
        return sets

    def _simulated_sets(self) -> dict:
        from ..generator.scene import SceneConfig, simulate_campaign

        sim, sets = self.cfg.simulation, {}
        old, new, large = {}, {}, {}
        for cls in self.cfg.classes:
            n_old_test = max(sim.n_new.get(cls, 10) // 3, 4)
            camp = simulate_campaign(cls, 1, sim.n_calibration + n_old_test, _seed(self.cfg, "old", cls),
                                     scene=dataclasses.replace(SceneConfig(), **self._reference_specimen()))
            sets[f"calibration_{cls}"] = (camp.profiles[: sim.n_calibration], camp.labels[: sim.n_calibration])
            old[cls] = (camp.profiles[sim.n_calibration:], camp.labels[sim.n_calibration:])
            n = sim.n_new.get(cls, 44)
            camp = simulate_campaign(cls, sim.new_specimens, n, _seed(self.cfg, "new", cls))
            new[cls] = (camp.profiles, camp.labels)
            if sim.large_factor > 1:
                camp = simulate_campaign(cls, 2 * sim.new_specimens, n * sim.large_factor,
                                         _seed(self.cfg, "new_large", cls))
                large[cls] = (camp.profiles, camp.labels)

        def cat(parts):
            return (np.concatenate([p[0] for p in parts.values()]), np.concatenate([p[1] for p in parts.values()]))

        sets["old"], sets["new"] = cat(old), cat(new)
        sets["mix"] = (np.concatenate([sets["old"][0], sets["new"][0]]),
                       np.concatenate([sets["old"][1], sets["new"][1]]))
        if large:
            sets["new_large"] = cat(large)
        return sets

    @staticmethod
    def _reference_specimen() -> dict:
        """Scene overrides that make the specimen the class reference itself."""
        from ..generator.scene import SceneConfig

        fields = {f.name for f in dataclasses.fields(SceneConfig)}
        return {name: 0.0 for name in fields if "spread" in name}

    def load_set(self, name: str):
        ps = load_profiles(self.out / "data" / f"{name}.npz")
        return ps.profiles, ps.labels

    def test_sets(self, index: dict) -> dict:
        return {name: self.load_set(name) for name in index if not name.startswith("calibration_")}

    # ---- stage 2: calibration --------------------------------------------------
    def calibrate(self, cls: str) -> dict:
        from ..inference import CalibrationSettings, calibrate

        def compute():
            X, _ = self.load_set(f"calibration_{cls}")
            p = self.cfg.protocol
            base = CalibrationSettings.quick(polish_budget=600) if self.cfg.quick else CalibrationSettings()
            settings = base.replace(max_steps=p.calibration_max_steps, n_starts=p.calibration_starts,
                                    fit_budget=p.calibration_fit_budget,
                                    check_every=min(base.check_every, p.calibration_max_steps))
            checkpoint = self.out / "posteriors" / f"{cls}.chain.h5"
            res = calibrate(X, cls, settings=settings, random_state=_seed(self.cfg, "calibrate", cls),
                            backend_path=checkpoint)
            nc = self.out / "posteriors" / f"{cls}.nc"
            res.save(nc)
            checkpoint.unlink(missing_ok=True)  # only needed to resume an interrupted chain
            corner_png = self.out / "figures" / f"corner_{cls}.png"
            trace_png = self.out / "figures" / f"trace_{cls}.png"
            res.plot_corner(corner_png, max_params=16)  # a 52-parameter corner is unreadable
            res.plot_trace(trace_png)
            return {"posterior": str(nc), "corner": str(corner_png), "trace": str(trace_png),
                    "converged": bool(res.converged), "diagnostics": _jsonable(res.diagnostics),
                    "summary": _jsonable(res.summary()), "n_profiles": int(len(X))}
        return self.cache.run(f"calibrate_{cls}", settings_key(self.calib_key, cls), compute)

    # ---- stage 3: sigma_P sweeps ---------------------------------------------
    def sweep(self, nuisance: str, tests: dict, executor) -> dict:
        from ..classify import sigma_p_sweep

        p = self.cfg.protocol

        def compute():
            make_train = partial(jobs.sigma_p_training_set, classes=list(self.cfg.classes),
                                 n_per_class=p.sweep_n_per_class,
                                 nuisance=dataclasses.asdict(self.nuisance(nuisance)),
                                 normalisation=p.normalisation)
            make_train.cache_key = settings_key(self.sweep_key, nuisance)  # lets the sweep resume per sigma_P
            res = sigma_p_sweep(make_train, tests, sigma_ps=p.sigma_p, models=p.models, n_boot=p.n_boot,
                                random_state=_seed(self.cfg, "sweep", nuisance), executor=executor,
                                cache_dir=self.out / "stages" / f"sweep_{nuisance}")  # progress: bar of the cells on a terminal
            png = self.out / "figures" / f"sweep_{nuisance}.png"
            res.plot(png)
            res.to_csv(self.out / f"sweep_{nuisance}.csv")
            return {"rows": _jsonable(res.rows), "figure": str(png)}
        return self.cache.run(f"sweep_{nuisance}", settings_key(self.sweep_key, nuisance), compute)

    @staticmethod
    def choose_sigma(rows: list[dict], test_set: str) -> dict:
        """The sigma_P with the best mean accuracy over the fast classifiers on one set."""
        by_sigma: dict[float, list[float]] = {}
        for r in rows:
            if r["test_set"] == test_set:
                by_sigma.setdefault(float(r["sigma_p"]), []).append(r["accuracy"])
        means = {s: float(np.mean(v)) for s, v in sorted(by_sigma.items())}
        best = max(means.values())
        chosen = min(s for s, m in means.items() if m == best)
        return {"sigma_p": chosen, "test_set": test_set, "mean_accuracy": means}

    # ---- stage 5: CNN per strategy -----------------------------------------------
    def cnn_jobs(self, sigma: dict[str, float], tests: dict, calib: dict) -> list[dict]:
        """One job per CNN strategy; model-based ones at their nuisance's chosen sigma_P."""
        p = self.cfg.protocol
        # tsaug (as published) augments the measurements of the old drones: the
        # calibration profiles and the 'old' set; it is then tested only on sets that
        # share no profile with its sources
        sources = [self.load_set(f"calibration_{c}") for c in self.cfg.classes]
        if "old" in tests:
            sources.append(tests["old"])
        src_X = np.concatenate([s[0] for s in sources])
        src_y = np.concatenate([s[1] for s in sources])
        unseen = {k: v for k, v in tests.items() if k not in ("old", "mix")}
        out = []
        for name in p.cnn_strategies:
            job = {"name": name, "model": "cnn", "classes": list(self.cfg.classes), "tests": tests,
                   "n_boot": p.n_boot, "normalisation": p.normalisation,
                   "seed": _seed(self.cfg, "cnn", name),
                   "model_path": str(self.out / "models" / f"cnn_{name}.zip")}
            if name == "tsaug":
                job.update(strategy_kind="tsaug", profiles=src_X, labels=src_y, n_per_class=p.tsaug_n_per_class,
                           model_params={"epochs": p.tsaug_epochs, "patience": p.cnn_patience},
                           tests=unseen or tests)
            else:
                kind = "posterior" if name == "posterior" else "sigma_p"
                if kind == "sigma_p":
                    job["sigma_p"] = sigma[STRATEGY_NUISANCE[name]]
                job.update(strategy_kind=kind, n_per_class=p.cnn_n_per_class,
                           nuisance=dataclasses.asdict(self.nuisance(STRATEGY_NUISANCE[name])),
                           posteriors={c: calib[c]["posterior"] for c in self.cfg.classes},
                           model_params={"epochs": p.cnn_epochs, "patience": p.cnn_patience})
            out.append(job)
        return out

    def cnn(self, job: dict) -> dict:
        return self.cache.run(f"cnn_{job['name']}", self._cnn_key(job), lambda: _jsonable(jobs.train_and_test(job)))

    def _cnn_key(self, job: dict) -> str:
        return settings_key(self.cnn_key, job["name"], job.get("sigma_p"))

    def profiles_figure(self, sigma: dict[str, float], tests: dict, calib: dict) -> str:
        """Measured (new-drone) profiles beside the sigma_P and posterior training sets."""
        from ..generator import SigmaPAugmenter
        from ..inference import PosteriorAugmenter
        from .figures import measured_vs_synthetic

        def compute():
            X, y = tests["new"] if "new" in tests else next(iter(tests.values()))
            n, seed, matched = 400, _seed(self.cfg, "figure"), self.nuisance("matched")
            sp, sm = sigma["published"], sigma["matched"]
            synthetic = {
                f"sigma_P={sp} (published nuisance)": {
                    c: SigmaPAugmenter(c, sp, random_state=seed).sample(n).profiles for c in self.cfg.classes},
                f"sigma_P={sm} (matched nuisance)": {
                    c: SigmaPAugmenter(c, sm, nuisance=matched, random_state=seed).sample(n).profiles
                    for c in self.cfg.classes},
                "posterior (matched nuisance)": {
                    c: PosteriorAugmenter(calib[c]["posterior"], label=c, nuisance=matched,
                                          random_state=seed).sample(n).profiles for c in self.cfg.classes},
            }
            path = self.out / "figures" / "profiles.png"
            measured_vs_synthetic({c: X[y == c] for c in self.cfg.classes}, synthetic, path,
                                  self.cfg.protocol.normalisation)
            return str(path)
        return self.cache.run("profiles_figure", settings_key(self.calib_key, sorted(sigma.items()),
                                                              self.cfg.protocol.acquisition_ramps), compute)

    # ---- stage 6: separability ceiling -----------------------------------------------
    def ceiling(self, tests: dict) -> dict:
        from ..classify import evaluate, make_classifier
        from ..generator.scene import simulate_campaign

        sim, p = self.cfg.simulation, self.cfg.protocol

        def compute():
            parts = [simulate_campaign(c, 2 * sim.new_specimens, sim.ceiling_per_class, _seed(self.cfg, "ceiling", c))
                     for c in self.cfg.classes]
            X = np.concatenate([c.profiles for c in parts])
            y = np.concatenate([c.labels for c in parts])
            result = {"n_train": int(len(y)), "models": {}}
            for model in ("svm", "xgb", "nb"):
                clf = make_classifier(model, random_state=_seed(self.cfg, "ceiling", model))
                t0 = time.perf_counter()
                clf.fit(X, y)
                result["models"][model] = {
                    "train_seconds": time.perf_counter() - t0,
                    "tests": {n: evaluate(yt, clf.predict(Xt), labels=sorted(self.cfg.classes), n_boot=p.n_boot,
                                          random_state=0) for n, (Xt, yt) in tests.items()
                              if not n.startswith("old") and n != "mix"}}
            return result
        return self.cache.run("ceiling", settings_key(self.key, self.cfg.protocol.n_boot), compute)

    # ---- stage 7: generator speed against error --------------------------------------
    def speed(self) -> dict:
        from ..generator import SigmaPAugmenter, profiles

        def compute():
            x = SigmaPAugmenter("QUAD", 0.2, random_state=0).sample_params(4000 if not self.cfg.quick else 1000)
            rows, ref = [], None
            for dtype in ("float64", "float32"):
                t0 = time.perf_counter()
                prof = profiles(x, dtype=dtype)
                sec = time.perf_counter() - t0
                ref = prof if ref is None else ref
                rows.append({"stage": "generator", "setting": f"f(x) QUAD {dtype}", "seconds": sec,
                             "rate_per_s": len(x) / sec, "error": float(np.max(np.abs(prof - ref))),
                             "error_metric": "max |profile - float64|"})
            return {"rows": rows}
        return self.cache.run("speed", settings_key(self.cfg.quick), compute)

    # ---- the whole study -------------------------------------------------------------
    def run(self) -> dict:
        t_start = time.perf_counter()
        executor = make_executor(self.cfg.workers, self.cfg.scheduler)
        try:
            index = self.data()
            tests = self.test_sets(index)
            calib = {c: self.calibrate(c) for c in self.cfg.classes}
            sweeps = {n: self.sweep(n, tests, executor) for n in self.cfg.protocol.nuisances}
            peek_set = "new" if "new" in tests else next(iter(tests))
            honest_set = "old" if "old" in tests else peek_set
            by_nuisance = {n: {"published_peeking": self.choose_sigma(sw["rows"], peek_set),
                               "non_peeking": self.choose_sigma(sw["rows"], honest_set)} for n, sw in sweeps.items()}
            choice = {**by_nuisance.get("published", next(iter(by_nuisance.values()))), "by_nuisance": by_nuisance}
            for n, c in by_nuisance.items():
                self.log(f"sigma_P [{n}]: {c['non_peeking']['sigma_p']} non-peeking (on '{honest_set}'), "
                         f"{c['published_peeking']['sigma_p']} the published way (peeks at '{peek_set}')")
            sigma = {n: by_nuisance.get(n, choice)["non_peeking"]["sigma_p"]
                     for n in set(STRATEGY_NUISANCE.values()) - {None}}
            cnn_jobs = self.cnn_jobs(sigma, tests, calib)
            todo = [j for j in cnn_jobs if not self.cache.has(f"cnn_{j['name']}", self._cnn_key(j))]
            if len(todo) > 1 and self.cfg.workers > 1:
                for job, res in zip(todo, executor.map(jobs.train_and_test, todo)):
                    self.cache.store(f"cnn_{job['name']}", self._cnn_key(job), _jsonable(res),
                                     res["data_seconds"] + res["train_seconds"])
            strategies = {j["name"]: self.cnn(j) for j in cnn_jobs}
            figure = self.profiles_figure(sigma, tests, calib)
            ceiling = self.ceiling(tests) if self.cfg.simulated else None
            speed = self.speed()
        finally:
            executor.close()
        results = {
            "config": self.cfg.to_dict(), "simulated": self.cfg.simulated, "data": index,
            "calibration": calib, "sweeps": sweeps, "sigma_p_choice": choice, "strategies": strategies,
            "ceiling": ceiling, "speed": speed, "profiles_figure": figure, "timings": dict(self.cache.timings),
            "resumed_stages": list(self.cache.resumed), "total_seconds": time.perf_counter() - t_start,
        }
        text = json.dumps(_jsonable(results), indent=1)
        atomic_write(self.out / "results.json", lambda fh: fh.write(text.encode()))
        from .report import write_report

        write_report(results, self.out / "report.html")
        return results

def _jsonable(obj):
    """Plain Python types for JSON (numpy scalars and arrays converted)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "to_dict") and hasattr(obj, "index"):  # a pandas table: {row: {column: value}}
        return _jsonable(obj.to_dict(orient="index"))
    return obj
