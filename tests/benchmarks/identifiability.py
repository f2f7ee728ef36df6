"""What do the measurements identify? A direct regression of the label-free quantities
from the mean log-profile of a drone's measurements, with the engines ordered by
brightness (the estimators' target) and by their lowest line (its first version).

python tests/benchmarks/identifiability.py --class QUAD --ramps 32 [--sims DIR] [--n 5000]

--sims: a training work folder's ``sims/`` (``mdaug train-estimator`` writes
``OUT.work/sims/``); without it, N drones are simulated here (5 measurements each).
Prints the held-out R^2 of an MLP (400 -> 256 -> 256 -> d, 30 epochs, 1 thread) per
quantity for both orderings: a quantity near 0 is one the profiles do not carry, for
this regression; the amortized posterior can only be sharp where this is well above 0.
"""
from __future__ import annotations

import argparse
import glob
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402


def lowest_line_order(lf, vectors: np.ndarray) -> np.ndarray:
    """q with the engines ordered by their lowest line (the first target version), lnG
    relative to that engine: same columns as ``lf.quantities``."""
    from mdaug.generator import IDX, N_PARAMS
    from mdaug.inference.space.priors import engine_lines

    xe = vectors.reshape(len(vectors), lf.E, N_PARAMS)
    w, a, _ = engine_lines(xe)
    o = np.argsort(w, -1)
    w, a = np.take_along_axis(w, o, -1), np.take_along_axis(a, o, -1)
    eng = np.argsort(w[:, :, 0], axis=1, kind="stable")
    w, a = np.take_along_axis(w, eng[..., None], 1), np.take_along_axis(a, eng[..., None], 1)
    lng = np.log(np.take_along_axis(xe[..., IDX["Gamma"]], eng, 1))
    cols = []
    for k in range(lf.E):
        cols += [np.log(w[:, k]), np.log(a[:, k] + 1e-6)]
        if k:
            cols.append((lng[:, k] - lng[:, 0])[:, None])
    return np.concatenate(cols, axis=1)


def regress(features: np.ndarray, target: np.ndarray, seed: int = 0, epochs: int = 30) -> np.ndarray:
    """Held-out (last 10%) R^2 per column of an MLP regression, best epoch by mean."""
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    n = len(target)
    ntr = int(0.9 * n)
    z = (target - target[:ntr].mean(0)) / target[:ntr].std(0)
    x = (features - features[:ntr].mean(0)) / (features[:ntr].std(0) + 1e-6)
    X, Z = torch.tensor(x, dtype=torch.float32), torch.tensor(z, dtype=torch.float32)
    net = torch.nn.Sequential(torch.nn.Linear(X.shape[1], 256), torch.nn.GELU(), torch.nn.Linear(256, 256),
                              torch.nn.GELU(), torch.nn.Linear(256, Z.shape[1]))
    opt = torch.optim.Adam(net.parameters(), 1e-3, weight_decay=1e-4)
    best = None
    for _ in range(epochs):
        perm = torch.randperm(ntr)
        for i in range(0, ntr, 256):
            idx = perm[i: i + 256]
            loss = ((net(X[idx]) - Z[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        with torch.no_grad():
            r2 = 1 - ((net(X[ntr:]) - Z[ntr:]) ** 2).mean(0).numpy()
        if best is None or r2.mean() > best.mean():
            best = r2
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--class", dest="cls", default="QUAD")
    p.add_argument("--ramps", type=int, default=32)
    p.add_argument("--sims", default=None)
    p.add_argument("--n", type=int, default=5000)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.simulate import SimulationSpec, load_shards, simulate
    from mdaug.inference.amortized.target import LabelFree

    spec = SimulationSpec(a.cls.upper(), Acquisition.measured(a.ramps), 5)
    if a.sims:
        vectors, profiles = load_shards(sorted(glob.glob(os.path.join(a.sims, "shard-*.npz"))))
        vectors, profiles = vectors[: a.n], profiles[: a.n, :5]
    else:
        vectors, profiles = simulate(spec, a.n, a.seed)
    ref = spec.reference
    lf = LabelFree(ref.n_engines, spec.priors(), ref.to_array())
    features = np.log10(np.maximum(profiles, 1e-6)).mean(axis=1)
    bright = lf.quantities(vectors)
    for j, kind in enumerate(lf.kinds):  # logs of lines and amplitudes, lnG as it is
        if kind in ("w", "A"):
            bright[:, j] = np.log(bright[:, j] + (1e-6 if kind == "A" else 0.0))
    print(f"{a.cls.upper()} K = {a.ramps}: {len(vectors)} drones x 5 measurements; held-out R^2 of an MLP on the "
          "mean log-profile")
    r_bright = regress(features, bright, a.seed)
    r_low = regress(features, lowest_line_order(lf, vectors), a.seed)
    print(f"{'quantity':14s} {'by brightness':>14s} {'by lowest line':>15s}")
    for name, rb, rl in zip(lf.names, r_bright, r_low):
        print(f"{name:14s} {rb:14.2f} {rl:15.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
