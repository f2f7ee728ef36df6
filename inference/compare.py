"""Engine-count selection by model comparison (PSIS-LOO over profile bins).

Each candidate engine count is calibrated in full; arviz's ``compare`` ranks them
by the expected log pointwise predictive density (elpd, leave-one-bin-out, Pareto
smoothed importance sampling) using the per-bin log-likelihood stored with every
posterior. Rule: among the candidates whose elpd is within 2 standard errors
(``dse``) of the best, the smallest engine count wins (parsimony: a larger model
must predict clearly better). Caveats, reported in the table: bins of one profile
are conditionally independent under the noise model but neighbouring bins share
the spectral leakage of the same lines, so LOO is optimistic for all candidates
alike; Pareto k > 0.7 warnings mean the LOO estimate of that model is unreliable;
a candidate that did not converge is marked.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .result.posterior import CalibrationResult, import_arviz

DSE_RULE = 2.0


def select_engines(profiles, ref, *, candidates=(1, 2, 4), settings=None, random_state=None, backend_path=None,
                   priors=None, radar=None, acquisition=None, predictive: int | None = None) -> CalibrationResult:
    """Calibrate every candidate engine count, compare by LOO, return the chosen
    result with the comparison table in ``result.comparison`` (list of dicts).
    predictive: ``calibrate``'s (None: its default), run on every candidate."""
    from .calibrate import calibrate, seed_sequence

    cands = sorted({int(c) for c in candidates})
    if not cands or cands[0] < 1:
        raise ValueError(f"engine-count candidates must be positive integers, got {candidates!r}")
    seeds = seed_sequence(random_state).spawn(len(cands))
    results = {}
    for e, ss in zip(cands, seeds):
        bp = None if backend_path is None else Path(f"{backend_path}.e{e}")
        kw = ({} if radar is None else {"radar": radar}) | ({} if predictive is None else {"predictive": predictive})
        results[e] = calibrate(profiles, ref, engines=e, settings=settings, random_state=ss, backend_path=bp,
                               priors=priors, acquisition=acquisition, **kw)
    table = compare_results(results)
    ok = [row for row in table if row["elpd_diff"] <= DSE_RULE * max(row["dse"], 1e-12) or row["rank"] == 0]
    chosen = min(row["engines"] for row in ok)
    for row in table:
        row["chosen"] = row["engines"] == chosen
    rule = f"smallest engine count whose elpd_loo is within {DSE_RULE} dse of the best (PSIS-LOO over bins)"
    return results[chosen].record(comparison=table, comparison_rule=rule)


def compare_results(results: dict) -> list[dict]:
    """arviz.compare over {engines: CalibrationResult} -> rows (plain floats)."""
    import warnings

    az = import_arviz()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = az.compare({str(e): r.idata for e, r in results.items()}, ic="loo", method="stacking")
        khat = {e: float(np.max(az.loo(r.idata, pointwise=True).pareto_k.values)) for e, r in results.items()}
    rows = []
    for name, row in df.iterrows():
        e = int(name)
        rows.append({"engines": e, "rank": int(row["rank"]), "elpd_loo": float(row["elpd_loo"]),
                     "se": float(row["se"]), "p_loo": float(row["p_loo"]), "elpd_diff": float(row["elpd_diff"]),
                     "dse": float(row["dse"]), "weight": float(row["weight"]), "max_pareto_k": khat[e],
                     "converged": bool(results[e].converged)})
    return sorted(rows, key=lambda r: r["engines"])
