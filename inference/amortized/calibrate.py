"""calibrate_amortized(): measured profiles of one drone -> a CalibrationResult, with no
training: the class's trained estimator (:mod:`.shipped` or a file).

Two posteriors, learned apart from the same simulations and each judged by the SBC
stored in the estimator: the amortized posterior (draws in milliseconds), and nlopt +
emcee on the learned likelihood (:mod:`.mcmc`). The posterior group holds the one
the strategies use (``route``, default the amortized one: its SBC ran on the most
truths and it needs no chain); the other lands in the group ``other_route`` beside
it, with its diagnostics in the metadata. Both are in the class-vector variables of
every mdaug posterior (Gamma, A_a, ..., C_m per engine, phases marginalised).

Out of range: when the amortized posterior leaks (under half the share of draws inside
the prior that it keeps on its own SBC drones) or the
two routes disagree (the emcee medians outside the amortized 98% intervals for a
quarter of the quantities or more), the measurements are unlike the training set:
the result says so (``diagnostics['out_of_range']``) and ``calibrate`` warns.
"""
from __future__ import annotations

import json
import time
import warnings

import numpy as np

from ...generator import IDX, load_reference
from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from ...radar.seeds import child_seed, seed_sequence
from ..likelihood.base import prepare_measured
from ..space.priors import SHARED
from ..result.posterior import FORMAT, IDENTIFIED_RATIO, CalibrationResult, import_arviz
from .shipped import find

ROUTES = ("amortized", "emcee")
LEAK_FACTOR = 0.5  # draws inside the prior below this share of the estimator's own SBC drones': out of range
DISAGREE_LIMIT = 0.25  # share of quantities whose emcee median leaves the amortized 98% interval


def calibrate_amortized(profiles, reference, *, acquisition: Acquisition | None = None, estimator=None,
                        settings=None, random_state=None, n_draws: int = 4000, route: str = "amortized",
                        emcee: bool = True, radar: RadarConfig = RadarConfig(), source: str = "measured profiles"):
    """Calibrate one drone (module doc). estimator: an :class:`.estimator.AmortizedEstimator`,
    a path, or None (the shipped one for the class and acquisition); settings: the
    :class:`~mdaug.inference.settings.CalibrationSettings` of the emcee route (its
    time budget, 50-tau rule, progress); emcee: False skips that route."""
    from ..settings import CalibrationSettings
    from .estimator import AmortizedEstimator, EstimatorError
    from .mcmc import LearnedPosterior, sample

    if route not in ROUTES:
        raise ValueError(f"route must be one of {ROUTES}, got {route!r}")
    if route == "emcee" and not emcee:
        raise ValueError("route 'emcee' needs the emcee route (emcee=True)")
    ref = load_reference(reference) if isinstance(reference, str) else reference
    acquisition = acquisition if acquisition is not None else Acquisition.measured(1)
    settings = settings if settings is not None else CalibrationSettings()
    est = estimator if isinstance(estimator, AmortizedEstimator) else find(ref.name, acquisition, radar, path=estimator)
    data, shifts = prepare_measured(profiles, radar, "peak", what=f"{source} of class {ref.name}")
    est.check_data(data, acquisition, radar, source)
    lf = est.label_free
    ss = seed_sequence(random_state)
    t0 = time.perf_counter()
    try:
        u, inside = est.sample_u(data, n_draws, child_seed(ss, "amortized"))
    except EstimatorError as exc:  # data far outside the training set: refused, not calibrated
        raise EstimatorError(f"{source}: {exc}") from None
    t_amortized = time.perf_counter() - t0
    x_amortized, _ = lf.vectors(lf.from_unbounded(u))
    diag = {"sampler": "amortized", "route": route, "amortized_seconds": t_amortized,
            "amortized_inside_prior": float(inside), "estimator": _estimator_info(est)}
    x_emcee = None
    if emcee:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(settings.threads):
            post = LearnedPosterior(est, data)
            run, fit = sample(post, u[:1000], settings, child_seed(ss, "emcee"))
        x_emcee = post.vectors(run.draws())
        names = post.label_free.names
        diag["emcee"] = {"converged": bool(run.converged), "reason": run.reason, "seconds": float(run.seconds),
                         "tau_max": float(run.tau.max()), "steps": int(run.n_steps),
                         "steps_over_tau": float(run.n_steps / run.tau.max()),
                         "acceptance_mean": float(run.acceptance.mean()), "n_walkers": int(run.chain.shape[1]),
                         "ess_min": float(run.ess.min()), "rhat_max": _rhat(run, names), "fit": fit,
                         "evaluations": int(post.n_calls)}
        diag.update({k: diag["emcee"][k] for k in ("n_walkers", "steps_over_tau", "ess_min", "acceptance_mean",
                                                    "tau_max")}, chain_steps=diag["emcee"]["steps"])
    diag["seconds"] = time.perf_counter() - t0
    typical = est.meta.get("sbc", {}).get("amortized", {}).get("inside_prior_share", 1.0)
    diag["out_of_range"], diag["out_of_range_why"] = _out_of_range(lf, x_amortized, x_emcee, inside, typical)
    chosen = x_amortized if route == "amortized" else x_emcee
    if route == "amortized":
        diag.update(converged=True, reason="amortized posterior: exact draws from the trained estimator "
                    f"(SBC in the estimator file: {_sbc_line(est, 'amortized')})")
    else:
        diag.update(converged=diag["emcee"]["converged"], reason=diag["emcee"]["reason"])
    if diag["out_of_range"]:
        warnings.warn(f"{source}: {diag['out_of_range_why']}", stacklevel=2)
    return _result(ref, est, data, shifts, chosen, x_emcee if route == "amortized" else x_amortized, diag, n_draws)


def _estimator_info(est) -> dict:
    m = est.meta
    return {"class": est.class_name, "ramps": est.spec.acquisition.ramps, "simulations": m.get("n_simulations"),
            "simulator": m["spec"].get("simulator"), "sbc": {r: {k: m["sbc"][r].get(k) for k in
                                                                 ("outer_share", "coverage90_range", "n_replicates", "pooled_p")}
                                                             for r in m.get("sbc", {}) if isinstance(m["sbc"][r], dict)
                                                             and "outer_share" in m["sbc"][r]}}


def _sbc_line(est, route: str) -> str:
    s = est.meta.get("sbc", {}).get(route)
    if not isinstance(s, dict) or "outer_share" not in s:
        return "none stored"
    lo, hi = s["coverage90_range"]
    return f"outer-10% share {s['outer_share']:.3f}, 90% coverage {lo:.2f}-{hi:.2f} on {s['n_replicates']} drones"


def _rhat(run, names) -> float:
    """Split R-hat (arviz) over the walkers, the worst coordinate."""
    az = import_arviz()
    chain = run.chain[run.burn // run.store_every:]
    if chain.shape[0] < 4:
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = az.rhat(az.convert_to_dataset(np.swapaxes(chain, 0, 1)))
    return float(np.nanmax(r["x"].values))


def _out_of_range(lf, x_amortized, x_emcee, inside: float, typical: float) -> tuple[bool, str]:
    """typical: the share of draws inside the prior on the estimator's own SBC drones."""
    if inside < LEAK_FACTOR * typical:
        return True, (f"only {inside:.0%} of the amortized posterior's draws fall inside the prior (on simulated "
                      f"drones {typical:.0%}): the measurements are unlike the estimator's training set")
    if x_emcee is None:
        return False, ""
    qa, qe = lf.quantities(x_amortized), lf.quantities(x_emcee)
    lo, hi = np.quantile(qa, [0.01, 0.99], axis=0)
    med = np.median(qe, axis=0)
    off = (med < lo) | (med > hi)
    if off.mean() >= DISAGREE_LIMIT:
        names = [n for n, o in zip(lf.names, off) if o]
        return True, (f"the two learned posteriors disagree on {len(names)} of {len(off)} quantities "
                      f"({', '.join(names[:4])}{'...' if len(names) > 4 else ''}): the measurements are unlike the "
                      "estimator's training set")
    return False, ""


def _group(x: np.ndarray, e: int) -> dict:
    xe = x.reshape(len(x), e, -1)
    return {name: xe[None, :, :, IDX[name]] for name in ("Gamma",) + SHARED}


def _result(ref, est, data, shifts, chosen, other, diag, n_draws) -> CalibrationResult:
    """The result's file: its acquisition and radar are the estimator's (the data's, as
    ``check_data`` found them: it refuses any field that differs)."""
    import xarray as xr

    az = import_arviz()
    e = ref.n_engines
    dims = {name: ["engine"] for name in ("Gamma",) + SHARED}
    idata = az.from_dict(posterior=_group(chosen, e), observed_data={"y": data}, dims={**dims, "y": ["measurement", "bin"]})
    if other is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            idata.add_groups({"other_route": xr.Dataset({k: (("chain", "draw", "engine"), v)
                                                         for k, v in _group(other, e).items()})})
    median = np.median(chosen, axis=0)
    meta = {"format": FORMAT, "class_name": ref.name, "n_engines": e, "n_measurements": int(len(data)),
            "settings": {"route": diag["route"], "n_draws": int(n_draws)}, "priors": est.priors.to_dict(),
            "radar": est.spec.radar.to_dict(), "acquisition": est.spec.acquisition.to_dict(),
            "likelihood": {"likelihood": "simulation-based (amortized posterior; learned likelihood for emcee)"},
            "marginal": True, "amortized": True,
            "fit": diag.get("emcee", {}).get("fit", {}), "best_fit": median.tolist(),
            "recentred_shifts": np.asarray(shifts).tolist(), "diagnostics": diag,
            "noise_model": "learned from the scene simulator (every nuisance drawn as a measurement draws it)"}
    idata.posterior.attrs["mdaug"] = json.dumps(meta, default=float)
    res = CalibrationResult(idata)
    table = res.summary()
    diag["identified"] = {k: bool(v) for k, v in table["identified"].items() if table.loc[k, "kind"] == "linear"}
    diag["identified_ratio"] = IDENTIFIED_RATIO
    idata.posterior.attrs["mdaug"] = json.dumps(meta, default=float)
    return CalibrationResult(idata)
