"""CalibrationResult: an arviz InferenceData with the toolkit's reading of it.

NetCDF layout (``.save`` / ``.load``):

* ``posterior`` (chain=1, draw): the thinned post-burn-in draws, all walkers
  pooled (walkers are not independent chains, so there is one chain), as physical
  parameters: ``Gamma, A_a, w_a, ...`` with dims (chain, draw, engine), the phases
  ``phi_*`` with (chain, draw, measurement, engine), ``offset`` (range offset, FFT
  bins) and ``sigma`` (noise level) with (chain, draw, measurement) when the phases
  were fitted; ``carrier`` (carrier-return ratio), ``offset`` (bins) and ``noise_db``
  (noise floor, dB) with (chain, draw, measurement) when they were marginalised. Gamma of engine 0
  is fixed (the scale of a normalised profile is not identifiable);
* ``sample_stats``: ``lp`` (log posterior);
* ``log_likelihood``: ``y`` per bin (chain, draw, measurement, bin) for LOO/WAIC
  (fitted phases) or per measurement (chain, draw, measurement) (marginal);
* ``observed_data``: ``y`` the normalised measured profiles;
* ``chain_trace``: the walkers' full path (every k-th step) for trace plots
  (with ``sampler="smc"``: one "step", the final particles; the tempering history --
  betas, ESS, acceptance, sweeps, log evidence -- is in the diagnostics);
* ``posterior.attrs["mdaug"]``: JSON with the class, engine count, settings,
  priors, the acquisition and the likelihood, fit, convergence diagnostics (tau,
  ESS, acceptance, converged, reason).
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ...generator import IDX, N_PARAMS, PARAM_NAMES
from ...generator.model import circular_stats
from ..space.priors import PHASE_NAMES, SHARED, Priors, label_free_lines

FORMAT = "mdaug-posterior-2"
READABLE_FORMATS = ("mdaug-posterior-1", FORMAT)
META_FIELDS = ("class_name", "n_engines", "n_measurements", "priors", "diagnostics", "fit", "best_fit")
"""Fields of the posterior attribute ``mdaug`` every reader needs."""
IDENTIFIED_RATIO = 0.5  # posterior sd / prior sd above this: "stays near its prior"

def import_arviz():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    return az


class CalibrationResult:
    """A calibrated class: posterior draws, fit, diagnostics (see the module docstring)."""

    def __init__(self, idata):
        self.idata = idata
        try:
            self.meta = json.loads(idata.posterior.attrs["mdaug"])
        except (AttributeError, KeyError, ValueError) as exc:
            raise ValueError("not an mdaug posterior (no 'mdaug' attributes in its posterior group)") from exc
        if not isinstance(self.meta, dict):
            raise ValueError("posterior attribute 'mdaug' is not a JSON table")
        if self.meta.get("format") not in READABLE_FORMATS:
            raise ValueError(f"posterior format {self.meta.get('format')!r}; expected one of {READABLE_FORMATS}")
        missing = [k for k in META_FIELDS if k not in self.meta]
        if missing:
            raise ValueError(f"posterior attribute 'mdaug' lacks field(s) {missing}")
        try:
            self.priors = Priors.from_dict(self.meta["priors"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"posterior attribute 'mdaug' field 'priors' is not a prior table ({exc})") from None

    def check_content(self) -> None:
        """Refuse (ValueError naming the variable or field) a posterior whose content
        disagrees with its metadata: a variable missing, of another dtype, dims or
        size (engines, measurements), NaN or infinite draws, draws outside the prior
        bounds the file states, a best fit of the wrong length."""
        meta = self.meta
        for key in ("n_engines", "n_measurements"):
            v = meta[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"posterior attribute 'mdaug' field {key!r} = {v!r}: expected an integer >= 1")
        e, m = self.n_engines, self.n_measurements
        if not isinstance(meta["diagnostics"], dict) or not {"converged", "reason"} <= set(meta["diagnostics"]):
            raise ValueError("posterior attribute 'mdaug' field 'diagnostics' lacks 'converged' or 'reason'")
        best = np.asarray(meta["best_fit"])
        if best.shape != (e * N_PARAMS,) or not np.issubdtype(best.dtype, np.number) or not np.all(np.isfinite(best)):
            raise ValueError(f"posterior attribute 'mdaug' field 'best_fit' has shape {best.shape}; expected "
                             f"{e * N_PARAMS} finite numbers (13 x n_engines = {e})")
        self.acquisition  # noqa: B018 (parses; its errors name the attribute)
        per_engine = ("chain", "draw", "engine")
        per_meas = ("chain", "draw", "measurement")
        expected = {"Gamma": per_engine, **{n: per_engine for n in SHARED}}
        if not self.marginal:
            expected.update({n: per_meas + ("engine",) for n in PHASE_NAMES})
        expected.update({n: per_meas for n in self.nuisances})
        if "observed_data" in self.idata.groups() and "y" in self.idata.observed_data:
            y = self.idata.observed_data["y"]
            if y.ndim != 2 or y.shape[0] != m:
                raise ValueError(f"observed_data variable 'y' has shape {y.shape}; expected (measurements, bins) "
                                 f"with {m} measurements (attribute 'mdaug' field 'n_measurements')")
        post = self.idata.posterior
        sizes = {"engine": e, "measurement": m}
        for name, dims in expected.items():
            if name not in post.data_vars:
                raise ValueError(f"posterior variable {name!r} is missing (expected dims {dims}); variables "
                                 f"present: {sorted(post.data_vars)}")
            var = post[name]
            if not np.issubdtype(var.dtype, np.floating):
                raise ValueError(f"posterior variable {name!r} has dtype {var.dtype}; expected floating point")
            want = tuple(sizes.get(d) for d in dims)
            if tuple(var.dims) != dims or any(w is not None and s != w for s, w in zip(var.shape, want)):
                raise ValueError(f"posterior variable {name!r} has dims {tuple(var.dims)} of shape {var.shape}; "
                                 f"expected {dims} with engine = n_engines = {e}, measurement = n_measurements = {m} "
                                 "(attribute 'mdaug')")
            v = var.values
            if v.size == 0:
                raise ValueError(f"posterior variable {name!r} holds no draws")
            bad = ~np.isfinite(v)
            if bad.any():
                idx = tuple(int(i) for i in np.argwhere(bad)[0])
                raise ValueError(f"posterior variable {name!r} holds NaN or inf (first at index {idx} of "
                                 f"{tuple(var.dims)})")
            if name in self.priors.bounds:
                lo, hi = self.priors.bounds[name]
                slack = 1e-6 * (hi - lo)
                if v.min() < lo - slack or v.max() > hi + slack:
                    raise ValueError(f"posterior variable {name!r} has draws in [{v.min():.6g}, {v.max():.6g}], "
                                     f"outside its prior bounds [{lo:.6g}, {hi:.6g}] stated in attribute 'priors'")

    # ---- identity ----------------------------------------------------------------
    @property
    def class_name(self) -> str:
        return self.meta["class_name"]

    @property
    def n_engines(self) -> int:
        return int(self.meta["n_engines"])

    @property
    def n_measurements(self) -> int:
        return int(self.meta["n_measurements"])

    @property
    def marginal(self) -> bool:
        """Whether the acquisition's phases were marginalised (no phases in the posterior)."""
        return bool(self.meta.get("marginal", False))

    @property
    def amortized(self) -> bool:
        """Simulation-based (:mod:`..amortized`): every nuisance was marginalised by training."""
        return bool(self.meta.get("amortized", False))

    @property
    def nuisances(self) -> tuple:
        """The per-measurement variables of the posterior group."""
        if self.amortized:
            return ()
        return ("carrier", "offset", "noise_db") if self.marginal else ("offset", "sigma")

    @property
    def acquisition(self):
        """The :class:`~mdaug.generator.acquisition.Acquisition` the measurements were
        modelled with (the published single chirp for files that predate it)."""
        from ...generator.acquisition import Acquisition

        return Acquisition.from_dict(self.meta.get("acquisition") or {}, "posterior attribute 'acquisition'")

    def measured_acquisition(self):
        """The calibration's acquisition with the carrier-return and noise-floor ranges it
        measured (the range of the measurements' posterior medians), where it measured
        them (marginal posteriors); otherwise the acquisition as stated."""
        acq = self.acquisition
        if not self.marginal or self.amortized:
            return acq
        carrier = np.median(self._var("carrier"), axis=0)  # (M,)
        noise = np.median(self._var("noise_db"), axis=0)
        return acq.replace(carrier=(float(carrier.min()), float(carrier.max())),
                           noise_db=(float(noise.min()), float(noise.max())))

    @property
    def converged(self) -> bool:
        return bool(self.meta["diagnostics"]["converged"])

    @property
    def diagnostics(self) -> dict:
        """Plain-float diagnostics: tau and ESS per sampled coordinate, acceptance,
        chain length / max tau, fit agreement, identifiability per parameter."""
        return self.meta["diagnostics"]

    @property
    def specimens(self) -> list[str]:
        """The drones (specimen ids) the measurements were of (["0"] when not recorded)."""
        return [str(v) for v in self.meta.get("specimens", ["0"])]

    def record(self, **fields) -> "CalibrationResult":
        """Set top-level metadata ``fields`` (kept in the file: the one place the
        metadata is written back to the InferenceData)."""
        self.meta.update(fields)
        self.idata.posterior.attrs["mdaug"] = json.dumps(self.meta)
        return self

    def record_specimens(self, ids) -> "CalibrationResult":
        """Record which drones the measurements were of (kept in the file)."""
        return self.record(specimens=sorted({str(v) for v in ids}))

    def record_diagnostics(self, **items) -> "CalibrationResult":
        """Add ``items`` to the diagnostics (kept in the file), e.g. a check run on the
        finished posterior."""
        return self.record(diagnostics={**self.meta["diagnostics"], **items})

    @property
    def fit(self) -> dict:
        return self.meta["fit"]

    @property
    def best_fit(self) -> np.ndarray:
        """Best-fit flat vector (13E,) (phases of measurement 0)."""
        return np.asarray(self.meta["best_fit"], float)

    @property
    def comparison(self):
        """Engine-count comparison table (list of dicts) when ``engines='auto'``."""
        return self.meta.get("comparison")

    # ---- draws ---------------------------------------------------------------------
    def _var(self, name: str, group: str = "posterior") -> np.ndarray:
        v = self.idata[group][name].values
        return v.reshape((-1,) + v.shape[2:])

    @property
    def n_draws(self) -> int:
        return int(self.idata.posterior.sizes["draw"])

    @property
    def groups(self) -> tuple[str, ...]:
        """The groups of draws this result holds: ``posterior``, and ``other_route`` where
        an amortized calibration kept the route it did not choose beside it (``check=True``
        of :func:`mdaug.inference.amortized.calibrate.calibrate_amortized`)."""
        return tuple(g for g in ("posterior", "other_route") if g in self.idata.groups())

    def draws(self, measurement: int | None = None, group: str = "posterior") -> np.ndarray:
        """Draws as flat parameter vectors (n, 13E): the posterior's, or those of another
        group in :attr:`groups` (``"other_route"``, marginal: its phases are 0).

        Phases are per measurement; ``measurement`` picks one, None (default) takes
        draw i's phases from measurement i mod M (all measurements used evenly). A
        marginal posterior holds no phases (they were marginalised): they are 0, and
        the acquisition that renders the vectors draws its own.
        """
        if group not in self.groups:
            raise ValueError(f"group must be one of {', '.join(self.groups)} for this result, got {group!r}")
        g = self.idata[group]
        n, e, m = int(g.sizes["chain"] * g.sizes["draw"]), self.n_engines, self.n_measurements
        marginal = self.marginal or group != "posterior"
        x = np.empty((n, e, N_PARAMS))
        for name in PARAM_NAMES:
            if name in PHASE_NAMES and marginal:
                x[:, :, IDX[name]] = 0.0
                continue
            v = self._var(name, group)
            if name in PHASE_NAMES:
                pick = np.arange(n) % m if measurement is None else np.full(n, int(measurement))
                v = v[np.arange(n), pick]
            x[:, :, IDX[name]] = v
        return x.reshape(n, e * N_PARAMS)

    def route_draws(self, route: str) -> np.ndarray:
        """Draws (n, 13E) of one route of an amortized calibration ('amortized', 'smc' or
        'stacked'): the posterior's where it is the route used, else the ``other_route``
        group's, which holds the other route (kept with ``check=True``): the smc route's
        beside the amortized route, the amortized posterior's beside the smc or stacked route."""
        used = self.diagnostics.get("route")
        if route == used:
            return self.draws()
        other = {"amortized": "smc", "smc": "amortized", "stacked": "amortized"}.get(used)
        if route == other and "other_route" in self.groups:
            return self.draws(group="other_route")
        kept = f"the {used} route's" + (" and the other route's" if "other_route" in self.groups else "")
        raise ValueError(f"route {route!r}: this result holds {kept} draws only")

    # ---- summaries -------------------------------------------------------------------
    def lines(self, by_brightness: bool = False) -> np.ndarray:
        """Label-free view of the posterior (n_draws, E, 4, 2): every engine's four
        vibration lines as (frequency rad/s, amplitude m), sorted by frequency.
        Which line is the roll, the pitch or a mixing term is a labelling the data
        cannot fix (:mod:`..space.priors`); the lines themselves are what one profile
        identifies. ``by_brightness``: engines in each draw's brightness order (see
        :func:`~mdaug.inference.space.priors.label_free_lines`) instead of their stored order."""
        return label_free_lines(self.draws().reshape(self.n_draws, self.n_engines, N_PARAMS), by_brightness)

    def summary(self):
        """pandas DataFrame, one row per parameter: mean, sd, q05, q95 (90% interval),
        prior_sd, sd_ratio (posterior/prior; phases: circular variance 1 - R),
        identified (sd_ratio <= 0.5), kind (linear / circular / fixed)."""
        import pandas as pd

        rows = {}
        b = self.priors.bounds
        for k in range(self.n_engines):
            for name in ("Gamma",) + SHARED:
                v = self._var(name)[:, k]
                if name == "Gamma":
                    if k == 0:
                        rows["Gamma[0]"] = dict(mean=float(v[0]), sd=0.0, q05=float(v[0]), q95=float(v[0]),
                                                 prior_sd=np.nan, sd_ratio=np.nan, identified=False, kind="fixed")
                        continue
                    lo, hi = b["lnG"]
                    prior_sd, post = (hi - lo) / np.sqrt(12), np.log(v / self.priors.gamma0)
                else:
                    lo, hi = b[name]
                    prior_sd, post = (hi - lo) / np.sqrt(12), v
                q05, q95 = np.quantile(v, [0.05, 0.95])
                ratio = float(np.std(post) / prior_sd)
                rows[f"{name}[{k}]"] = dict(mean=float(np.mean(v)), sd=float(np.std(v)), q05=float(q05),
                                            q95=float(q95), prior_sd=float(prior_sd), sd_ratio=ratio,
                                            identified=ratio <= IDENTIFIED_RATIO, kind="linear")
        for m in range(self.n_measurements):
            for k in range(self.n_engines if not self.marginal else 0):
                for name in PHASE_NAMES:
                    cs = circular_stats(self._var(name)[:, m, k])
                    ratio = 1.0 - cs["R"]
                    rows[f"{name}[{k}]@{m}"] = dict(mean=cs["mean"], sd=cs["sd"], q05=cs["q05"], q95=cs["q95"],
                                                    prior_sd=np.inf, sd_ratio=ratio,
                                                    identified=ratio <= IDENTIFIED_RATIO, kind="circular")
            for name in self.nuisances:
                v = self._var(name)[:, m]
                q05, q95 = np.quantile(v, [0.05, 0.95])
                rows[f"{name}@{m}"] = dict(mean=float(np.mean(v)), sd=float(np.std(v)), q05=float(q05),
                                           q95=float(q95), prior_sd=np.nan, sd_ratio=np.nan, identified=True,
                                           kind="nuisance")
        return pd.DataFrame.from_dict(rows, orient="index")

    def report(self) -> str:
        """Human-readable fit, convergence and posterior summary (:func:`.report.report`)."""
        from .report import amortized_report, report

        return (amortized_report if self.amortized else report)(self, IDENTIFIED_RATIO)

    # ---- plots (:mod:`.plots`) ------------------------------------------------------
    def plot_corner(self, path, engines: str = "brightest", truths=None):
        """The corner plot (:func:`.plots.plot_corner`)."""
        from .plots import plot_corner

        return plot_corner(self, path, engines=engines, truths=truths)

    def plot_trace(self, path):
        """The trace plot (:func:`.plots.plot_trace`)."""
        from .plots import plot_trace

        return plot_trace(self, path)

    # ---- files ---------------------------------------------------------------------------
    def save(self, path) -> Path:
        """Write NetCDF atomically (a temporary file in the same folder, then rename),
        with the usual file mode (0666 minus the umask), like every other output."""
        from ...radar.io import atomic_path

        path = Path(path)
        with atomic_path(path) as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.idata.to_netcdf(str(tmp), engine="h5netcdf")
        return path

    @classmethod
    def load(cls, path, *, class_name: str | None = None, n_engines: int | None = None) -> "CalibrationResult":
        """Read a posterior written by :meth:`save`; ``class_name`` / ``n_engines``
        check that it is the posterior expected (clear errors otherwise)."""
        from ...radar import DataFileError
        from ...radar.npz import check_readable

        path = check_readable(path, "posterior file")
        az = import_arviz()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                idata = az.from_netcdf(str(path), engine="h5netcdf")
        except Exception as exc:  # h5py/netCDF raise many types for a foreign file
            raise DataFileError(f"{path}: not a NetCDF posterior ({type(exc).__name__}: {exc})") from exc
        if "posterior" not in idata.groups():
            raise DataFileError(f"{path}: no 'posterior' group; not an mdaug posterior")
        try:
            res = cls(idata)
            res.check_content()
        except ValueError as exc:
            raise DataFileError(f"{path}: {exc}") from None
        if class_name is not None and res.class_name != class_name.upper():
            raise DataFileError(f"{path}: posterior of class {res.class_name!r}, expected {class_name.upper()!r}")
        if n_engines is not None and res.n_engines != int(n_engines):
            raise DataFileError(f"{path}: posterior has {res.n_engines} engine(s), expected {n_engines}")
        return res
