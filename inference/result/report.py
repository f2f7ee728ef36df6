"""The calibration's text report: fit, sampler, the status (:mod:`.status`: route,
convergence, SBC, out of range) and the posterior summary table with units (:meth:`~.posterior.CalibrationResult.report` calls :func:`report`)."""
from __future__ import annotations

import numpy as np

from ..samplers.smc import describe_route_knobs
from .status import (
    BEST_FIT_BESIDE,
    STATISTICS_UNITS,
    predictive_record,
    best_fit_beside,
    calibration_status,
    chain_words,
    smc_role,
)

SUMMARY_UNITS = {"Gamma": "rel.", "A": "m", "w": "rad/s", "C": "ratio", "phi": "rad", "offset": "bins",
                 "carrier": "x sum Gamma", "noise_db": "dB", "sigma": "peak = 1"}
"""Units of the summary table's rows (the stored units: metres, rad/s)."""


def summary_unit(row: str) -> str:
    """The unit of a summary row name such as ``A_a[0]``, ``phi_b[0]@1`` or ``noise_db@2``."""
    base = row.split("[")[0].split("@")[0]
    return SUMMARY_UNITS.get(base, SUMMARY_UNITS.get(base.split("_")[0], ""))


def report(res, identified_ratio: float) -> str:
    """Human-readable fit, convergence and posterior summary of ``res`` (parameters whose
    posterior sd exceeds ``identified_ratio`` x the prior sd are listed as not identified)."""
    import pandas as pd

    d, f = res.diagnostics, res.fit
    lines = [f"class {res.class_name}: {res.n_engines} engine(s), {res.n_measurements} measurement(s), "
             f"{res.n_draws} posterior draws",
             f"acquisition: {res.acquisition.describe()}; "
             + (f"phases marginalised ({res.meta.get('likelihood', {}).get('likelihood', 'marginal')})"
                if res.marginal else "phases fitted"),
             f"fit ({f['algorithm']}, {len(f['starts_misfit'])} starts, {f['seconds']:.1f} s"
             f"{', reused from the checkpoint' if d.get('fit_reused') else ''}): "
             f"misfit {f['misfit']:.2f}, {f['n_agree']} start(s) agree, "
             + (f"noise floor {np.round(f['sigma'], 1).tolist()} dB" if res.marginal else
                f"noise sigma {np.round(f['sigma'], 4).tolist()}")]
    lines += [f"  note: {n}" for n in f["notes"]]
    if d.get("sampler") == "smc":
        lines.append(f"SMC: {d['smc_n_particles']} particles, {d['smc_stages']} tempering stages, "
                     f"{d['smc_n_evals']} evaluations ({d['seconds']:.1f} s), ESS {d['ess_min']:.0f}, "
                     f"last acceptance {d['acceptance_mean']:.2f}, distinct particles "
                     f"{d['smc_unique_share']:.0%}, log evidence {d['smc_log_z']:.2f}, modes known to the "
                     f"jumps {d.get('smc_modes', 0)}")
    else:
        resumed = f", resumed at step {d['resumed_at']}" if d.get("resumed_at") else ""
        lines.append(f"MCMC: {d['n_walkers']} walkers x {d['chain_steps']} steps ({d['seconds']:.1f} s{resumed}), "
                     f"max tau {d['tau_max']:.0f} steps, chain/tau {d['steps_over_tau']:.1f}, "
                     f"min ESS {d['ess_min']:.0f}, acceptance {d['acceptance_mean']:.2f}, "
                     f"burn {d['burn']}, thin {d['thin']}")
    lines += status_lines(res)
    if d.get("weak_engines"):
        lines.append(f"WARNING: engine(s) {d['weak_engines']} stay near their prior (too weak to identify)")
    unid = [k for k, v in d["identified"].items() if not v]
    if unid:
        lines.append(f"not identified (posterior sd > {identified_ratio} x prior sd): {', '.join(unid)}")
    if res.comparison:
        lines.append("engine-count comparison (LOO):")
        lines.append(pd.DataFrame(res.comparison).to_string(index=False))
    table = res.summary()[["mean", "sd", "q05", "q95", "sd_ratio", "identified"]]
    table.insert(0, "unit", [summary_unit(n) for n in table.index])
    with pd.option_context("display.width", 140, "display.max_rows", 500):
        lines.append(table.to_string(float_format=lambda v: f"{v:.4g}"))
    lines.append("units: m (amplitudes A), rad/s (angular frequencies w; f = w / 2 pi), rad (phases), "
                 "ratio (C, carrier x sum Gamma), bins (FFT bins), dB; sd_ratio: posterior sd / prior sd")
    return "\n".join(lines)


def amortized_report(res, identified_ratio: float) -> str:
    """The report of a simulation-based calibration (:mod:`..amortized`): the estimator,
    both routes with their diagnostics and SBC figures, the out-of-range check and
    the posterior summary table."""
    import pandas as pd

    d = res.diagnostics
    est = d["estimator"]
    lines = [f"class {res.class_name}: {res.n_engines} engine(s), {res.n_measurements} measurement(s), "
             f"{res.n_draws} posterior draws",
             f"acquisition: {res.acquisition.describe()}; every nuisance marginalised by training on the scene "
             "simulator",
             f"estimator: {est['class']} K = {est['ramps']}, {est['simulations']} simulated drones ({est['simulator']})"]
    temp = est.get("temperature", 1.0)
    lines.append(f"amortized posterior: {d['amortized_seconds'] * 1e3:.0f} ms, {d['amortized_inside_prior']:.0%} of "
                 "its draws inside the prior" + (f", drawn at temperature {temp:g} (the file's, chosen by SBC and "
                                                 "log score on fresh drones)" if temp != 1.0 else ""))
    if "smc" in d:
        m = d["smc"]
        which = {"summary": "the summary likelihood", "ratio": "the learned likelihood ratio"}.get(
            m.get("likelihood", "ratio"), "the learned likelihood")
        role = {"smc": "the route used", "stacked": "stacked in the route used"}.get(d["route"]) or smc_role(d)
        lines.append(f"tempered SMC from the amortized posterior on {which} ({role}): "
                     f"{m['particles']} particles, {m['stages']} stages ({m['seconds']:.1f} s), unique share "
                     f"{m['unique_share']:.2f}, last acceptance {m['acceptance_last']:.2f}: "
                     + "{}: {}".format(*chain_words(m["converged"], m["reason"])))
        if "route_settings" in m:  # results of earlier releases have none
            k = m["route_settings"]
            lines.append("  its tempering: " + describe_route_knobs(k, particles=False))
    if d["route"] == "stacked":
        st = d["stacked"]
        lines.append(f"stacked route: {st['weight']:.2f} x the smc route's posterior + {1 - st['weight']:.2f} x the "
                     f"amortized posterior ({st['smc_share']:.0%} of the draws from the smc route); the weight is the "
                     "file's, chosen by the log score of the truth on "
                     f"{st['stacking'].get('drones', '?')} held-out simulated drones")
    lines.append(f"posterior used by the strategies: {d['route']} route"
                 + (f"; best fit (sigma_p_fit's centre): {BEST_FIT_BESIDE}" if best_fit_beside(d) else "")
                 + ("; best fit: the component-wise median of the draws (no labelling of their label-free "
                    "median fits the prior)"
                    if d.get("best_fit_median") == "component-wise" else ""))
    lines += status_lines(res)
    if d.get("widths"):
        lines.append("label-free quantities (the lines sorted by frequency; rad/s and m): median, 90% interval, "
                     "its width / median, and the Cramer-Rao bound's 90% width / median for these measurements")
        rows = {n: {"median": v["median"], "q05": v["q05"], "q95": v["q95"],
                    "width/median": (v["q95"] - v["q05"]) / abs(v["median"]),
                    "CRB width/median": v.get("crb_width", float("nan")) / abs(v["median"])}
                for n, v in d["widths"].items()}
        with pd.option_context("display.width", 140, "display.max_rows", 500):
            lines.append(pd.DataFrame(rows).T.to_string(float_format=lambda v: f"{v:.4g}"))
    table = res.summary()[["mean", "sd", "q05", "q95", "sd_ratio", "identified"]]
    table.insert(0, "unit", [summary_unit(n) for n in table.index])
    with pd.option_context("display.width", 140, "display.max_rows", 500):
        lines.append(table.to_string(float_format=lambda v: f"{v:.4g}"))
    lines.append("units: m (amplitudes A), rad/s (angular frequencies w; f = w / 2 pi); sd_ratio: posterior sd / "
                 f"prior sd (identified at <= {identified_ratio})")
    return "\n".join(lines)


def status_lines(res) -> list[str]:
    """The status of ``res`` (:func:`.status.calibration_status`) and, where the posterior
    predictive check ran, its table: what either route's report says of its verdicts."""
    p = predictive_record(res.diagnostics)
    return calibration_status(res).lines() + ([] if p is None else [predictive_table(p)])


def predictive_table(p: dict) -> str:
    """The posterior predictive check's statistics (its record ``p``, :mod:`mdaug.inference.diagnostics.predictive`)
    as a table: the data's value, the predictive mean and sd, z and the data's predictive quantile,
    the statistics beyond the limit marked."""
    import pandas as pd

    rows = {n: {"data": o, "predictive mean": m, "sd": sd, "z": z, "quantile": q,
                "": "beyond the limit" if n in p["flagged"] else ""}
            for n, o, m, sd, z, q in zip(p["names"], p["observed"], p["mean"], p["sd"], p["z"], p["quantile"])}
    with pd.option_context("display.width", 140, "display.max_rows", 500):
        table = pd.DataFrame(rows).T.to_string(float_format=lambda v: f"{v:.3f}")
    return f"posterior predictive check, statistic by statistic ({STATISTICS_UNITS})\n" + table

