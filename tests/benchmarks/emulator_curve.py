"""How many simulated drones does the summary likelihood's emulator need? Its learning curve over the prior.

python tests/benchmarks/emulator_curve.py --class QUAD --ramps 32 --sims DIR [DIR ...] \
    [--sizes 4000,8000,17500,35000] [--test 1000] [--seed 0] [--estimator FILE]

DIR: folders of simulated prior drones (``shard-*.npz``, as ``train-estimator`` writes them
under ``OUT.work/sims/``, 2 or more measurements each). The last --test drones of the first
folder are the test drones, never trained on. For each size N, one emulator of the file's
configuration (one member; :func:`mdaug.inference.emulator.net.fit`, its own early stopping)
is trained on the first N of a seeded permutation of the other drones, in the file's whitening
(so every size is measured in the same units). Printed per size:

* the best epoch and the seconds;
* the emulator's error at the truth on the test drones: the squared distance between the
  emulated mean and the drone's M-measurement mean, its own noise (the trace of its
  sample covariance / M) taken off, summed over the D components, in the pooled noise of 5
  measurements (the whitening makes the pooled within-drone covariance the identity, so the
  noise of 5 measurements itself gives D): median and mean;
* the same on as many training drones (training error: a gap to the test error says more
  drones help, none says the network's size or fit limits it).

Then the slope of log error against log N between the last two sizes, and the N at which
that line would halve the last size's error. 1 thread.
"""
from __future__ import annotations

import argparse
import glob
import os
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")

import numpy as np  # noqa: E402

N_CAL = 5


def features(model, lf, x: np.ndarray, profiles: np.ndarray):
    """(u (N, d), sketch (N, F), mean summary (N, D), its own noise (N,)) of drones x with
    peak-normalised profiles (N, M, L), in the model's whitening."""
    from mdaug.inference.emulator.summary import folded_log_profile

    z_all = model.whitening(folded_log_profile(profiles, model.whitening.n_offsets))  # (N, M, D)
    m = z_all.shape[1]
    z = z_all.mean(1)
    noise = ((z_all - z[:, None]) ** 2).sum((1, 2)) / (m - 1) / m
    u = lf.to_unbounded(lf.quantities(x))
    return u, model.features(u), z, noise


def error_in_noise_units(net, u, sk, z, noise) -> np.ndarray:
    """(N,) squared error of the emulated mean, own noise off, in the pooled noise of 5 measurements."""
    import torch

    with torch.no_grad():
        mu = net(torch.as_tensor(u, dtype=torch.float32), torch.as_tensor(sk, dtype=torch.float32)).double().numpy()
    return (((mu - z) ** 2).sum(1) - noise) * N_CAL


def main(argv=None) -> int:
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.estimator import EstimatorError
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.amortized.simulate import load_shards
    from mdaug.inference.emulator.net import Emulator, fit

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", default="QUAD")
    ap.add_argument("--ramps", type=int, default=32)
    ap.add_argument("--sims", nargs="+", required=True, help="folders of simulated prior drones")
    ap.add_argument("--sizes", default="4000,8000,17500,35000", help="training drones per emulator, comma-separated")
    ap.add_argument("--test", type=int, default=1000, help="test drones: the last of the first folder")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--estimator", help="estimator file whose summary model's whitening and sizes are used "
                    "(default: the shipped one)")
    a = ap.parse_args(argv)
    try:
        sizes = sorted({int(v) for v in a.sizes.split(",")})
    except ValueError:
        raise SystemExit(f"--sizes must be comma-separated whole numbers, got {a.sizes!r}") from None
    if not sizes or sizes[0] < 100:
        raise SystemExit(f"--sizes must be at least 100 each, got {a.sizes!r}")
    torch.set_num_threads(1)
    try:  # the file's whitening sets the units
        est = find(a.cls, Acquisition.measured(a.ramps), path=a.estimator)
        lf, model = est.label_free, est.summary_model(a.estimator or f"the shipped {a.cls} K = {a.ramps} file")
    except EstimatorError as exc:
        raise SystemExit(str(exc)) from None
    parts, test = [], None
    for i, folder in enumerate(a.sims):
        paths = sorted(glob.glob(os.path.join(folder, "shard-*.npz")))
        if not paths:
            raise SystemExit(f"{folder}: no shard-*.npz files (simulated drones) in it")
        for j in range(0, len(paths), 8):  # a few shards at a time: the profiles are large
            x, y = load_shards(paths[j: j + 8])
            if y.ndim != 3 or y.shape[1] < 2:
                raise SystemExit(f"{paths[j]}: field 'profiles' must hold 2 or more measurements per drone, "
                                 f"got shape {y.shape}")
            parts.append(features(model, lf, x, y))
        if i == 0:
            first = [np.concatenate(v) for v in zip(*parts)]
            if len(first[0]) <= a.test:
                raise SystemExit(f"{folder}: {len(first[0])} drones, not more than --test {a.test}")
            test = [v[-a.test:] for v in first]
            parts = [[v[: -a.test] for v in first]]
    pool = [np.concatenate(v) for v in zip(*parts)]
    n_pool = len(pool[0])
    if sizes[-1] > n_pool:
        raise SystemExit(f"--sizes asks for {sizes[-1]} training drones; the folders hold {n_pool} besides the test drones")
    perm = np.random.default_rng(a.seed).permutation(n_pool)
    cfg = model.net.config()
    print(f"{a.cls} K = {a.ramps}: {n_pool} training drones available, {a.test} test drones; D = {model.n_components} "
          f"(the noise of {N_CAL} measurements gives {model.n_components}); emulator {cfg['hidden']} x {cfg['depth']}, "
          "one member")
    print(f"{'drones':>8s} {'epoch':>6s} {'test median':>12s} {'test mean':>10s} {'train median':>13s} {'s':>6s}")
    rows = []
    for n in sizes:
        idx = perm[:n]
        torch.manual_seed(a.seed)  # the network's starting weights: the same for every size and run
        net = Emulator.member(lf.dim, model.whitening.basis, model.whitening.centre, cfg["hidden"], cfg["depth"])
        t = time.time()
        hist = fit(net, pool[0][idx], pool[1][idx], pool[2][idx], seed=a.seed)
        te = error_in_noise_units(net, *test)
        k = idx[: len(test[0])]
        tr = error_in_noise_units(net, *(v[k] for v in pool))
        rows.append((n, float(np.median(te))))
        print(f"{n:8d} {hist['best_epoch']:6d} {np.median(te):12.1f} {np.mean(te):10.1f} {np.median(tr):13.1f} "
              f"{time.time() - t:6.0f}", flush=True)
    if len(rows) >= 2:
        (n1, e1), (n2, e2) = rows[-2], rows[-1]
        slope = float(np.log(e2 / e1) / np.log(n2 / n1))
        halve = f"{n2 * 2 ** (-1 / slope):,.0f}" if slope < 0 else "never (the error does not fall)"
        print(f"slope of log error against log drones, last two sizes: {slope:.2f}; the error of {n2} drones halves "
              f"at about {halve} drones on that line")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
