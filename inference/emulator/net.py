"""The emulator: label-free quantities u -> the expected whitened summary of a drone.

Input: u (the unbounded label-free coordinates, :mod:`mdaug.inference.amortized.target`)
and the physics sketch of :mod:`.sketch` (the folded log-magnitude where the lines put
power), each z-scored with the training set's mean and sd; output: the D whitened
components of :class:`.summary.Whitening`, as the sketch's projection plus a learned
correction (an MLP of the inputs). Trained on squared error against the mean summary
of simulated drones' measurements; :func:`fit` keeps the epoch of the lowest
validation loss (early stopping).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn


def _split(n: int, val_share: float, g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """(train, validation) indices: the last ``val_share`` of a seeded permutation of n."""
    perm = torch.randperm(n, generator=g)
    n_val = max(1, int(round(val_share * n)))
    return perm[n_val:], perm[:n_val]


def _early_stopping(net: nn.Module, epoch, validate, *, epochs: int, patience: int, tol: float, sched=None) -> dict:
    """Run ``epoch()`` (one pass of training; returns its loss or None) and ``validate()``
    (the validation loss) up to ``epochs`` times, stopping after ``patience`` epochs
    without a gain of ``tol``; ``net`` ends with the weights of its best epoch."""
    best, best_state, hist, since = np.inf, None, [], 0
    for _ in range(epochs):
        net.train()
        train_loss = epoch()
        net.eval()
        with torch.no_grad():
            v = float(validate())
        if sched is not None:
            sched.step(v)
        hist.append(v if train_loss is None else (train_loss, v))
        if v < best - tol:
            best, since = v, 0
            best_state = {k: t.clone() for k, t in net.state_dict().items()}
        else:
            since += 1
            if since >= patience:
                break
    net.load_state_dict(best_state)
    net.eval()
    vals = [h[1] if isinstance(h, tuple) else h for h in hist]
    return {"history": hist, "best_epoch": int(np.argmin(vals)), "best_val": best}


class Emulator(nn.Module):
    """u (n, d), sketch (n, F) -> mean whitened summary (n, D) (module doc).

    The correction is the mean of ``members`` MLPs, each trained on its own seed (its
    own validation split and batches) by :func:`fit` and joined by :meth:`stack`: a
    bagged ensemble, whose members' errors partly cancel (QUAD K = 32, 18,400 drones:
    held-out mean squared error 0.65-0.67 for one member, 0.50 for four)."""

    def __init__(self, dim: int, n_offsets: int, n_components: int, hidden: int = 256, depth: int = 3,
                 members: int = 1):
        super().__init__()
        self.dim, self.n_offsets, self.n_components = int(dim), int(n_offsets), int(n_components)
        self.hidden, self.depth, self.members = int(hidden), int(depth), int(members)
        if self.members < 1:
            raise ValueError(f"members must be >= 1, got {members}")
        self.register_buffer("in_mean", torch.zeros(self.members, dim + n_offsets))
        self.register_buffer("in_sd", torch.ones(self.members, dim + n_offsets))
        self.register_buffer("sketch_basis", torch.zeros(n_components, n_offsets))
        self.register_buffer("sketch_centre", torch.zeros(n_offsets))
        self.mlps = nn.ModuleList([self._mlp() for _ in range(self.members)])

    def _mlp(self) -> nn.Sequential:
        layers, width = [], self.dim + self.n_offsets
        for _ in range(self.depth):
            layers += [nn.Linear(width, self.hidden), nn.SiLU()]
            width = self.hidden
        layers.append(nn.Linear(width, self.n_components))
        return nn.Sequential(*layers)

    def config(self) -> dict:
        return {"dim": self.dim, "n_offsets": self.n_offsets, "n_components": self.n_components,
                "hidden": self.hidden, "depth": self.depth, "members": self.members}

    def forward(self, u: torch.Tensor, sk: torch.Tensor) -> torch.Tensor:
        x = torch.cat([u, sk], dim=-1)
        corr = sum(mlp((x - self.in_mean[k]) / self.in_sd[k]) for k, mlp in enumerate(self.mlps))
        return (sk - self.sketch_centre) @ self.sketch_basis.T + corr / self.members

    @classmethod
    def member(cls, dim: int, basis: np.ndarray, centre: np.ndarray, hidden: int = 256, depth: int = 3) -> "Emulator":
        """A one-member emulator of ``dim`` coordinates whose sketch projection is the
        whitening's: basis (D, F), centre (F,) (sizes read from them), ready for :func:`fit`."""
        basis, centre = np.asarray(basis), np.asarray(centre)
        net = cls(dim, basis.shape[1], basis.shape[0], hidden, depth)
        with torch.no_grad():
            net.sketch_basis.copy_(torch.as_tensor(basis, dtype=torch.float32))
            net.sketch_centre.copy_(torch.as_tensor(centre, dtype=torch.float32))
        return net

    @classmethod
    def stack(cls, nets: list["Emulator"]) -> "Emulator":
        """One emulator whose correction is the mean of the given one-member emulators'
        (same sizes and sketch projection)."""
        first = nets[0]
        if any(n.members != 1 or n.config() != first.config() for n in nets):
            raise ValueError("stack takes one-member emulators of the same sizes")
        cfg = dict(first.config(), members=len(nets))
        out = cls(**cfg)
        with torch.no_grad():
            out.sketch_basis.copy_(first.sketch_basis)
            out.sketch_centre.copy_(first.sketch_centre)
            for k, n in enumerate(nets):
                out.in_mean[k].copy_(n.in_mean[0])
                out.in_sd[k].copy_(n.in_sd[0])
                out.mlps[k].load_state_dict(n.mlps[0].state_dict())
        return out.eval()

    @staticmethod
    def upgrade_state(state: dict) -> dict:
        """A one-network state of files written before the ensemble (``mlp.*``, in_mean
        (F,)) as the one-member state of this class (``mlps.0.*``, in_mean (1, F))."""
        if not any(k.startswith("mlp.") for k in state):
            return state
        out = {}
        for k, v in state.items():
            if k.startswith("mlp."):
                out["mlps.0." + k[4:]] = v
            elif k in ("in_mean", "in_sd") and v.ndim == 1:
                out[k] = v[None]
            else:
                out[k] = v
        return out


def fit(net: Emulator, u: np.ndarray, sk: np.ndarray, target: np.ndarray, *, seed: int, epochs: int = 300,
        batch: int = 256, lr: float = 2e-3, patience: int = 30, val_share: float = 0.1, progress=None) -> dict:
    """Train ``net`` in place on (u, sketch) -> target (n, D); returns the history
    (train / validation loss per epoch, the best epoch). The validation split is the
    last ``val_share`` of a seeded permutation."""
    if net.members != 1:
        raise ValueError(f"fit trains a one-member emulator (Emulator.stack joins them), got {net.members} members")
    g = torch.Generator().manual_seed(int(seed))
    tr, va = _split(len(u), val_share, g)
    U, S, T = (torch.as_tensor(a, dtype=torch.float32) for a in (u, sk, target))
    x = torch.cat([U, S], 1)
    net.in_mean[0].copy_(x[tr].mean(0))
    net.in_sd[0].copy_(x[tr].std(0).clamp_min(1e-6))
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=patience // 3)

    def epoch():
        order = tr[torch.randperm(len(tr), generator=g)]
        tot = 0.0
        for i in range(0, len(order), batch):
            b = order[i: i + batch]
            loss = ((net(U[b], S[b]) - T[b]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            tot += float(loss.detach()) * len(b)
        return tot / len(tr)

    out = _early_stopping(net, epoch, lambda: ((net(U[va], S[va]) - T[va]) ** 2).mean(), epochs=epochs,
                          patience=patience, tol=1e-5, sched=sched)
    return {"loss": out["history"], "best_epoch": out["best_epoch"], "best_val": out["best_val"],
            "validation": va.numpy()}


class CovarianceNet(nn.Module):
    """u (n, d), sketch (n, F) -> Cholesky factor (n, D, D) of the within-drone covariance
    of one measurement's whitened summary (the pooled one is the identity; this one
    follows the drone: a faint, slow drone's profiles vary less from acquisition to
    acquisition than a bright, fast one's). L = diag(exp(s)) + strictly lower part,
    both from an MLP whose last layer starts at zero (L = I before training)."""

    def __init__(self, dim: int, n_offsets: int, n_components: int, hidden: int = 256, depth: int = 2):
        super().__init__()
        self.dim, self.n_offsets, self.n_components = int(dim), int(n_offsets), int(n_components)
        self.hidden, self.depth = int(hidden), int(depth)
        d = self.n_components
        self.register_buffer("in_mean", torch.zeros(dim + n_offsets))
        self.register_buffer("in_sd", torch.ones(dim + n_offsets))
        self.register_buffer("lower", torch.tril_indices(d, d, -1))
        layers, width = [], dim + n_offsets
        for _ in range(depth):
            layers += [nn.Linear(width, hidden), nn.SiLU()]
            width = hidden
        last = nn.Linear(width, d + d * (d - 1) // 2)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.mlp = nn.Sequential(*layers, last)

    def config(self) -> dict:
        return {"dim": self.dim, "n_offsets": self.n_offsets, "n_components": self.n_components,
                "hidden": self.hidden, "depth": self.depth}

    def forward(self, u: torch.Tensor, sk: torch.Tensor) -> torch.Tensor:
        d = self.n_components
        out = self.mlp((torch.cat([u, sk], dim=-1) - self.in_mean) / self.in_sd)
        chol = torch.diag_embed(torch.exp(out[..., :d].clamp(-10.0, 10.0)))
        chol[..., self.lower[0], self.lower[1]] = out[..., d:]
        return chol


def fit_covariance(net: CovarianceNet, u: np.ndarray, sk: np.ndarray, z: np.ndarray, *, seed: int,
                   epochs: int = 200, batch: int = 256, lr: float = 1e-3, patience: int = 20,
                   val_share: float = 0.1) -> dict:
    """Train ``net`` in place on the measurements' whitened summaries z (n, M, D) of
    drones (u, sketch): the deviations from each drone's own mean are Gaussian with
    covariance W (M - 1) / M, W = L L' (maximum likelihood; early stopping on a seeded
    validation split). Returns the history."""
    g = torch.Generator().manual_seed(int(seed))
    n, m, _ = z.shape
    tr, va = _split(n, val_share, g)
    U, S = torch.as_tensor(u, dtype=torch.float32), torch.as_tensor(sk, dtype=torch.float32)
    Z = torch.as_tensor(z, dtype=torch.float32)
    dev = (Z - Z.mean(1, keepdim=True)) * float(np.sqrt(m / (m - 1)))
    x = torch.cat([U, S], 1)
    net.in_mean.copy_(x[tr].mean(0))
    net.in_sd.copy_(x[tr].std(0).clamp_min(1e-6))

    def nll(idx):
        chol = net(U[idx], S[idx])  # (b, D, D)
        w = torch.linalg.solve_triangular(chol, dev[idx].transpose(1, 2), upper=False)  # (b, D, M)
        logdet = torch.log(torch.diagonal(chol, dim1=1, dim2=2)).sum(1)
        return (m * logdet + 0.5 * (w * w).sum((1, 2))).mean() / m

    opt = torch.optim.Adam(net.parameters(), lr=lr)

    def epoch():
        order = tr[torch.randperm(len(tr), generator=g)]
        for i in range(0, len(order), batch):
            loss = nll(order[i: i + batch])
            opt.zero_grad()
            loss.backward()
            opt.step()

    out = _early_stopping(net, epoch, lambda: nll(va), epochs=epochs, patience=patience, tol=1e-4)
    return {"val_nll": out["history"], "best_epoch": out["best_epoch"], "best_val": out["best_val"]}


class ErrorNet(nn.Module):
    """u (n, d) -> (log a, log b) (n, 2): the emulator's own error covariance at u is
    a W(u) + b I (W the within-drone covariance). The emulator is good where the
    training drones were dense and poor where they were sparse, so its error follows
    the drone; the last layer starts at (log alpha0, log beta0), the pooled fit."""

    def __init__(self, dim: int, hidden: int = 32):
        super().__init__()
        self.dim, self.hidden = int(dim), int(hidden)
        self.register_buffer("in_mean", torch.zeros(dim))
        self.register_buffer("in_sd", torch.ones(dim))
        self.mlp = nn.Sequential(nn.Linear(dim, hidden), nn.SiLU(), nn.Linear(hidden, hidden), nn.SiLU(),
                                 nn.Linear(hidden, 2))

    def config(self) -> dict:
        return {"dim": self.dim, "hidden": self.hidden}

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        return self.mlp((u - self.in_mean) / self.in_sd).clamp(-20.0, 5.0)


def fit_error(net: ErrorNet, u: np.ndarray, within: np.ndarray, resid: np.ndarray, m: int, *, start: tuple,
              seed: int, epochs: int = 400, lr: float = 3e-3, patience: int = 40, val_share: float = 0.25,
              weight_decay: float = 1e-3) -> dict:
    """Train ``net`` on held-out drones: resid (n, D) = the M-measurement mean summary
    minus the emulator, Gaussian with covariance W / m + a(u) W + b(u) I (maximum
    likelihood, full batch, early stopping on a seeded split). start: (alpha0, beta0)."""
    g = torch.Generator().manual_seed(int(seed))
    tr, va = _split(len(u), val_share, g)
    U = torch.as_tensor(u, dtype=torch.float64)
    W = torch.as_tensor(within, dtype=torch.float64)
    R = torch.as_tensor(resid, dtype=torch.float64)
    net.double()
    net.in_mean.copy_(U[tr].mean(0))
    net.in_sd.copy_(U[tr].std(0).clamp_min(1e-6))
    with torch.no_grad():
        net.mlp[-1].weight.zero_()
        net.mlp[-1].bias.copy_(torch.log(torch.as_tensor(start, dtype=torch.float64).clamp_min(1e-8)))
    eye = torch.eye(W.shape[-1], dtype=torch.float64)

    def nll(idx):
        ab = torch.exp(net(U[idx]))
        cov = W[idx] * (1.0 / m + ab[:, :1, None]) + ab[:, 1:, None] * eye
        chol = torch.linalg.cholesky(cov)
        y = torch.linalg.solve_triangular(chol, R[idx][..., None], upper=False)[..., 0]
        return (torch.log(torch.diagonal(chol, dim1=1, dim2=2)).sum(1) + 0.5 * (y * y).sum(1)).mean()

    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)

    def epoch():  # full batch
        loss = nll(tr)
        opt.zero_grad()
        loss.backward()
        opt.step()

    out = _early_stopping(net, epoch, lambda: nll(va), epochs=epochs, patience=patience, tol=1e-5)
    net.float().eval()
    return {"val_nll": out["history"], "best_epoch": out["best_epoch"], "best_val": out["best_val"]}
