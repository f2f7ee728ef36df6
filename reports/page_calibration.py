"""The report's "Calibration" section: per class, its status (route, convergence, SBC,
out of range: :mod:`mdaug.inference.result.status`, the words of every other place), the
label-free posterior of the vibration lines (figure and numbers), the acquisition as
measured against as stated (far-outside levels flagged, :func:`.verdicts.nuisances`),
the population across drones (measured or assumed), the corner and trace plots."""
from __future__ import annotations

import html
import os
from pathlib import Path

import numpy as np

from . import figures
from .markup import Figures, Html, details, img, table, td
from ..inference.result.status import (MISFIT, NOT_CHECKED, OUT_OF_RANGE, STATISTICS_UNITS, calibration_status,
                                       predictive_record, run_facts)
from .numbers import column_decimals, fmt
from .verdicts import FAR, nuisances


def _sbc_text(status, w: Html) -> str:
    """The stored SBC of the route used and the one gate's word (:mod:`mdaug.inference.result.status`)."""
    if status.sbc is None:
        return f"{w.esc(status.sbc_words)} (see docs/calibration.md)."
    return (f"<span class='{'ok' if status.passed else 'warn'}'>{w.esc(status.honesty)}</span>: "
            f"{w.esc(status.sbc_facts)}.")


def _lines_table(cal: dict) -> str:
    lines = cal.get("lines")
    if not lines:
        return ""
    fq = np.asarray(lines["frequency_q"], float) / (2 * np.pi)
    aq = np.asarray(lines["amplitude_q"], float) * 1e3
    rows = []
    cells = [(k, j) for k in range(fq.shape[1]) for j in range(fq.shape[2])]
    # one precision per column: the sharpest line's (frequencies to tens or hundreds of Hz, whole Hz at most)
    fd = min(column_decimals([[fq[0, k, j], fq[2, k, j]] for k, j in cells], 0, -3, 2), 0)
    ad = column_decimals([[aq[0, k, j], aq[2, k, j]] for k, j in cells], 2, 1, 4)
    f = lambda v: f"{round(v, fd):,.0f}" if fd <= 0 else f"{v:,.{fd}f}"  # noqa: E731
    for k in range(fq.shape[1]):
        for j in range(fq.shape[2]):
            f_ci, a_ci = [fq[0, k, j], fq[2, k, j]], [aq[0, k, j], aq[2, k, j]]
            rows.append([td(str(k)), td(str(j + 1)),
                         td(f"{f(fq[1, k, j])} <span class='ci'>[{f(f_ci[0])}, {f(f_ci[1])}]</span>"),
                         td(f"{fmt(aq[1, k, j], ad)} <span class='ci'>[{fmt(a_ci[0], ad)}, {fmt(a_ci[1], ad)}]"
                            "</span>")])
    return table(["engine", "line (by frequency)", "frequency (Hz): median [5%, 95%]",
                  "amplitude (mm): median [5%, 95%]"], rows)


def _acquisition_compare(cls: str, cal: dict, w: Html) -> str:
    st, me = cal.get("acquisition") or {}, cal.get("measured_acquisition") or {}
    far = {f["key"] for f in nuisances({cls: cal})}
    bits = []
    for key, label, unit, d in (("carrier", "carrier return", " x sum(Gamma)", 2),
                                ("noise_db", "noise floor", " dB", 0)):
        if st.get(key) and me.get(key) and st[key] != me[key]:
            text = (f"{label} measured {me[key][0]:.{d}f} to {me[key][1]:.{d}f}{unit} "
                    f"(the campaign states {st[key][0]:.{d}f} to {st[key][1]:.{d}f}{unit})")
            if key in far:
                text = w.warn(text + f": far outside the stated range (by more than {FAR:g} of its width)")
            bits.append(text)
    if not bits:
        return ""
    return "<p class='note'>What the calibration measured of the acquisition: " + "; ".join(bits) + ".</p>"


def _population(cls: str, c: dict, w: Html) -> str:
    """The class's population: each spread across drones, measured against assumed."""
    rows = c.get("population_spreads")
    if not rows:
        return ""
    drones = c.get("drones") or ["0"]
    bad = [d for d, ok in zip(drones, c.get("drones_converged") or []) if not ok]
    if c.get("population_assumed"):
        head = (f"From one drone the spreads across drones are not measured: the <code>population</code> strategy "
                f"{w.warn('assumes')} them (the specimen model's stated physical guesses, as a half-normal prior).")
    else:
        head = (f"Calibrated from {fmt(len(drones))} drones ({w.esc(', '.join(map(str, drones)))}): each spread "
                "across drones, its prior (assumed) against its posterior (measured where the drones moved it).")
    if bad and not c.get("population_assumed"):
        head += " " + w.warn(f"Drone calibration(s) not converged ({', '.join(map(str, bad))}): the spreads inherit "
                             "their errors (a drone posterior too narrow or off its truth inflates a spread, one too "
                             "wide shrinks it).")
    cells = [[td(x["spread"]), td(f"{fmt(x['prior_median'], 3)} <span class='ci'>[{fmt(x['prior_q05'], 3)}, "
                                  f"{fmt(x['prior_q95'], 3)}]</span>"),
              td(f"{fmt(x['median'], 3)} <span class='ci'>[{fmt(x['q05'], 3)}, {fmt(x['q95'], 3)}]</span>"),
              td(x["status"])] for x in rows]
    return (f"<p class='note'><b>Population of {w.esc(cls)}</b>: {head}</p>"
            + table(["spread (relative)", "prior: median [5%, 95%]", "posterior: median [5%, 95%]", "status"],
                    cells))


def _predictive_text(st, d: dict, w: Html, key: str) -> str:
    """The predictive check's word (a warning when a misfit) and its facts; key: the
    diagnostics' place in results.json."""
    if st.predictive == NOT_CHECKED:
        return w.esc(NOT_CHECKED)
    word = w.warn(w.esc(st.predictive)) if st.predictive == MISFIT else f"<b>{w.esc(st.predictive)}</b>"
    return f"{word}: {w.esc(st.predictive_facts)} ({w.num(key + '.predictive.seconds', d['predictive'].get('seconds'), 1)} s)"


def _predictive_table(d: dict) -> str:
    """The predictive check statistic by statistic ('' where it did not run), folded with the lines."""
    p = predictive_record(d)
    if p is None:
        return ""
    rows = [[td(html.escape(n), False), td(fmt(o, 3)), td(f"{fmt(m, 3)} &plusmn; {fmt(sd, 3)}"), td(fmt(z, 1)),
             td(fmt(q, 2))] for n, o, m, sd, z, q in zip(p["names"], p["observed"], p["mean"], p["sd"], p["z"],
                                                          p["quantile"])]
    marks = ["warn" if n in p["flagged"] else "" for n in p["names"]]
    return (f"<p>The posterior predictive check, statistic by statistic ({STATISTICS_UNITS}; beyond |z| = "
            f"{fmt(p['z_limit'], 1)}: a misfit):</p>"
            + table(["statistic", "measured", "predictive mean &plusmn; sd", "z", "predictive quantile"], rows,
                    marks))


def calibration_section(r: dict, figs: Figures, w: Html, report_dir: Path) -> str:
    out = ["<p class='note'>Each class is calibrated on its few measurements under the campaign's acquisition "
           "(phases marginalised). A vibration model is a sum of four lines per engine; which line is the roll, "
           "the pitch or a mixing term is a labelling one profile cannot fix, so the posterior is shown label-free: "
           "every line's frequency and amplitude, lines sorted by frequency.</p>"]
    for cls, c in r["calibration"].items():
        d = c["diagnostics"]
        st = calibration_status(c)
        k = f"calibration.{cls}.diagnostics"
        run = run_facts(d, lambda key, value, dec: w.num(f"{k}.{key}", value, dec))
        if st.route == "amortized":
            chain = (f"{w.esc(st.route_words)} ({fmt(d.get('amortized_seconds', 0) * 1e3)} ms, "
                     f"{fmt(100 * d.get('amortized_inside_prior', 0))}% of its draws inside the prior)")
            if st.check:
                chain += f"; {w.esc(st.check)}" + (f", {run}" if run else "")
        else:
            chain = w.esc(st.route_words) + (f": {run}" if run else "")
        out.append(f"<h3>{w.esc(cls)}: <span class='{'ok' if st.trusted else 'warn'}'>{w.esc(st.headline)}</span></h3>")
        detail = w.esc(st.convergence_detail)
        out.append(f"<ul><li><b>Convergence</b>: {w.esc(st.convergence)}{': ' + detail if detail else ''}.</li>"
                   f"<li><b>Route</b>: {chain}; {w.num(k + '.seconds', d.get('seconds'), 0)} s on "
                   f"{fmt(c.get('n_profiles'))} measurements.</li>"
                   f"<li><b>SBC</b>: {_sbc_text(st, w)}</li>"
                   + (f"<li><b>Drones like a user's</b>: {w.esc(st.users_facts)}.</li>" if st.users else "")
                   + f"<li><b>Posterior predictive check</b>: {_predictive_text(st, d, w, k)}</li></ul>")
        if st.out_of_range:
            out.append(f"<p class='warn'>{w.esc(OUT_OF_RANGE)}: "
                       f"{w.esc(st.out_of_range_why or 'measurements unlike the training set')}</p>")
        if c.get("lines"):
            out.append(figs.embed(f"posterior_{cls}", figures.posterior_lines_figure(c, cls),
                                  f"{cls} posterior, label-free: each engine's four vibration lines, frequency in Hz "
                                  f"against amplitude in mm, medians with 5-95% intervals, and the class reference's "
                                  "line frequencies"))
        out.append(figs.embed(f"predictive_{cls}", figures.predictive_figure(c, cls),
                              f"{cls} posterior predictive check: each statistic's z against the limit"))
        out.append(_acquisition_compare(cls, c, w))
        out.append(_population(cls, c, w))
        unid = [p for p, ok in (d.get("identified") or {}).items() if not ok]
        body = _lines_table(c) + _predictive_table(d)
        if unid:
            body += (f"<p class='note'>Parameters that stay near their prior (posterior sd over "
                     f"{fmt(d.get('identified_ratio', 0.5), 1)} x prior sd): {w.esc(', '.join(unid))}.</p>")
        corner = c.get("corner")
        if corner and Path(corner).is_file():
            rel = os.path.relpath(corner, report_dir)
            body += (f"<p>Corner plot of the brightest engine's label-free lines (physical units; true values "
                     f"where the data are simulated): "
                     f"<a href='{html.escape(rel)}'>{html.escape(rel)}</a> (opens at full size).</p>"
                     + img(corner, f"{cls} corner plot of the sampled parameters"))
        trace = c.get("trace")
        if trace and Path(trace).is_file():
            body += ("<p>The walkers' paths (burn-in shaded):</p>"
                     + img(trace, f"{cls} trace plot of the walkers' paths"))
        out.append(details(f"{cls}: the lines in numbers, the predictive check, the corner and trace plots", body))
    return "\n".join(out)


