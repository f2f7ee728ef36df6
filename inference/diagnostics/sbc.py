"""Simulation-based calibration (Talts et al. 2018) of the supported case: a handful
of measurements of one drone, simulated by the scene simulator, not by the
likelihood's own model.

Each replicate: a truth drawn from the calibration's prior (the drone's physics);
``n_measurements`` acquisitions of it rendered through the scene simulator and the
radar chain (:func:`mdaug.generator.chain.render_through_chain`: random phases
per frame, K ramps, yaw, body return, range, azimuth, hover drift, clutter, noise,
ADC, MTI); a full calibration (fit + sampler) under the matching
:class:`~mdaug.generator.acquisition.Acquisition`; the rank of the truth among
``n_rank`` posterior draws for every test quantity:

* the label-free line frequencies: each engine's four vibration lines sorted by
  frequency (which line is the roll and which a mixing term only the prior tells:
  :mod:`..space.priors`);
* the other physics: the amplitudes of those lines (same order) and, with several
  engines, the Gamma ratios.

When the pipeline samples the true posterior the ranks are uniform on 0..n_rank:
a chi-square test per quantity over ``n_bins`` rank bins (p-values), the pooled
chi-square over all quantities, and the share of truths in the outer 10% of their
posterior (5% each side; 0.10 for an honest sampler, more when posteriors are too
narrow, less when too wide).
"""
from __future__ import annotations

import numpy as np

from ...generator import N_PARAMS, ClassParams, load_reference
from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from ...radar.seeds import rng as seeded_rng
from ...radar.seeds import seed_sequence
from ..space.layout import Layout
from ..space.priors import Priors, engine_lines
from ..settings import CalibrationSettings


def sbc_quantities(x: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Label-free test quantities (n, q) of vectors x (n, 13E) and their names: per
    engine the four line frequencies sorted (rad/s), their amplitudes (m) in the same
    order, and for k >= 1 ln(Gamma_k / Gamma_0)."""
    x = np.atleast_2d(x)
    n, e = len(x), x.shape[1] // N_PARAMS
    xe = x.reshape(n, e, N_PARAMS)
    w, a, _ = engine_lines(xe)
    order = np.argsort(w, axis=-1)
    w, a = np.take_along_axis(w, order, -1), np.take_along_axis(a, order, -1)
    cols, names = [], []
    for k in range(e):
        cols += [w[:, k], a[:, k]]
        names += [f"line {j + 1} w[{k}]" for j in range(4)] + [f"line {j + 1} A[{k}]" for j in range(4)]
        if k:
            cols.append(np.log(xe[:, k, 0] / xe[:, 0, 0])[:, None])
            names.append(f"lnG[{k}]")
    return np.concatenate(cols, axis=1), names


def simulate_measurements(truth: np.ndarray, n_measurements: int, acquisition: Acquisition, seed,
                          scene=None, radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """n_measurements profiles (n, L) of one drone (13E,) through the scene simulator and
    the chain, the scene (default :class:`~mdaug.generator.chain.SceneConfig`) taking
    its ramps, phases, yaw and body return from the acquisition."""
    from ...generator.augment import Renderer

    renderer = Renderer(acquisition, normalisation="none", radar=radar, through_chain=True, scene=scene)
    return renderer.render(np.repeat(np.asarray(truth, float)[None], n_measurements, axis=0),
                           seeded_rng(seed))


def sbc_replicate(ref: ClassParams, i: int, ss: np.random.SeedSequence, ramps: int, n_measurements: int,
                  settings: CalibrationSettings, n_rank: int, scene=None,
                  radar: RadarConfig = RadarConfig()) -> dict:
    """One SBC replicate (a truth from the prior, its measurements, a calibration): the
    ranks of the truth's test quantities among n_rank posterior draws."""
    import time

    from ..calibrate import calibrate

    acq = Acquisition.measured(ramps)
    layout = Layout(ref.n_engines, n_measurements, Priors.from_reference(ref, radar), marginal=True)
    truth_ss, data_ss, run_ss = ss.spawn(3)
    z, _ = layout.split_theta(layout.sample_prior(1, seeded_rng(truth_ss)))
    truth = layout.shared_physics(z)[0]
    data = simulate_measurements(truth, n_measurements, acq, data_ss, scene, radar)
    t0 = time.perf_counter()
    res = calibrate(data, ref, acquisition=acq, settings=settings, random_state=run_ss, radar=radar, predictive=0)
    draws = res.draws()
    pick = np.linspace(0, len(draws) - 1, n_rank).round().astype(int)
    q_true, names = sbc_quantities(truth)
    q_draw, _ = sbc_quantities(draws[pick])
    return {"i": i, "ranks": np.sum(q_draw < q_true, axis=0).tolist(), "names": names,
            "converged": bool(res.converged), "seconds": time.perf_counter() - t0}


def run_sbc(reference: ClassParams | str = "HELI", n_replicates: int = 100, *, ramps: int = 32,
            n_measurements: int = 5, settings: CalibrationSettings | None = None, seed=0, n_rank: int = 99,
            n_bins: int = 5, scene=None, radar: RadarConfig = RadarConfig(), progress=None,
            checkpoint=None, workers: int = 1) -> dict:
    """Run SBC (module doc). Returns ranks (R, q), names, per-quantity chi-square
    p-values and outer-10% shares, the pooled p-value and outer share, the share of
    converged runs, seconds per calibration and the settings.

    checkpoint: a JSON-lines file; every finished replicate is appended to it, and a
    rerun with the same arguments skips the replicates it holds (resume). workers:
    replicates run in that many processes (each replicate has its own seed, so the
    result does not depend on the count)."""
    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = settings or CalibrationSettings()
    key = [ref.name, n_replicates, ramps, n_measurements, settings.to_dict(), str(seed), n_rank]
    recs = run_replicates(sbc_replicate, (ref,), (ramps, n_measurements, settings, n_rank, scene, radar), key,
                          n_replicates, seed, checkpoint=checkpoint, workers=workers, progress=progress)
    out = summarise(recs, n_rank, n_bins)
    out.update(settings=settings.to_dict(), ramps=ramps, n_measurements=n_measurements)
    return out


def run_replicates(replicate, head: tuple, tail: tuple, key, n_replicates: int, seed, *, checkpoint=None,
                   workers: int = 1, progress=None) -> list[dict]:
    """Records ``replicate(*head, i, seed_sequence_i, *tail)`` for i < n_replicates, in
    order. checkpoint: a JSON-lines file every finished record is appended to; a rerun
    with the same ``key`` (JSON-able: everything the records depend on) skips the ones
    it holds (resume). workers: that many processes (each replicate has its own seed
    from ``seed``, so the records do not depend on the count)."""
    import json
    from concurrent.futures import ProcessPoolExecutor
    from pathlib import Path

    key = json.dumps(key, default=str)
    done: dict[int, dict] = {}
    path = None if checkpoint is None else Path(checkpoint)
    if path is not None and path.is_file():
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            if rec.get("key") == key:
                done[int(rec["i"])] = rec
    todo = [(i, ss) for i, ss in enumerate(seed_sequence(seed).spawn(n_replicates)) if i not in done]

    def record(rec):
        done[rec["i"]] = rec
        if path is not None:
            with path.open("a") as fh:
                fh.write(json.dumps({**rec, "key": key}) + "\n")
        if progress:
            progress(len(done), n_replicates)

    if workers > 1 and len(todo) > 1:
        n = len(todo)
        with ProcessPoolExecutor(workers) as pool:
            for rec in pool.map(replicate, *[[h] * n for h in head], *zip(*todo), *[[a] * n for a in tail]):
                record(rec)
    else:
        for i, ss in todo:
            record(replicate(*head, i, ss, *tail))
    return [done[i] for i in sorted(done)]


def summarise(recs: list[dict], n_rank: int, n_bins: int = 5) -> dict:
    """Rank statistics of finished replicates (:func:`sbc_replicate` records, e.g. read
    back from a checkpoint): per-quantity chi-square p-values and outer-10% shares, the
    pooled p-value and outer share, converged share, seconds."""
    from scipy import stats

    n_replicates = len(recs)
    names = recs[0]["names"]
    ranks = np.array([r["ranks"] for r in recs])
    converged = [r["converged"] for r in recs]
    seconds = [r["seconds"] for r in recs]
    edges = np.linspace(0, n_rank + 1, n_bins + 1)
    counts = np.stack([np.histogram(ranks[:, j], bins=edges)[0] for j in range(ranks.shape[1])])
    expected = n_replicates / n_bins
    chi2 = ((counts - expected) ** 2 / expected).sum(axis=1)
    pvals = stats.chi2.sf(chi2, n_bins - 1)
    pooled = stats.chi2.sf(chi2.sum(), (n_bins - 1) * len(chi2))
    tail = int(round(0.05 * (n_rank + 1)))
    outer = (ranks < tail) | (ranks > n_rank - tail)
    return {"ranks": ranks, "names": names, "p_values": dict(zip(names, map(float, pvals))),
            "pooled_p": float(pooled), "min_p": float(pvals.min()), "outer_share": float(outer.mean()),
            "outer_share_by_quantity": dict(zip(names, map(float, outer.mean(axis=0)))), "n_rank": n_rank,
            "converged_share": float(np.mean(converged)), "seconds": seconds, "n_replicates": n_replicates}
