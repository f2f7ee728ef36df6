"""CNN training throughput on 1 thread: profiles/s per epoch, the current loop
(:class:`mdaug.classify.cnn.CNNClassifier`) against the previous one, in the same run.

``python tests/benchmarks/cnn_throughput.py [--n N] [--epochs E] [--batch B] [--repeats R] [--bf16]``

The previous loop is kept here only, as a reference copy (:func:`reference_fit`): a
shuffled index per batch (a gather of each batch), the loss read back with ``.item()``
after every batch, the best weights deep-copied, validation under ``torch.no_grad`` in
4,096-profile chunks. Both train the same network from the same seed on the same
profiles (random data: throughput does not depend on the values), so their weights
must agree exactly, which is checked and printed. The two alternate ``--repeats``
times (the machine is shared: the median of each is quoted, and the ratio of medians).
Training profiles/s = (80% split) x epochs / training seconds, validation included.

``--bf16`` also trains the current loop with ``precision="bfloat16"`` (autocast) and
``float32`` on generator profiles (sigma_P 0.2 around the HELI and QUAD references,
``--n`` profiles, ``--bf16-epochs`` epochs, the same seed) and prints each one's
profiles/s and accuracy on 2,000 profiles of another seed: whether the speed-up keeps
the accuracy.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import copy  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402

torch.set_num_threads(1)

from mdaug.classify.cnn import CNNClassifier, split_indices, torch_threads  # noqa: E402
from mdaug.classify.preprocess import preprocess  # noqa: E402
from mdaug.radar.seeds import child_seed, torch_generator  # noqa: E402


def reference_fit(clf: CNNClassifier, X: np.ndarray, yi: np.ndarray) -> float:
    """The previous training loop (a copy; the CNN before the throughput work): trains
    ``clf.net_`` in place; returns the seconds of its epochs."""
    def logits(x, chunk=4096):
        clf.net_.eval()
        with torch.no_grad():
            return torch.cat([clf.net_(x[i:i + chunk]) for i in range(0, len(x), chunk)])

    def evaluate(x, y):
        out = logits(x)
        return nn.functional.cross_entropy(out, y).item(), (out.argmax(1) == y).float().mean().item()

    x_all = clf.to_tensor(X)
    y_all = torch.from_numpy(yi)
    tr, va, te = split_indices(yi, clf.fractions, None, child_seed(clf.random_state, 4))
    shuffle = torch_generator(clf.random_state, 5)
    seconds = 0.0
    with torch_threads(clf.threads):
        clf.net_ = clf.build(2)
        opt = torch.optim.Adam(clf.net_.parameters(), lr=clf.learning_rate)
        xtr, ytr = x_all[tr], y_all[tr]
        xva, yva = x_all[va], y_all[va]
        best, best_state = None, None
        for _ in range(clf.epochs):
            t0 = time.perf_counter()
            clf.net_.train()
            order = torch.randperm(len(ytr), generator=shuffle)
            total = 0.0
            for lo in range(0, len(order), clf.batch_size):
                idx = order[lo:lo + clf.batch_size]
                opt.zero_grad(set_to_none=True)
                loss = nn.functional.cross_entropy(clf.net_(xtr[idx]), ytr[idx])
                loss.backward()
                opt.step()
                total += loss.item() * len(idx)
            val_loss, _ = evaluate(xva, yva)
            if best is None or val_loss < best:
                best, best_state = val_loss, copy.deepcopy(clf.net_.state_dict())
            seconds += time.perf_counter() - t0
        clf.net_.load_state_dict(best_state)
    return seconds


def current_fit(clf: CNNClassifier, X: np.ndarray, yi: np.ndarray) -> float:
    clf.classes_ = np.array(["HELI", "QUAD"])
    clf._fit(X, yi)
    return sum(h["seconds"] for h in clf.history_)


def bf16_check(n: int, epochs: int, batch: int) -> None:
    from mdaug.generator import SigmaPAugmenter, make_dataset

    def synthetic(n_per_class, seed):
        ds = make_dataset([SigmaPAugmenter(c, 0.2) for c in ("HELI", "QUAD")], n_per_class, seed, progress=False)
        return ds.profiles, ds.labels

    x, y = synthetic(n // 2, 1)
    xt, yt = synthetic(1000, 99)
    print(f"bfloat16 autocast against float32: {n} generator profiles (sigma_P 0.2), {epochs} epochs, batch "
          f"{batch}, 1 thread; accuracy on 2,000 profiles of another seed")
    out = {}
    for precision in ("float32", "bfloat16", "float32", "bfloat16"):  # alternating: a shared machine
        clf = CNNClassifier(epochs=epochs, batch_size=batch, random_state=3, progress=False, device="cpu",
                            precision=precision).fit(x, y)
        rate = clf.split_scores_["n_train"] * len(clf.history_) / sum(h["seconds"] for h in clf.history_)
        out.setdefault(precision, []).append((rate, clf.score(xt, yt)))
    for precision, rows in out.items():
        print(f"  {precision:8s}: {statistics.median(r for r, _ in rows):7.0f} profiles/s per epoch, "
              f"accuracy {rows[0][1]:.3f} (the same seed twice: {rows[1][1]:.3f})")
    med = {p: statistics.median(r for r, _ in rows) for p, rows in out.items()}
    print(f"  ratio bfloat16 / float32: {med['bfloat16'] / med['float32']:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=12000, help="profiles (the study's 6,000 per class)")
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--bf16", action="store_true", help="also: bfloat16 autocast against float32, accuracy too")
    ap.add_argument("--bf16-epochs", type=int, default=8)
    args = ap.parse_args(argv)

    rng = np.random.default_rng(0)
    X = preprocess(np.abs(rng.normal(0.1, 0.05, (args.n, 400))) + np.eye(400)[np.full(args.n, 200)])
    yi = (rng.random(args.n) < 0.5).astype(np.int64)

    def model():
        return CNNClassifier(epochs=args.epochs, batch_size=args.batch, random_state=7, progress=False,
                             device="cpu")

    n_train = split_indices(yi, (0.8, 0.1, 0.1), None, child_seed(7, 4))[0].size
    rates = {"previous": [], "current": []}
    same = None
    for _ in range(args.repeats):
        old, new = model(), model()
        rates["previous"].append(n_train * args.epochs / reference_fit(old, X, yi))
        rates["current"].append(n_train * args.epochs / current_fit(new, X, yi))
        a, b = old.net_.state_dict(), new.net_.state_dict()
        same = all(torch.equal(a[k], b[k]) for k in a) if same is None else same and all(
            torch.equal(a[k], b[k]) for k in a)
    med = {k: statistics.median(v) for k, v in rates.items()}
    print(f"CNN training, 1 thread, batch {args.batch}, {n_train} training profiles, {args.epochs} epochs, "
          f"{args.repeats} alternating repeats (torch {torch.__version__})")
    for k, v in rates.items():
        print(f"  {k:8s} loop: median {med[k]:7.0f} profiles/s per epoch  (runs: "
              f"{', '.join(f'{r:.0f}' for r in v)})")
    print(f"  ratio current / previous: {med['current'] / med['previous']:.2f}")
    print(f"  same weights from the same seed: {same}")
    if args.bf16:
        bf16_check(args.n, args.bf16_epochs, args.batch)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
