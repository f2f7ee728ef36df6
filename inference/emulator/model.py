"""The emulated likelihood's trained model: everything a calibration needs, as data.

:class:`SummaryModel` holds the label-free space of a class, the summary's whitening,
the emulator network and the covariance of the emulator's own held-out error, for one
acquisition and radar. For a drone with label-free coordinates u and n measurements:

    z_bar | u ~ N(mu(u), c (W(u) (1 / n + a(u)) + b(u) I))

z_bar the whitened mean folded log-profile of the n measurements, mu the emulator,
W(u) the drone's own within-drone covariance of one measurement (a network; the
pooled one is the identity after whitening), a(u) W(u) + b(u) I the emulator's own
error (a small network :class:`.net.ErrorNet` fitted by maximum likelihood to the
emulator's residuals on held-out simulated drones, net of the noise in its targets:
the emulator is worse where training drones were sparse), c >= 1 an inflation chosen
on other held-out drones so that the chi-square of the truth's residual has its
expected median (stated in the file: ``inflation``), times a widening w(u) >= 1 (log w
linear and quadratic in u, ``widening``) fitted so that twice the gap between the
likelihood's maximum and its value at the truth is the chi-square of d degrees of
freedom that an honest likelihood gives (Wilks): where the emulator's error is
smooth in u the truth's residual looks right while the maximum moves away from the
truth, and only this second check sees it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from .net import CovarianceNet, Emulator, ErrorNet
from .sketch import sketch
from .summary import Whitening

LOG_2PI = float(np.log(2 * np.pi))


def gaussian_log_density(resid: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """log N(resid; 0, L L') (N,) for residuals (N, D) and a Cholesky factor L: one (D, D)
    for every residual, or (N, D, D), one each."""
    resid = np.asarray(resid, float)
    if chol.ndim == 2:
        w = np.linalg.solve(chol, resid.T).T
        logdet = np.log(np.diag(chol)).sum()
    else:
        w = np.linalg.solve(chol, resid[..., None])[..., 0]
        logdet = np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(1)
    return -0.5 * resid.shape[-1] * LOG_2PI - logdet - 0.5 * (w * w).sum(-1)


@dataclass
class SummaryModel:
    """The emulated likelihood of one class under one acquisition (module doc)."""

    class_name: str
    acquisition: Acquisition
    radar: RadarConfig
    label_free: object
    """A :class:`mdaug.inference.amortized.target.LabelFree` (duck-typed: this room
    imports nothing of the amortized room, which holds it)."""
    whitening: Whitening
    net: Emulator
    cov_net: CovarianceNet
    error_net: ErrorNet
    inflation: float = 1.0
    widening: dict | None = None

    @property
    def dim(self) -> int:
        return self.label_free.dim

    @property
    def n_components(self) -> int:
        return self.whitening.n_components

    def features(self, u: np.ndarray) -> np.ndarray:
        """Physics sketch (n, F) of label-free coordinates u (n, d)."""
        q = self.label_free.from_unbounded(u)
        return sketch(q, self.label_free.E, self.whitening.n_offsets, self.radar)

    def nets(self, u: np.ndarray, covariance: bool = True):
        """The three networks at drones u (N, d): (mu (N, D), the within-drone covariance
        W (N, D, D) or None, the emulator error's (a, b) (N, 2) or None)."""
        u = np.atleast_2d(np.asarray(u, float))
        tu = torch.as_tensor(u, dtype=torch.float32)
        ts = torch.as_tensor(self.features(u), dtype=torch.float32)
        with torch.no_grad():
            mean = self.net(tu, ts).double().numpy()
            if not covariance:
                return mean, None, None
            chol = self.cov_net(tu, ts).double().numpy()
            ab = torch.exp(self.error_net(tu)).double().numpy()
        return mean, chol @ np.swapaxes(chol, -1, -2), ab

    def mean(self, u: np.ndarray) -> np.ndarray:
        """mu(u): (n, D) expected whitened summary of drones u (n, d)."""
        return self.nets(u, False)[0]

    def moments(self, u: np.ndarray, n_measurements: int, widen: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(mu (N, D), covariance (N, D, D)) of the whitened mean of n measurements of drones u (N, d)."""
        u = np.atleast_2d(np.asarray(u, float))
        mean, w, ab = self.nets(u)
        cov = self.covariance_from(w, ab, n_measurements)
        return mean, cov * self.widen(u)[:, None, None] if widen else cov

    def log_likelihood(self, u: np.ndarray, z_bar: np.ndarray, n_measurements: int,
                       widen: bool = True) -> np.ndarray:
        """log N(z_bar; mu(u), Sigma_n(u)): (N,) for u (N, d) and the whitened mean z_bar
        (D,) of n measurements (the widening left out with ``widen=False``)."""
        mean, cov = self.moments(u, n_measurements, widen=widen)
        return gaussian_log_density(mean - z_bar, np.linalg.cholesky(cov))

    def covariance_from(self, within: np.ndarray, ab: np.ndarray, n_measurements: int) -> np.ndarray:
        """c (W (1 / n + a) + b I) (module doc) from W (N, D, D) and (a, b) (N, 2)."""
        eye = np.eye(within.shape[-1])
        return self.inflation * (within * (1.0 / int(n_measurements) + ab[:, :1, None]) + ab[:, 1:, None] * eye)

    def widen(self, u: np.ndarray) -> np.ndarray:
        """w(u) >= 1 (N,) (module doc); 1 without a fitted widening."""
        u = np.atleast_2d(np.asarray(u, float))
        if not self.widening:
            return np.ones(len(u))
        w = self.widening
        t = (u - np.asarray(w["centre"])) / np.asarray(w["scale"])
        log_w = w["intercept"] + t @ np.asarray(w["slope"])
        if "quadratic" in w:
            log_w = log_w + (t * t) @ np.asarray(w["quadratic"])
        return np.exp(np.clip(log_w, 0.0, 5.0))

    def summarise(self, profiles: np.ndarray) -> np.ndarray:
        """(D,) whitened mean folded log-profile of measurements (M, L)."""
        from .summary import folded_log_profile

        return self.whitening(folded_log_profile(profiles, self.whitening.n_offsets).mean(axis=0))

    def fisher(self, u: np.ndarray, n_measurements: int, step: float = 1e-3) -> np.ndarray:
        """Fisher information (d, d) of u at u (d,) for n measurements (:func:`fisher_information`,
        the mean's and the covariance's derivatives by central differences in u). The
        widening enters as its value at u, held: it is a calibration of the emulator's
        error, not something the drone changes in its profiles, and its slope in u would
        otherwise count as information (HELI K = 32's w^3 made line 1's bound 10% narrower
        than with no widening at all)."""
        u = np.asarray(u, float).reshape(-1)
        e = np.eye(len(u)) * step
        pts = np.concatenate([u[None], u + e, u - e])
        mean, cov = self.moments(pts, n_measurements, widen=False)
        cov = cov * self.widen(u[None])[0]
        d = len(u)
        jac = ((mean[1: d + 1] - mean[d + 1:]) / (2 * step)).T
        dcov = (cov[1: d + 1] - cov[d + 1:]) / (2 * step)
        return fisher_information(jac, cov[0], dcov)


def fisher_information(jac: np.ndarray, cov: np.ndarray, dcov: np.ndarray | None = None) -> np.ndarray:
    """Fisher information of a Gaussian N(mu(theta), S(theta)): jac (D, d) = d mu / d theta,
    cov (D, D), dcov (d, D, D) = d S / d theta_i or None (constant S):
    I_ij = d_i mu' S^-1 d_j mu + 1/2 tr(S^-1 d_i S S^-1 d_j S)."""
    jac = np.asarray(jac, float)
    sinv_j = np.linalg.solve(cov, jac)
    info = jac.T @ sinv_j
    if dcov is not None:
        a = np.stack([np.linalg.solve(cov, dc) for dc in dcov])  # S^-1 d_i S
        info = info + 0.5 * np.einsum("iab,jba->ij", a, a)
    return 0.5 * (info + info.T)


def cramer_rao(info: np.ndarray) -> np.ndarray:
    """Cramer-Rao bound: the covariance bound (d, d) = I^-1. Where a direction carries
    no information (eigenvalue below 1e-10 of the largest), the bound of every
    coordinate that direction touches is infinite (its diagonal entry is inf); the
    rest is the pseudo-inverse."""
    w, v = np.linalg.eigh(0.5 * (info + info.T))
    ok = w > w.max(initial=0.0) * 1e-10
    inv_w = np.where(ok, 1.0 / np.where(ok, w, 1.0), 0.0)
    bound = (v * inv_w) @ v.T
    blind = (np.abs(v[:, ~ok]) > 1e-9).any(axis=1)
    bound[np.diag_indices_from(bound)] = np.where(blind, np.inf, np.diag(bound))
    return bound


SUMMARY_FORMAT = "mdaug-summary-1"
"""Version of the summary likelihood's file parts (meta field 'summary.format')."""


def to_parts(model: SummaryModel, report: dict | None = None) -> tuple[dict, dict]:
    """(meta, state): the model as plain JSON numbers and one state dict of tensors
    (the emulator's and covariance network's weights, the whitening), for a file read
    with ``torch.load(weights_only=True)``."""
    state = {f"net.{k}": v.detach().cpu() for k, v in model.net.state_dict().items()}
    state.update({f"cov.{k}": v.detach().cpu() for k, v in model.cov_net.state_dict().items()})
    state.update({f"error.{k}": v.detach().cpu().float() for k, v in model.error_net.state_dict().items()})
    for name in ("centre", "basis", "between"):
        state[f"whitening.{name}"] = torch.as_tensor(np.asarray(getattr(model.whitening, name), np.float64))
    meta = {"format": SUMMARY_FORMAT, "net": model.net.config(), "cov_net": model.cov_net.config(),
            "error_net": model.error_net.config(), "inflation": float(model.inflation),
            "widening": model.widening, "training": dict(report or {})}
    return meta, state


WIDENING_KEYS = ("centre", "intercept", "scale", "slope")
"""The widening's fields in a file; ``quadratic`` (d numbers) may follow them."""


def from_parts(meta: dict, state: dict, class_name: str, acquisition: Acquisition, radar: RadarConfig,
               label_free, src: str) -> SummaryModel:
    """The model of :func:`to_parts`' output; ValueError naming ``src`` and the field
    that does not fit."""
    if not isinstance(meta, dict) or meta.get("format") != SUMMARY_FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else meta
        raise ValueError(f"{src}: meta.json field 'summary.format' is {got!r}; expected {SUMMARY_FORMAT!r}")
    v = meta.get("inflation")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 1:
        raise ValueError(f"{src}: meta.json field 'summary.inflation' must be a finite number >= 1, got {v!r}")
    widening = meta.get("widening")
    if widening is not None:
        d = label_free.dim
        keys = sorted(widening) if isinstance(widening, dict) else []
        lists = ("centre", "scale", "slope") + (("quadratic",) if "quadratic" in keys else ())
        ok = keys in (sorted(WIDENING_KEYS), sorted(WIDENING_KEYS + ("quadratic",)))
        ok = ok and _finite(widening["intercept"]) and all(
            isinstance(widening[k], list) and len(widening[k]) == d and all(_finite(v) for v in widening[k])
            for k in lists)
        if not ok or not all(v > 0 for v in widening["scale"]):
            raise ValueError(f"{src}: meta.json field 'summary.widening' must hold a finite intercept and {d} finite "
                             "numbers each of centre, scale (> 0), slope and (optionally) quadratic")
    nets = {}
    for key, cls_, prefix in (("net", Emulator, "net."), ("cov_net", CovarianceNet, "cov."),
                              ("error_net", ErrorNet, "error.")):
        cfg = meta.get(key)
        want = ("dim", "hidden") if key == "error_net" else ("dim", "n_offsets", "n_components", "hidden", "depth")
        if key == "net" and isinstance(cfg, dict) and "members" in cfg:  # absent from files before the ensemble (one member)
            want += ("members",)
        if not isinstance(cfg, dict) or sorted(cfg) != sorted(want) or not all(
                isinstance(cfg[k], int) and not isinstance(cfg[k], bool) and 1 <= cfg[k] <= 4096 for k in want):
            raise ValueError(f"{src}: meta.json field 'summary.{key}' must hold the integers {', '.join(want)}")
        if cfg["dim"] != label_free.dim:
            raise ValueError(f"{src}: meta.json field 'summary.{key}.dim' is {cfg['dim']}; class {class_name} has "
                             f"{label_free.dim} label-free quantities")
        net = cls_(**cfg)
        sub = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
        if key == "net":
            sub = Emulator.upgrade_state(sub)
        try:
            net.load_state_dict(sub)
        except (RuntimeError, KeyError, TypeError) as exc:
            raise ValueError(f"{src}: member 'summary.pt' does not fit meta.json field 'summary.{key}' "
                             f"({str(exc).splitlines()[0][:120]})") from None
        if not all(torch.isfinite(t).all() for t in sub.values() if t.is_floating_point()):
            raise ValueError(f"{src}: member 'summary.pt' holds NaN or inf weights ({prefix[:-1]})")
        nets[key] = net.eval()
    arrays = {}
    for name in ("centre", "basis", "between"):
        t = state.get(f"whitening.{name}")
        if t is None or not torch.isfinite(t).all():
            raise ValueError(f"{src}: member 'summary.pt' entry 'whitening.{name}' is missing or not finite")
        arrays[name] = t.double().numpy()
    cfg = meta["net"]
    if arrays["basis"].shape != (cfg["n_components"], cfg["n_offsets"]) or arrays["centre"].shape != (cfg["n_offsets"],):
        raise ValueError(f"{src}: member 'summary.pt': the whitening's shape does not fit meta.json field 'summary.net'")
    if meta["cov_net"]["n_components"] != cfg["n_components"] or meta["cov_net"]["n_offsets"] != cfg["n_offsets"]:
        raise ValueError(f"{src}: meta.json fields 'summary.net' and 'summary.cov_net' disagree on the summary's size")
    return SummaryModel(class_name, acquisition, radar, label_free, Whitening(**arrays), nets["net"], nets["cov_net"],
                        nets["error_net"], float(meta["inflation"]), widening)


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))
