"""A trained estimator: data, saved without pickle and checked like any input file.

File: a ZIP of ``meta.json`` (format, class, radar, acquisition, prior, simulator
version, simulations, network and training settings, SBC figures) and two torch
state dicts, ``posterior.pt`` (the amortized posterior q(u | measurements)) and
``ratio.pt`` (the per-measurement likelihood ratio of the emcee path), read with
``torch.load(weights_only=True)``. Loading checks every field and refuses, by name,
an estimator of another class, radar or acquisition than the data's, with the
command that trains the right one.
"""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import torch

from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from ...radar.io import atomic_write
from ..space.priors import Priors
from .nets import NetConfig, RatioNet, posterior_net
from .simulate import SIMULATOR, SimulationSpec, spec_from_dict
from .target import TARGET, LabelFree

FORMAT = "mdaug-estimator-1"
MEMBERS = ("meta.json", "posterior.pt", "ratio.pt")
META_FIELDS = ("format", "spec", "prior", "net", "n_simulations", "label_free", "training", "sbc", "seed")


class EstimatorError(ValueError):
    """A file that is not a usable estimator, or one that does not match the data."""


def train_command(spec: SimulationSpec) -> str:
    return (f"mdaug train-estimator --class {spec.class_name} --ramps {spec.acquisition.ramps} "
            f"--out {spec.class_name.lower()}-k{spec.acquisition.ramps}.zip")


class AmortizedEstimator:
    """Posterior and ratio networks of one class and acquisition (module doc)."""

    def __init__(self, spec: SimulationSpec, net_cfg: NetConfig, posterior: torch.nn.Module, ratio: RatioNet,
                 meta: dict | None = None):
        self.spec, self.net_cfg = spec, net_cfg
        self.posterior, self.ratio = posterior.eval(), ratio.eval()
        ref = spec.reference
        self.priors = spec.priors()
        self.label_free = LabelFree(ref.n_engines, self.priors, ref.to_array())
        self.meta = dict(meta or {})
        self.meta.update(format=FORMAT, spec=spec.to_dict(), prior=self.priors.to_dict(), net=net_cfg.to_dict(),
                         label_free=self.label_free.names, target=TARGET)

    @property
    def class_name(self) -> str:
        return self.spec.class_name

    @property
    def max_measurements(self) -> int:
        return int(self.spec.n_measurements)

    @classmethod
    def build(cls, spec: SimulationSpec, net_cfg: NetConfig, u: torch.Tensor, x: torch.Tensor) -> "AmortizedEstimator":
        """Untrained networks for training data u (N, d), x (N, M, L) (the flow's
        z-scoring is fitted on them)."""
        post = posterior_net(u, x, net_cfg)
        ratio = RatioNet(x.shape[-1], u.shape[-1], net_cfg).to(u.device)
        ratio.u_mean.copy_(u.mean(0))
        ratio.u_std.copy_(u.std(0).clamp_min(1e-6))
        return cls(spec, net_cfg, post.to(u.device), ratio)

    # ---- use ------------------------------------------------------------------------------
    def check_data(self, profiles: np.ndarray, acquisition: Acquisition, radar: RadarConfig, source: str) -> None:
        """Refuse (EstimatorError naming the field) data this estimator was not trained for."""
        want = self.spec.acquisition.to_dict()
        got = acquisition.to_dict()
        diff = [k for k in want if want[k] != got.get(k)]
        if diff:
            k = diff[0]
            wanted = SimulationSpec(self.class_name, acquisition, self.spec.n_measurements, radar)
            raise EstimatorError(f"{source}: acquisition field {k!r} is {got.get(k)!r} but the estimator was "
                                 f"trained for {want[k]!r}; train one with: {train_command(wanted)}")
        if radar.to_dict() != self.spec.radar.to_dict():
            raise EstimatorError(f"{source}: the radar configuration differs from the estimator's (field 'radar'); "
                                 f"train one with: {train_command(self.spec)}")
        n = np.asarray(profiles).shape[0]
        if not 1 <= n <= self.max_measurements:
            raise EstimatorError(f"{source}: {n} measurements; the estimator takes 1 to {self.max_measurements} "
                                 "of one drone")

    def condition(self, profiles: np.ndarray) -> torch.Tensor:
        """Prepared profiles (M, L) -> the flow's condition (1, M_max, L) (NaN rows pad)."""
        y = np.full((1, self.max_measurements, profiles.shape[-1]), np.nan, np.float32)
        y[0, : len(profiles)] = profiles
        return torch.as_tensor(y, device=self._device)

    @property
    def _device(self):
        return next(self.posterior.parameters()).device

    def sample_u(self, profiles: np.ndarray, n: int, seed: int, *, strict: bool = True) -> tuple[np.ndarray, float]:
        """n draws of u from the amortized posterior given prepared profiles (M, L),
        inside the prior's support (draws outside are rejected and redrawn: leakage).
        Returns (u (n, d), accepted share). When fewer than n fall inside after 20 n
        tries: EstimatorError if ``strict``, else the rest filled with rejected draws."""
        torch.manual_seed(int(seed))
        cond = self.condition(profiles)
        out, rejected, tried, kept = [], [], 0, 0
        with torch.inference_mode():
            while kept < n and tried < 20 * n:
                k = max(2 * (n - kept), 1024)
                u = self.posterior.sample((k,), condition=cond).reshape(k, -1).double().cpu().numpy()
                _, ok = self.label_free.vectors(self.label_free.from_unbounded(u))
                ok &= np.all(np.isfinite(u), axis=1)
                out.append(u[ok])
                rejected.append(u[~ok & np.all(np.isfinite(u), axis=1)][:n])
                tried, kept = tried + k, kept + int(ok.sum())
        u = np.concatenate(out)[:n]
        if len(u) < n and not strict:
            u = np.concatenate([u] + rejected)[:n]
        if len(u) < n:
            raise EstimatorError(f"the amortized posterior put {kept} of {tried} draws inside the prior; the "
                                 "measurements are unlike anything in its training set")
        return u, kept / tried

    def log_prob_u(self, u: np.ndarray, profiles: np.ndarray) -> np.ndarray:
        """Log density of the amortized posterior at u (n, d) given prepared profiles
        (M, L). The profiles are embedded once: sbi's ``log_prob`` expands the condition
        to every draw and embeds each copy (n CNN passes over M profiles), so this runs
        the steps of its nflows flow (embedding, transform, base density) itself, with
        the one embedding; the same numbers (``tests/test_amortized.py``)."""
        flow = self.posterior.net  # the nflows Flow inside sbi's estimator
        with torch.inference_mode():
            t = torch.as_tensor(np.asarray(u, np.float32), device=self._device).reshape(len(u), -1)
            context = flow._embedding_net(self.condition(profiles)).expand(len(t), -1)
            noise, log_det = flow._transform(t, context=context)
            return (flow._distribution.log_prob(noise, context=context) + log_det).double().cpu().numpy()

    def embed(self, profiles: np.ndarray) -> torch.Tensor:
        """The ratio network's embeddings (M, D) of prepared profiles (M, L)."""
        with torch.inference_mode():
            return self.ratio.embed(torch.as_tensor(np.asarray(profiles, np.float32), device=self._device))

    def log_likelihood_u(self, u: np.ndarray, emb: torch.Tensor) -> np.ndarray:
        """Learned log-likelihood (up to a constant) per measurement at u (n, d): (n, M),
        the measurements taken as independent given the drone."""
        with torch.inference_mode():
            t = torch.as_tensor(np.asarray(u, np.float32), device=emb.device)
            return self.ratio.from_embedding(emb[None], t[:, None, :]).double().cpu().numpy()

    # ---- file ---------------------------------------------------------------------------------
    def save(self, path) -> Path:
        """Write the ZIP atomically (no half-written file)."""
        blobs = {"meta.json": json.dumps(self.meta, indent=1, default=float).encode()}
        for name, net in (("posterior.pt", self.posterior), ("ratio.pt", self.ratio)):
            buf = io.BytesIO()
            torch.save({k: v.detach().cpu() for k, v in net.state_dict().items()}, buf)
            blobs[name] = buf.getvalue()

        def write(fh):
            with zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as z:
                for name, data in blobs.items():
                    z.writestr(name, data)

        return atomic_write(path, write)

    @classmethod
    def load(cls, path, *, device: str = "cpu") -> "AmortizedEstimator":
        """Read and check an estimator file (module doc); EstimatorError names the
        file and the field."""
        path = Path(path)
        src = str(path)
        try:
            with zipfile.ZipFile(path) as z:
                names = set(z.namelist())
                missing = [m for m in MEMBERS if m not in names]
                if missing:
                    raise EstimatorError(f"{src}: not an mdaug estimator (member {missing[0]!r} missing)")
                meta = json.loads(z.read("meta.json"))
                states = {m: torch.load(io.BytesIO(z.read(m)), map_location=device, weights_only=True)
                          for m in MEMBERS[1:]}
        except FileNotFoundError:
            raise EstimatorError(f"{src}: no such estimator file") from None
        except EstimatorError:
            raise
        except (zipfile.BadZipFile, OSError, EOFError, RuntimeError, ValueError, KeyError) as exc:
            raise EstimatorError(f"{src}: not a readable mdaug estimator ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0][:120] if str(exc) else 'truncated or damaged'})") from None
        if not isinstance(meta, dict):
            raise EstimatorError(f"{src}: member 'meta.json' is not a JSON table")
        absent = [k for k in META_FIELDS if k not in meta]
        if absent:
            raise EstimatorError(f"{src}: meta.json field {absent[0]!r} is missing")
        if meta["format"] != FORMAT:
            raise EstimatorError(f"{src}: meta.json field 'format' is {meta['format']!r}; expected {FORMAT!r}")
        try:
            spec = spec_from_dict(meta["spec"])
            net_cfg = NetConfig.from_dict(meta["net"])
        except (KeyError, TypeError, ValueError) as exc:
            raise EstimatorError(f"{src}: meta.json field 'spec' or 'net' is not valid ({exc})") from None
        if meta["spec"].get("simulator") != SIMULATOR:
            raise EstimatorError(f"{src}: meta.json field 'spec.simulator' is {meta['spec'].get('simulator')!r}; "
                                 f"this mdaug simulates {SIMULATOR!r}; retrain with: {train_command(spec)}")
        if Priors.from_dict(meta["prior"]).to_dict() != spec.priors().to_dict():
            raise EstimatorError(f"{src}: meta.json field 'prior' differs from the class reference's prior; "
                                 f"retrain with: {train_command(spec)}")
        ref = spec.reference
        if ref.n_engines > 1 and meta.get("target", 1) != TARGET:  # one engine: every version is the same
            raise EstimatorError(f"{src}: meta.json field 'target' is {meta.get('target', 1)!r}: its quantities "
                                 f"order the engines differently from this mdaug's (version {TARGET}); "
                                 f"retrain with: {train_command(spec)}")
        lf = LabelFree(ref.n_engines, spec.priors(), ref.to_array())
        length = spec.radar.slice_length
        u0 = torch.randn(64, lf.dim)
        x0 = torch.rand(64, spec.n_measurements, length)
        est = cls.build(spec, net_cfg, u0.to(device), x0.to(device))
        for name, net in (("posterior.pt", est.posterior), ("ratio.pt", est.ratio)):
            try:
                net.load_state_dict(states[name])
            except (RuntimeError, KeyError, TypeError) as exc:
                raise EstimatorError(f"{src}: member {name!r} does not fit the networks of meta.json field 'net' "
                                     f"({str(exc).splitlines()[0][:120]})") from None
            for k, v in net.state_dict().items():
                if v.is_floating_point() and not torch.isfinite(v).all():
                    raise EstimatorError(f"{src}: member {name!r} tensor {k!r} holds NaN or inf")
        est.posterior.eval()
        est.ratio.eval()
        est.meta = meta
        return est
