"""The report's "Speed against error" section: every stage's cost against its error,
the training of each strategy's CNN included (the cost of one training run against
the spread of the runs' errors: what the several seeds buy)."""
from __future__ import annotations

import numpy as np

from .figures_speed import speed_figure
from .markup import Figures, Html, details, table, td
from .numbers import decimals, fmt, fmt_sig, spread
from ..inference.result.status import run_facts

INTRO = ("<p class='note'>Each stage's cost against its error, measured in this run on 1 thread: the "
         "generator f(x) (float32 against float64), the marginal likelihood (Monte Carlo error against the "
         "number of simulated acquisitions), the calibration (Monte Carlo error of posterior means against "
         "sampling time), the chain path (reduced against literal computation) and the training of each "
         "classifier (its error on the test set against training time).</p>")


def seeds_note(r: dict) -> str:
    """How the study pays for its training runs (what they cost, what they buy)."""
    p = r["config"]["protocol"]
    s = p.get("cnn_seeds", 1)
    if s <= 1:
        return ""
    return (f"<p class='note'>Training randomness: every CNN is trained {s} times (seeds) on its strategy's one "
            f"training set ({p['cnn_n_per_class']:,} profiles per class, drawn once; {p['tsaug_n_per_class']:,} for "
            f"tsaug), each run for at most {p['cnn_epochs']} epochs ({p['tsaug_epochs']} for tsaug). The set is "
            f"made once, so the runs cost {s} trainings, not {s} sets. The spread of the runs (below: the lowest "
            "and highest run's error) is the error one run alone would carry; the mean over the runs has about "
            f"1/sqrt({s}) of it, and the report's intervals include it. README, 'Training runs: where they are "
            "paid for', gives the measured trade against set size and epochs.</p>")


def speed_section(r: dict, j: dict, figs: Figures, w: Html) -> str:
    test = j["test"]
    out = [INTRO, seeds_note(r),
           figs.embed("speed", speed_figure(r, test),
                      "Speed against error of every stage: generator, likelihood, calibration, chain path, training")]
    rows = []
    for i, row in enumerate((r.get("speed") or {}).get("rows") or []):
        rows.append([td(w.esc(row["stage"]), False), td(w.esc(row["setting"]), False), td(w.esc(row["rate"])),
                     td(f'<span data-key="speed.rows.{i}.error">{fmt_sig(row["error"])}</span>'),
                     td(w.esc(row["error_metric"]), False)])
    for cls, c in r["calibration"].items():
        d = c["diagnostics"]
        k = f"calibration.{cls}.diagnostics"
        ess = d.get("ess_min")
        run = run_facts(d, lambda key, value, dec: w.num(f"{k}.{key}", value, dec)) or "exact draws, no sampler"
        rows.append([td("calibration", False), td(f"{w.esc(cls)}, {run}", False),
                     td(f"{w.num(k + '.seconds', d.get('seconds'), 0)} s"),
                     td(fmt_sig(1 / np.sqrt(ess)) if ess else "–"),
                     td("Monte Carlo error of posterior means, in posterior sd (1/sqrt(min ESS))", False)])
    if test:
        for name, s in r["strategies"].items():
            m = s["tests"].get(test)
            if m is None:
                continue
            runs = m.get("n_runs") or 1
            d = decimals(m["ci"].get("balanced_accuracy"))
            lo_hi = (m.get("seed_spread") or {}).get("balanced_accuracy")
            err = fmt(1 - m["balanced_accuracy"], d)
            if runs > 1 and lo_hi:
                err += f" (runs {spread({'balanced_accuracy': [1 - lo_hi[1], 1 - lo_hi[0]]}, d)})"
            rows.append([td("training", False),
                         td(f"CNN {w.esc(name)}, {runs} run(s) on one set of {s['n_train']:,} profiles", False),
                         td(f"{fmt(s['train_seconds'] / runs, 1)} s per run"),
                         td(err),
                         td(f"1 - balanced accuracy on the '{w.esc(test)}' set, mean over the runs (lowest–highest run)",
                            False)])
    out.append(details("Speed against error in numbers",
                       table(["stage", "setting", "speed", "error", "error metric"], rows)))
    return "\n".join(out)
