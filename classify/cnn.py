"""The CNN of SPEC section 6, in torch.

Architecture (input: the 400-bin profile reshaped to 1 x 20 x 20)::

    conv 3x3, 32 filters (valid)  -> 32 x 18 x 18, ReLU
    max pool 2x2                  -> 32 x 9 x 9
    conv 3x3, 64 filters (valid)  -> 64 x 7 x 7, ReLU
    average pool 7x7, stride 7    -> 64 x 1 x 1
    flatten                       -> 64
    fully connected 64 -> hidden, ReLU
    fully connected hidden -> n_classes (softmax via the cross-entropy loss)

The SPEC does not give the kernel size; 3x3 "valid" convolutions make the published
7x7 average pool cover exactly the 7x7 map left after the second convolution.

Training: Adam (lr 1e-3), cross-entropy, ``epochs`` (50) at ``batch_size`` (256);
the training set is split 80/10/10 (stratified; by ``groups`` when given, so copies
of one source profile stay in one split); the model with the best validation loss
is kept; ``patience`` stops early after that many epochs without improvement; the
10% test split's accuracy is reported in ``split_scores_``.

Speed: channels-last tensors and in-place ReLUs (the ReLU backward on the default
layout took ~40% of an epoch): ~2.9 s/epoch on 25,600 profiles at batch 256 on one
thread here (vs ~4.7 s with the default layout). The tensors are built once (on the
device) and kept; an epoch is one gather of the shuffled training set and views of
it, with the loss summed on the device (no per-batch ``.item()``, no copies of the
weights but one in-place copy of the best); validation and prediction run under
``torch.inference_mode`` in large chunks. ``tests/benchmarks/cnn_throughput.py``
measures profiles/s per epoch against the previous loop: on one CPU thread the loop
was not the cost (0.9-1.3x, within the shared machine's noise; the convolutions are),
and batches above 256 gave no more profiles/s.

Precision: ``precision`` "float32" (the default), "bfloat16" or "auto" (bfloat16 on a
CPU with native bfloat16 instructions, float32 elsewhere: :func:`resolve_precision`;
the study's default, ``protocol.cnn_precision``): the forward passes
under ``torch.autocast`` in bfloat16 (weights, gradients and Adam stay float32). On
CPUs with bfloat16 instructions (AVX512-BF16, AMX) an epoch is faster; whether the
accuracy holds is measured by ``tests/benchmarks/cnn_throughput.py --bf16`` (on the
shared project machine's AVX512-BF16: 1.4-1.6x the profiles/s, accuracy 0.805 against
0.807 after 8 epochs on 12,000 generator profiles; rerun 2026-11-26: 1.48x, 0.805
against 0.807). The class default stays float32; the study asks for "auto".

Device: ``device`` "auto" (a CUDA GPU when torch sees one, else the CPU), "cpu" or
"cuda"; it is where a model runs, not what it is: it is not saved with the model
(weights are saved from the CPU), and a loaded model runs wherever it is asked to.

Progress: on a terminal a bar shows the epochs, the ETA, the training loss and the
validation accuracy (``progress``: None automatic, see :mod:`mdaug.radar.progress`).

Determinism: weights, split and shuffles come from ``random_state`` (torch
generators seeded from it, on the CPU; the global torch RNG is untouched); on the CPU
on one thread the same seed gives the same model (a GPU's kernels may differ in the
last bits).
"""
from __future__ import annotations

import contextlib
import functools
import math
import time

import numpy as np
import torch
from torch import nn
from ..radar.progress import progress_bar
from ..radar.seeds import child_seed, torch_generator
from ..radar.seeds import rng as seeded_rng
from .base import DEVICES, PRECISIONS, ProfileClassifier

SIDE = 20


class ProfileCNN(nn.Module):
    """The SPEC's network; input (N, 1, 20, 20), output logits (N, n_classes)."""

    def __init__(self, n_classes: int, hidden: int = 64, conv1: int = 32, conv2: int = 64):
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv2d(1, conv1, 3), nn.ReLU(inplace=True), nn.MaxPool2d(2),
            nn.Conv2d(conv1, conv2, 3), nn.ReLU(inplace=True), nn.AvgPool2d(7, stride=7),
            nn.Flatten())
        self.head = nn.Sequential(nn.Linear(conv2, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, n_classes))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))

    def layer_shapes(self, batch: int = 1) -> list[tuple[str, tuple[int, ...]]]:
        """(layer name, output shape) of every layer for a (batch, 1, 20, 20) input."""
        x = torch.zeros(batch, 1, SIDE, SIDE)
        out = []
        with torch.no_grad():
            for layer in list(self.features) + list(self.head):
                x = layer(x)
                out.append((type(layer).__name__, tuple(x.shape)))
        return out


@contextlib.contextmanager
def torch_threads(n: int):
    """Run with ``n`` torch threads, restoring the previous count afterwards."""
    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


def split_indices(yi: np.ndarray, fractions=(0.8, 0.1, 0.1), groups=None, rng=None):
    """Stratified train / validation / test indices; whole groups go to one split.

    Each class's items (or its groups) are shuffled and cut at the fractions; a
    class with at least 3 items (groups) puts at least one in each split of
    non-zero fraction. Returns three sorted index arrays (train, validation, test).
    """
    rng = seeded_rng(rng)
    yi = np.asarray(yi)
    groups = np.arange(yi.size) if groups is None else np.asarray(groups)
    if groups.shape != yi.shape:
        raise ValueError(f"groups must have one entry per profile ({yi.size}), got {groups.shape}")
    parts = ([], [], [])
    for c in np.unique(yi):
        in_class = yi == c
        g = rng.permutation(np.unique(groups[in_class]))
        n = g.size
        n_val, n_test = int(round(fractions[1] * n)), int(round(fractions[2] * n))
        if n >= 3:
            n_val = max(n_val, 1) if fractions[1] > 0 else 0
            n_test = max(n_test, 1) if fractions[2] > 0 else 0
        for part, sel in zip(parts, np.split(g, [n - n_val - n_test, n - n_test])):
            part.append(np.flatnonzero(in_class & np.isin(groups, sel)))
    return tuple(np.sort(np.concatenate(p)) for p in parts)


def resolve_precision(precision: str, device: str) -> str:
    """'float32' or 'bfloat16' for ``precision`` in :data:`PRECISIONS` on ``device``
    ('cpu' or 'cuda'): "auto" is bfloat16 on a CPU with native bfloat16 instructions
    (AVX512-BF16, AMX: 1.4-1.6x the profiles/s of float32 here at the same accuracy,
    ``tests/benchmarks/cnn_throughput.py --bf16``), float32 elsewhere."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if precision != "auto":
        return precision
    return "bfloat16" if device == "cpu" and _native_bf16() else "float32"


@functools.cache
def _native_bf16() -> bool:
    """Whether this CPU has native bfloat16 instructions (asked once per process: the
    answer is read on every training batch)."""
    return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())


def resolve_device(device: str = "auto") -> str:
    """'cuda' or 'cpu' for ``device`` in :data:`DEVICES` ("auto": a GPU when torch sees one)."""
    if device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda': torch sees no CUDA GPU here (use 'auto' or 'cpu')")
    return device


class CNNClassifier(ProfileClassifier):
    name = "cnn"

    def __init__(self, epochs: int = 50, batch_size: int = 256, learning_rate: float = 1e-3,
                 hidden: int = 64, patience: int | None = None, monitor: str = "loss",
                 fractions=(0.8, 0.1, 0.1), progress: bool | None = None, device: str = "auto",
                 precision: str = "float32", **kw):
        super().__init__(**kw)
        if int(epochs) < 1 or int(batch_size) < 1:
            raise ValueError(f"epochs and batch_size must be >= 1, got {epochs}, {batch_size}")
        if monitor not in ("loss", "accuracy"):
            raise ValueError(f"monitor must be 'loss' or 'accuracy', got {monitor!r}")
        if len(fractions) != 3 or not math.isclose(sum(fractions), 1.0) or min(fractions) < 0 or fractions[1] <= 0:
            raise ValueError(f"fractions must be (train, validation, test) summing to 1, got {fractions}")
        if device not in DEVICES:
            raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
        self.precision = precision
        self.epochs, self.batch_size, self.learning_rate = int(epochs), int(batch_size), float(learning_rate)
        self.hidden, self.patience, self.monitor = int(hidden), patience, monitor
        self.fractions = tuple(float(f) for f in fractions)
        self.progress = progress
        self.device = device
        self.net_: ProfileCNN | None = None
        self.history_: list[dict] = []
        self.split_scores_: dict = {}
        self.best_epoch_: int | None = None

    def params(self) -> dict:  # the device is where it runs, not what it is: not saved
        return {**super().params(), "epochs": self.epochs, "batch_size": self.batch_size,
                "learning_rate": self.learning_rate, "hidden": self.hidden, "patience": self.patience,
                "monitor": self.monitor, "fractions": list(self.fractions), "precision": self.precision}

    def build(self, n_classes: int) -> ProfileCNN:
        g = torch_generator(self.random_state, 3)
        net = ProfileCNN(n_classes, hidden=self.hidden)
        with torch.no_grad():  # seeded re-initialisation with torch's default schemes
            for m in net.modules():
                if isinstance(m, (nn.Conv2d, nn.Linear)):
                    bound = 1.0 / math.sqrt(m.weight[0].numel())
                    m.weight.uniform_(-bound, bound, generator=g)
                    m.bias.uniform_(-bound, bound, generator=g)
        return net.to(memory_format=torch.channels_last)

    @staticmethod
    def to_tensor(X: np.ndarray, device: str = "cpu") -> torch.Tensor:
        if X.shape[1] != SIDE * SIDE:
            raise ValueError(f"the CNN takes {SIDE * SIDE}-bin profiles (1 x {SIDE} x {SIDE}), got {X.shape[1]} bins")
        t = torch.from_numpy(np.ascontiguousarray(X, dtype=np.float32)).reshape(-1, 1, SIDE, SIDE)
        return t.to(device).contiguous(memory_format=torch.channels_last)

    def _autocast(self, device: str):
        """The forward pass's precision (:data:`PRECISIONS`): autocast in bfloat16, or nothing."""
        return torch.autocast(device_type=device, dtype=torch.bfloat16,
                              enabled=resolve_precision(self.precision, device) == "bfloat16")

    def _on_device(self) -> str:
        """The resolved device, with the network moved there."""
        device = resolve_device(self.device)
        self.net_ = self.net_.to(device)
        return device

    def _evaluate(self, x: torch.Tensor, y: torch.Tensor) -> tuple[float, float]:
        if len(y) == 0:
            return float("nan"), float("nan")
        logits = self._logits(x)
        with torch.inference_mode():
            loss = nn.functional.cross_entropy(logits, y)
            acc = (logits.argmax(1) == y).float().mean()
        return loss.item(), acc.item()

    def _logits(self, x: torch.Tensor, chunk: int = 8192) -> torch.Tensor:
        self.net_.eval()
        with torch.inference_mode(), self._autocast(x.device.type):
            return torch.cat([self.net_(x[i:i + chunk]).float() for i in range(0, len(x), chunk)])

    def _fit(self, X, yi, groups=None):
        device = resolve_device(self.device)
        tr, va, te = split_indices(yi, self.fractions, groups, child_seed(self.random_state, 4))
        if tr.size == 0 or va.size == 0:
            raise ValueError(f"too few profiles ({yi.size}) for a {self.fractions} split")
        shuffle = torch_generator(self.random_state, 5)
        with torch_threads(self.threads):
            x_all = self.to_tensor(X, device)  # built once, kept on the device
            y_all = torch.from_numpy(yi).to(device)
            self.net_ = self.build(len(self.classes_)).to(device)
            opt = torch.optim.Adam(self.net_.parameters(), lr=self.learning_rate)
            xtr, ytr = x_all[tr], y_all[tr]
            xva, yva = x_all[va], y_all[va]
            n_tr, step = len(ytr), self.batch_size
            best, stale = None, 0
            best_state = {k: v.detach().clone() for k, v in self.net_.state_dict().items()}
            self.history_ = []
            bar = progress_bar(range(1, self.epochs + 1), desc="CNN epochs", unit="epoch",
                               progress=self.progress)
            for epoch in bar:
                t0 = time.perf_counter()
                self.net_.train()
                order = torch.randperm(n_tr, generator=shuffle).to(device)
                xs, ys = xtr[order], ytr[order]  # one gather an epoch; the batches are views of it
                total = torch.zeros((), device=device)
                for lo in range(0, n_tr, step):
                    opt.zero_grad(set_to_none=True)
                    with self._autocast(device):
                        loss = nn.functional.cross_entropy(self.net_(xs[lo:lo + step]), ys[lo:lo + step])
                    loss.backward()
                    opt.step()
                    total += loss.detach() * min(step, n_tr - lo)
                val_loss, val_acc = self._evaluate(xva, yva)
                train_loss = total.item() / n_tr
                self.history_.append({"epoch": epoch, "train_loss": train_loss,
                                      "val_loss": val_loss, "val_accuracy": val_acc,
                                      "seconds": time.perf_counter() - t0})
                key = val_loss if self.monitor == "loss" else -val_acc
                if best is None or key < best:
                    best, stale, self.best_epoch_ = key, 0, epoch
                    with torch.no_grad():
                        for k, v in self.net_.state_dict().items():
                            best_state[k].copy_(v)
                else:
                    stale += 1
                bar.set_postfix_str(f"loss {train_loss:.3f} val acc {val_acc:.3f} "
                                    f"best {self.history_[self.best_epoch_ - 1]['val_accuracy']:.3f}"
                                    f"@{self.best_epoch_}", refresh=False)
                if self.patience is not None and stale >= self.patience:
                    break
            bar.close()
            self.net_.load_state_dict(best_state)
            test_loss, test_acc = self._evaluate(x_all[te], y_all[te])
            self.split_scores_ = {"n_train": int(tr.size), "n_val": int(va.size), "n_test": int(te.size),
                                  "best_epoch": self.best_epoch_, "epochs_run": len(self.history_),
                                  "val_loss": self.history_[self.best_epoch_ - 1]["val_loss"],
                                  "val_accuracy": self.history_[self.best_epoch_ - 1]["val_accuracy"],
                                  "test_loss": test_loss, "test_accuracy": test_acc}

    def _proba(self, X):
        with torch_threads(self.threads):
            device = self._on_device()
            logits = self._logits(self.to_tensor(X, device))
            with torch.inference_mode():
                return torch.softmax(logits, dim=1).double().cpu().numpy()
