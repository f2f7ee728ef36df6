"""The amortized posterior's temperature, chosen on fresh drones by the gate and the log score.

A flow trained by maximum likelihood on a finite set of drones comes out a little too
sharp in places (the shipped files' 300-drone SBC: outer-10% share 0.11-0.12, some
quantity's 90% coverage 0.81-0.85 where the gate asks for 0.85). Drawing the flow's base
at a temperature T >= 1 (:attr:`~mdaug.inference.amortized.estimator.AmortizedEstimator.temperature`:
the transform of T x a standard normal) widens every mode in its own shape and keeps an
exact density. :func:`fit_temperature` runs SBC of the amortized route at each T of a
grid on the same fresh drones and keeps, among the temperatures that pass the gate
(:func:`mdaug.inference.result.status.honest`), the one with the best exact log score
of the truth (the rule that names a file's default route); the smallest temperature
that comes nearest to passing when none does. The file's stored SBC is then run on other
fresh drones at the chosen T: the choice never sees the drones that judge it.
"""
from __future__ import annotations

import numpy as np

from .amortized.estimator import AmortizedEstimator
from .diagnostics.routes import run as run_sbc
from .diagnostics.yardsticks import COVERAGE_MIN, OUTER_MAX, verdict

GRID = (1.0, 1.05, 1.1, 1.15, 1.2, 1.3, 1.4, 1.5, 1.75, 2.0)
"""Temperatures searched, in order (1: the flow as trained). The search stops at the first
temperature that passes the gate with a worse log score than the one before it: past
the log score's minimum a wider posterior only scores worse (a unimodal curve in T, as
for any location-scale family), so the rule's choice is already among those run."""


def amortized_draw(est: AmortizedEstimator, accepted: list | None = None):
    """The amortized route as an SBC draw(profiles, n, seed) -> (q draws, True), with its
    exact density at a truth (``log_density``); the share of draws inside the prior is
    appended to ``accepted`` when given."""
    lf = est.label_free

    def draw(y, n, s):
        u, share = est.sample_u(y, n, s, strict=False)
        if accepted is not None:
            accepted.append(share)
        return lf.from_unbounded(u), True

    draw.log_density = lambda u, y, s: float(est.truncated_log_prob_u(np.asarray(u)[None], y, s)[0])
    return draw


def fit_temperature(est: AmortizedEstimator, truths_q: np.ndarray, profiles, *, grid=GRID, n_rank: int = 199,
                    seed: int = 0, progress=None, log=print) -> dict:
    """SBC of ``est``'s amortized route at each temperature of ``grid`` on the drones
    (truths_q (R, d), profiles (R, M, L)); returns {"temperature": the choice (module
    doc), "passed": whether it passes the gate there, "drones", "seed", "rule", "rows":
    {T: outer share, 90% coverage range, exact log score, verdict, share of draws inside
    the prior, widths}} for the temperatures run (the search's stop: GRID)."""
    lf = est.label_free
    rows, previous = {}, None
    for t in grid:
        accepted = []
        s = run_sbc(amortized_draw(est.at_temperature(t), accepted), truths_q, profiles, lf.names, n_rank=n_rank,
                    seed=seed, to_unbounded=lf.to_unbounded, progress=progress, desc=f"SBC at T = {t:g}")
        row = rows[f"{t:g}"] = {"outer_share": s["outer_share"], "coverage90_range": s["coverage90_range"],
                                "log_score": s["log_score"], "log_score_by": s["log_score_by"],
                                "verdict": verdict(s), "inside_prior_share": float(np.mean(accepted)),
                                "width_over_truth": s["width_over_truth"]}
        lo, hi = s["coverage90_range"]
        log(f"  T = {t:g}: outer-10% share {s['outer_share']:.3f}, 90% coverage {lo:.2f}-{hi:.2f}, "
            f"log score {s['log_score']:.2f} (exact), {row['verdict']}; draws inside the prior "
            f"{row['inside_prior_share']:.3f}")
        if row["verdict"] == "honest" and previous is not None and row["log_score"] > previous:
            break  # past the log score's minimum (GRID)
        previous = row["log_score"]
    passing = [k for k, r in rows.items() if r["verdict"] == "honest"]
    if passing:
        best = min(passing, key=lambda k: rows[k]["log_score"])
    else:  # nearest to the gate: the largest shortfall of the two rules, smallest T on ties
        best = min(rows, key=lambda k: (max(rows[k]["outer_share"] - OUTER_MAX,
                                            COVERAGE_MIN - rows[k]["coverage90_range"][0]), float(k)))
    return {"temperature": float(best), "passed": bool(passing), "drones": int(len(truths_q)), "seed": int(seed),
            "rule": "among the temperatures whose SBC passes the gate on these drones, the best exact log score "
                    "of the truth; else the one nearest to passing",
            "rows": rows}
