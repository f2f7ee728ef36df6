"""Classifier verbs: ``mdaug train``, ``evaluate``, ``sweep`` (the published sigma_P
protocol) and ``baseline`` (tsaug).

The sweep builds its synthetic training sets with mdaug.generator
(:class:`SyntheticTrainSet`); mdaug.classify itself only trains on arrays.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from .common import (SECONDS_CNN_PROFILE, SECONDS_FAST_RAMP, SECONDS_RESAMPLE, SECONDS_TREE_BIN, SECONDS_TSAUG,
                     add_classifier_options, acquisition_from_args, add_acquisition_options, add_verb, check_size,
                     check_training_memory, class_list, count_2, csv_list, info, load_profile_file, model_list,
                     model_params, nonneg_int, nothing_written, positive_int, result, seed_int, sigma_list)

CNN_BINS = 400  # the CNN's 1 x 20 x 20 input
SWEEP_FILES = ("sweep.csv", "sweep.md", "settings.json", "sweep.png", "jobs/")
"""What ``mdaug sweep`` writes in its --out folder."""


def _paths(text: str) -> list[Path]:
    return [Path(t) for t in csv_list(text)]


def check_training_sizes(args, model: str, n_profiles: int, repeats: int = 1) -> None:
    """Epochs and trees against time for ``repeats`` trainings on ``n_profiles`` profiles."""
    if model == "cnn":
        check_size(("--epochs", args.epochs, 50), seconds_each=n_profiles * repeats * SECONDS_CNN_PROFILE,
                   what="profile epochs")
    if model == "xgb":
        check_size(("--n-estimators", args.n_estimators, 100), seconds_each=n_profiles * repeats * CNN_BINS *
                   SECONDS_TREE_BIN, what="trees")


def check_boot_size(n_boot: int, n_predictions: int) -> None:
    """Bootstrap resamples against time (``n_predictions`` resampled per resample)."""
    check_size(("--n-boot", n_boot, 1000), seconds_each=n_predictions * SECONDS_RESAMPLE, bytes_each=200,
               what="bootstrap resamples")


def _check_test(model, test, path):
    x = model.check_input(test.profiles, source=f"{path}: field 'profiles'")
    y = model.check_labels(test.labels, source=f"{path}: field 'labels'")
    return x, y


# ---- train ------------------------------------------------------------------------------------
def run_train(args) -> int:
    from ..classify.models import make_classifier
    from ..classify.persist import save_model
    from ..radar import DataFileError
    from .guard import Output, check_paths

    check_paths(inputs=[("DATA", args.data)], outputs=[Output("--out", args.out, "model")])
    cnn = args.model == "cnn"
    data = load_profile_file(args.data, length=CNN_BINS if cnn else None, why="the CNN (1 x 20 x 20 input)")
    if len(data.classes) < 2:
        raise DataFileError(f"{args.data}: field 'labels' holds only class(es) {data.classes}; training needs "
                            "at least 2")
    check_training_sizes(args, args.model, len(data))
    model = make_classifier(args.model, random_state=args.seed, **model_params(args, args.model))
    info(f"training {args.model} on {len(data)} profiles x {data.profiles.shape[1]} bins "
         f"({', '.join(data.classes)}) from {args.data}")
    model.fit(data.profiles, data.labels)
    save_model(model, args.out)
    result(f"trained in {model.train_seconds_:.1f} s; wrote {args.out}")
    if cnn:
        s = model.split_scores_
        result(f"best epoch {s['best_epoch']}/{s['epochs_run']}: validation accuracy {s['val_accuracy']:.3f}; "
               f"held-out 10% split ({s['n_test']} profiles) accuracy {s['test_accuracy']:.3f}")
    return 0


def add_train(sub, parents, help):
    from ..classify.models import CLASSIFIERS

    p = add_verb(sub, "train", parents, help=help, interrupted=nothing_written,
                 description="Train a classifier on profiles + labels (NPZ, CSV or .mat) and save it as a model "
                             "file (a ZIP that loads without executing code).")
    p.add_argument("data", type=Path, help="training profiles (NPZ, CSV or .mat with profiles + labels)")
    p.add_argument("--model", choices=tuple(CLASSIFIERS), required=True,
                   help="svm, naive Bayes (nb), XGBoost (xgb) or the CNN of SPEC section 6 (400-bin profiles)")
    p.add_argument("--out", type=Path, required=True, help="model file to write (.zip)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the model and its splits (default: %(default)s)")
    add_classifier_options(p)
    p.set_defaults(func=run_train)
    return p


# ---- evaluate ---------------------------------------------------------------------------------
def run_evaluate(args) -> int:
    from ..classify.metrics import evaluate, format_metrics, plot_confusion
    from ..classify.persist import load_model
    from ..radar import atomic_write
    from .guard import Output, check_paths

    check_paths(inputs=[("MODEL", args.model), ("TEST", args.test)],
                outputs=[Output("--json", args.json, "json"), Output("--plot", args.plot, "plot")])
    model = load_model(args.model)
    test = load_profile_file(args.test)
    x, y = _check_test(model, test, args.test)
    check_boot_size(args.n_boot, len(y))
    m = evaluate(y, model.predict(x), labels=model.classes_.tolist(), n_boot=args.n_boot, random_state=args.seed)
    result(f"{model.name} model {args.model} on {args.test}")
    result(format_metrics(m))
    if args.json is not None:
        payload = json.dumps({**m, "model": str(args.model), "test": str(args.test), "kind": model.name},
                             indent=1).encode()
        atomic_write(args.json, lambda fh: fh.write(payload))
        result(f"wrote {args.json}")
    if args.plot is not None:
        from ..radar.plots import save_figure

        fig = plot_confusion(m, title=f"{model.name} on {Path(args.test).name}: accuracy {m['accuracy']:.1%}")
        save_figure(fig, args.plot)
        result(f"wrote {args.plot}")
    return 0


def add_evaluate(sub, parents, help):
    p = add_verb(sub, "evaluate", parents, help=help, interrupted=nothing_written,
                 description="Accuracy, balanced accuracy, per-class precision and recall, the confusion matrix "
                             "and bootstrap 95% intervals of a trained model on a labelled test file.")
    p.add_argument("model", type=Path, help="model file written by 'mdaug train' or 'mdaug baseline'")
    p.add_argument("test", type=Path, help="test profiles (NPZ, CSV or .mat with profiles + labels)")
    p.add_argument("--json", type=Path, default=None, help="also write the metrics as JSON (default: none)")
    p.add_argument("--plot", type=Path, default=None, help="also write the confusion matrix as PNG (default: none)")
    p.add_argument("--n-boot", type=nonneg_int, default=1000, metavar="N",
                   help="bootstrap resamples of the intervals, 0 = no intervals (default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="bootstrap seed (default: %(default)s)")
    p.set_defaults(func=run_evaluate)
    return p


# ---- sweep ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SyntheticTrainSet:
    """Picklable ``make_train(sigma_p, seed) -> (X, y)`` for the sweep: the registry's
    sigma_p_published sets (:mod:`mdaug.strategies`) of ``classes`` under the given
    acquisition (``n_per_class`` profiles per class)."""

    classes: tuple
    n_per_class: int
    acquisition: dict = None
    perturb_phases: bool = True
    normalisation: str = "peak"
    dtype: str = "float32"
    sign_policy: str = "reflect"

    @property
    def cache_key(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def __call__(self, sigma_p: float, seed: int):
        from ..strategies import TrainingSpec, training_set

        spec = TrainingSpec("sigma_p_published", sigma_p=sigma_p, normalisation=self.normalisation,
                            acquisition=self.acquisition or {}, sign_policy=self.sign_policy,
                            perturb_phases=self.perturb_phases, dtype=self.dtype)
        X, y, _ = training_set(spec, self.classes, self.n_per_class, seed)
        return X, y


def check_sweep_sizes(args, acq, n_test: int) -> None:
    """Every size of the sweep against memory and time: the synthetic sets (their ramps
    included), the trainings, the bootstrap, the workers' copies."""
    from ..generator import load_reference

    cells = len(args.classes) * len(args.sigma_p)
    engines = max(load_reference(c).n_engines for c in args.classes)
    n = ("--n-per-class", args.n_per_class, 4000)
    check_size(n, ("--ramps", acq.ramps, 32), seconds_each=cells * engines * SECONDS_FAST_RAMP,
               what="rendered ramps")
    for m in args.models:
        check_training_sizes(args, m, args.n_per_class, cells)
    check_boot_size(args.n_boot, n_test * len(args.sigma_p) * len(args.models))
    check_size(("--workers", args.workers, 1), n, bytes_each=len(args.classes) * CNN_BINS * 8 * 3,
               what="training profiles held at once")
    check_size(("--workers", args.workers, 1), bytes_each=300 * 2 ** 20, what="worker processes")


def run_sweep(args) -> int:
    from ..classify.protocol import sigma_p_sweep
    from ..generator import load_reference
    from ..radar import DataFileError, RadarConfig, atomic_write

    from .guard import Output, check_paths

    check_paths(inputs=[*(("--test", p) for p in args.test), ("--select", args.select)],
                outputs=[Output("--out", args.out, "folder", inside=SWEEP_FILES)])
    out = Path(args.out)
    for c in args.classes:
        load_reference(c)  # unknown class: fail before any work
    check_training_memory(2 * args.n_per_class, "--n-per-class", args.n_per_class, len(args.classes))
    length = RadarConfig().slice_length
    tests = {}
    for path in args.test + ([args.select] if args.select is not None else []):
        ps = load_profile_file(path, length=length, why="the synthetic training set (400-bin signatures)")
        unknown = sorted(set(ps.classes) - set(args.classes))
        if unknown:
            raise DataFileError(f"{path}: field 'labels' holds classes {unknown} that are not trained "
                                f"(--classes {','.join(args.classes)})")
        name = SELECT if path is args.select else path.stem
        if name in tests:
            raise ValueError(f"--test: two test files share the name {name!r}; rename one")
        tests[name] = (ps.profiles, ps.labels)
    acq, perturb = acquisition_from_args(args)
    check_sweep_sizes(args, acq, sum(len(v[1]) for v in tests.values()))
    make_train = SyntheticTrainSet(tuple(args.classes), args.n_per_class, acquisition=acq.to_dict(),
                                   perturb_phases=perturb, normalisation=args.normalisation, dtype=args.dtype,
                                   sign_policy=args.sign_policy)
    params = {m: model_params(args, m) for m in args.models}
    out.mkdir(parents=True, exist_ok=True)
    executor = None
    if args.workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        from ..radar.progress import quiet_worker

        executor = ProcessPoolExecutor(args.workers, initializer=quiet_worker)
    info(f"sweep: {len(args.sigma_p)} sigma_P x {len(args.models)} models, {2 * args.n_per_class} training "
         f"profiles each, tests {', '.join(f'{k} ({len(v[1])})' for k, v in tests.items())}")
    try:
        res = sigma_p_sweep(make_train, tests, sigma_ps=args.sigma_p, models=args.models, random_state=args.seed,
                            executor=executor, model_params=params, n_boot=args.n_boot,
                            cache_dir=None if args.no_resume else out / "jobs")
    finally:
        if executor is not None:
            executor.shutdown(cancel_futures=True)
    res.settings["make_train"] = asdict(make_train)
    res.settings["test_files"] = [str(p) for p in args.test]
    md = res.to_markdown()
    if args.select is not None:
        res.settings["select_file"] = str(args.select)
        md += "\n" + honest_choice(res, args.select)
    res.to_csv(out / "sweep.csv")
    atomic_write(out / "sweep.md", lambda fh: fh.write(md.encode()))
    atomic_write(out / "settings.json", lambda fh: fh.write(json.dumps(res.settings, indent=1).encode()))
    res.plot(out / "sweep.png")
    result(md)
    result(f"wrote {out / 'sweep.csv'}, {out / 'sweep.md'}, {out / 'sweep.png'} "
           f"({res.settings['seconds']:.0f} s, {res.settings['resumed_jobs']} sigma_P points reused)")
    return 0


SELECT = "select"  # the name of the --select set among the sweep's sets


def honest_choice(res, path) -> str:
    """Markdown: per model, the sigma_P with the best balanced accuracy on the selection
    set (ties: the smaller sigma_P), and what it scores on every test set."""
    tests = [t for t in res.test_sets if t != SELECT]
    lines = [f"**sigma_P chosen on the selection set** ({path}, disjoint from the test sets: no peeking) by balanced "
             "accuracy, and its scores on the test sets\n",
             "| model | sigma_P | balanced on the selection set | " + " | ".join(f"balanced on {t}" for t in tests) + " |",
             "|---" * (3 + len(tests)) + "|"]
    for m in res.models:
        b = res.best(m, SELECT, "balanced_accuracy")
        scores = [next(r["balanced_accuracy"] for r in res.rows if r["model"] == m and r["test_set"] == t
                       and r["sigma_p"] == b["sigma_p"]) for t in tests]
        lines.append(f"| {m} | {b['sigma_p']:.2f} | {100 * b['balanced_accuracy']:.1f} | "
                     + " | ".join(f"{100 * s:.1f}" for s in scores) + " |")
    return "\n".join(lines) + "\n"


def _sweep_interrupted(args) -> str:
    if args.no_resume:
        return "finished sigma_P points were not kept (--no-resume)"
    return f"finished sigma_P points are kept in {Path(args.out) / 'jobs'}; run the same command again to resume"


def add_sweep(sub, parents, help):
    from ..classify.protocol import FAST_MODELS, PUBLISHED_SIGMA_PS
    from ..generator.augment import SIGN_POLICIES

    p = add_verb(sub, "sweep", parents, help=help, interrupted=_sweep_interrupted,
                 description="Train classifiers on synthetic sigma_P sets and test them on measured sets; "
                             "writes sweep.csv, sweep.md and sweep.png to --out. An interrupted run resumes "
                             "from --out/jobs.")
    p.add_argument("--test", type=_paths, required=True, metavar="FILES",
                   help="comma-separated measured test files (e.g. old.npz,new.npz), 400-bin profiles + labels")
    p.add_argument("--out", type=Path, required=True, help="output folder (created if needed)")
    p.add_argument("--select", type=Path, default=None, metavar="FILE",
                   help="measured selection set disjoint from the test files (e.g. more acquisitions of the "
                        "calibration drones): sigma_P is also chosen on it, the honest choice, and its test "
                        "scores are reported (default: none; the published pick on each test set peeks)")
    p.add_argument("--sigma-p", type=sigma_list, default=list(PUBLISHED_SIGMA_PS), metavar="LIST",
                   help="comma-separated sigma_P grid, each in [0, 1] (default: the published "
                        f"{','.join(f'{s:g}' for s in PUBLISHED_SIGMA_PS)})")
    p.add_argument("--models", type=model_list, default=list(FAST_MODELS), metavar="LIST",
                   help=f"comma-separated classifiers, of svm, nb, xgb, cnn (default: {','.join(FAST_MODELS)})")
    p.add_argument("--classes", type=class_list, default=["HELI", "QUAD"], metavar="LIST",
                   help="comma-separated class references (default: HELI,QUAD)")
    p.add_argument("--n-per-class", type=positive_int, default=4000, metavar="N",
                   help="synthetic profiles per class and sigma_P; the paper used 16000 (default: %(default)s)")
    p.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect",
                   help="sigma_P draws that flip a non-negative parameter's sign (default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of every training set and model (default: "
                                                             "%(default)s)")
    p.add_argument("--n-boot", type=nonneg_int, default=1000, metavar="N",
                   help="bootstrap resamples per score, 0 = no intervals (default: %(default)s)")
    p.add_argument("--workers", type=positive_int, default=1, metavar="N",
                   help="parallel processes, one sigma_P point each (default: %(default)s)")
    p.add_argument("--no-resume", action="store_true", help="ignore results of an earlier run in --out/jobs")
    add_acquisition_options(p)
    add_classifier_options(p, normalisation=False)
    p.set_defaults(func=run_sweep)
    return p


# ---- baseline -----------------------------------------------------------------------------------
def check_baseline_sizes(args, data) -> None:
    """Folds against the data, and the augmented sets and epochs against time."""
    import numpy as np

    if args.folds is not None:
        counts = {c: int(np.sum(data.labels == c)) for c in data.classes}
        few = min(counts, key=counts.get)
        if args.folds > counts[few]:
            raise ValueError(f"--folds {args.folds}: {args.data} holds only {counts[few]} profile(s) of class {few}; "
                             "every fold needs one of each class")
    trainings = (args.out is not None) + (args.folds or 0) + (args.out_set is not None)
    n = ("--n-per-class", args.n_per_class, 16000)
    check_size(n, seconds_each=len(data.classes) * trainings * SECONDS_TSAUG, what="tsaug profiles")
    check_size(n, ("--epochs", args.epochs, 100), seconds_each=len(data.classes) * trainings * SECONDS_CNN_PROFILE,
               what="profile epochs")


def run_baseline(args) -> int:
    from ..classify.metrics import evaluate, format_metrics
    from ..classify.persist import save_model
    from ..classify.tsaug_baseline import tsaug_baseline, tsaug_cross_validate
    from ..radar import DataFileError, atomic_write
    from .guard import Output, check_paths

    if args.folds is None and args.out is None and args.out_set is None:
        raise ValueError("give --out MODEL (train on all of DATA), --out-set NPZ (write the tsaug training set) "
                         "or --folds K (cross-validate on DATA)")
    if args.test and args.out is None:
        raise ValueError("--test scores the model trained on all of DATA: give --out MODEL too")
    check_paths(inputs=[("DATA", args.data), *(("--test", p) for p in args.test or [])],
                outputs=[Output("--out", args.out, "model"), Output("--out-set", args.out_set, "npz"),
                         Output("--json", args.json, "json")])
    data = load_profile_file(args.data, length=CNN_BINS, why="the CNN (1 x 20 x 20 input)")
    if len(data.classes) < 2:
        raise DataFileError(f"{args.data}: field 'labels' holds only class(es) {data.classes}; training needs "
                            "at least 2")
    check_training_memory(args.n_per_class * len(data.classes), "--n-per-class", args.n_per_class,
                          len(data.classes))
    check_baseline_sizes(args, data)
    tests = {}
    for path in args.test or []:  # read and check every test file before training
        test = load_profile_file(path, length=CNN_BINS, why="the CNN (1 x 20 x 20 input)")
        unknown = sorted(set(test.classes) - set(data.classes))
        if unknown:
            raise DataFileError(f"{path}: field 'labels' holds classes {unknown} that are not in {args.data} "
                                f"({data.classes})")
        tests[path] = test
    params = {k: v for k, v in model_params(args, "cnn").items() if k != "epochs"}
    report = {}
    if args.out_set is not None:  # the tsaug set itself, so that any classifier can train on it
        import numpy as np

        from ..classify.tsaug_baseline import TsaugSettings, tsaug_set
        from ..generator.dataset import SyntheticDataset, save_dataset
        from ..radar.seeds import seed_sequence

        xs, ys, src = tsaug_set(data.profiles, data.labels, args.n_per_class, seed_sequence(args.seed, "augment"),
                                normalisation=args.normalisation)
        from dataclasses import asdict

        ds = SyntheticDataset(profiles=xs, labels=ys, params={}, param_row=np.full(len(ys), -1),
                              settings={"strategy": "tsaug", "seed": args.seed, "source_file": str(args.data),
                                        "tsaug": asdict(TsaugSettings()), "normalisation": args.normalisation,
                                        "n_per_class": args.n_per_class, "classes": sorted(set(ys.tolist()))})
        save_dataset(args.out_set, ds)
        result(f"wrote {args.out_set}: {len(ys)} tsaug profiles of {len(data)} measured ones")
    if args.folds is not None:
        info(f"tsaug baseline, {args.folds}-fold cross-validation on {args.data} ({len(data)} profiles); "
             f"augmenting only inside each training fold")
        pred, _ = tsaug_cross_validate(data.profiles, data.labels, n_splits=args.folds, n_per_class=args.n_per_class,
                                       random_state=args.seed, epochs=args.epochs, **params)
        report["cross_validation"] = evaluate(data.labels, pred, random_state=args.seed)
        result(format_metrics(report["cross_validation"]))
    if args.out is not None:
        model = tsaug_baseline(data.profiles, data.labels, args.n_per_class, args.seed, epochs=args.epochs, **params)
        save_model(model, args.out)
        n_aug = args.n_per_class * len(data.classes)
        result(f"trained the tsaug-baseline CNN on {n_aug:,} tsaug-augmented profiles ({args.n_per_class:,} per "
               f"class) made from the {len(data)} measured profiles of {args.data}; wrote {args.out}")
        for path, test in tests.items():
            x, y = _check_test(model, test, path)
            report[str(path)] = evaluate(y, model.predict(x), labels=model.classes_.tolist(), random_state=args.seed)
            result(f"on {path}:")
            result(format_metrics(report[str(path)]))
    if args.json is not None:
        payload = json.dumps(report, indent=1).encode()
        atomic_write(args.json, lambda fh: fh.write(payload))
        result(f"wrote {args.json}")
    return 0


def add_baseline(sub, parents, help):
    p = add_verb(sub, "baseline", parents, help=help, interrupted=nothing_written,
                 description="Augment measured profiles with tsaug (drift + pool + reverse, as published) and "
                             "train the CNN (100 epochs as published): on all of DATA (--out, optionally scored "
                             "on --test files) and/or by k-fold cross-validation on DATA (--folds).")
    p.add_argument("data", type=Path, help="measured training profiles (NPZ, CSV or .mat), 400 bins")
    p.add_argument("--out", type=Path, default=None,
                   help="model file to write, trained on all of DATA (default: none; give --out or --folds)")
    p.add_argument("--test", type=_paths, default=None, metavar="FILES",
                   help="comma-separated test files to score the --out model on (default: none)")
    p.add_argument("--folds", type=count_2, default=None, metavar="K",
                   help="k-fold cross-validation on DATA, K >= 2 (default: none)")
    p.add_argument("--n-per-class", type=positive_int, default=16000, metavar="N",
                   help="augmented profiles per class (default: %(default)s)")
    p.add_argument("--out-set", type=Path, default=None, metavar="NPZ",
                   help="also write the tsaug training set (profiles + labels, the synthetic-dataset format), so "
                        "any classifier (mdaug train) can use it (default: none)")
    p.add_argument("--json", type=Path, default=None, help="also write the metrics as JSON (default: none)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of augmentation and CNN (default: %(default)s)")
    add_classifier_options(p, epochs_default=100, cnn_only=True)
    p.set_defaults(func=run_baseline)
    return p


VERBS = {
    "train": ("train a classifier (svm, nb, xgb, cnn) on a profile file", add_train),
    "evaluate": ("score a trained model on a labelled test file", add_evaluate),
    "sweep": ("the published sigma_P protocol (Table IV, Fig. 13)", add_sweep),
    "baseline": ("the conventional tsaug baseline (drift + pool + reverse, then the CNN)", add_baseline),
}
