"""Where to pay for the CNN's training runs: one run on a large set against several runs
on smaller sets of the same total size (the same cost), scored on a study's test sets.

    python tests/benchmarks/cnn_seeds.py STUDY_DIR [--strategy sigma_p_published] [--total 6000]

STUDY_DIR is a finished (or running: its data stage done) ``mdaug run`` folder; its
``data/`` sets are used. Prints, per layout (runs x profiles per class), the training
time, each run's balanced accuracy on every test set, their mean and spread.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mdaug.classify import evaluate, make_classifier
from mdaug.radar import load_profiles
from mdaug.radar.seeds import child_seed
from mdaug.reports import jobs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study")
    ap.add_argument("--strategy", default="sigma_p_published", choices=("sigma_p_published", "tsaug", "posterior"))
    ap.add_argument("--total", type=int, default=6000, help="profiles per class over all runs")
    ap.add_argument("--epochs", type=int, default=40)
    ap.add_argument("--layouts", default="1,3", help="numbers of runs to compare")
    ap.add_argument("--patience", type=int, default=8)
    ap.add_argument("--shared", action="store_true",
                    help="every run trains on one set of --total profiles per class (drawn once) instead of "
                         "its own 1/runs of them")
    args = ap.parse_args(argv)
    classes = ["HELI", "QUAD"]
    sets = {}
    for name in ("new", "new_large", "select"):
        try:
            ps = load_profiles(f"{args.study}/data/{name}.npz")
            sets[name] = (ps.profiles, ps.labels)
        except (OSError, ValueError):
            pass
    if args.strategy == "tsaug":
        parts = [load_profiles(f"{args.study}/data/calibration_{c}.npz") for c in classes]
        spec = {"strategy": "tsaug", "profiles": np.concatenate([p.select(c) for p, c in zip(parts, classes)]),
                "labels": np.concatenate([[c] * len(p.select(c)) for p, c in zip(parts, classes)])}
    elif args.strategy == "posterior":  # the study's calibrated posteriors
        spec = {"strategy": "posterior", "posteriors": {c: f"{args.study}/posteriors/{c}.nc" for c in classes},
                "through_chain": False}
    else:
        spec = {"strategy": "sigma_p_published", "sigma_p": 0.2, "through_chain": False}
    print(f"strategy {args.strategy}, {args.total} profiles per class")
    for runs in (int(k) for k in args.layouts.split(",")):
        n = args.total if args.shared else args.total // runs
        scores, t_data, t_train, epochs = {k: [] for k in sets}, 0.0, 0.0, []
        for i in range(runs):
            seed = child_seed(0, "cnn-seeds-benchmark", runs, i)
            t0 = time.perf_counter()
            if i == 0 or not args.shared:
                X, y, groups = jobs.training_set(spec, classes, n, seed)
            t_data += time.perf_counter() - t0
            clf = make_classifier("cnn", random_state=seed, epochs=args.epochs, patience=args.patience)
            t0 = time.perf_counter()
            clf.fit(X, y, **({} if groups is None else {"groups": groups}))
            t_train += time.perf_counter() - t0
            epochs.append(f"{clf.split_scores_['epochs_run']} (best {clf.split_scores_['best_epoch']})")
            for k, (Xt, yt) in sets.items():
                scores[k].append(evaluate(yt, clf.predict(Xt), labels=classes, n_boot=0)["balanced_accuracy"])
        print(f"{runs} run(s) x {n} per class{' (one shared set)' if args.shared else ''}, {args.epochs} epochs, "
              f"patience {args.patience}: data {t_data:.0f} s, training {t_train:.0f} s; epochs run {', '.join(epochs)}")
        for k, v in scores.items():
            v = np.array(v)
            print(f"  {k:>9s}: mean {v.mean():.3f}  runs {' '.join(f'{x:.3f}' for x in v)}"
                  + (f"  sd {v.std(ddof=1):.3f}" if len(v) > 1 else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
