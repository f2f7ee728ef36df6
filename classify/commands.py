"""CLI verbs of the classify layer: ``mdaug train``, ``mdaug evaluate``, ``mdaug sweep``.

This glue module is the only place in classify that imports mdaug.generator (the
sweep builds its synthetic training sets); everything else trains on arrays.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from pathlib import Path

from ..generator.commands import csv_list  # CLI glue: the only place classify uses the generator

MODELS = ("svm", "nb", "xgb", "cnn")


def _floats(text: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _model_params(args, name: str) -> dict:
    """Classifier parameters from the command line (only those that apply to ``name``)."""
    p = {"normalisation": args.normalisation, "threads": args.threads}
    if name == "cnn":
        p.update(epochs=args.epochs, batch_size=args.batch_size, patience=args.patience)
    elif name == "svm":
        p.update(kernel=args.kernel)
    elif name == "xgb":
        p.update(n_estimators=args.n_estimators)
    return p


def _add_model_options(p: argparse.ArgumentParser, epochs_default: int = 50) -> None:
    from ..radar import NORMALISATIONS

    g = p.add_argument_group("classifier options")
    if "--normalisation" not in p._option_string_actions:
        g.add_argument("--normalisation", choices=NORMALISATIONS, default="peak",
                       help="preprocessing shared by training and testing (default peak)")
    g.add_argument("--epochs", type=int, default=epochs_default, help="CNN epochs (default %(default)s)")
    g.add_argument("--batch-size", type=int, default=256, help="CNN batch size (default 256)")
    g.add_argument("--patience", type=int, default=None, help="CNN early stopping patience (epochs)")
    g.add_argument("--kernel", default="rbf", choices=("rbf", "linear", "poly", "sigmoid"),
                   help="SVM kernel (rbf = scikit-learn SVC default; linear = LinearSVC, fast)")
    g.add_argument("--n-estimators", type=int, default=100, help="XGBoost trees (default 100)")


def _load_set(path, what: str):
    from ..radar import load_profiles

    return load_profiles(path)


def run_train(args) -> int:
    from ..radar import check_writable
    from .models import make_classifier
    from .persist import save_model

    check_writable(args.out)
    data = _load_set(args.data, "training data")
    model = make_classifier(args.model, random_state=args.seed, **_model_params(args, args.model))
    print(f"training {args.model} on {len(data)} profiles x {data.profiles.shape[1]} bins "
          f"({', '.join(data.classes)}) from {args.data}")
    model.fit(data.profiles, data.labels)
    save_model(model, args.out)
    print(f"trained in {model.train_seconds_:.1f} s; wrote {args.out}")
    if args.model == "cnn":
        s = model.split_scores_
        print(f"best epoch {s['best_epoch']}/{s['epochs_run']}: validation accuracy {s['val_accuracy']:.3f}; "
              f"held-out 10% split ({s['n_test']} profiles) accuracy {s['test_accuracy']:.3f}")
    return 0


def run_evaluate(args) -> int:
    from ..radar import atomic_write, check_outputs
    from .metrics import evaluate, format_metrics, plot_confusion
    from .persist import load_model

    check_outputs(args.json, args.plot)
    model = load_model(args.model)
    test = _load_set(args.test, "test data")
    x = model.check_input(test.profiles, source=str(args.test))
    y = model.check_labels(test.labels, source=f"{args.test}: field 'labels'")
    m = evaluate(y, model.predict(x), labels=model.classes_.tolist(), n_boot=args.n_boot,
                 random_state=args.seed)
    print(f"{model.name} model {args.model} on {args.test}")
    print(format_metrics(m))
    if args.json is not None:
        payload = json.dumps({**m, "model": str(args.model), "test": str(args.test), "kind": model.name},
                             indent=1).encode()
        atomic_write(args.json, lambda fh: fh.write(payload))
        print(f"wrote {args.json}")
    if args.plot is not None:
        import matplotlib.pyplot as plt

        fig = plot_confusion(m, title=f"{model.name} on {Path(args.test).name}: accuracy {m['accuracy']:.1%}")
        atomic_write(args.plot, lambda fh: fig.savefig(fh, format="png", dpi=110))
        plt.close(fig)
        print(f"wrote {args.plot}")
    return 0


@dataclass(frozen=True)
class SyntheticTrainSet:
    """Picklable ``make_train(sigma_p, seed) -> (X, y)`` for the sweep: sigma_P sets
    of ``classes`` with the given nuisances (``n_per_class`` profiles per class)."""

    classes: tuple
    n_per_class: int
    phases: str = "relative"
    range_jitter_bins: float = 0.0
    n_ramps: int = 1
    normalisation: str = "peak"
    dtype: str = "float32"
    sign_policy: str = "reflect"

    @property
    def cache_key(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def __call__(self, sigma_p: float, seed: int):
        from ..generator import Nuisance, SigmaPAugmenter, make_dataset

        nuisance = Nuisance(phases=self.phases, range_jitter_bins=self.range_jitter_bins, n_ramps=self.n_ramps)
        augs = [SigmaPAugmenter(c, sigma_p, sign_policy=self.sign_policy, nuisance=nuisance,
                                normalisation=self.normalisation, dtype=self.dtype) for c in self.classes]
        ds = make_dataset(augs, self.n_per_class, seed, progress=False)
        return ds.profiles, ds.labels


def run_sweep(args) -> int:
    from ..radar import DataFileError, RadarConfig
    from .protocol import sigma_p_sweep

    if args.n_per_class <= 0:
        raise ValueError(f"--n-per-class must be a positive integer, got {args.n_per_class}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise DataFileError(f"{out}: --out must be a folder, found a file")
    length = RadarConfig().slice_length
    tests = {}
    for path in args.test:
        ps = _load_set(path, "test data")
        if ps.profiles.shape[1] != length:
            raise DataFileError(f"{path}: field 'profiles' has {ps.profiles.shape[1]}-bin profiles; the synthetic "
                                f"training profiles have {length} bins (extract 400-bin signatures first)")
        unknown = sorted(set(ps.classes) - set(args.classes))
        if unknown:
            raise DataFileError(f"{path}: field 'labels' holds classes {unknown} that are not trained "
                                f"(--classes {','.join(args.classes)})")
        name = Path(path).stem
        if name in tests:
            raise ValueError(f"two test files share the name {name!r}; rename one")
        tests[name] = (ps.profiles, ps.labels)
    make_train = SyntheticTrainSet(tuple(args.classes), args.n_per_class, phases=args.phases,
                                   range_jitter_bins=args.range_jitter, n_ramps=args.ramps,
                                   normalisation=args.normalisation, dtype=args.dtype,
                                   sign_policy=args.sign_policy)
    params = {m: _model_params(args, m) for m in args.models}
    out.mkdir(parents=True, exist_ok=True)
    executor = None
    if args.workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        executor = ProcessPoolExecutor(args.workers)
    print(f"sweep: {len(args.sigma_p)} sigma_P x {len(args.models)} models, {2 * args.n_per_class} training "
          f"profiles each, tests {', '.join(f'{k} ({len(v[1])})' for k, v in tests.items())}")
    try:
        result = sigma_p_sweep(make_train, tests, sigma_ps=args.sigma_p, models=args.models,
                               random_state=args.seed, executor=executor, model_params=params,
                               n_boot=args.n_boot, cache_dir=None if args.no_resume else out / "jobs")
    finally:
        if executor is not None:
            executor.shutdown()
    result.settings["make_train"] = asdict(make_train)
    result.settings["test_files"] = [str(p) for p in args.test]
    result.to_csv(out / "sweep.csv")
    md = result.to_markdown()
    from ..radar import atomic_write

    atomic_write(out / "sweep.md", lambda fh: fh.write(md.encode()))
    atomic_write(out / "settings.json", lambda fh: fh.write(json.dumps(result.settings, indent=1).encode()))
    result.plot(out / "sweep.png")
    print(md)
    print(f"wrote {out / 'sweep.csv'}, {out / 'sweep.md'}, {out / 'sweep.png'} "
          f"({result.settings['seconds']:.0f} s, {result.settings['resumed_jobs']} sigma_P points reused)")
    return 0


def run_baseline(args) -> int:
    from ..radar import atomic_write, check_outputs
    from .metrics import evaluate, format_metrics
    from .persist import save_model
    from .tsaug_baseline import tsaug_baseline, tsaug_cross_validate

    check_outputs(args.out, args.json)
    if args.folds is None and args.out is None:
        raise ValueError("give --out MODEL (train on all of DATA) or --folds K (cross-validate on DATA)")
    data = _load_set(args.data, "measured profiles")
    params = {k: v for k, v in _model_params(args, "cnn").items() if k != "epochs"}
    report = {}
    if args.folds is not None:
        print(f"tsaug baseline, {args.folds}-fold cross-validation on {args.data} ({len(data)} profiles); "
              f"augmenting only inside each training fold")
        pred, _ = tsaug_cross_validate(data.profiles, data.labels, n_splits=args.folds, n_per_class=args.n_per_class,
                                       random_state=args.seed, epochs=args.epochs, **params)
        report["cross_validation"] = evaluate(data.labels, pred, random_state=args.seed)
        print(format_metrics(report["cross_validation"]))
    if args.out is not None:
        model = tsaug_baseline(data.profiles, data.labels, args.n_per_class, args.seed, epochs=args.epochs, **params)
        save_model(model, args.out)
        print(f"trained the tsaug-baseline CNN on all {len(data)} profiles; wrote {args.out}")
        for path in args.test or []:
            test = _load_set(path, "test data")
            x = model.check_input(test.profiles, source=str(path))
            y = model.check_labels(test.labels, source=f"{path}: field 'labels'")
            report[str(path)] = evaluate(y, model.predict(x), labels=model.classes_.tolist(), random_state=args.seed)
            print(f"on {path}:")
            print(format_metrics(report[str(path)]))
    if args.json is not None:
        payload = json.dumps(report, indent=1).encode()
        atomic_write(args.json, lambda fh: fh.write(payload))
        print(f"wrote {args.json}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("train", help="train a classifier (svm, nb, xgb, cnn) on a profile file",
                       description="Train a classifier on profiles + labels (NPZ/CSV/.mat) and save it "
                                   "as a model file that loads without executing code.")
    p.add_argument("data", type=Path, help="training profiles (NPZ, CSV or .mat with profiles + labels)")
    p.add_argument("--model", choices=MODELS, required=True)
    p.add_argument("--out", type=Path, required=True, help="model file to write (.zip)")
    p.add_argument("--seed", type=int, default=0)
    _add_model_options(p)
    p.set_defaults(func=run_train)

    p = sub.add_parser("evaluate", help="score a trained model on a labelled test file",
                       description="Accuracy, balanced accuracy, per-class precision and recall, the "
                                   "confusion matrix and bootstrap 95%% intervals.")
    p.add_argument("model", type=Path, help="model file written by 'mdaug train'")
    p.add_argument("test", type=Path, help="test profiles (NPZ, CSV or .mat)")
    p.add_argument("--json", type=Path, default=None, help="write the metrics as JSON")
    p.add_argument("--plot", type=Path, default=None, help="write the confusion matrix as PNG")
    p.add_argument("--n-boot", type=int, default=1000, help="bootstrap resamples (default 1000; 0 = none)")
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    p.set_defaults(func=run_evaluate)

    p = sub.add_parser("baseline", help="the conventional tsaug baseline (drift + pool + reverse, then the CNN)",
                       description="Augment measured profiles with tsaug and train the CNN (100 epochs as "
                                   "published): on all of DATA (--out, optionally scored on --test files) "
                                   "and/or by k-fold cross-validation on DATA (--folds).")
    p.add_argument("data", type=Path, help="measured training profiles (NPZ, CSV or .mat)")
    p.add_argument("--out", type=Path, default=None, help="model file to write")
    p.add_argument("--test", type=csv_list, default=None, help="comma-separated test files (with --out)")
    p.add_argument("--folds", type=int, default=None, help="k-fold cross-validation on DATA")
    p.add_argument("--n-per-class", type=int, default=16000, help="augmented profiles per class (default 16000)")
    p.add_argument("--json", type=Path, default=None, help="write the metrics as JSON")
    p.add_argument("--seed", type=int, default=0)
    _add_model_options(p, epochs_default=100)
    p.set_defaults(func=run_baseline)

    from ..generator.augment import SIGN_POLICIES
    from ..generator.commands import add_nuisance_arguments
    from .protocol import FAST_MODELS, PUBLISHED_SIGMA_PS

    p = sub.add_parser("sweep", help="the published sigma_P protocol (Table IV, Fig. 13)",
                       description="Train classifiers on synthetic sigma_P sets and test them on measured "
                                   "sets; writes sweep.csv, sweep.md and sweep.png to --out. Resumes an "
                                   "interrupted run from --out/jobs.")
    p.add_argument("--sigma-p", type=_floats, default=list(PUBLISHED_SIGMA_PS),
                   help="comma-separated sigma_P grid (default the published 10 values)")
    p.add_argument("--models", type=csv_list, default=list(FAST_MODELS), help="default svm,nb,xgb")
    p.add_argument("--test", type=csv_list, required=True, help="comma-separated test files (e.g. old.npz,new.npz)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--classes", type=csv_list, default=["HELI", "QUAD"], help="class references (default HELI,QUAD)")
    p.add_argument("--n-per-class", type=int, default=4000,
                   help="synthetic profiles per class and sigma_P (default 4000; the paper used 16000)")
    p.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-boot", type=int, default=1000, help="bootstrap resamples per score")
    p.add_argument("--workers", type=int, default=1, help="parallel processes (default 1)")
    p.add_argument("--no-resume", action="store_true", help="ignore results of an earlier run in --out/jobs")
    add_nuisance_arguments(p)
    _add_model_options(p)
    p.set_defaults(func=run_sweep)
