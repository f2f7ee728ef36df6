"""Simulation-based calibration of the population (Talts et al. 2018, one level up).

Each replicate: spreads drawn from the hyperprior; ``n_drones + 1`` drones of the
class drawn around a class mean by the scene simulator's specimen model with those
spreads, ``n_acquisitions`` acquisitions of each through the scene simulator and
the radar chain (:func:`~mdaug.generator.chain.simulate_campaign`); the first
``n_drones`` calibrated one by one (``method`` "amortized": the shipped estimator's
posterior, milliseconds; "likelihood": the closed-form route of ``settings``), then
their population (:func:`..population.result.calibrate_population`); the last drone
is the one not seen. Ranks among ``n_rank`` draws of:

* each spread, among the hyper-posterior's draws;
* the unseen drone's label-free lines (:func:`.sbc.sbc_quantities`: each engine's
  line frequencies sorted, their amplitudes, the Gamma ratios; the engines by
  brightness, as the estimators' target orders them, :func:`engines_in_order`), among new drones
  drawn from the population (:meth:`..population.result.PopulationResult.draw_drones`).

The class mean: with the amortized drones, drawn from the calibration prior the
estimator was trained on (the box of :class:`..space.priors.Priors`, through
:class:`..amortized.target.DroneSpace`), redrawn until every drone lies inside it
(the estimator refuses data from outside; the truths are then the prior truncated to
drones it can calibrate). A drone's posterior is that prior times its likelihood, so
the truths must come from it: with a mean fixed at the reference, coordinates no
drone identifies would rank the reference among prior-wide draws (a central rank
every time: measured, outer share 0.00 over 4 populations). With the closed form,
the class mean is the reference in every replicate (its drones' posteriors are
summarised only where identified, where the mean's flat prior gives exact coverage).
"""
from __future__ import annotations

import time

import numpy as np

from ...generator import N_PARAMS, ClassParams, load_reference
from ...radar.seeds import seed_sequence
from ..amortized.target import brightness_order
from ..population.model import SPREADS, Hyperprior
from ..settings import CalibrationSettings
from .sbc import run_replicates, sbc_quantities, summarise

METHODS = ("amortized", "likelihood")
"""How each drone is calibrated: the shipped estimator, or the closed-form route."""


def engines_in_order(x: np.ndarray) -> np.ndarray:
    """Class vectors (n, 13E) with each vector's engines ordered by brightness (Gamma,
    decreasing; ties in their given order), the order of the estimators' label-free
    target (:class:`..amortized.target.LabelFree`): which engine a simulator or a
    population calls 0 is a label, and the ranks of a per-engine quantity compare like
    with like only in a label-free order (any fixed function of the parameters is a
    valid SBC quantity; this one ranks first what the profiles identify best)."""
    x = np.atleast_2d(np.asarray(x, float))
    n, e = len(x), x.shape[1] // N_PARAMS
    xe = x.reshape(n, e, N_PARAMS)
    order = brightness_order(xe)
    return np.take_along_axis(xe, order[:, :, None], axis=1).reshape(n, -1)


def _mean_inside_prior(ref: ClassParams, n: int, scene, truth_ss, data_ss, attempts: int = 1000):
    """A class mean drawn from the calibration prior (:class:`..amortized.target.DroneSpace`)
    and the campaign seed whose ``n`` drones all lie inside the prior's support (the
    truths the estimator was trained on): redrawn until they do, checked on the drones
    :func:`~mdaug.generator.chain.simulate_campaign` will draw from that seed (its first
    spawned stream), before any chain runs."""
    from ...generator.chain.scene import draw_specimens
    from ..amortized.target import DroneSpace
    from ..space.priors import Priors

    space = DroneSpace(ref.n_engines, Priors.from_reference(ref))
    mean_rng = np.random.default_rng(truth_ss.spawn(1)[0])
    for attempt in range(attempts):
        mean = ClassParams.from_array(space.vectors(space.sample_prior(1, mean_rng))[0], name=ref.name)
        data_seed = int(data_ss.generate_state(attempt + 1)[attempt])
        drones = draw_specimens(mean.to_array(), n, scene, np.random.default_rng(seed_sequence(data_seed).spawn(3)[0]))
        if np.all(np.isfinite(space.log_prior(space.from_vectors(drones)))):
            break
    return mean, data_seed


def population_replicate(ref: ClassParams, i: int, ss: np.random.SeedSequence, n_drones: int,
                         n_acquisitions: int, ramps: int, settings: CalibrationSettings, hyperprior: Hyperprior,
                         n_rank: int, method: str = "amortized") -> dict:
    """One population SBC replicate (module doc): ranks of the spreads and of the unseen drone's lines."""
    from ...generator.chain import SceneConfig, simulate_campaign
    from ...generator.specimens import SpecimenSpread
    from ..calibrate import calibrate
    from ..population.result import calibrate_population

    truth_ss, data_ss, run_ss, pop_ss, draw_ss = ss.spawn(5)
    spreads = hyperprior.sample(1, np.random.default_rng(truth_ss))[0]
    scene = SceneConfig(specimens=SpecimenSpread(**dict(zip(SPREADS, spreads.tolist())))).with_acquisition(ramps=ramps)
    t0 = time.perf_counter()
    if method == "amortized":  # the class mean from the calibration prior the drones' posteriors were trained on
        mean, data_seed = _mean_inside_prior(ref, n_drones + 1, scene, truth_ss, data_ss)
    else:
        mean, data_seed = ref, int(data_ss.generate_state(1)[0])
    camp = simulate_campaign(mean, n_drones + 1, (n_drones + 1) * n_acquisitions, data_seed, scene=scene)
    if method == "amortized":  # the shipped estimator's posterior per drone (milliseconds; no smc route)
        from ..amortized.calibrate import calibrate_amortized
        from ..amortized.estimator import EstimatorError

        try:
            results = [calibrate_amortized(camp.profiles[camp.specimen == d], ref, acquisition=camp.acquisition,
                                           random_state=seed_sequence(run_ss, d), route="amortized", n_draws=2000,
                                           source=f"drone {d}", predictive=0) for d in range(n_drones)]
        except EstimatorError as exc:  # the calibration refuses this drone, as it refuses a user's: counted
            return {"i": i, "refused": str(exc), "seconds": time.perf_counter() - t0}
    else:
        results = [calibrate(camp.profiles[camp.specimen == d], ref, acquisition=camp.acquisition,
                             settings=settings, random_state=seed_sequence(run_ss, d), predictive=0)
                   for d in range(n_drones)]
    pop = calibrate_population(results, random_state=pop_ss)
    hyper = pop.spreads()
    pick = np.linspace(0, len(hyper) - 1, n_rank).round().astype(int)
    new_true, line_names = sbc_quantities(engines_in_order(camp.specimen_params[n_drones]))
    new_draws, _ = sbc_quantities(engines_in_order(pop.draw_drones(n_rank, np.random.default_rng(draw_ss))))
    ranks = np.concatenate([np.sum(hyper[pick] < spreads, axis=0), np.sum(new_draws < new_true, axis=0)])
    return {"i": i, "ranks": ranks.tolist(), "names": [f"spread:{n}" for n in SPREADS] + [f"new:{n}" for n in line_names],
            "converged": bool(pop.converged and all(r.converged for r in results)),
            "drones_converged": [bool(r.converged) for r in results], "seconds": time.perf_counter() - t0,
            "spreads_true": spreads.tolist()}


def run_population_sbc(reference: ClassParams | str = "HELI", n_replicates: int = 50, *, n_drones: int = 3,
                       n_acquisitions: int = 5, ramps: int = 32, settings: CalibrationSettings | None = None,
                       hyperprior: Hyperprior | None = None, seed=0, n_rank: int = 99, n_bins: int = 5,
                       checkpoint=None, workers: int = 1, progress=None, method: str = "amortized") -> dict:
    """Population SBC (module doc): :func:`.sbc.summarise` of the ranks, separately for
    the spreads (``spreads``) and the unseen drone's lines (``new_drone``), plus all
    (``all``), and ``refused``: the populations with a drone the calibration refused (its
    posterior nearly all outside the prior), counted and left out of the ranks (a
    calibration that refuses is a failure the SBC reports, not a rank). Resumable
    (``checkpoint``, JSON lines) and spread over ``workers``."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = settings or CalibrationSettings(sampler="laplace")
    hyperprior = hyperprior or Hyperprior.stated()
    key = ["population", ref.name, n_replicates, n_drones, n_acquisitions, ramps, settings.to_dict(),
           hyperprior.scales, str(seed), n_rank] + ([] if method == "likelihood" else [method, "engines by brightness"])
    recs = run_replicates(population_replicate, (ref,),
                          (n_drones, n_acquisitions, ramps, settings, hyperprior, n_rank, method), key, n_replicates, seed,
                          checkpoint=checkpoint, workers=workers, progress=progress)
    refused = [r for r in recs if "refused" in r]
    recs = [r for r in recs if "refused" not in r]
    if not recs:
        raise ValueError(f"population SBC: every one of {len(refused)} populations had a drone the calibration "
                         f"refused (first: {refused[0]['refused']})")
    out = {"all": summarise(recs, n_rank, n_bins)}
    for part, prefix in (("spreads", "spread:"), ("new_drone", "new:")):
        cols = [j for j, n in enumerate(recs[0]["names"]) if n.startswith(prefix)]
        sub = [{**r, "ranks": [r["ranks"][j] for j in cols], "names": [r["names"][j] for j in cols]} for r in recs]
        out[part] = summarise(sub, n_rank, n_bins)
    out["settings"] = settings.to_dict()
    out["refused"] = {"count": len(refused), "of": len(refused) + len(recs),
                      "first": refused[0]["refused"] if refused else ""}
    return out
