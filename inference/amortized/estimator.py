"""A trained estimator: data, saved without pickle and checked like any input file.

File: a ZIP of ``meta.json`` (format, class, radar, acquisition, prior, simulator
version, simulations, network and training settings, SBC figures) and two torch
state dicts, ``posterior.pt`` (the amortized posterior q(u | measurements)) and
``ratio.pt`` (the per-measurement likelihood ratio, the smc route's likelihood where
there is no other), and optionally ``summary.pt`` with the meta field ``summary`` (the
summary likelihood of :mod:`mdaug.inference.emulator`, which the smc route then uses
instead of the ratio), read with ``torch.load(weights_only=True)``. Loading checks every field and refuses, by name,
an estimator of another class, radar or acquisition than the data's, with the
command that trains the right one.
"""
from __future__ import annotations

import copy
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
SUMMARY_MEMBER = "summary.pt"
"""Optional member: the summary likelihood's weights (with meta field 'summary')."""
ROUTES = ("amortized", "smc", "stacked")
"""The routes of a calibration: the amortized posterior's exact draws, tempered SMC
from the amortized posterior to the posterior of the file's likelihood (the summary
likelihood where the file has one, else the ratio network's; :mod:`.tempered`), or the
two stacked: the mixture w smc + (1 - w) amortized, w the file's stacking weight (meta
field ``stacking``, :mod:`mdaug.inference.diagnostics.stacking`; only a file that states
one has this route). (nlopt + emcee started from the amortized draws lost to both on
every row of the route tables, docs/calibration-history.md, and left the package.)"""
MAX_TEMPERATURE = 4.0
"""Largest flow temperature a file may state (a posterior four times wider than trained
says little more than the prior; :mod:`mdaug.inference.temperature` searches 1-2)."""
META_FIELDS = ("format", "spec", "prior", "net", "n_simulations", "label_free", "training", "sbc", "seed")


class EstimatorError(ValueError):
    """A file that is not a usable estimator, or one that does not match the data."""


def train_command(spec: SimulationSpec) -> str:
    return (f"mdaug train-estimator --class {spec.class_name} --ramps {spec.acquisition.ramps} "
            f"--out {spec.class_name.lower()}-k{spec.acquisition.ramps}.zip")


class AmortizedEstimator:
    """Posterior and ratio networks of one class and acquisition (module doc)."""

    def __init__(self, spec: SimulationSpec, net_cfg: NetConfig, posterior: torch.nn.Module, ratio: RatioNet,
                 meta: dict | None = None, summary=None):
        self.spec, self.net_cfg = spec, net_cfg
        self.summary = summary  # a SummaryModel (mdaug.inference.emulator) or None
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
    def default_route(self) -> str:
        """The route a calibration takes unless told: the file's ``default_route`` (set
        by its route table: the best log score among the routes that pass SBC), else
        the amortized posterior."""
        return self.meta.get("default_route", "amortized")

    @property
    def stacking_weight(self) -> float | None:
        """The smc route's weight in the stacked route (meta field ``stacking.weight``,
        chosen by the log score of the truth on held-out drones,
        :func:`mdaug.inference.diagnostics.stacking.stacking_weight`), or None: the file has
        no stacked route."""
        st = self.meta.get("stacking")
        return None if not st else float(st["weight"])

    def users_row(self, route: str) -> dict | None:
        """What the file's route table stores of ``route`` on drones like a user's (the
        specimen model around the class reference, meta field ``sbc.specimens``):
        ``drones``, ``log_score`` (nats, lower is better) and ``lines``, the brightest
        engine's lines 1-4 median 90% width / truth (empty where not stored); None where
        the file stores no such row."""
        specimens = (self.meta.get("sbc") or {}).get("specimens") or {}
        row = (specimens.get("rows") or {}).get(route)
        if not row or "log_score" not in row:
            return None
        lines = [float(v) for k, v in (row.get("width_over_truth") or {}).items() if " w[0]" in k][:4]
        return {"drones": int(specimens["drones"]), "log_score": float(row["log_score"]), "lines": lines}

    def check_route(self, route: str, source: str = "the estimator") -> None:
        """ValueError naming ``source`` unless this file has ``route`` (one of :data:`ROUTES`;
        'stacked' only with a stacking weight)."""
        if route not in ROUTES:
            raise ValueError(f"route must be one of {', '.join(ROUTES)}, got {route!r}")
        if route == "stacked" and self.stacking_weight is None:
            raise EstimatorError(f"{source}: the stacked route needs a stacking weight, and the file (class "
                                 f"{self.class_name}, K = {self.spec.acquisition.ramps}) states none (meta field "
                                 "'stacking'); use --route smc or amortized")

    @property
    def temperature(self) -> float:
        """The flow's base temperature T >= 1 (meta field ``temperature``, 1 when absent):
        draws are the flow's transform of T x a standard normal, so T > 1 widens every
        mode of the posterior in its own shape, and :meth:`log_prob_u` is the density of
        those draws. Chosen on fresh drones by SBC and the log score
        (:mod:`mdaug.inference.temperature`); stated in the file."""
        return float(self.meta.get("temperature", 1.0))

    def at_temperature(self, t: float) -> "AmortizedEstimator":
        """This estimator (the same networks) drawing at temperature ``t``."""
        new = copy.copy(self)
        new.meta = dict(self.meta, temperature=float(t))
        return new

    @property
    def likelihood_name(self) -> str:
        """The sampled route's likelihood: 'summary' (the file has one) or 'ratio'."""
        return "ratio" if self.summary is None else "summary"

    def target(self, profiles: np.ndarray, plug_in: np.ndarray | None = None):
        """The sampled routes' target for these measurements (M, L): the summary
        likelihood's posterior where the file has one (its covariance held at u =
        ``plug_in`` when given, :class:`~mdaug.inference.emulator.posterior.EmulatedPosterior`),
        else the ratio network's (which has no covariance: ``plug_in`` is not used); both vectorised callables u (W, d) -> (W,) with ``dim``,
        ``label_free``, ``vectors``."""
        if self.summary is not None:
            from ..emulator.posterior import EmulatedPosterior

            return EmulatedPosterior(self.summary, profiles, plug_in)
        from .ratio_posterior import LearnedPosterior

        return LearnedPosterior(self, profiles)

    def with_summary(self, model, report: dict | None = None, default_route: str | None = None) -> "AmortizedEstimator":
        """This estimator carrying a summary likelihood (and the route table's default)."""
        from ..emulator.model import to_parts

        meta, _ = to_parts(model, report)
        self.summary = model
        self.meta["summary"] = meta
        if default_route is not None:
            if default_route not in ROUTES:
                raise ValueError(f"default_route must be one of {ROUTES}, got {default_route!r}")
            self.meta["default_route"] = default_route
        return self

    def summary_model(self, source: str = "the estimator"):
        """The file's summary likelihood (:class:`mdaug.inference.emulator.model.SummaryModel`);
        EstimatorError naming ``source`` and the command that trains one when it has none."""
        if self.summary is None:
            raise EstimatorError(f"{source}: carries no summary likelihood (class {self.class_name}, K = "
                                 f"{self.spec.acquisition.ramps}); `{train_command(self.spec)}` trains one with it")
        return self.summary

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
        self.check_acquisition(acquisition, radar, source)
        n = np.asarray(profiles).shape[0]
        if not 1 <= n <= self.max_measurements:
            raise EstimatorError(f"{source}: {n} measurements; the estimator takes 1 to {self.max_measurements} "
                                 "of one drone")

    def check_acquisition(self, acquisition: Acquisition, radar: RadarConfig, source: str) -> None:
        """Refuse (EstimatorError naming the field) an acquisition or radar this estimator
        was not trained for (``source``: the data file, or the option that stated it);
        the one check of calibrate's data and of sbc's options."""
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
                u = self._flow_draws(k, cond)
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

    def _flow_draws(self, k: int, cond: torch.Tensor) -> np.ndarray:
        """k draws (k, d) of the flow at the file's temperature (torch's seeded generator)."""
        t = self.temperature
        if t == 1.0:
            return self.posterior.sample((k,), condition=cond).reshape(k, -1).double().cpu().numpy()
        flow = self.posterior.net
        context = flow._embedding_net(cond).expand(k, -1)
        noise = t * torch.randn(k, self.label_free.dim, device=context.device)
        u, _ = flow._transform.inverse(noise, context=context)
        return u.double().cpu().numpy()

    def log_prob_u(self, u: np.ndarray, profiles: np.ndarray) -> np.ndarray:
        """Log density of the amortized posterior at u (n, d) given prepared profiles
        (M, L). The profiles are embedded once: sbi's ``log_prob`` expands the condition
        to every draw and embeds each copy (n CNN passes over M profiles), so this runs
        the steps of its nflows flow (embedding, transform, base density) itself, with
        the one embedding; the same numbers (``tests/test_amortized.py``); at the file's
        temperature T the base is N(0, T^2 I), the density of :meth:`sample_u`'s draws."""
        flow = self.posterior.net  # the nflows Flow inside sbi's estimator
        with torch.inference_mode():
            t = torch.as_tensor(np.asarray(u, np.float32), device=self._device).reshape(len(u), -1)
            context = flow._embedding_net(self.condition(profiles)).expand(len(t), -1)
            noise, log_det = flow._transform(t, context=context)
            temp = self.temperature
            base = flow._distribution.log_prob(noise / temp, context=context) - t.shape[1] * np.log(temp)
            return (base + log_det).double().cpu().numpy()

    def truncated_log_prob_u(self, u: np.ndarray, profiles: np.ndarray, seed: int, n_draws: int = 1024) -> np.ndarray:
        """Log density (n,) at u (n, d) of the posterior :meth:`sample_u` draws from: the
        flow's density restricted to the prior's support, so minus the log of the share of
        its mass inside (estimated from n_draws draws seeded by ``seed``, floored at one
        in 20 n_draws). Minus this at the truth is the exact log score of the truth."""
        _, inside = self.sample_u(profiles, n_draws, seed, strict=False)
        return self.log_prob_u(u, profiles) - np.log(max(inside, 1.0 / (20 * n_draws)))

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
        states = {"posterior.pt": self.posterior.state_dict(), "ratio.pt": self.ratio.state_dict()}
        if self.summary is not None:
            from ..emulator.model import to_parts

            summary_meta, states[SUMMARY_MEMBER] = to_parts(self.summary, self.meta.get("summary", {}).get("training"))
            self.meta["summary"] = summary_meta
            blobs["meta.json"] = json.dumps(self.meta, indent=1, default=float).encode()
        for name, state in states.items():
            buf = io.BytesIO()
            torch.save({k: v.detach().cpu() for k, v in state.items()}, buf)
            blobs[name] = buf.getvalue()

        def write(fh):
            with zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as z:
                for name, data in blobs.items():
                    z.writestr(name, data)

        return atomic_write(path, write)

    @classmethod
    def load(cls, path, *, device: str = "cpu") -> "AmortizedEstimator":
        """Read and check an estimator file (module doc) as untrusted input: a regular
        file only (a device, FIFO or folder is refused without being opened), each
        member's declared size bounded before it is decompressed, the weights read
        without pickle (any error of the reader: one line naming the member), every
        meta field checked against the values this mdaug knows. EstimatorError names
        the file and the member or field."""
        path = Path(path)
        src = str(path)
        _check_regular(path, src)
        try:
            with zipfile.ZipFile(path) as z:
                names = set(z.namelist())
                missing = [m for m in MEMBERS if m not in names]
                if missing:
                    raise EstimatorError(f"{src}: not an mdaug estimator (member {missing[0]!r} missing)")
                blobs = {m: _read_member(z, m, src) for m in MEMBERS + ((SUMMARY_MEMBER,) if SUMMARY_MEMBER in names
                                                                         else ())}
        except EstimatorError:
            raise
        except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, RuntimeError, ValueError, KeyError,
                NotImplementedError) as exc:
            raise EstimatorError(f"{src}: not a readable mdaug estimator ({_first_line(exc, 'truncated or damaged')})"
                                 ) from None
        try:
            meta = json.loads(blobs["meta.json"])
        except (ValueError, RecursionError) as exc:
            raise EstimatorError(f"{src}: member 'meta.json' is not JSON ({_first_line(exc)})") from None
        states = {m: _load_state(blobs[m], m, src, "cpu" if m == SUMMARY_MEMBER else device)
                  for m in blobs if m != "meta.json"}
        if not isinstance(meta, dict):
            raise EstimatorError(f"{src}: member 'meta.json' is not a JSON table")
        absent = [k for k in META_FIELDS if k not in meta]
        if absent:
            raise EstimatorError(f"{src}: meta.json field {absent[0]!r} is missing")
        if meta["format"] != FORMAT:
            raise EstimatorError(f"{src}: meta.json field 'format' is {meta['format']!r}; expected {FORMAT!r}")
        spec, net_cfg = _spec_and_net(meta, src)
        if meta["spec"].get("simulator") != SIMULATOR:
            raise EstimatorError(f"{src}: meta.json field 'spec.simulator' is {meta['spec'].get('simulator')!r}; "
                                 f"this mdaug simulates {SIMULATOR!r}; retrain with: {train_command(spec)}")
        _check_prior(meta, spec, src)
        _check_fields(meta, src)
        t = meta.get("temperature", 1.0)
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not 1.0 <= t <= MAX_TEMPERATURE:
            raise EstimatorError(f"{src}: meta.json field 'temperature' must be a number from 1 to "
                                 f"{MAX_TEMPERATURE:g}, got {t!r}")
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
        est.summary = _summary(meta, states.get(SUMMARY_MEMBER), est, src)
        return est


def _summary(meta: dict, state: dict | None, est: AmortizedEstimator, src: str):
    """The file's summary likelihood, or None; refuses a field without its member (or
    the reverse), a default route that is not a route, and anything from_parts refuses."""
    from ..emulator.model import from_parts

    route = meta.get("default_route", "amortized")
    if route not in ROUTES:
        raise EstimatorError(f"{src}: meta.json field 'default_route' is {route!r}; expected one of {', '.join(ROUTES)}")
    check_route_settings(meta, src)
    check_stacking(meta, src)
    if state is None and "summary" not in meta:
        return None
    if state is None or "summary" not in meta:
        what = f"member {SUMMARY_MEMBER!r}" if state is None else "meta.json field 'summary'"
        raise EstimatorError(f"{src}: {what} is missing (the summary likelihood needs both)")
    try:
        return from_parts(meta["summary"], state, est.class_name, est.spec.acquisition, est.spec.radar,
                          est.label_free, src)
    except ValueError as exc:
        raise EstimatorError(str(exc)) from None


def check_route_settings(meta: dict, src: str) -> None:
    """Refuse a meta field ``route_settings`` (the smc route's knobs the file's route table
    was made with, :data:`mdaug.inference.samplers.smc.ROUTE_KNOBS`) that is not an object
    of known knobs in range, naming the file, the field and what was expected."""
    from ..samplers.smc import ROUTE_KNOBS, check_route_knobs

    knobs = meta.get("route_settings")
    if knobs is None:
        return
    if not isinstance(knobs, dict):
        raise EstimatorError(f"{src}: meta.json field 'route_settings' is {type(knobs).__name__}; expected an "
                             f"object of some of {', '.join(ROUTE_KNOBS)}")
    try:
        check_route_knobs(knobs, where="meta.json field 'route_settings'")
    except ValueError as exc:
        raise EstimatorError(f"{src}: {exc}") from None


def check_stacking(meta: dict, src: str) -> None:
    """Refuse a meta field ``stacking`` without a weight in (0, 1), and a default route
    'stacked' without the field, naming the file and the field."""
    st = meta.get("stacking")
    if st is not None:
        w = st.get("weight") if isinstance(st, dict) else None
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not np.isfinite(w) or not 0 < w < 1:
            raise EstimatorError(f"{src}: meta.json field 'stacking.weight' must be a number in (0, 1), got {w!r}")
    elif meta.get("default_route") == "stacked":
        raise EstimatorError(f"{src}: meta.json field 'default_route' is 'stacked' but the file has no field "
                             "'stacking' (the weight of its smc route)")


# ---- reading a file as untrusted input -------------------------------------------------------------
MEMBER_LIMITS = {"meta.json": 16 * 2 ** 20, "posterior.pt": 512 * 2 ** 20, "ratio.pt": 512 * 2 ** 20,
                 SUMMARY_MEMBER: 64 * 2 ** 20}
"""Largest size (bytes, uncompressed) of each member, checked against the ZIP's
declared size before any byte is decompressed and again while reading (the shipped
files: meta.json 40-130 KB, weights 0.6-3 MB)."""
KNOWN_TARGETS = tuple(range(1, TARGET + 1))
"""Target versions there have been (:mod:`.target`); a several-engine file must be of
this one, a one-engine file of any of them (they agree for one engine)."""


def _first_line(exc: BaseException, empty: str = "") -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0][:120] if text else empty or 'no detail'}"


def _check_regular(path: Path, src: str) -> None:
    """A regular file, found without opening it (a FIFO or /dev/zero would hang or never end)."""
    import os
    import stat

    try:
        st = os.stat(path)  # follows links: a link to a device is a device
    except FileNotFoundError:
        raise EstimatorError(f"{src}: no such estimator file") from None
    except OSError as exc:
        raise EstimatorError(f"{src}: cannot read the estimator file ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = ("a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else
                "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
        raise EstimatorError(f"{src}: is {kind}, not an estimator file (a ZIP of mdaug train-estimator); it was "
                             "not read")


def _read_member(z: zipfile.ZipFile, name: str, src: str) -> bytes:
    """A member's bytes, its declared size bounded before decompression and the bytes
    read bounded too (a ZIP bomb stops at the limit)."""
    info = z.getinfo(name)
    limit = MEMBER_LIMITS[name]
    if info.file_size > limit:
        raise EstimatorError(f"{src}: member {name!r} declares {info.file_size:,} bytes; an estimator's {name} holds "
                             f"at most {limit:,}")
    with z.open(info) as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise EstimatorError(f"{src}: member {name!r} holds more than {limit:,} bytes")
    return data


def _load_state(blob: bytes, name: str, src: str, device: str) -> dict:
    """A state dict of tensors, read without pickle; any error of the reader is one line."""
    import pickle
    import warnings

    try:
        with warnings.catch_warnings():  # torch's warnings about the pickle protocol: the line below says it
            warnings.simplefilter("ignore")
            state = torch.load(io.BytesIO(blob), map_location=device, weights_only=True)
    except pickle.UnpicklingError:  # Python objects other than tensors: refused, never executed
        raise EstimatorError(f"{src}: member {name!r} is not a state dict of plain tensors (damaged, or holding "
                             "Python objects, which are refused without being run)") from None
    except Exception as exc:  # noqa: BLE001 (a format or zip error of any kind: untrusted input)
        raise EstimatorError(f"{src}: member {name!r} is not a torch state dict ({_first_line(exc, 'damaged')})"
                             ) from None
    if not isinstance(state, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                              for k, v in state.items()):
        raise EstimatorError(f"{src}: member {name!r} is not a table of named tensors (a torch state dict)")
    return state


def _spec_and_net(meta: dict, src: str):
    """The simulation spec and network settings of meta.json, each field named when bad."""
    from ...generator import load_reference

    if not isinstance(meta["spec"], dict):
        raise EstimatorError(f"{src}: meta.json field 'spec' is not a table")
    name = meta["spec"].get("class_name")
    try:
        known = isinstance(name, str) and load_reference(name) is not None
    except (KeyError, ValueError):
        known = False
    if not known:
        raise EstimatorError(f"{src}: meta.json field 'spec.class_name' is {meta['spec'].get('class_name')!r}: not "
                             "a class mdaug has a reference for (HELI, QUAD)")
    try:
        spec = spec_from_dict(meta["spec"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise EstimatorError(f"{src}: meta.json field 'spec' is not valid ({_first_line(exc)})") from None
    try:
        net_cfg = NetConfig.from_dict(meta["net"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise EstimatorError(f"{src}: meta.json field 'net' is not valid ({_first_line(exc)})") from None
    return spec, net_cfg


def _check_prior(meta: dict, spec: SimulationSpec, src: str) -> None:
    """The prior must be the class reference's; a prior of another class means the
    class name was changed (said so, not 'retrain')."""
    if _bad_number(meta["prior"]):
        raise EstimatorError(f"{src}: meta.json field 'prior' holds NaN or inf")
    try:
        prior = Priors.from_dict(meta["prior"]).to_dict()
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise EstimatorError(f"{src}: meta.json field 'prior' is not valid ({_first_line(exc)})") from None
    if prior == spec.priors().to_dict():
        return
    for other in ("HELI", "QUAD"):
        if other != spec.class_name:
            try:
                theirs = SimulationSpec(other, spec.acquisition, spec.n_measurements, spec.radar).priors().to_dict()
            except (KeyError, ValueError):
                continue
            if prior == theirs:
                raise EstimatorError(f"{src}: meta.json field 'spec.class_name' is {spec.class_name!r} but its field "
                                     f"'prior' is class {other}'s: the class name does not match the networks (an "
                                     "edited or damaged file)")
    raise EstimatorError(f"{src}: meta.json field 'prior' differs from the class reference's prior; retrain with: "
                         f"{train_command(spec)}")


def _bad_number(value) -> bool:
    if isinstance(value, float):
        return not np.isfinite(value)
    if isinstance(value, dict):
        return any(_bad_number(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_bad_number(v) for v in value)
    return False


def _check_fields(meta: dict, src: str) -> None:
    """The other meta fields against the values this mdaug knows."""
    target = meta.get("target", 1)
    if isinstance(target, bool) or target not in KNOWN_TARGETS:
        raise EstimatorError(f"{src}: meta.json field 'target' is {target!r}: not a target version of mdaug (known: "
                             f"{', '.join(map(str, KNOWN_TARGETS))})")
    for key, ok, want in (("n_simulations", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0,
                           "an integer >= 0"),
                          ("seed", lambda v: v is None or isinstance(v, int) and not isinstance(v, bool) and v >= 0,
                           "an integer >= 0"),
                          ("label_free", lambda v: isinstance(v, list) and all(isinstance(n, str) for n in v),
                           "a list of names"),
                          ("training", lambda v: isinstance(v, dict), "a table"),
                          ("sbc", lambda v: isinstance(v, dict), "a table")):
        if not ok(meta[key]):
            raise EstimatorError(f"{src}: meta.json field {key!r} is {str(meta[key])[:60]!r}: expected {want}")
