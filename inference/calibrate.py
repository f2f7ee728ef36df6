"""calibrate(): measured profiles of one class -> posterior over its parameter vector.

Steps: check and normalise the measurements; priors from the class reference; the
likelihood of the measurements under their acquisition (phases marginalised,
:mod:`.likelihood.synthetic`, or fitted, :mod:`.likelihood.fitted_phases`, see
:func:`use_marginal`); a multi-start nlopt fit (:mod:`.fit`); a sampler plugin
(:mod:`.samplers`: emcee by default, to 50 tau or the time budget); draws,
log-likelihood and diagnostics packed in an arviz InferenceData (:mod:`.result.posterior`).
Engine-count comparison sits above this module (:mod:`.compare`). One seed drives
everything (a SeedSequence spawns the fit's and the sampler's streams, and the
marginal likelihood's common random numbers).

Resume: with ``backend_path`` the sampler checkpoints there and the fit is saved
beside it (``<backend>.fit.json``); a rerun of the same problem reuses the fit and
continues the chain, and says so (``diagnostics["resumed_at"]``, ``fit_reused``).
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from ..generator import IDX, N_PARAMS, ClassParams, load_reference
from ..generator.acquisition import Acquisition
from ..generator.magnitude import carrier_line_factor
from ..radar import RadarConfig, atomic_write
from ..radar.seeds import child_seed, seed_sequence
from .diagnostics.predictive import N_DRAWS, timed_check
from .samplers.toolbox import fingerprint
from .fit import FitResult, global_fit
from .likelihood.closed_form import ClosedFormLikelihood
from .space.layout import DEFAULT_STEADY, Layout
from .space.line_layout import LineLayout
from .likelihood.base import prepare_measured
from .likelihood.fitted_phases import LogPosterior
from .space.priors import PHASE_NAMES, SHARED, Priors
from .result.posterior import FORMAT, IDENTIFIED_RATIO, CalibrationResult, import_arviz
from .samplers import SamplerRun, get_sampler
from .settings import CalibrationSettings
from .likelihood.synthetic import SyntheticLikelihood

MAX_DRAWS = 4000  # posterior draws kept (thinned further when the chain holds more)
TRACE_STEPS = 400  # steps kept in the trace group


def start_vector(ref: ClassParams, n_engines: int) -> np.ndarray:
    """A start point for n_engines engines from the reference: its engines, cycled
    with their frequencies spread by 10% when there are more engines than in it."""
    e = ref.to_array().reshape(-1, N_PARAMS)
    rows = []
    for k in range(n_engines):
        r = e[k % len(e)].copy()
        r[[IDX["w_a"], IDX["w_b"]]] *= 1.0 + 0.1 * (k // len(e))
        rows.append(r)
    return np.concatenate(rows)


def use_marginal(acquisition: Acquisition, settings: CalibrationSettings) -> bool:
    """Whether the phases are marginalised: ``settings.likelihood`` when forced, else
    when the acquisition draws them at random or averages several ramps or an MTI
    residual (the published single chirp at fixed phases fits them)."""
    if settings.likelihood != "auto":
        return settings.likelihood in ("marginal", "synthetic")
    return acquisition.phases == "uniform" or acquisition.ramps > 1 or acquisition.mti_depth > 0


def make_likelihood(data: np.ndarray, ref: ClassParams, n_engines: int, acquisition: Acquisition,
                    settings: CalibrationSettings, ss: np.random.SeedSequence, priors: Priors | None = None,
                    radar: RadarConfig = RadarConfig()):
    """The likelihood object (with its :class:`Layout`) for normalised data (M, L)."""
    priors = priors or Priors.from_reference(ref, radar, alignment=settings.alignment)
    if use_marginal(acquisition, settings):
        if settings.normalisation != "peak":
            raise ValueError(f"the marginal likelihood compares peak-normalised profiles; normalisation "
                             f"{settings.normalisation!r} is only available with fitted phases (likelihood='fitted')")
        if settings.likelihood == "synthetic":
            layout = Layout(n_engines, data.shape[0], priors, marginal=True)
            return SyntheticLikelihood(data, layout, acquisition, radar, n_acquisitions=settings.n_acquisitions,
                                       ramps_drawn=settings.ramps_drawn, stride=settings.stride, seed=ss,
                                       dtype=settings.dtype)
        layout = LineLayout(n_engines, data.shape[0], priors, carrier_bounds=DEFAULT_STEADY, carrier_name="steady")
        return ClosedFormLikelihood(data, layout, acquisition, radar, stride=settings.stride,
                                    floor=settings.model_floor, amp_tol=settings.amp_tol,
                                    pair_tol=settings.pair_tol, reach_tol=settings.reach_tol)
    layout = Layout(n_engines, data.shape[0], priors, settings.range_offset,
                    sigma_bounds=(settings.sigma_min, settings.sigma_max))
    return LogPosterior(data, layout, radar, normalisation=settings.normalisation, dtype=settings.dtype,
                        sigma_bounds=(settings.sigma_min, settings.sigma_max), alignment=settings.alignment,
                        acquisition=acquisition)


def calibrate(profiles, reference, *, engines: int | None = None, acquisition: Acquisition | None = None,
              settings: CalibrationSettings = CalibrationSettings(), random_state=None, backend_path=None,
              priors: Priors | None = None, radar: RadarConfig = RadarConfig(),
              predictive: int = N_DRAWS) -> CalibrationResult:
    """Calibrate one class from its measured profiles.

    profiles: (n, L) or (L,) linear-magnitude measured profiles of one class (a
    handful, typically 5; L = radar.slice_length). reference: ClassParams or class
    name (prior centres and bounds, default engine count). engines: None (the
    reference's count) or an int (to choose it by model comparison use
    :func:`.compare.select_engines`). acquisition: how the profiles were measured
    (:class:`~mdaug.generator.acquisition.Acquisition`; None = the published single
    chirp). backend_path: checkpoint of the sampler (an interrupted run with the same
    arguments resumes from it). priors: override the reference-derived
    :class:`Priors`. predictive: posterior draws measured for the posterior predictive
    check (:mod:`.diagnostics.predictive`, ``diagnostics['predictive']``; 0: none), run
    where the phases are marginalised (the acquisition draws them, as the replicates
    do); a fitted-phase posterior is not checked.
    """
    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = settings if settings is not None else CalibrationSettings()
    acquisition = acquisition if acquisition is not None else Acquisition()
    if engines == "auto":
        raise ValueError("engines='auto' is model comparison: use mdaug.inference.compare.select_engines")
    n_eng = ref.n_engines if engines is None else int(engines)
    if n_eng < 1:
        raise ValueError(f"engines must be >= 1 or None, got {engines!r}")
    data, shifts = prepare_measured(profiles, radar, settings.normalisation,
                                    what=f"measured profiles of class {ref.name}")
    ss = seed_sequence(random_state)
    lik_ss, run_ss = ss.spawn(2)
    post = make_likelihood(data, ref, n_eng, acquisition, settings, lik_ss, priors, radar)
    res = run_calibration(post, ref, settings, run_ss, start_vector(ref, n_eng), backend_path=backend_path,
                          shifts=shifts)
    if predictive and res.marginal:
        peak, _ = prepare_measured(profiles, radar, "peak", what=f"measured profiles of class {ref.name}")
        lines = np.median(res.lines(by_brightness=True)[:, 0, :, 0], axis=0)  # the brightest engine's, sorted
        res.record_diagnostics(predictive=timed_check(res.draws(), peak, res.measured_acquisition(), radar, lines,
                                                      predictive, child_seed(ss, "predictive")))
    return res


def _fit_path(backend_path) -> Path | None:
    return None if backend_path is None else Path(f"{backend_path}.fit.json")


def saved_fit(backend_path, fp: str) -> FitResult | None:
    """The fit saved beside a checkpoint of the same problem (None when there is none)."""
    path = _fit_path(backend_path)
    if path is None or not path.is_file():
        return None
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if stored.get("fingerprint") != fp:
        return None
    return FitResult.from_dict(stored["fit"])


def run_calibration(post, ref: ClassParams, settings: CalibrationSettings, ss: np.random.SeedSequence, start_x,
                    *, backend_path=None, shifts=None) -> CalibrationResult:
    """Fit + sampler + packing for a prepared likelihood (its data, layout, radar and
    acquisition are the result's). start_x: (13E,) vector the first fit start begins at."""
    from threadpoolctl import threadpool_limits

    layout, radar = post.layout, post.radar
    fit_ss, mc_ss = ss.spawn(2)
    with threadpool_limits(settings.threads):
        key = settings.resume_key()  # a resumed run may have other budgets
        fp = fingerprint(post.data, text=json.dumps([ref.name, layout.E, layout.priors.to_dict(), key,
                                                     str(ss.entropy), list(ss.spawn_key), radar.to_dict(),
                                                     post.acquisition.to_dict()], default=str))
        fit = saved_fit(backend_path, fp)
        fit_reused = fit is not None
        if fit is None:
            fit = global_fit(post, settings, fit_ss, start=post.fit_start(start_x))
            path = _fit_path(backend_path)
            if path is not None:
                text = json.dumps({"fingerprint": fp, "fit": fit.to_dict()})
                atomic_write(path, lambda fh: fh.write(text.encode()))
        run = get_sampler(settings.sampler).run(post, fit, settings, mc_ss, backend_path=backend_path,
                                                fingerprint=fp)
        theta = run.draws()
        lp = run.draws_log_prob()
        if len(theta) > MAX_DRAWS:
            keep = np.linspace(0, len(theta) - 1, MAX_DRAWS).round().astype(int)
            theta, lp = theta[keep], lp[keep]
        loglik = post.pointwise(theta)
    shifts = np.zeros(layout.M, int) if shifts is None else shifts
    return build_result(ref, layout, post, fit, run, theta, lp, loglik, settings, radar, shifts,
                        fit_reused=fit_reused)


def _diagnostics(layout: Layout, run: SamplerRun, fit, settings, fit_reused: bool) -> dict:
    names = layout.theta_names()
    tau, ess = run.tau, run.ess
    return {"sampler": run.sampler, **run.extra,
            "converged": bool(run.converged), "reason": run.reason,
            "tau": {n: float(t) for n, t in zip(names, tau)}, "ess": {n: float(v) for n, v in zip(names, ess)},
            "tau_max": float(tau.max()), "ess_min": float(ess.min()),
            "chain_steps": int(run.n_steps), "steps_over_tau": float(run.n_steps / tau.max()),
            "acceptance_mean": float(run.acceptance.mean()), "acceptance_min": float(run.acceptance.min()),
            "n_walkers": int(run.chain.shape[1]), "burn": int(run.burn), "thin": int(run.thin),
            "seconds": float(run.seconds), "fit_seconds": float(fit.seconds), "resumed_at": int(run.resumed_at),
            "fit_reused": bool(fit_reused), "store_every": int(run.store_every),
            "n_fit_starts": int(settings.n_starts), "n_fit_starts_agreeing": int(fit.n_agree),
            "multimodal": bool(fit.multimodal), "min_tau_multiple": float(settings.of("emcee").min_tau_multiple)}


def _posterior_variables(layout: Layout, theta: np.ndarray):
    """(variables, dims) of the posterior group for draws theta (n, dim)."""
    z, tail = layout.split_theta(theta)
    x, extra = layout.physics(z)  # (n, M, 13E), (n, M)
    n, m_meas = x.shape[:2]
    xe = x.reshape(n, m_meas, layout.E, N_PARAMS)
    post_vars = {name: xe[None, :, 0, :, IDX[name]] for name in ("Gamma",) + SHARED}
    dims = {name: ["engine"] for name in ("Gamma",) + SHARED}
    if layout.marginal:
        level = layout.carriers(z)
        if layout.carrier_name == "steady":  # the steady line; the body return it implies at least
            post_vars["steady"] = level[None]
            dims["steady"] = ["measurement"]
            level = np.abs(level - carrier_line_factor(xe[:, 0])[:, None])
        post_vars["carrier"] = level[None]
        post_vars["offset"] = extra[None]
        post_vars["noise_db"] = tail[None]
        dims.update({"carrier": ["measurement"], "offset": ["measurement"], "noise_db": ["measurement"],
                     "y": ["measurement"]})
    else:
        post_vars.update({name: xe[None, :, :, :, IDX[name]] for name in PHASE_NAMES})
        post_vars["offset"] = extra[None]
        post_vars["sigma"] = np.exp(tail)[None]
        dims.update({name: ["measurement", "engine"] for name in PHASE_NAMES})
        dims.update({"offset": ["measurement"], "sigma": ["measurement"], "y": ["measurement", "bin"]})
    return post_vars, dims


def build_result(ref, layout: Layout, post, fit, run: SamplerRun, theta, lp, loglik, settings, radar,
                 shifts, *, fit_reused: bool = False) -> CalibrationResult:
    """Pack draws, diagnostics and metadata into an InferenceData (see :mod:`.result.posterior`).
    loglik: (n, M, L) per bin (fitted phases) or (n, M) per measurement (marginal)."""
    import xarray as xr

    az = import_arviz()
    post_vars, dims = _posterior_variables(layout, theta)
    idata = az.from_dict(posterior=post_vars, sample_stats={"lp": lp[None]}, log_likelihood={"y": loglik[None]},
                         observed_data={"y": post.data}, dims=dims)
    step = max(1, run.chain.shape[0] // TRACE_STEPS)
    trace = xr.Dataset({"theta": (("step", "walker", "coord"), run.chain[::step]),
                        "lp": (("step", "walker"), run.log_prob[::step])},
                       coords={"step": (np.arange(0, run.chain.shape[0], step) + 1) * run.store_every,
                               "coord": layout.theta_names()})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arviz warns that "chain_trace" is not a standard group
        idata.add_groups({"chain_trace": trace})
    best_theta = post.theta_from_fit(fit.best_z[None])
    best_x, _ = layout.physics(layout.split_theta(best_theta)[0])
    noise_model = post.noise_model
    lik = post.settings() if layout.marginal else {"likelihood": "fitted phases"}
    meta = {"format": FORMAT, "class_name": ref.name, "n_engines": layout.E, "n_measurements": layout.M,
            "settings": settings.to_dict(), "priors": layout.priors.to_dict(), "radar": radar.to_dict(),
            "acquisition": post.acquisition.to_dict(), "likelihood": lik, "marginal": bool(layout.marginal),
            "fit": fit.to_dict(), "best_fit": best_x[0, 0].tolist(), "theta_names": layout.theta_names(),
            "recentred_shifts": np.asarray(shifts).tolist(),
            "diagnostics": _diagnostics(layout, run, fit, settings, fit_reused), "noise_model": noise_model}
    idata.posterior.attrs["mdaug"] = json.dumps(meta)
    res = CalibrationResult(idata)
    table = res.summary()
    identified = {k: bool(v) for k, v in table["identified"].items() if table.loc[k, "kind"] in ("linear", "circular")}
    ratios = {k: float(v) for k, v in table["sd_ratio"].items() if np.isfinite(v)}
    weak = []
    for k in range(layout.E):
        # weak: none of its four vibration amplitudes is pinned down by the data
        if not any(identified[f"{n}[{k}]"] for n in ("A_a", "A_b", "A_p", "A_m")):
            weak.append(k)
    meta["diagnostics"].update(identified=identified, sd_ratio=ratios, weak_engines=weak,
                               identified_ratio=IDENTIFIED_RATIO)
    idata.posterior.attrs["mdaug"] = json.dumps(meta)
    return CalibrationResult(idata)
