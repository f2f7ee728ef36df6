"""Simulation-based calibration of any posterior route on fresh simulated drones.

``draw(profiles, n, seed) -> q draws (n, d)`` is the route under test (the amortized
posterior, or tempered SMC to the learned likelihood's posterior). For each truth: the rank of
its label-free quantities among n_rank draws (:func:`.sbc.summarise`
turns ranks into the rank chi-square p-values and the outer-10% share, 0.10 when
honest), the coverage of central intervals at several levels (the coverage curve),
the median 90% width over the truth beside the prior's, and TARP (Lemos et al. 2023,
sbi's implementation: expected coverage of random reference balls; ATC near 0 and a
large KS p-value when honest), and the log score of the truth (:mod:`.yardsticks`): exact
where the route is a density (``draw.log_density(u_true, profiles, seed)``, its log density
at the truth in the unbounded coordinates u, normalised on the prior's support), else a
Gaussian fitted to its draws; the Gaussian's score is kept beside it for every route.
"""
from __future__ import annotations

import time

import numpy as np

from ..result.status import exact_fail_chance, noise_note
from .sbc import summarise
from .yardsticks import honest, log_score, verdict

LEVELS = (0.5, 0.6, 0.7, 0.8, 0.9, 0.95)


def _timed(draw, y, n, seed, truth_u=None):
    t0 = time.perf_counter()
    dq, converged = draw(y, n, seed)
    seconds = time.perf_counter() - t0
    density = getattr(draw, "log_density", None)
    ld = float(density(truth_u, y, seed)) if density is not None and truth_u is not None else None
    return dq, bool(converged), seconds, ld


def run(draw, truths_q: np.ndarray, data, names: list[str], *, n_rank: int = 199, prior_q: np.ndarray | None = None,
        seed: int = 0, to_unbounded=None, progress=None, desc: str = "SBC", workers: int = 1,
        keep_draws: bool = False) -> dict:
    """SBC of ``draw`` (module doc) over truths_q (R, d) and their data (R profile
    sets). prior_q: prior draws (n, d) for the prior's widths; to_unbounded: map of q
    for TARP (z-scored there); workers: processes (``draw`` must then pickle, e.g.
    :class:`mdaug.inference.estimator_job.Route`). Returns the summary (plain floats
    and lists); drone i's draws depend only on ``seed + i``, whatever the workers.
    keep_draws: also ``draws`` (n_rank, R, d) and ``truths`` (R, d), arrays for a row
    derived from this one (a stacked route's widths); whoever asks for them drops them
    before the row is stored."""
    from ...radar.progress import progress_bar

    recs, samples = [], []
    bar = progress_bar(total=len(truths_q), desc=desc, unit="drone", progress=progress)
    tu = np.asarray(truths_q, float) if to_unbounded is None else to_unbounded(truths_q)
    jobs = [(draw, y, n_rank, seed + i, tu[i]) for i, y in enumerate(data)]
    if workers > 1 and len(jobs) > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(min(workers, len(jobs))) as pool:
            done = pool.map(_timed, *zip(*jobs))
            results = []
            for r in done:
                results.append(r)
                bar.update(1)
    else:
        results = []
        for job in jobs:
            results.append(_timed(*job))
            bar.update(1)
    for i, (q, (dq, converged, seconds, _)) in enumerate(zip(truths_q, results)):
        recs.append({"i": i, "ranks": np.sum(dq < q, axis=0).tolist(), "names": names,
                     "converged": converged, "seconds": seconds})
        samples.append(dq)
    bar.close()
    out = summarise(recs, n_rank)
    s = np.stack(samples, axis=1)  # (n_rank, R, d)
    out.update(coverage(s, truths_q, names))
    out["width_over_truth"] = widths_over_truth(s, truths_q, names)
    if prior_q is not None:
        lo, hi = np.quantile(prior_q, [0.05, 0.95], axis=0)
        out["prior_width_over_truth"] = dict(zip(names, map(float, np.median((hi - lo) / np.abs(truths_q), axis=0))))
    su = s if to_unbounded is None else np.stack([to_unbounded(d) for d in s])
    out.update(tarp(su, tu))
    densities = [r[3] for r in results]
    out.update(log_score(su, tu, None if None in densities else np.array(densities)))
    out["ranks"] = out["ranks"].tolist()
    out["exact_fail_chance"] = exact_fail_chance(len(truths_q), len(names))
    if keep_draws:
        out["draws"], out["truths"] = s, np.asarray(truths_q, float)
    return out


def coverage(samples: np.ndarray, truths: np.ndarray, names: list[str]) -> dict:
    """Share of truths inside the central interval at each of ``LEVELS``, pooled and
    per quantity (samples (S, R, d), truths (R, d))."""
    pooled, per = {}, {n: {} for n in names}
    for a in LEVELS:
        lo, hi = np.quantile(samples, [(1 - a) / 2, (1 + a) / 2], axis=0)
        inside = (truths >= lo) & (truths <= hi)
        pooled[f"{a:.2f}"] = float(inside.mean())
        for j, n in enumerate(names):
            per[n][f"{a:.2f}"] = float(inside[:, j].mean())
    return {"coverage": pooled, "coverage_by_quantity": per,
            "coverage90_range": [min(v["0.90"] for v in per.values()), max(v["0.90"] for v in per.values())]}


def widths_over_truth(samples: np.ndarray, truths: np.ndarray, names: list[str]) -> dict:
    """Per quantity, the median over drones of the 90% interval's width over |truth|
    (samples (S, R, d), truths (R, d))."""
    lo, hi = np.quantile(samples, [0.05, 0.95], axis=0)
    return dict(zip(names, map(float, np.median((hi - lo) / np.abs(truths), axis=0))))


def tarp(samples: np.ndarray, truths: np.ndarray, seed: int = 0) -> dict:
    """TARP's area-to-curve and KS p-value (sbi) of samples (S, R, d) against truths (R, d)
    (NaN under 20 truths)."""
    import torch
    from sbi.diagnostics.tarp import _run_tarp, check_tarp, get_tarp_references

    torch.manual_seed(seed)
    t = torch.as_tensor(truths, dtype=torch.float32)
    if len(t) < 20:
        return {"tarp_atc": float("nan"), "tarp_ks_p": float("nan")}
    ecp, alpha = _run_tarp(torch.as_tensor(samples, dtype=torch.float32), t, get_tarp_references(t),
                           num_bins=max(2, len(t) // 10), z_score_theta=True)
    atc, ks = check_tarp(ecp, alpha)
    return {"tarp_atc": float(atc), "tarp_ks_p": float(ks)}


def headline(summary: dict) -> str:
    """One line: outer share, 90% coverage range, pooled p, TARP."""
    lo, hi = summary["coverage90_range"]
    return (f"outer-10% share {summary['outer_share']:.3f} (honest 0.10), 90% coverage {lo:.2f}-{hi:.2f}, "
            f"rank chi-square pooled p {summary['pooled_p']:.3g}, "
            + (f"TARP ATC {summary['tarp_atc']:.3f} (KS p {summary['tarp_ks_p']:.2f}), "
               if np.isfinite(summary.get("tarp_atc", np.nan)) else "")
            + (f"log score {summary['log_score']:.2f}{score_by(summary)}, " if "log_score" in summary else "")
            + f"{summary['n_replicates']} truths" + noise_note(summary["n_replicates"], len(summary.get("names") or [])))


def least_covered(summary: dict, k: int = 4) -> list[list]:
    """The k quantities of lowest 90% coverage, [[name, coverage], ...] lowest first ([] where
    the summary kept no per-quantity coverage): which quantities a failed coverage rule names."""
    by_quantity = summary.get("coverage_by_quantity") or {}
    cov90 = sorted((float(c["0.90"]), q) for q, c in by_quantity.items())
    return [[q, c] for c, q in cov90[:k]]


def score_by(row: dict) -> str:
    """' (exact)' or ' (Gaussian fit)': how a row's log score was taken (rows written
    before the exact score have no ``log_score_by``: theirs is the Gaussian's)."""
    return " (exact)" if row.get("log_score_by") == "exact" else " (Gaussian fit)"


def route_table(routes: dict, truths_q: np.ndarray, data, names: list[str], *, to_unbounded, n_rank: int = 199,
                seed: int = 0, progress=None, workers: int = 1, keep_draws: bool = False) -> dict:
    """Every route (name -> draw(profiles, n, seed) -> (q draws (n, d), converged)) on
    the same drones; returns {"rows": {name: summary}, "default": name or None}: the
    best (lowest) log score among the routes that pass the gate (None when none does;
    :func:`default_route`). keep_draws: as :func:`run`'s, for every row."""
    rows = {}
    for name, draw in routes.items():
        rows[name] = run(draw, truths_q, data, names, n_rank=n_rank, seed=seed, to_unbounded=to_unbounded,
                         progress=progress, desc=f"SBC {name}", workers=workers, keep_draws=keep_draws)
        rows[name]["verdict"] = verdict(rows[name])
    return {"rows": rows, "default": default_route(rows)}


def passing_routes(rows: dict) -> list[str]:
    """The routes of a route table's SBC rows that pass the gate (:func:`honest`)."""
    return [n for n, r in rows.items() if honest(r)]


def default_route(rows: dict, specimen_rows: dict | None = None) -> str | None:
    """The route a file runs by default: among the routes that pass the gate on fresh
    prior drones (``rows``, the route table's SBC rows), the best (lowest) log score of the
    truth on drones like a user's where ``specimen_rows`` (the same routes on drones of
    the specimen model around the class reference) are given, else on the SBC drones;
    None when no route passes."""
    passing = passing_routes(rows)
    judge = rows if specimen_rows is None else specimen_rows
    passing = [n for n in passing if n in judge]
    return min(passing, key=lambda n: judge[n]["log_score"]) if passing else None
