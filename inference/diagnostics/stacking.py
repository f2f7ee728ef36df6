"""Stacking two posterior routes: the mixture w p_smc + (1 - w) q_amortized.

Where one route is sharp but a little overconfident (QUAD's smc route on the summary
likelihood: the truth's log score 2 nats better than the amortized posterior's, one
quantity's 90% coverage 0.83) and the other honest but wide (the amortized posterior),
the mixture keeps most of the first one's sharpness and takes its misses from the
second. The weight is chosen as stacking chooses it (Yao, Vehtari, Simpson & Gelman
2018, "Using stacking to average Bayesian predictive distributions"): the one that
maximises the mean log density of the truth over held-out simulated drones, the same
log score the route table ranks routes by, so the weight sees no coverage figure and
no drone the gate then judges it on.

The mixture's SBC needs no run of its own: on the drones where both routes ran, with
the same draws, the mixture's cumulative distribution at the truth is w F_a + (1 - w)
F_b, each F from the route's rank of the truth among its n draws ((rank + 1/2) / (n + 1),
uniform on the n + 1 steps for an exact posterior, so an exact mixture's 90% coverage
is 0.90 here, where the 5-95% interval of 199 draws gives 0.891), and its density at
the truth is w p_a + (1 - w) p_b (:func:`stacked_row`).
"""
from __future__ import annotations

import numpy as np

from ..amortized.stacked import mixture_log_density
from .routes import LEVELS

CDF_DRAWS = 10 ** 6
"""The draws a stacked row's intervals stand for (``n_draws`` of
:func:`mdaug.inference.result.status.exact_fail_chance`): they come from the mixture's CDF,
not from 199 draws, so an exact posterior's 90% coverage is 0.90 (module doc)."""


def stacking_weight(log_p_a: np.ndarray, log_p_b: np.ndarray) -> float:
    """The weight w in [0, 1] of route a that maximises mean log(w p_a + (1 - w) p_b) of the
    truth over drones (log_p_a, log_p_b (R,): each route's log density at each drone's
    truth). The objective is concave in w: a bounded scalar search finds its maximum."""
    from scipy.optimize import minimize_scalar

    a, b = np.asarray(log_p_a, float), np.asarray(log_p_b, float)
    if a.shape != b.shape or a.ndim != 1 or len(a) < 2:
        raise ValueError(f"need two equal-length 1-D arrays of >= 2 log densities, got shapes {a.shape} and {b.shape}")
    if not (np.all(np.isfinite(a) | (a == -np.inf)) and np.all(np.isfinite(b) | (b == -np.inf))):
        raise ValueError("log densities must be finite or -inf")
    top = np.maximum(a, b)
    if not np.all(np.isfinite(top)):
        raise ValueError("both routes give density 0 at some truth: no weight mixes them")

    def loss(w):
        with np.errstate(divide="ignore"):
            return -np.mean(mixture_log_density(a, b, w))

    ends = {0.0: loss(0.0), 1.0: loss(1.0)}
    res = minimize_scalar(loss, bounds=(0.0, 1.0), method="bounded", options={"xatol": 1e-4})
    best = min([(res.fun, float(res.x))] + [(v, k) for k, v in ends.items()])
    return float(best[1])


def stacked_row(row_a: dict, row_b: dict, weight: float, sources: tuple[str, str] = ("smc", "amortized"),
                to_unbounded=None) -> dict:
    """The SBC summary of the mixture w a + (1 - w) b from the rows of routes a and b on
    the same drones (:func:`mdaug.inference.diagnostics.routes.run` summaries, with their
    ``ranks`` and ``log_score_by_drone``; module doc): outer-10% share, coverage at
    :data:`LEVELS` pooled and per quantity, the log score of the truth (exact: both rows'
    must be), convergence (route a's: b is the amortized route's exact draws), seconds
    per drone (both routes'). The widths need the draws: where both rows kept theirs
    (``draws`` and ``truths`` of :func:`~mdaug.inference.diagnostics.routes.run` with
    ``keep_draws``), the mixture's draws of each drone are the first round(w n) of a's and
    the first n - round(w n) of b's (each route's draws exchangeable), and the row has
    ``width_over_truth`` and TARP (on those draws, mapped by ``to_unbounded`` as
    :func:`~mdaug.inference.diagnostics.routes.run` maps them); else it has neither.
    sources: the two routes' names, kept in the row (``derived_from``)."""
    from scipy import stats

    from ..result.status import exact_fail_chance

    if not 0.0 < weight < 1.0:
        raise ValueError(f"weight must be in (0, 1), got {weight!r}")
    ra, rb = np.asarray(row_a["ranks"], float), np.asarray(row_b["ranks"], float)
    if ra.shape != rb.shape or row_a["n_rank"] != row_b["n_rank"] or list(row_a["names"]) != list(row_b["names"]):
        raise ValueError("the two rows must hold the same drones, quantities and number of draws")
    if row_a.get("log_score_by") != "exact" or row_b.get("log_score_by") != "exact":
        raise ValueError("stacking needs both routes' own densities at the truth (log_score_by 'exact')")
    n, names = row_a["n_rank"], list(row_a["names"])
    f = weight * (ra + 0.5) / (n + 1) + (1 - weight) * (rb + 0.5) / (n + 1)  # (R, d)
    per = {q: {} for q in names}
    pooled = {}
    for level in LEVELS:
        inside = (f > (1 - level) / 2) & (f < (1 + level) / 2)
        pooled[f"{level:.2f}"] = float(inside.mean())
        for j, q in enumerate(names):
            per[q][f"{level:.2f}"] = float(inside[:, j].mean())
    outer = (f < 0.05) | (f > 0.95)
    ls = -mixture_log_density(-np.asarray(row_a["log_score_by_drone"]), -np.asarray(row_b["log_score_by_drone"]),
                              weight)
    counts = np.stack([np.histogram(f[:, j], bins=np.linspace(0, 1, 6))[0] for j in range(f.shape[1])])
    chi2 = ((counts - len(f) / 5) ** 2 / (len(f) / 5)).sum(axis=1)  # F's histogram, as the ranks' (sbc.summarise)
    cov90 = [v["0.90"] for v in per.values()]
    seconds = np.asarray(row_a["seconds"], float) + np.asarray(row_b["seconds"], float)
    from_draws = {}  # widths and TARP, where the mixture has draws of its own
    if "draws" in row_a and "draws" in row_b:  # the mixture's own draws, drone by drone
        from .routes import tarp, widths_over_truth

        k = int(round(weight * n))
        mixed = np.concatenate([row_a["draws"][:k], row_b["draws"][:n - k]])
        from_draws["width_over_truth"] = widths_over_truth(mixed, row_a["truths"], names)
        truths = np.asarray(row_a["truths"], float)
        if to_unbounded is not None:
            mixed, truths = np.stack([to_unbounded(d) for d in mixed]), to_unbounded(truths)
        from_draws.update(tarp(mixed, truths))
    return {**from_draws, "names": names, "n_rank": n, "n_replicates": int(len(f)), "weight": float(weight),
            "pooled_p": float(stats.chi2.sf(chi2.sum(), 4 * len(chi2))), "outer_share": float(outer.mean()),
            "outer_share_by_quantity": dict(zip(names, map(float, outer.mean(0)))),
            "coverage": pooled, "coverage_by_quantity": per, "coverage90_range": [min(cov90), max(cov90)],
            "log_score": float(np.mean(ls)), "log_score_median": float(np.median(ls)),
            "log_score_by_drone": ls.tolist(), "log_score_by": "exact",
            "converged_share": float(row_a["converged_share"]), "seconds": seconds.tolist(),
            "exact_fail_chance": exact_fail_chance(len(f), len(names), n_draws=CDF_DRAWS),
            "derived_from": list(sources)}
