"""The networks: a per-profile 1-D CNN, sbi's permutation-invariant embedding over a
drone's measurements (any number: missing ones are NaN rows, sbi masks them and
adds their count), sbi's neural spline flow for the posterior, and a ratio network
(the same kind of CNN plus an MLP) for the per-measurement likelihood ratio.

Input features: ``log10(max(profile, 1e-6)) / 3`` of peak-normalised profiles (all
bins), so a profile's floor and its lines weigh alike. Torch is imported here only.
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass

import torch
from torch import nn

FLOOR = 1e-6
warnings.filterwarnings("ignore", message="torch.triangular_solve is deprecated")  # nflows' LU transform


@dataclass(frozen=True)
class NetConfig:
    """Sizes of the networks (stored in every estimator file).

    channels: the CNN's four stride-2 conv layers; trial_out: one profile's
    embedding; set_hidden / set_out: the set embedding's MLP; flow_hidden /
    flow_transforms: the spline flow; ratio_hidden: the ratio network's MLP."""

    channels: tuple = (8, 16, 32, 32)
    trial_out: int = 64
    set_hidden: int = 128
    set_out: int = 64
    flow_hidden: int = 64
    flow_transforms: int = 5
    ratio_hidden: int = 128

    def to_dict(self) -> dict:
        d = asdict(self)
        d["channels"] = list(self.channels)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "NetConfig":
        d = dict(d)
        d["channels"] = tuple(int(c) for c in d["channels"])
        return cls(**d)


def features(profiles: torch.Tensor) -> torch.Tensor:
    """Peak-normalised profiles (..., L) -> network input (NaN rows stay NaN)."""
    return torch.log10(torch.clamp(profiles, min=FLOOR)) / 3.0


class TrialNet(nn.Module):
    """One profile (..., L) -> (..., trial_out): four stride-2 conv layers, then an MLP."""

    def __init__(self, length: int, cfg: NetConfig):
        super().__init__()
        layers, c_in, size = [], 1, int(length)
        for c in cfg.channels:
            layers += [nn.Conv1d(c_in, c, 5, stride=2, padding=2), nn.GELU()]
            c_in, size = c, (size - 1) // 2 + 1
        self.conv = nn.Sequential(*layers)
        self.head = nn.Sequential(nn.Linear(c_in * size, 128), nn.GELU(), nn.Linear(128, cfg.trial_out))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        lead = x.shape[:-1]
        h = self.conv(features(x).reshape(-1, 1, x.shape[-1]))
        return self.head(h.flatten(1)).reshape(*lead, -1)


def set_embedding(length: int, cfg: NetConfig) -> nn.Module:
    """sbi's permutation-invariant embedding (mean over the measurements, their count
    appended) around a :class:`TrialNet`."""
    from sbi.neural_nets.embedding_nets import PermutationInvariantEmbedding

    return PermutationInvariantEmbedding(TrialNet(length, cfg), cfg.trial_out, aggregation_fn="mean",
                                         num_hiddens=cfg.set_hidden, num_layers=2, output_dim=cfg.set_out)


def posterior_net(u: torch.Tensor, x: torch.Tensor, cfg: NetConfig) -> nn.Module:
    """sbi's conditional neural spline flow q(u | measurements), built on a batch u (B, d),
    x (B, M, L) (its z-scoring of u is fitted on that batch and kept in its state)."""
    from sbi.neural_nets import posterior_nn

    build = posterior_nn("nsf", hidden_features=cfg.flow_hidden, num_transforms=cfg.flow_transforms,
                         z_score_theta="independent", z_score_x="none",
                         embedding_net=set_embedding(x.shape[-1], cfg))
    return build(u, x)


class RatioNet(nn.Module):
    """log r(u, x) = log p(x | u) - log p(x) for ONE profile x (..., L) and label-free
    quantities u (..., d), up to the classifier's error (NRE; Hermans et al. 2020).
    ``u_mean``, ``u_std``: the training set's standardisation of u (buffers)."""

    def __init__(self, length: int, dim: int, cfg: NetConfig):
        super().__init__()
        self.trial = TrialNet(length, cfg)
        self.register_buffer("u_mean", torch.zeros(dim))
        self.register_buffer("u_std", torch.ones(dim))
        h = cfg.ratio_hidden
        self.mlp = nn.Sequential(nn.Linear(cfg.trial_out + dim, h), nn.GELU(), nn.Linear(h, h), nn.GELU(),
                                 nn.Linear(h, h), nn.GELU(), nn.Linear(h, 1))

    def embed(self, x: torch.Tensor) -> torch.Tensor:
        return self.trial(x)

    def from_embedding(self, e: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Logits (...,) of embeddings e (..., trial_out) and u (..., d) (broadcast)."""
        z = (u - self.u_mean) / self.u_std
        shape = torch.broadcast_shapes(e.shape[:-1], z.shape[:-1])
        e = e.expand(*shape, e.shape[-1])
        z = z.expand(*shape, z.shape[-1])
        return self.mlp(torch.cat([e, z], dim=-1)).squeeze(-1)

    def forward(self, u: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        return self.from_embedding(self.embed(x), u)
