"""Classifier verbs: ``mdaug train``, ``evaluate`` and ``baseline`` (tsaug), and the
size checks of training they share with ``mdaug sweep`` (:mod:`.sweep`).
"""
from __future__ import annotations

import json
from pathlib import Path

from .common import (SECONDS_CNN_PROFILE, SECONDS_RESAMPLE, SECONDS_TREE_BIN, SECONDS_TSAUG, add_verb, check_size,
                     check_training_memory, count_2, info, load_profile_file, nonneg_int, nothing_written, path_list,
                     positive_int, result, seed_int)
from .options import add_classifier_options, add_device_option, model_params

CNN_BINS = 400  # the CNN's 1 x 20 x 20 input


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


def drones(ps):
    """The drone of each profile of a file (its field 'specimen'), the clusters of every
    bootstrap interval; None when the file does not say (then items are resampled)."""
    return None if "specimen" not in ps.extra else ps.extra["specimen"]


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

    check_paths(inputs=[("DATA", args.data)], outputs=[Output("--out", args.out, "model")], overwrite=args.overwrite)
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
    result(f"trained in {model.train_seconds_:.1f} s")
    if cnn:
        s = model.split_scores_
        result(f"best epoch {s['best_epoch']}/{s['epochs_run']}: validation accuracy {s['val_accuracy']:.3f}; "
               f"held-out 10% split ({s['n_test']} profiles) accuracy {s['test_accuracy']:.3f}")
    verdict, words = training_verdict(model, data)
    result(verdict)
    refuse_degenerate(args, verdict, words, f"{args.data}: the {args.model} model trained on it")
    save_model(model, args.out)
    result(f"wrote {args.out}")
    return 0


def refuse_degenerate(args, verdict: str, words: list, what: str) -> None:
    """A model that recognises no profile of a class of its own training data is not a
    result: refused (one line naming the file, exit 2, nothing written) unless
    ``--allow-degenerate``. ``verdict``, ``words``: :func:`training_verdict`'s."""
    if words and words[0].startswith("degenerate") and not args.allow_degenerate:
        on = verdict.split(":", 1)[0].removeprefix("verdict ")  # "on 40 of its training profiles"
        raise ValueError(f"{what} is {words[0]} {on} (recall {verdict.rsplit('(recall ', 1)[1]}; nothing written "
                         "(give --allow-degenerate to write it anyway)")


def add_degenerate_option(p) -> None:
    p.add_argument("--allow-degenerate", action="store_true",
                   help="write the model even when it recognises only one class of its own training profiles "
                        "(default: refuse it, exit status 2)")


def training_verdict(model, data, what: str = "its training profiles", per_class: int = 1000) -> tuple[str, list]:
    """The degenerate rule (:func:`mdaug.classify.metrics.degenerate`, the study's) on up
    to ``per_class`` profiles of each class of ``data`` (evenly spaced): (one line, its
    words of :func:`mdaug.classify.metrics.degenerate_words`, [] when not degenerate)."""
    import numpy as np

    from ..classify.metrics import degenerate, degenerate_words, evaluate

    labels = np.asarray(data.labels).astype(str)
    idx = np.concatenate([rows[np.linspace(0, rows.size - 1, min(per_class, rows.size)).astype(int)]
                          for rows in (np.flatnonzero(labels == c) for c in data.classes)])
    m = evaluate(labels[idx], model.predict(data.profiles[idx]), labels=model.classes_.tolist(), n_boot=0)
    words = degenerate_words(degenerate(m))
    recalls = ", ".join(f"{c} {pc['recall']:.3f}" for c, pc in m["per_class"].items() if pc["recall"] is not None)
    return (f"verdict on {idx.size} of {what}: "
            + ("; ".join(words) if words else "not degenerate") + f" (recall {recalls})"), words


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
    add_degenerate_option(p)
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
                outputs=[Output("--json", args.json, "json"), Output("--plot", args.plot, "plot")],
                overwrite=args.overwrite)
    model = load_model(args.model)
    if model.name == "cnn":
        from ..classify.cnn import resolve_device

        resolve_device(args.device)  # 'cuda' without a GPU: refused before any work
        model.device = args.device
    test = load_profile_file(args.test)
    x, y = _check_test(model, test, args.test)
    check_boot_size(args.n_boot, len(y))
    m = evaluate(y, model.predict(x), labels=model.classes_.tolist(), n_boot=args.n_boot, random_state=args.seed,
                 clusters=drones(test))
    result(f"{model.name} model {args.model} on {args.test}")
    result(format_metrics(m))
    if m["ci"] and drones(test) is None:
        result(f"(the intervals treat every acquisition as independent: {args.test} names no drones, field "
               "'specimen'; acquisitions of one drone are alike, so these intervals are too narrow for new drones)")
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
    add_device_option(p)
    p.set_defaults(func=run_evaluate)
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
                         Output("--json", args.json, "json")], overwrite=args.overwrite)
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
    if args.folds is not None:
        info(f"tsaug baseline, {args.folds}-fold cross-validation on {args.data} ({len(data)} profiles); "
             f"augmenting only inside each training fold")
        pred, _ = tsaug_cross_validate(data.profiles, data.labels, n_splits=args.folds, n_per_class=args.n_per_class,
                                       random_state=args.seed, epochs=args.epochs, **params)
        report["cross_validation"] = evaluate(data.labels, pred, random_state=args.seed,
                                              clusters=drones(data))
        result(format_metrics(report["cross_validation"]))
    if args.out is not None:
        model = tsaug_baseline(data.profiles, data.labels, args.n_per_class, args.seed, epochs=args.epochs, **params)
        n_aug = args.n_per_class * len(data.classes)
        result(f"trained the tsaug-baseline CNN on {n_aug:,} tsaug-augmented profiles ({args.n_per_class:,} per "
               f"class) made from the {len(data)} measured profiles of {args.data}")
        verdict, words = training_verdict(model, data, f"the measured profiles of {args.data}")
        result(verdict)
        refuse_degenerate(args, verdict, words, f"{args.data}: the tsaug-baseline CNN made from it")  # before any file
        save_model(model, args.out)
        result(f"wrote {args.out}")
        for path, test in tests.items():
            x, y = _check_test(model, test, path)
            report[str(path)] = evaluate(y, model.predict(x), labels=model.classes_.tolist(), random_state=args.seed,
                                         clusters=drones(test))
            result(f"on {path}:")
            result(format_metrics(report[str(path)]))
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
    p.add_argument("--test", type=path_list, default=None, metavar="FILES",
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
    add_degenerate_option(p)
    add_classifier_options(p, epochs_default=100, cnn_only=True)
    p.set_defaults(func=run_baseline)
    return p


VERBS = {
    "train": ("train a classifier (svm, nb, xgb, cnn) on a profile file", add_train),
    "evaluate": ("score a trained model on a labelled test file", add_evaluate),
    "baseline": ("the conventional tsaug baseline (drift + pool + reverse, then the CNN)", add_baseline),
}
