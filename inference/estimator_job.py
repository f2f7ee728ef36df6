"""Training an estimator is a job: simulate (resumable shards, workers), train the
posterior and the ratio network (progress bar, early stopping, checkpoints, the
device), end with its own SBC of both routes on fresh drones, save. It uses both
:mod:`.amortized` and :mod:`.diagnostics` (the SBC), so it lives above them.

Everything lives in one work folder (``sims/``, ``posterior.ckpt``, ``ratio.ckpt``);
a rerun with the same arguments resumes where it stopped.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..radar.seeds import child_seed, seed_sequence
from .amortized.estimator import AmortizedEstimator
from .amortized.nets import NetConfig
from .amortized.simulate import SimulationSpec, load_shards, simulate, simulate_shards
from .amortized.target import LabelFree
from .amortized.train import TrainConfig, device_of, fit, posterior_loss, ratio_loss
from .diagnostics.routes import headline
from .diagnostics.routes import run as run_sbc

SBC_MEASUREMENTS = 5


def train_estimator(spec: SimulationSpec, n_simulations: int, work, out, *, seed: int = 0, workers: int = 1,
                    device: str = "auto", net_cfg: NetConfig = NetConfig(), train_cfg: TrainConfig = TrainConfig(),
                    post_budget: float | None = None, ratio_budget: float | None = None,
                    sim_budget: float | None = None,
                    sbc_truths: int = 300, sbc_mcmc_truths: int = 0, mcmc_settings=None, shard_size: int = 500,
                    command: str | None = None, progress=None, log=print) -> AmortizedEstimator:
    """The whole job (module doc); writes the estimator to ``out`` and returns it.
    post_budget, ratio_budget: training seconds of each network (default: the
    train_cfg's time budget); sim_budget: simulation seconds (training then uses the
    drones simulated by then); command: the command line that ran the job (kept in the
    file, so anyone can train it again)."""
    import torch

    t0 = time.perf_counter()
    work = Path(work)
    dev = device_of(device)
    paths = simulate_shards(work / "sims", spec, n_simulations, seed=child_seed(seed, "sims"), workers=workers,
                            shard_size=shard_size, time_budget=sim_budget, progress=progress, log=log)
    t_sim = time.perf_counter() - t0
    vectors, profiles = load_shards(paths)
    ref = spec.reference
    label_free = LabelFree(ref.n_engines, spec.priors(), ref.to_array())
    u = torch.as_tensor(label_free.to_unbounded(label_free.quantities(vectors)), dtype=torch.float32, device=dev)
    x = torch.as_tensor(profiles, device=dev)
    torch.manual_seed(child_seed(seed, "init"))
    est = AmortizedEstimator.build(spec, net_cfg, u, x)
    log(f"{spec.class_name} K={spec.acquisition.ramps}: {len(u)} simulated drones x {spec.n_measurements} "
        f"measurements in {t_sim:.0f} s; training on {dev}")
    logs = {}
    budgets = {"posterior": post_budget, "ratio": ratio_budget}
    for name, net, loss in (("posterior", est.posterior, posterior_loss), ("ratio", est.ratio, ratio_loss)):
        cfg = train_cfg if budgets[name] is None else replace(train_cfg, time_budget=budgets[name])
        tl = fit(net, loss, u, x, cfg, child_seed(seed, name), checkpoint=work / f"{name}.ckpt",
                 progress=progress, desc=f"train {name}", log=log)
        logs[name] = tl.to_dict()
        log(f"  {name}: {tl.epochs} epochs, best validation loss {tl.best_val:.4f} at epoch {tl.best_epoch} "
            f"({tl.stopped}), {tl.seconds:.0f} s")
    del x
    est.meta.update(n_simulations=int(len(u)), seed=int(seed), simulation_seconds=t_sim, command=command,
                    training={"config": train_cfg.to_dict(), "device": str(dev), **logs}, sbc={})
    est.save(out)  # usable now; rewritten with its SBC figures below
    if sbc_truths:
        est.meta["sbc"] = estimator_sbc(est, sbc_truths, seed=child_seed(seed, "sbc"), workers=workers,
                                        mcmc_truths=sbc_mcmc_truths, mcmc_settings=mcmc_settings,
                                        progress=progress, log=log)
    est.meta["job_seconds"] = time.perf_counter() - t0
    est.save(out)
    log(f"estimator written to {out} ({time.perf_counter() - t0:.0f} s in all)")
    return est


def sbc_data(spec: SimulationSpec, n: int, seed, workers: int = 1):
    """Fresh drones for SBC: (vectors (n, 13E), profiles (n, 5, L); fewer measurements
    when the estimator takes fewer)."""
    from concurrent.futures import ProcessPoolExecutor

    spec5 = replace(spec, n_measurements=min(SBC_MEASUREMENTS, spec.n_measurements))
    chunks = np.array_split(np.arange(n), max(1, min(workers, n)))
    seeds = seed_sequence(seed).spawn(len(chunks))
    if workers > 1 and len(chunks) > 1:
        with ProcessPoolExecutor(workers) as pool:
            parts = list(pool.map(simulate, [spec5] * len(chunks), [len(c) for c in chunks], seeds))
    else:
        parts = [simulate(spec5, len(c), s) for c, s in zip(chunks, seeds)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def estimator_sbc(est: AmortizedEstimator, n_truths: int, *, seed: int = 0, workers: int = 1, mcmc_truths: int = 0,
                  mcmc_settings=None, progress=None, log=print) -> dict:
    """SBC of the amortized route on n_truths fresh drones (5 measurements each), and
    of the emcee route on the first ``mcmc_truths`` of them."""
    from .amortized.mcmc import LearnedPosterior, sample

    lf = est.label_free
    vectors, profiles = sbc_data(est.spec, n_truths, seed, workers)
    truths = lf.quantities(vectors)
    space = est.spec.space()
    prior_q = lf.quantities(space.vectors(space.sample_prior(4000, np.random.default_rng(seed_sequence(seed, "prior")))))

    accepted = []

    def amortized(y, n, s):
        u, share = est.sample_u(y, n, s, strict=False)
        accepted.append(share)
        return lf.from_unbounded(u), True

    out = {"n_measurements": int(profiles.shape[1]),
           "amortized": run_sbc(amortized, truths, profiles, lf.names, prior_q=prior_q, seed=seed,
                                to_unbounded=lf.to_unbounded, progress=progress, desc="SBC amortized")}
    out["amortized"]["inside_prior_share"] = float(np.mean(accepted))
    log(f"  SBC amortized: {headline(out['amortized'])}; draws inside the prior {np.mean(accepted):.3f}")
    if mcmc_truths:
        from .settings import CalibrationSettings

        settings = mcmc_settings or CalibrationSettings(progress=False)

        def mcmc(y, n, s):
            u, _ = est.sample_u(y, 1000, s, strict=False)
            post = LearnedPosterior(est, y)
            run, _ = sample(post, u, settings, s)
            draws = run.draws()
            pick = np.linspace(0, len(draws) - 1, n).round().astype(int)
            return lf.from_unbounded(draws[pick]), run.converged

        k = min(mcmc_truths, n_truths)
        out["emcee"] = run_sbc(mcmc, truths[:k], profiles[:k], lf.names, prior_q=prior_q, seed=seed,
                               to_unbounded=lf.to_unbounded, progress=progress, desc="SBC emcee")
        log(f"  SBC emcee: {headline(out['emcee'])}; converged {out['emcee']['converged_share']:.2f}")
    return out
