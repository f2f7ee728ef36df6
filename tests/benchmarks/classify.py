"""Benchmark of mdaug.classify (run on demand: ``python tests/benchmarks/classify.py``).

Threads pinned to 1. Data: real generator profiles (mdaug.generator.SigmaPAugmenter,
HELI vs QUAD). Prints medians and ratios against baselines measured in the same run:

1. CNN seconds per epoch on 25,600 training profiles at batch 256 (the 80% of a
   32,000 set), ours (channels-last, in-place ReLU) vs the plain layout; projected
   50 epochs against the 3-minute target.
2. Speed against error: each classifier's training time and test accuracy at
   several training sizes (test: 2,000 profiles of a held-out seed, same sigma_P).
3. The default sweep: 10 published sigma_P x (svm, nb, xgb) at the default
   n_per_class, two 136-profile test sets; total time against the 10-minute target.

Options: ``--quick`` (smaller sizes, for a smoke run).
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

torch.set_num_threads(1)
threadpool_limits(1)

from mdaug.classify import make_classifier, sigma_p_sweep  # noqa: E402
from mdaug.cli.sweep import SyntheticTrainSet  # noqa: E402
from mdaug.generator import Acquisition, SigmaPAugmenter, make_dataset  # noqa: E402


def synthetic(n_per_class, sigma_p=0.2, seed=0, acquisition=Acquisition()):
    ds = make_dataset([SigmaPAugmenter(c, sigma_p, acquisition=acquisition) for c in ("HELI", "QUAD")],
                      n_per_class, seed, progress=False)
    return ds.profiles, ds.labels


def plain_epoch_seconds(x, y, batch=256):
    """The same network on torch's default layout with out-of-place ReLUs (baseline)."""
    from torch import nn

    torch.manual_seed(0)
    net = nn.Sequential(nn.Conv2d(1, 32, 3), nn.ReLU(), nn.MaxPool2d(2), nn.Conv2d(32, 64, 3), nn.ReLU(),
                        nn.AvgPool2d(7, 7), nn.Flatten(), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, 2))
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    xt = torch.from_numpy(x.reshape(-1, 1, 20, 20))
    yt = torch.from_numpy(y)
    t0 = time.perf_counter()
    for lo in range(0, len(yt), batch):
        opt.zero_grad()
        nn.functional.cross_entropy(net(xt[lo:lo + batch]), yt[lo:lo + batch]).backward()
        opt.step()
    return time.perf_counter() - t0


def bench_cnn(quick):
    n_per_class = 4000 if quick else 16000
    epochs = 2 if quick else 3
    x, y = synthetic(n_per_class, seed=1)
    model = make_classifier("cnn", random_state=0, epochs=epochs, progress=False, patience=None).fit(x, y)
    ours = [h["seconds"] for h in model.history_]
    n_train = model.split_scores_["n_train"]
    from mdaug.classify.preprocess import preprocess

    xp = preprocess(x)[:n_train]
    yi = (y[:n_train] == "QUAD").astype(np.int64)
    base = [plain_epoch_seconds(xp, yi) for _ in range(2)]
    med, bmed = statistics.median(ours), statistics.median(base)
    print(f"\n[1] CNN, batch 256, {n_train} training profiles, 1 thread")
    print(f"    ours  s/epoch: median {med:.2f} (epochs: {', '.join(f'{s:.2f}' for s in ours)}; incl. validation)")
    print(f"    plain s/epoch: median {bmed:.2f} (training only)  -> speed-up x{bmed / med:.2f}")
    scale = 25600 / n_train
    print(f"    projected 50 epochs on 25,600: {50 * med * scale:.0f} s (target < 180 s: ratio "
          f"{50 * med * scale / 180:.2f})")


def bench_speed_vs_error(quick):
    xt, yt = synthetic(1000, seed=99)
    sizes = (500, 2000) if quick else (1000, 4000, 8000, 16000)
    configs = [("nb", {}), ("svm", {"kernel": "linear"}), ("svm", {}), ("xgb", {}),
               ("cnn", {"epochs": 10 if quick else 20, "progress": False})]
    print("\n[2] speed against error (sigma_P 0.2, test 2,000 profiles of another seed; medians of 3 "
          "fits for fits under 5 s)")
    print(f"    {'model':<12s} {'n_train':>8s} {'train s':>9s} {'accuracy':>9s} {'s / NB s':>9s}")
    nb_time = {}
    for n in sizes:
        x, y = synthetic(n, seed=2)
        for name, kw in configs:
            if name == "svm" and not kw and n > 8000:
                continue  # RBF SVC is super-linear: ~17 s at 16,000 x 400, not repeated here
            if name == "cnn" and n > 8000:
                continue
            times, accs = [], []
            for rep in range(3):
                m = make_classifier(name, random_state=rep, **kw).fit(x, y)
                times.append(m.train_seconds_)
                accs.append(m.score(xt, yt))
                if m.train_seconds_ > 5:
                    break
            label = name + ("-" + kw["kernel"] if "kernel" in kw else "") + (
                f"-{kw['epochs']}ep" if name == "cnn" else "")
            t = statistics.median(times)
            if name == "nb":
                nb_time[n] = t
            print(f"    {label:<12s} {2 * n:>8d} {t:>9.2f} {statistics.median(accs):>9.3f} "
                  f"{t / max(nb_time.get(n, t), 1e-9):>9.0f}")


def bench_sweep(quick):
    n_per_class = 500 if quick else 4000
    measured_like = Acquisition(phases="uniform", range_jitter_bins=1.0, ramps=4)
    tests = {"same": synthetic(68, 0.1, seed=7),
             "uniform_phase": synthetic(68, 0.2, seed=8, acquisition=measured_like)}
    make_train = SyntheticTrainSet(("HELI", "QUAD"), n_per_class)
    t0 = time.perf_counter()
    res = sigma_p_sweep(make_train, tests, random_state=0, progress=False)
    took = time.perf_counter() - t0
    print(f"\n[3] default sweep: 10 sigma_P x svm,nb,xgb, {2 * n_per_class} training profiles each, 1 thread")
    per = {m: statistics.median([r["train_seconds"] for r in res.rows if r["model"] == m]) for m in res.models}
    print("    median train s per sigma_P: " + ", ".join(f"{m} {s:.2f}" for m, s in per.items()))
    print(f"    total {took:.0f} s (target < 600 s: ratio {took / 600:.2f})")
    print(res.to_markdown())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("cnn", "speed", "sweep"), default=None)
    a = ap.parse_args()
    print(f"torch {torch.__version__}, threads 1{' (quick)' if a.quick else ''}")
    if a.only in (None, "cnn"):
        bench_cnn(a.quick)
    if a.only in (None, "speed"):
        bench_speed_vs_error(a.quick)
    if a.only in (None, "sweep"):
        bench_sweep(a.quick)


if __name__ == "__main__":
    main()
