"""Training the networks: tensors kept on the device, random subsets of each drone's
measurements, early stopping on a fixed validation split, a time budget, a progress
bar, and a checkpoint after every epoch that a rerun resumes from.

Each training example holds M measurements of one drone; every batch keeps a random
1..M of them (the rest become NaN rows, which the set embedding masks), so one
estimator serves any number of measurements up to M. The validation split and its
subsets are fixed by the seed, so its loss is comparable between epochs.
"""
from __future__ import annotations

import io
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from ...radar.io import atomic_write
from ...radar.progress import progress_bar


@dataclass(frozen=True)
class TrainConfig:
    """batch: drones per step; lr: Adam's rate; patience: epochs without a better
    validation loss before stopping; max_epochs; validation: share held out;
    time_budget: seconds (None: none); min_measurements: the smallest subset kept."""

    batch: int = 256
    lr: float = 1e-3
    patience: int = 8
    max_epochs: int = 200
    validation: float = 0.1
    time_budget: float | None = None
    min_measurements: int = 1

    def to_dict(self) -> dict:
        return asdict(self)


def device_of(name: str = "auto") -> torch.device:
    """'auto' (a GPU when present), 'cpu' or 'cuda'; refuses cuda without a GPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' asked for, but torch sees no GPU; use --device cpu or auto")
    if name not in ("cpu", "cuda"):
        raise ValueError(f"device must be auto, cpu or cuda, got {name!r}")
    return torch.device(name)


def subset_mask(n: int, m: int, gen: torch.Generator, device, lowest: int = 1) -> torch.Tensor:
    """(n, m) bool: True where a measurement is dropped; each row keeps a uniform
    random count in lowest..m of its measurements, chosen at random."""
    keep = torch.randint(lowest, m + 1, (n, 1), generator=gen).to(device)
    rank = torch.argsort(torch.rand(n, m, generator=gen), dim=1).argsort(dim=1).to(device)
    return rank >= keep


@dataclass
class TrainLog:
    epochs: int = 0
    best_epoch: int = 0
    best_val: float = float("inf")
    history: list = None
    stopped: str = ""
    seconds: float = 0.0
    resumed_at: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def fit(net: torch.nn.Module, loss_fn, u: torch.Tensor, x: torch.Tensor, cfg: TrainConfig, seed: int, *,
        checkpoint=None, progress=None, desc: str = "train", log=None) -> TrainLog:
    """Train ``net`` to minimise ``loss_fn(net, u_batch, x_batch)`` (x with dropped
    measurements as NaN rows) over u (N, d), x (N, M, L) on their device. Returns the
    log; ``net`` ends with the weights of the best validation epoch. checkpoint: a
    file rewritten after each epoch; a rerun with it resumes (its epochs count)."""
    device = u.device
    gen = torch.Generator().manual_seed(int(seed))
    n, m = x.shape[0], x.shape[1]
    perm = torch.randperm(n, generator=gen)
    n_val = max(1, int(round(cfg.validation * n)))
    val_idx, train_idx = perm[:n_val].to(device), perm[n_val:].to(device)
    val_mask = subset_mask(n_val, m, gen, device, cfg.min_measurements)
    x_val = x[val_idx].masked_fill(val_mask[..., None], float("nan"))
    u_val = u[val_idx]
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    state = TrainLog(history=[])
    best = {k: v.detach().clone() for k, v in net.state_dict().items()}
    path = None if checkpoint is None else Path(checkpoint)
    if path is not None and path.is_file():
        ck = torch.load(path, map_location=device, weights_only=True)
        net.load_state_dict(ck["net"])
        opt.load_state_dict(ck["opt"])
        best = ck["best"]
        gen.set_state(ck["gen"])
        state = TrainLog(**{k: ck["log"][k] for k in TrainLog.__dataclass_fields__})
        state.resumed_at = state.epochs
        if log:
            log(f"{desc}: resumed at epoch {state.epochs} from {path}")
    t0 = time.perf_counter() - state.seconds
    bar = progress_bar(total=cfg.max_epochs, initial=state.epochs, desc=desc, unit="epoch", progress=progress)
    try:
        while state.epochs < cfg.max_epochs and state.epochs - state.best_epoch < cfg.patience:
            if cfg.time_budget is not None and time.perf_counter() - t0 > cfg.time_budget:
                state.stopped = f"time budget of {cfg.time_budget:g} s"
                break
            net.train()
            order = train_idx[torch.randperm(len(train_idx), generator=gen).to(device)]
            total = 0.0
            for i in range(0, len(order), cfg.batch):
                idx = order[i: i + cfg.batch]
                mask = subset_mask(len(idx), m, gen, device, cfg.min_measurements)
                loss = loss_fn(net, u[idx], x[idx].masked_fill(mask[..., None], float("nan")))
                opt.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
                opt.step()
                total += loss.item() * len(idx)
            net.eval()
            with torch.no_grad():
                val = float(np.mean([float(loss_fn(net, u_val[i: i + 1024], x_val[i: i + 1024]))
                                     for i in range(0, n_val, 1024)]))
            state.epochs += 1
            state.history.append([total / len(train_idx), val])
            if val < state.best_val:
                state.best_val, state.best_epoch = val, state.epochs
                best = {k: v.detach().clone() for k, v in net.state_dict().items()}
            state.seconds = time.perf_counter() - t0
            bar.update(1)
            bar.set_postfix_str(f"val {val:.3f} (best {state.best_val:.3f} at {state.best_epoch})")
            if path is not None:
                ck = {"net": net.state_dict(), "opt": opt.state_dict(), "best": best, "gen": gen.get_state(),
                      "log": state.to_dict()}
                buf = io.BytesIO()
                torch.save(ck, buf)
                atomic_write(path, lambda fh: fh.write(buf.getvalue()))
    finally:
        bar.close()
    if not state.stopped:
        state.stopped = ("no better validation loss in " f"{cfg.patience} epochs"
                         if state.epochs < cfg.max_epochs else f"max_epochs {cfg.max_epochs}")
    state.seconds = time.perf_counter() - t0
    net.load_state_dict(best)
    net.eval()
    return state


def posterior_loss(net, u, x):
    """Negative log density of u under the flow conditioned on x (mean)."""
    return net.loss(u, condition=x).mean()


def ratio_loss(net, u, x):
    """NRE: every kept measurement of drone i against u_i (joint) and against the next
    drone's u (marginal), binary cross-entropy on the logits (mean)."""
    keep = ~torch.isnan(x[..., 0])  # (B, M)
    e = net.embed(torch.nan_to_num(x, nan=1.0))  # (B, M, D)
    u_other = torch.roll(u, 1, dims=0)
    pos = net.from_embedding(e, u[:, None, :])
    neg = net.from_embedding(e, u_other[:, None, :])
    loss = torch.nn.functional.softplus(-pos) + torch.nn.functional.softplus(neg)
    return (loss * keep).sum() / keep.sum()
