"""calibrate_amortized(): measured profiles of one drone -> a CalibrationResult, with no
training: the class's trained estimator (:mod:`.shipped` or a file).

Three routes (:data:`.estimator.ROUTES`), each judged by the SBC and the route table
stored in the estimator: the amortized posterior (draws in milliseconds),
tempered SMC from the amortized posterior to the posterior of the file's likelihood
(:mod:`.tempered`; the summary likelihood of :mod:`mdaug.inference.emulator` where
the file has one, else the ratio network's, :mod:`.ratio_posterior`), and, where the
file states a stacking weight w, the two stacked (:mod:`.stacked`: w of the draws from
the smc route, the rest from the amortized posterior). ``route`` None
takes the file's default route (named by its route table,
:func:`mdaug.inference.diagnostics.routes.default_route`); with ``check=True`` the
other route runs too and lands in the group ``other_route``, with its diagnostics in
the metadata. Where the file has a summary likelihood and the route is the amortized
one, the smc route still runs (``fit=True``, the default) for the **best fit**: the
median of its draws (of their label-free lines, mapped back to a class vector:
:func:`label_free_median`), the centre of the sigma_p_fit strategy (``tests/benchmarks/best_fit.py``:
on 11 QUAD K = 32 drones of the specimen model the amortized median's brightest-engine
lines 1-4 were a median 67 / 14 / 32 / 36% off, the best fit's 23 / 8 / 10 / 5%: the
amortized QUAD posterior is near its prior). Its draws are not the posterior then (the
route table keeps the amortized route, honest by SBC);
``diagnostics['best_fit_from']`` names the route the best fit came from. All are in
the class-vector variables of every mdaug posterior (Gamma, A_a, ..., C_m per engine,
phases marginalised).

Out of range: when the amortized posterior leaks (under half the share of draws inside
the prior that it keeps on its own SBC drones) or the
two routes disagree (the smc medians outside the amortized 98% intervals for a
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
from ..diagnostics.predictive import N_DRAWS, timed_check
from ..result.posterior import FORMAT, IDENTIFIED_RATIO, CalibrationResult, import_arviz
from .estimator import ROUTES
from .shipped import find

LEAK_FACTOR = 0.5  # draws inside the prior below this share of the estimator's own SBC drones': out of range
DISAGREE_LIMIT = 0.25  # share of quantities whose smc median leaves the amortized 98% interval


def calibrate_amortized(profiles, reference, *, acquisition: Acquisition | None = None, estimator=None,
                        settings=None, random_state=None, n_draws: int = 4000, route: str | None = None,
                        check: bool = False, fit: bool = True, radar: RadarConfig = RadarConfig(),
                        source: str = "measured profiles", predictive: int = N_DRAWS):
    """Calibrate one drone (module doc). estimator: an :class:`.estimator.AmortizedEstimator`,
    a path, or None (the shipped one for the class and acquisition); settings: the
    :class:`~mdaug.inference.settings.CalibrationSettings` of the smc route (its
    time budget, progress, the SMC plugin's ``n_particles`` and ``max_stages``); route:
    one of :data:`.estimator.ROUTES` or None (the estimator's default route); check:
    also run another route, as a check; fit: where the file has a summary likelihood and
    the route is amortized, run the smc route for the best fit (module doc; False: the
    amortized median, as for a population's drones, whose best fits nothing uses);
    predictive: posterior draws measured for the posterior predictive check
    (:mod:`mdaug.inference.diagnostics.predictive`, ``diagnostics['predictive']``; 0: none)."""
    from ..settings import CalibrationSettings
    from .estimator import AmortizedEstimator, EstimatorError

    if route is not None and route not in ROUTES:
        raise ValueError(f"route must be one of {ROUTES}, got {route!r}")
    ref = load_reference(reference) if isinstance(reference, str) else reference
    acquisition = acquisition if acquisition is not None else Acquisition.measured(1)
    settings = settings if settings is not None else CalibrationSettings()
    est = estimator if isinstance(estimator, AmortizedEstimator) else find(ref.name, acquisition, radar, path=estimator)
    route = est.default_route if route is None else route
    est.check_route(route, source)
    fit_smc = fit and route == "amortized" and est.summary is not None
    sampled = "smc" if route != "amortized" or check or fit_smc else None  # the sampler that runs
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
    diag = {"sampler": "amortized" if route == "amortized" else "smc", "route": route,
            "amortized_seconds": t_amortized, "amortized_inside_prior": float(inside),
            "estimator": _estimator_info(est, route), "check": bool(check),
            "best_fit_from": "smc" if (sampled == "smc" and est.summary is not None) else route}
    x_sampled = None
    if sampled:
        from threadpoolctl import threadpool_limits

        from .tempered import smc_route

        with threadpool_limits(settings.threads):
            post, run = smc_route(est, data, settings, child_seed(ss, "smc-start"), child_seed(ss, "smc"),
                                  plug_in=np.median(u, axis=0))
        x_sampled = post.vectors(run.draws())
        info = {"converged": bool(run.converged), "reason": run.reason, "seconds": float(run.seconds),
                "likelihood": est.likelihood_name, "evaluations": int(post.n_calls),
                "particles": int(run.chain.shape[1]), "stages": int(run.extra["smc_stages"]),
                "acceptance_last": float(run.acceptance.mean()),
                "unique_share": float(run.extra["smc_unique_share"]), "log_evidence": float(run.extra["smc_log_z"]),
                "route_settings": run.extra["route_settings"]}
        if est.summary is not None:
            info["crb"] = _crb(post, np.median(run.draws(), axis=0))
        diag[sampled] = info
    diag["seconds"] = time.perf_counter() - t0
    typical = est.meta.get("sbc", {}).get("amortized", {}).get("inside_prior_share", 1.0)
    diag["out_of_range"], diag["out_of_range_why"] = _out_of_range(lf, x_amortized, x_sampled, inside, typical)
    chosen = x_amortized if route == "amortized" else x_sampled
    if route == "stacked":  # the file's mixture of the two routes (.stacked)
        from .stacked import mix_draws

        w = est.stacking_weight
        chosen, share = mix_draws(x_sampled, x_amortized, w, n_draws, np.random.default_rng(child_seed(ss, "stack")))
        diag["stacked"] = {"weight": w, "smc_share": share, "stacking": dict(est.meta["stacking"])}
    diag["widths"] = _widths(lf, chosen, diag["smc"].get("crb", {}) if route != "amortized" else {})
    if route == "amortized":
        diag.update(converged=True, reason="amortized posterior: exact draws from the trained estimator "
                    f"(SBC in the estimator file: {_sbc_line(est, 'amortized')})")
    else:
        diag.update(converged=diag["smc"]["converged"], reason=diag["smc"]["reason"])
    if diag["out_of_range"]:
        warnings.warn(f"{source}: {diag['out_of_range_why']}", stacklevel=2)
    if predictive:
        diag["predictive"] = _predictive(lf, chosen, data, est, predictive, child_seed(ss, "predictive"))
    other = None if not check else (x_sampled if route == "amortized" else x_amortized)
    best, diag["best_fit_median"] = label_free_median(lf, x_sampled if diag["best_fit_from"] == "smc" else chosen)
    return _result(ref, est, data, shifts, chosen, other, diag, n_draws, best)


def label_free_median(lf, x: np.ndarray) -> tuple[np.ndarray, str]:
    """The best fit of draws x (n, 13E): the median of each label-free quantity (sorted
    lines, amplitudes in the same order, Gamma ratios), mapped back to a class vector
    by :meth:`.target.LabelFree.vectors` (the labelling nearest the reference's). The
    component-wise median of the class vectors mixes the draws' labellings (one draw's
    roll is another's pitch) and lands between lines. The medians of sorted lines keep
    their order, so the map back fails only where no labelling of the medians fits the
    prior: then the component-wise median, and the second value says which
    ('label-free' or 'component-wise')."""
    q = np.median(lf.quantities(x), axis=0)
    v, ok = lf.vectors(q[None])
    if ok[0]:
        return v[0], "label-free"
    return np.median(x, axis=0), "component-wise"


def _predictive(lf, x: np.ndarray, data: np.ndarray, est, n_draws: int, seed: int) -> dict:
    """The posterior predictive check of draws x (n, 13E) against the calibrated data (M, L),
    at the brightest engine's label-free median lines, as plain data with its time."""
    lines = np.median(lf.quantities(x)[:, :4], axis=0)  # 'line 1-4 w[0]': the brightest engine's, sorted
    return timed_check(x, data, est.spec.acquisition, est.spec.radar, lines, n_draws, seed)


def _widths(lf, x: np.ndarray, crb: dict) -> dict:
    """Median and 90% interval of every label-free quantity of draws x, with the
    Cramer-Rao bound's 90% width (2 x 1.645 sd) where one is given."""
    q = lf.quantities(x)
    lo, med, hi = np.quantile(q, [0.05, 0.5, 0.95], axis=0)
    out = {}
    for j, name in enumerate(lf.names):
        out[name] = {"median": float(med[j]), "q05": float(lo[j]), "q95": float(hi[j])}
        if name in crb:
            out[name]["crb_width"] = 2 * 1.645 * float(crb[name])
    return out


def _crb(post, u) -> dict:
    """Cramer-Rao sd of every label-free quantity at the posterior median u (the summary
    likelihood's Fisher information for these measurements)."""
    try:
        sd = post.crb_quantities(np.asarray(u, float))
    except (np.linalg.LinAlgError, ValueError):
        return {}
    return dict(zip(post.label_free.names, map(float, sd)))


def _estimator_info(est, route: str) -> dict:
    """The file's facts a result keeps: its class, K, simulations, temperature, every
    route's stored SBC, and the route used's row on drones like a user's (``users``)."""
    m = est.meta
    return {"class": est.class_name, "ramps": est.spec.acquisition.ramps, "simulations": m.get("n_simulations"),
            "simulator": m["spec"].get("simulator"), "temperature": est.temperature, "users": est.users_row(route),
            "sbc": {r: {**{k: m["sbc"][r].get(k) for k in ("outer_share", "coverage90_range", "n_replicates",
                                                             "pooled_p")}, "n_quantities": est.label_free.dim}
                    for r in m.get("sbc", {}) if isinstance(m["sbc"][r], dict) and "outer_share" in m["sbc"][r]}}


def _sbc_line(est, route: str) -> str:
    s = est.meta.get("sbc", {}).get(route)
    if not isinstance(s, dict) or "outer_share" not in s:
        return "none stored"
    lo, hi = s["coverage90_range"]
    return f"outer-10% share {s['outer_share']:.3f}, 90% coverage {lo:.2f}-{hi:.2f} on {s['n_replicates']} drones"


def _out_of_range(lf, x_amortized, x_sampled, inside: float, typical: float) -> tuple[bool, str]:
    """typical: the share of draws inside the prior on the estimator's own SBC drones."""
    if inside < LEAK_FACTOR * typical:
        return True, (f"only {inside:.0%} of the amortized posterior's draws fall inside the prior (on simulated "
                      f"drones {typical:.0%}): the measurements are unlike the estimator's training set")
    if x_sampled is None:
        return False, ""
    qa, qe = lf.quantities(x_amortized), lf.quantities(x_sampled)
    lo, hi = np.quantile(qa, [0.01, 0.99], axis=0)
    med = np.median(qe, axis=0)
    off = (med < lo) | (med > hi)
    if off.mean() >= DISAGREE_LIMIT:
        names = [n for n, o in zip(lf.names, off) if o]
        return True, (f"the two learned posteriors disagree on {len(names)} of {len(off)} quantities "
                      f"({', '.join(names[:4])}{'...' if len(names) > 4 else ''}): the measurements are unlike the "
                      "estimator's training set")
    return False, ""


def _likelihood_words(est, route: str) -> str:
    if route == "amortized":
        return "simulation-based (the amortized posterior of the trained estimator)"
    if est.summary is not None:
        return ("simulation-based summary likelihood (the folded mean log-profile; emulated mean and "
                "within-drone covariance, the emulator's error included)")
    return "simulation-based (a learned likelihood ratio per measurement)"


def _group(x: np.ndarray, e: int) -> dict:
    xe = x.reshape(len(x), e, -1)
    return {name: xe[None, :, :, IDX[name]] for name in ("Gamma",) + SHARED}


def _result(ref, est, data, shifts, chosen, other, diag, n_draws, best) -> CalibrationResult:
    """The result's file (best: the best fit's class vector, module doc): its acquisition
    and radar are the estimator's (the data's, as ``check_data`` found them: it refuses
    any field that differs)."""
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
    meta = {"format": FORMAT, "class_name": ref.name, "n_engines": e, "n_measurements": int(len(data)),
            "settings": {"route": diag["route"], "n_draws": int(n_draws)}, "priors": est.priors.to_dict(),
            "radar": est.spec.radar.to_dict(), "acquisition": est.spec.acquisition.to_dict(),
            "likelihood": {"likelihood": _likelihood_words(est, diag["route"])},
            "marginal": True, "amortized": True,
            "fit": diag.get(diag["route"], {}).get("fit", {}), "best_fit": np.asarray(best, float).tolist(),
            "recentred_shifts": np.asarray(shifts).tolist(), "diagnostics": diag,
            "noise_model": "learned from the scene simulator (every nuisance drawn as a measurement draws it)"}
    idata.posterior.attrs["mdaug"] = json.dumps(meta, default=float)
    res = CalibrationResult(idata)
    table = res.summary()
    diag["identified"] = {k: bool(v) for k, v in table["identified"].items() if table.loc[k, "kind"] == "linear"}
    diag["identified_ratio"] = IDENTIFIED_RATIO
    idata.posterior.attrs["mdaug"] = json.dumps(meta, default=float)
    return CalibrationResult(idata)
