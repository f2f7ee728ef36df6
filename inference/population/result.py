"""The calibrated population of a class: fit from drones, saved, loaded, drawn from.

:func:`calibrate_population` pools the per-drone calibrations of one class
(:mod:`.model` for the model and the method); :class:`PopulationResult` holds
the hyper-posterior draws (spreads, and the class's mean drone given each), the
drones' own posterior draws (for the coordinates no drone identifies), and draws
new drones: spreads and mean from the hyper-posterior, then the scene simulator's
specimen model (:meth:`SpecimenSpread.apply`) around that mean. File: NPZ, read
with ``allow_pickle=False``; every field checked on load, errors name file and field.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...generator.params import IDX, N_PARAMS
from ...generator.specimens import SpecimenSpread
from ...radar.io import DataFileError, atomic_savez
from ...radar.npz import Field, check_field, read_arrays
from ...radar.seeds import rng as as_rng
from .model import SPREADS, Hyperprior, PopulationModel, sample_spreads, summarise_drone

FORMAT = "mdaug-population-1"
POOL_PER_DRONE = 1000  # posterior draws kept per drone (for coordinates no drone identifies)
META_FIELDS = ("class_name", "n_engines", "specimens", "hyperprior", "acquisition", "priors", "drones_converged",
               "diagnostics")
ARRAYS = ("spreads", "mu", "measured", "pool", "pool_drone", "drone_means", "reference")


def _union_acquisition(results):
    """The drones' acquisition with the union of their measured carrier and noise ranges."""
    acqs = [r.measured_acquisition() for r in results]
    lo = lambda name, i: min(getattr(a, name)[i] for a in acqs)  # noqa: E731
    hi = lambda name, i: max(getattr(a, name)[i] for a in acqs)  # noqa: E731
    noise = None if acqs[0].noise_db is None else (lo("noise_db", 0), hi("noise_db", 1))
    return acqs[0].replace(carrier=(lo("carrier", 0), hi("carrier", 1)), noise_db=noise)


def calibrate_population(results, specimens=None, *, reference=None, hyperprior: Hyperprior | None = None,
                         random_state=None, max_steps: int = 40000) -> "PopulationResult":
    """The population of one class from its drones' calibrations.

    results: :class:`~..result.posterior.CalibrationResult` per drone (same class, engine count
    and acquisition); specimens: their ids (default "0", "1", ...); reference: the
    class vector whose labelling the drones are read in (default: the class
    reference); hyperprior: the spreads' prior (default :meth:`Hyperprior.stated`).
    """
    from ...generator import load_reference

    results = list(results)
    if not results:
        raise ValueError("calibrate_population needs at least one drone's calibration")
    names = {r.class_name for r in results}
    engines = {r.n_engines for r in results}
    if len(names) != 1 or len(engines) != 1:
        raise ValueError(f"the drones' calibrations must be of one class and engine count, got classes "
                         f"{sorted(names)} and engine counts {sorted(engines)}")
    specimens = [str(s) for s in (specimens if specimens is not None else range(len(results)))]
    if len(specimens) != len(results) or len(set(specimens)) != len(specimens):
        raise ValueError(f"need one distinct specimen id per calibration, got {specimens} for {len(results)}")
    cls, n_eng = names.pop(), engines.pop()
    ref = np.asarray(reference if reference is not None else load_reference(cls).to_array(), float)
    if ref.shape != (n_eng * N_PARAMS,):
        ref = np.resize(ref, n_eng * N_PARAMS)  # a reference with other engines: cycled, as the fit's start
    gamma0 = float(results[0].priors.gamma0)
    model = PopulationModel(n_eng)
    hyperprior = hyperprior or Hyperprior.stated()
    rng = as_rng(random_state)
    drones = [summarise_drone(r, model, ref, s) for r, s in zip(results, specimens)]
    fit = sample_spreads(drones, model, hyperprior, rng, max_steps=max_steps)
    pool, pool_drone = [], []
    for k, d in enumerate(drones):
        keep = np.linspace(0, len(d.draws) - 1, min(POOL_PER_DRONE, len(d.draws))).round().astype(int)
        pool.append(d.draws[keep]), pool_drone.append(np.full(len(keep), k))
    means = np.array([model.transform(d.draws).mean(axis=0) for d in drones])
    meta = {"format": FORMAT, "class_name": cls, "n_engines": n_eng, "gamma0": gamma0,
            "specimens": specimens, "hyperprior": hyperprior.scales, "coords": model.names,
            "priors": results[0].priors.to_dict(),
            "acquisition": _union_acquisition(results).to_dict(),
            "drones_converged": [bool(r.converged) for r in results],
            "identified": [d.mask.tolist() for d in drones],
            "diagnostics": {"tau": fit["tau"].tolist(), "steps": fit["steps"], "converged": fit["converged"],
                            "acceptance": fit["acceptance"]}}
    arrays = {"spreads": fit["spreads"], "mu": fit["mu"], "measured": fit["measured"],
              "pool": np.concatenate(pool), "pool_drone": np.concatenate(pool_drone), "drone_means": means,
              "reference": ref}
    return PopulationResult(arrays, meta)


class PopulationResult:
    """Hyper-posterior of a class's population (see the module doc)."""

    def __init__(self, arrays: dict, meta: dict):
        self.arrays, self.meta = arrays, meta
        self.model = PopulationModel(int(meta["n_engines"]))

    # ---- what it holds ----------------------------------------------------------------
    @property
    def class_name(self) -> str:
        return str(self.meta["class_name"])

    @property
    def n_engines(self) -> int:
        return int(self.meta["n_engines"])

    @property
    def n_drones(self) -> int:
        return len(self.meta["specimens"])

    @property
    def assumed(self) -> bool:
        """True when the spreads were assumed (one drone), not measured."""
        return self.n_drones < 2

    @property
    def converged(self) -> bool:
        return bool(self.meta["diagnostics"]["converged"])

    def measured_acquisition(self):
        """The acquisition new drones are rendered under: the drones' own, with the union
        of the carrier and noise ranges their calibrations measured."""
        from ...generator.acquisition import Acquisition

        return Acquisition.from_dict(self.meta["acquisition"], "population attribute 'acquisition'")

    def spreads(self) -> np.ndarray:
        """Hyper-posterior draws of the spreads (n, 5), columns in :data:`SPREADS` order."""
        return self.arrays["spreads"]

    def summary(self) -> list[dict]:
        """One row per spread: prior (half-normal) median and 90% interval, posterior
        median and 90% interval, and whether the data moved it (``measured``: with two
        or more drones, the posterior's sd under 0.7 x the prior's or its median more
        than half a prior sd from the prior's) or it stays ``assumed``."""
        rows = []
        z = np.array([0.0627, 0.674, 1.645])  # half-normal quantiles 5%, 50%, 95%
        for j, name in enumerate(SPREADS):
            scale = self.meta["hyperprior"][name]
            q = np.quantile(self.arrays["spreads"][:, j], [0.05, 0.5, 0.95])
            pq = z * scale
            draws = self.arrays["spreads"][:, j]
            prior_sd = scale * np.sqrt(1 - 2 / np.pi)  # half-normal
            measured = self.n_drones >= 2 and (draws.std() < 0.7 * prior_sd or abs(q[1] - pq[1]) > 0.5 * prior_sd)
            rows.append({"spread": name, "prior_q05": pq[0], "prior_median": pq[1], "prior_q95": pq[2],
                         "q05": q[0], "median": q[1], "q95": q[2], "status": "measured" if measured else "assumed"})
        return rows

    def report(self) -> str:
        head = (f"population of {self.class_name}: {self.n_drones} drone(s) "
                f"({', '.join(self.meta['specimens'])}); hyper-posterior "
                f"{'converged' if self.converged else 'NOT converged'} "
                f"({self.meta['diagnostics']['steps']} steps, max tau "
                f"{max(self.meta['diagnostics']['tau']):.0f})")
        bad = [s for s, ok in zip(self.meta["specimens"], self.meta["drones_converged"]) if not ok]
        if bad and not self.assumed:
            head += (f"\n  drone calibration(s) NOT converged: {', '.join(bad)}; the spreads inherit their errors (a drone "
                     "posterior too narrow or off its truth inflates a spread, one too wide shrinks it)")
        if self.assumed:
            head += "\n  one drone: the spreads are the stated prior (SpecimenSpread's physical guesses), assumed"
        lines = [head, f"  {'spread':<10} {'prior median [90%]':>24} {'posterior median [90%]':>28}  status"]
        for r in self.summary():
            lines.append(f"  {r['spread']:<10} {r['prior_median']:>8.3f} [{r['prior_q05']:.3f}, {r['prior_q95']:.3f}]"
                         f" {r['median']:>12.3f} [{r['q05']:.3f}, {r['q95']:.3f}]  {r['status']}")
        return "\n".join(lines)

    # ---- new drones -------------------------------------------------------------------
    def inside_prior(self, x: np.ndarray) -> np.ndarray:
        """(n,) bool: class vectors x (n, 13E) inside the calibration prior's box (every
        amplitude, w_a, w_b, C and Gamma ratio; the box keeps every line below the
        profile window's edge)."""
        from ..space.priors import SHARED, Priors

        pri = Priors.from_dict(self.meta["priors"])
        e = np.asarray(x).reshape(len(x), self.n_engines, N_PARAMS)
        ok = np.ones(len(x), bool)
        for name in SHARED:
            lo, hi = pri.bounds[name]
            v = e[..., IDX[name]]
            ok &= np.all((v >= lo) & (v <= hi), axis=1)
        if self.n_engines > 1:
            lo, hi = pri.bounds["lnG"]
            with np.errstate(divide="ignore"):
                g = np.log(e[:, 1:, IDX["Gamma"]] / e[:, :1, IDX["Gamma"]])
            ok &= np.all((g >= lo) & (g <= hi), axis=1)
        return ok

    def draw_drones(self, n: int, rng) -> np.ndarray:
        """n class vectors (n, 13E) of new drones: a hyper-posterior draw (spreads and
        mean drone; a drone's own posterior draw for coordinates no drone
        identifies), then the specimen model with those spreads around it, kept when
        inside the calibration prior (:meth:`inside_prior`; the population is
        truncated to the physics the class allows), redrawn otherwise. Phases are 0:
        the acquisition that renders the vectors draws them."""
        rng = as_rng(rng)
        out = np.empty((n, self.n_engines * N_PARAMS))
        todo = np.arange(n)
        for _ in range(100):
            x = self._draw(len(todo), rng)
            ok = self.inside_prior(x)
            out[todo[ok]] = x[ok]
            todo = todo[~ok]
            if not todo.size:
                return out
        raise ValueError(f"population of {self.class_name}: new drones keep falling outside the calibration prior "
                         f"({todo.size} of {n} after 100 redraws); its spreads are far too wide for the class")

    def _draw(self, n: int, rng) -> np.ndarray:
        a = self.arrays
        i = rng.integers(len(a["spreads"]), size=n)
        t = rng.integers(len(a["pool"]), size=n)
        x = self.model.fill(a["pool"][t], a["mu"][i], a["measured"].astype(bool))
        out = np.empty_like(x)
        for u in np.unique(i):
            rows = np.flatnonzero(i == u)
            spread = SpecimenSpread(**dict(zip(SPREADS, a["spreads"][u].tolist())))
            out[rows] = spread.apply(x[rows], rng)
        return out

    # ---- files ------------------------------------------------------------------------
    def save(self, path) -> Path:
        return atomic_savez(path, meta=np.array(json.dumps(self.meta)), **self.arrays)

    @classmethod
    def load(cls, path, *, class_name: str | None = None) -> "PopulationResult":
        """Read a population file through the checked NPZ reader (:func:`mdaug.radar.npz.read_checked`):
        every field present with its dtype, rank and shape, finite; ``meta`` a JSON
        table with its keys; errors are one :class:`DataFileError` naming file and field."""
        path = Path(path)
        arrays = read_arrays(path, "population file")
        missing = [k for k in ARRAYS + ("meta",) if k not in arrays]
        if missing:
            raise DataFileError(f"{path}: not a population file, missing field(s) {missing}")
        meta = _load_meta(path, check_field(arrays, Field("meta", "U", 0, text="a JSON table"), path))
        n_eng = int(meta["n_engines"])
        model = PopulationModel(n_eng)
        e13 = n_eng * N_PARAMS
        sizes = {"p": model.p, "e13": e13, "drones": len(meta["specimens"])}
        measured = check_field(arrays, Field("measured", "biu", 1, ("p",), text="booleans (p,)"), path, sizes)
        if not np.isin(measured, (0, 1)).all():
            raise DataFileError(f"{path}: field 'measured' holds values other than true/false")
        sizes["q"] = int(measured.astype(bool).sum())
        for f in FIELDS:
            arrays[f.name] = check_field(arrays, f, path, sizes)
        for k in ("spreads", "pool"):
            if len(arrays[k]) < 1:
                raise DataFileError(f"{path}: field {k!r} holds no draws")
        if np.any(arrays["spreads"] < 0):
            raise DataFileError(f"{path}: field 'spreads' holds negative spreads")
        drone = arrays["pool_drone"]
        if drone.min() < 0 or drone.max() >= sizes["drones"]:
            raise DataFileError(f"{path}: field 'pool_drone' holds drone indices outside 0..{sizes['drones'] - 1}")
        res = cls({k: arrays[k] for k in ARRAYS}, meta)
        if class_name is not None and res.class_name != class_name.upper():
            raise DataFileError(f"{path}: population of class {res.class_name!r}, expected {class_name.upper()!r}")
        return res


MAX_ENGINES = 16
FIELDS = (Field("spreads", "f", 2, ("draws", len(SPREADS)), text=f"spread draws (n, {len(SPREADS)})"),
          Field("mu", "f", 2, ("draws", "q"), text="mean-drone draws (n, measured coordinates)"),
          Field("pool", "f", 2, ("pool", "e13"), text="drone posterior draws (m, 13E)"),
          Field("pool_drone", "iu", 1, ("pool",), text="drone index per pool draw (m,)"),
          Field("drone_means", "f", 2, ("drones", "p"), text="each drone's mean (drones, p)"),
          Field("reference", "f", 1, ("e13",), text="the class vector (13E,)"))
"""The array fields of a population file after ``meta`` and ``measured`` (named axes: see
:class:`mdaug.radar.npz.Field`)."""


def _load_meta(path, raw) -> dict:
    """The ``meta`` table of a population file, every key the population reads checked."""
    try:
        meta = json.loads(str(raw))
    except ValueError:
        raise DataFileError(f"{path}: field 'meta' is not JSON") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else meta
        raise DataFileError(f"{path}: field 'meta' format {got!r}, expected {FORMAT!r}")
    gone = [k for k in META_FIELDS if k not in meta]
    if gone:
        raise DataFileError(f"{path}: field 'meta' lacks {gone}")

    def bad(key, expected):
        return DataFileError(f"{path}: field 'meta' key {key!r} = {str(meta.get(key))[:60]!r}: expected {expected}")

    n = meta["n_engines"]
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_ENGINES:
        raise bad("n_engines", f"an integer in 1..{MAX_ENGINES}")
    if not isinstance(meta["class_name"], str) or not meta["class_name"]:
        raise bad("class_name", "a class name")
    spec = meta["specimens"]
    if not isinstance(spec, list) or not spec or not all(isinstance(s, str) for s in spec):
        raise bad("specimens", "a non-empty list of drone ids")
    conv = meta["drones_converged"]
    if not isinstance(conv, list) or len(conv) != len(spec) or not all(isinstance(c, bool) for c in conv):
        raise bad("drones_converged", f"a list of {len(spec)} true/false")
    hyper = meta["hyperprior"]
    if not isinstance(hyper, dict) or not all(isinstance(hyper.get(k), (int, float)) and not isinstance(
            hyper.get(k), bool) and np.isfinite(hyper[k]) and hyper[k] > 0 for k in SPREADS):
        raise bad("hyperprior", f"a table of positive scales for {list(SPREADS)}")
    d = meta["diagnostics"]
    if not (isinstance(d, dict) and isinstance(d.get("converged"), bool) and isinstance(d.get("steps"), int)
            and isinstance(d.get("tau"), list) and d["tau"] and all(isinstance(t, (int, float)) for t in d["tau"])):
        raise bad("diagnostics", "a table with converged (true/false), steps (an integer) and tau (numbers)")
    from ...generator.acquisition import Acquisition
    from ..space.priors import Priors

    for key, read in (("acquisition", lambda v: Acquisition.from_dict(v, "acquisition")), ("priors", Priors.from_dict)):
        try:
            read(meta[key])
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
            raise DataFileError(f"{path}: field 'meta' key {key!r} is not readable ({type(exc).__name__}: "
                                f"{exc})") from None
    return meta
