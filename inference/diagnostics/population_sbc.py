"""Simulation-based calibration of the population (Talts et al. 2018, one level up).

Each replicate: spreads drawn from the hyperprior; ``n_drones + 1`` drones of the
class drawn around its reference by the scene simulator's specimen model with those
spreads, ``n_acquisitions`` acquisitions of each through the scene simulator and
the radar chain (:func:`~mdaug.generator.chain.simulate_campaign`); the first
``n_drones`` calibrated one by one, then their population
(:func:`..population.result.calibrate_population`); the last drone is the one not
seen. Ranks among ``n_rank`` draws of:

* each spread, among the hyper-posterior's draws;
* the unseen drone's label-free lines (:func:`.sbc.sbc_quantities`: each engine's
  line frequencies sorted, their amplitudes, the Gamma ratios), among new drones
  drawn from the population (:meth:`..population.result.PopulationResult.draw_drones`).

The class mean is the reference in every replicate. That is a valid SBC of both
because the class mean has a flat prior: the spreads' marginal likelihood does not
depend on where the drones sit, and the mean's Gaussian posterior under a flat
prior has exact frequentist coverage.
"""
from __future__ import annotations

import time

import numpy as np

from ...generator import ClassParams, load_reference
from ...radar.seeds import seed_sequence
from ..population.model import SPREADS, Hyperprior
from .sbc import run_replicates, sbc_quantities, summarise
from ..settings import CalibrationSettings


def population_replicate(ref: ClassParams, i: int, ss: np.random.SeedSequence, n_drones: int,
                         n_acquisitions: int, ramps: int, settings: CalibrationSettings, hyperprior: Hyperprior,
                         n_rank: int) -> dict:
    """One population SBC replicate (module doc): ranks of the spreads and of the unseen drone's lines."""
    from ...generator.chain import SceneConfig, simulate_campaign
    from ...generator.specimens import SpecimenSpread
    from ..calibrate import calibrate
    from ..population.result import calibrate_population

    truth_ss, data_ss, run_ss, pop_ss, draw_ss = ss.spawn(5)
    spreads = hyperprior.sample(1, np.random.default_rng(truth_ss))[0]
    scene = SceneConfig(n_ramps=ramps, specimens=SpecimenSpread(**dict(zip(SPREADS, spreads.tolist()))))
    t0 = time.perf_counter()
    camp = simulate_campaign(ref, n_drones + 1, (n_drones + 1) * n_acquisitions, int(data_ss.generate_state(1)[0]),
                             scene=scene)
    results = [calibrate(camp.profiles[camp.specimen == d], ref, acquisition=camp.acquisition, settings=settings,
                         random_state=seed_sequence(run_ss, d)) for d in range(n_drones)]
    pop = calibrate_population(results, random_state=pop_ss)
    hyper = pop.spreads()
    pick = np.linspace(0, len(hyper) - 1, n_rank).round().astype(int)
    new_true, line_names = sbc_quantities(camp.specimen_params[n_drones])
    new_draws, _ = sbc_quantities(pop.draw_drones(n_rank, np.random.default_rng(draw_ss)))
    ranks = np.concatenate([np.sum(hyper[pick] < spreads, axis=0), np.sum(new_draws < new_true, axis=0)])
    return {"i": i, "ranks": ranks.tolist(), "names": [f"spread:{n}" for n in SPREADS] + [f"new:{n}" for n in line_names],
            "converged": bool(pop.converged and all(r.converged for r in results)),
            "drones_converged": [bool(r.converged) for r in results], "seconds": time.perf_counter() - t0,
            "spreads_true": spreads.tolist()}


def run_population_sbc(reference: ClassParams | str = "HELI", n_replicates: int = 50, *, n_drones: int = 3,
                       n_acquisitions: int = 5, ramps: int = 32, settings: CalibrationSettings | None = None,
                       hyperprior: Hyperprior | None = None, seed=0, n_rank: int = 99, n_bins: int = 5,
                       checkpoint=None, workers: int = 1, progress=None) -> dict:
    """Population SBC (module doc): :func:`.sbc.summarise` of the ranks, separately for
    the spreads (``spreads``) and the unseen drone's lines (``new_drone``), plus all
    (``all``). Resumable (``checkpoint``, JSON lines) and spread over ``workers``."""
    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = settings or CalibrationSettings(sampler="laplace")
    hyperprior = hyperprior or Hyperprior.stated()
    key = ["population", ref.name, n_replicates, n_drones, n_acquisitions, ramps, settings.to_dict(),
           hyperprior.scales, str(seed), n_rank]
    recs = run_replicates(population_replicate, (ref,),
                          (n_drones, n_acquisitions, ramps, settings, hyperprior, n_rank), key, n_replicates, seed,
                          checkpoint=checkpoint, workers=workers, progress=progress)
    out = {"all": summarise(recs, n_rank, n_bins)}
    for part, prefix in (("spreads", "spread:"), ("new_drone", "new:")):
        cols = [j for j, n in enumerate(recs[0]["names"]) if n.startswith(prefix)]
        sub = [{**r, "ranks": [r["ranks"][j] for j in cols], "names": [r["names"][j] for j in cols]} for r in recs]
        out[part] = summarise(sub, n_rank, n_bins)
    out["settings"] = settings.to_dict()
    return out
