"""calibrate(): measured profiles of one class -> posterior over its parameter vector.

Steps: check and normalise the measurements; priors from the class reference; a
multi-start nlopt fit (:mod:`.fit`); emcee from the best point until 50 tau or the
budget (:mod:`.sampler`); draws, per-bin log-likelihood and diagnostics packed in
an arviz InferenceData (:mod:`.result`). ``engines="auto"`` compares engine counts
(:mod:`.compare`). One seed drives everything (a SeedSequence spawns the fit's,
the start ball's and emcee's streams).
"""
from __future__ import annotations

import json
import warnings

import numpy as np

from ..generator import IDX, N_PARAMS, ClassParams, load_reference
from ..radar import RadarConfig
from .fit import AGREE_DISTANCE, RIVAL_MISFIT, global_fit
from .likelihood import LogPosterior, prepare_measured
from .priors import PHASE_NAMES, SHARED, Layout, Priors
from .result import FORMAT, IDENTIFIED_RATIO, CalibrationResult, import_arviz
from .sampler import curvature_scales, fingerprint, initial_ball, run_sampler
from .settings import CalibrationSettings

MAX_DRAWS = 4000  # posterior draws kept (thinned further when the chain holds more)
TRACE_STEPS = 400  # steps kept in the trace group


def seed_sequence(random_state) -> np.random.SeedSequence:
    if isinstance(random_state, np.random.SeedSequence):
        return random_state
    if isinstance(random_state, np.random.Generator):
        return np.random.SeedSequence(int(random_state.integers(2**63 - 1)))
    return np.random.SeedSequence(random_state)


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


def calibrate(profiles, reference, *, engines=None, settings: CalibrationSettings = CalibrationSettings(),
              random_state=None, backend_path=None, priors: Priors | None = None,
              radar: RadarConfig = RadarConfig(), candidates=(1, 2, 4)) -> CalibrationResult:
    """Calibrate one class from its measured profiles.

    profiles: (n, L) or (L,) linear-magnitude measured profiles of one class (1-5
    measurements; L = radar.slice_length). reference: ClassParams or class name (prior
    centres and bounds, default engine count). engines: None (the reference's
    count), an int, or "auto" (choose among ``candidates`` by LOO, see
    :func:`.compare.select_engines`). backend_path: HDF5 file for emcee's chain
    (an interrupted run with the same arguments resumes from it). priors: override
    the reference-derived :class:`Priors`.
    """
    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = settings if settings is not None else CalibrationSettings()
    if engines == "auto":
        from .compare import select_engines

        return select_engines(profiles, ref, candidates=candidates, settings=settings, random_state=random_state,
                              backend_path=backend_path, priors=priors, radar=radar)
    n_eng = ref.n_engines if engines is None else int(engines)
    if n_eng < 1:
        raise ValueError(f"engines must be >= 1, None or 'auto', got {engines!r}")
    data, shifts = prepare_measured(profiles, radar, settings.normalisation,
                                    what=f"measured profiles of class {ref.name}")
    priors = priors or Priors.from_reference(ref, radar, alignment=settings.alignment)
    layout = Layout(n_eng, data.shape[0], priors, settings.range_offset)
    post = LogPosterior(data, layout, radar, normalisation=settings.normalisation, dtype=settings.dtype,
                        sigma_bounds=(settings.sigma_min, settings.sigma_max), alignment=settings.alignment)
    return run_calibration(post, ref, settings, seed_sequence(random_state), start_vector(ref, n_eng),
                           backend_path=backend_path, shifts=shifts)


def run_calibration(post: LogPosterior, ref: ClassParams, settings: CalibrationSettings,
                    ss: np.random.SeedSequence, start_x, *, backend_path=None, shifts=None) -> CalibrationResult:
    """Fit + MCMC + packing for a prepared :class:`LogPosterior` (also used by the
    simulation-based calibration, which builds its own data). start_x: (13E,) vector
    the first fit start begins at."""
    from threadpoolctl import threadpool_limits

    layout, radar = post.layout, post.radar
    fit_ss, ball_ss, mc_ss = ss.spawn(3)
    with threadpool_limits(settings.threads):
        start = layout.canonical(layout.z_from_physics(start_x))[0]
        fit = global_fit(post, settings, fit_ss, start=start)
        resume_key = {k: v for k, v in settings.to_dict().items() if k not in ("max_steps", "progress", "threads")}
        if settings.sampler == "emcee":  # keep the fingerprint of existing checkpoints unchanged
            resume_key = {k: v for k, v in resume_key.items() if k != "sampler" and not k.startswith("smc_")
                          and k != "n_particles"}
        fp = fingerprint(post.data, text=json.dumps([ref.name, layout.E, layout.priors.to_dict(), resume_key,
                                                     str(ss.entropy), list(ss.spawn_key), radar.to_dict()],
                                                    default=str))
        smc = None
        if settings.sampler == "smc":
            from .tempering import calibrate_smc

            chain, smc = calibrate_smc(post, settings, mc_ss, backend_path=backend_path, fp=fp, fit=fit)
            n_modes = 0
        else:
            n_walkers = max(settings.n_walkers or 3 * layout.dim, 2 * layout.dim + 2, 32)  # DE needs > 2 dim
            n_walkers += n_walkers % 2
            p0, n_modes = start_walkers(post, fit, settings, n_walkers, np.random.default_rng(ball_ss))
            chain = run_sampler(post, p0, settings, seed=int(mc_ss.generate_state(1)[0]),
                                backend_path=backend_path, fp=fp, phase_cols=layout.phase_cols,
                                relabel=layout.random_relabel)
        theta = chain.draws()
        lp = chain.draws_log_prob()
        if len(theta) > MAX_DRAWS:
            keep = np.linspace(0, len(theta) - 1, MAX_DRAWS).round().astype(int)
            theta, lp = theta[keep], lp[keep]
        loglik = post.pointwise(theta)
    shifts = np.zeros(layout.M, int) if shifts is None else shifts
    return build_result(ref, layout, post, fit, chain, theta, lp, loglik, settings, radar, shifts, n_modes, smc)


def start_walkers(post: LogPosterior, fit, settings, n_walkers: int, rng) -> tuple[np.ndarray, int]:
    """Initial walkers (n_walkers, dim): around the best fit, and with ``init_modes``
    also around every distinct rival mode the fit found (within RIVAL_MISFIT nats),
    split evenly, so the ensemble starts on every competitive mode it knows of.
    Returns (walkers, number of modes started on)."""
    layout = post.layout
    lo, hi = layout.z_bounds()
    width = (hi - lo)[: layout.n_shared]
    order = np.argsort(fit.starts_misfit)
    centres = [fit.best_z]
    if settings.init_modes:
        for i in order:
            z = fit.starts_z[i]
            if fit.starts_misfit[i] - fit.misfit > RIVAL_MISFIT:
                break
            if all(np.max(np.abs(z[: layout.n_shared] - c[: layout.n_shared]) / width) > AGREE_DISTANCE
                   for c in centres):
                centres.append(z)
    counts = np.full(len(centres), n_walkers // len(centres))
    counts[0] += n_walkers - counts.sum()
    groups = []
    for z, n in zip(centres, counts):
        sigma = np.sqrt(post.ssr(z[None])[0] / post.n_bins)
        ln_sig = np.log(np.clip(sigma, settings.sigma_min * 1.01, settings.sigma_max * 0.99))
        theta = layout.theta_from_z(z[None], ln_sig[None])[0]
        scales = settings.init_ball * curvature_scales(layout, theta, post)
        groups.append(initial_ball(layout, theta, post, int(n), scales, rng))
    return np.concatenate(groups), len(centres)


def _diagnostics(layout: Layout, chain, fit, settings, n_modes: int, smc=None) -> dict:
    names = layout.z_names() + [f"ln_sigma@{m}" for m in range(layout.M)]
    tau, ess = chain.tau, chain.ess
    extra = {"sampler": "emcee"}
    if smc is not None:
        from .tempering import smc_diagnostics

        extra = smc_diagnostics(smc)
    return {**extra,
        "converged": bool(chain.converged), "reason": chain.reason,
        "tau": {n: float(t) for n, t in zip(names, tau)}, "ess": {n: float(v) for n, v in zip(names, ess)},
        "tau_max": float(tau.max()), "ess_min": float(ess.min()),
        "chain_steps": int(chain.n_steps), "steps_over_tau": float(chain.n_steps / tau.max()),
        "acceptance_mean": float(chain.acceptance.mean()), "acceptance_min": float(chain.acceptance.min()),
        "n_walkers": int(chain.chain.shape[1]), "burn": int(chain.burn), "thin": int(chain.thin),
        "seconds": float(chain.seconds), "resumed_at": int(chain.resumed_at),
        "store_every": int(chain.store_every),
        "n_fit_starts": int(settings.n_starts), "n_fit_starts_agreeing": int(fit.n_agree),
        "multimodal": bool(fit.multimodal), "min_tau_multiple": float(settings.min_tau_multiple),
        "n_start_modes": int(n_modes),
    }


def build_result(ref, layout: Layout, post: LogPosterior, fit, chain, theta, lp, loglik, settings, radar,
                 shifts, n_modes: int = 1, smc=None) -> CalibrationResult:
    """Pack draws, diagnostics and metadata into an InferenceData (see :mod:`.result`)."""
    import xarray as xr

    az = import_arviz()
    z, ln_sigma = layout.split_theta(theta)
    x, off = layout.physics(z)  # (n, M, 13E), (n, M)
    n, m_meas = x.shape[:2]
    xe = x.reshape(n, m_meas, layout.E, N_PARAMS)
    post_vars = {name: xe[None, :, 0, :, IDX[name]] for name in ("Gamma",) + SHARED}
    post_vars.update({name: xe[None, :, :, :, IDX[name]] for name in PHASE_NAMES})
    post_vars["offset"] = off[None]
    post_vars["sigma"] = np.exp(ln_sigma)[None]
    dims = {name: ["engine"] for name in ("Gamma",) + SHARED}
    dims.update({name: ["measurement", "engine"] for name in PHASE_NAMES})
    dims.update({"offset": ["measurement"], "sigma": ["measurement"], "y": ["measurement", "bin"]})
    idata = az.from_dict(posterior=post_vars, sample_stats={"lp": lp[None]}, log_likelihood={"y": loglik[None]},
                         observed_data={"y": post.data}, dims=dims)
    step = max(1, chain.chain.shape[0] // TRACE_STEPS)
    names = layout.z_names() + [f"ln_sigma@{m}" for m in range(layout.M)]
    trace = xr.Dataset({"theta": (("step", "walker", "coord"), chain.chain[::step]),
                        "lp": (("step", "walker"), chain.log_prob[::step])},
                       coords={"step": (np.arange(0, chain.chain.shape[0], step) + 1) * chain.store_every,
                               "coord": names})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # arviz warns that "chain_trace" is not a standard group
        idata.add_groups({"chain_trace": trace})
    best_x, _ = layout.physics(fit.best_z[None])
    meta = {"format": FORMAT, "class_name": ref.name, "n_engines": layout.E, "n_measurements": layout.M,
            "settings": settings.to_dict(), "priors": layout.priors.to_dict(), "radar": radar.to_dict(),
            "fit": fit.to_dict(), "best_fit": best_x[0, 0].tolist(), "z_names": layout.z_names(),
            "recentred_shifts": np.asarray(shifts).tolist(),
            "diagnostics": _diagnostics(layout, chain, fit, settings, n_modes, smc),
            "noise_model": "Gaussian iid per bin on the normalised profile, sigma per measurement (log-uniform)"}
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
