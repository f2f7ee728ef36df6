"""The report's speed-against-error figure: one panel per stage, cost against error
(the training panel: one run's cost against the mean error, bars the lowest and highest
run). In the style of :mod:`.style`, like :mod:`.figures`."""
from __future__ import annotations

import re

import numpy as np

from .style import PAGE_WIDTH_IN, REFERENCE_STYLE, colour, figure_style, pyplot


# ---- speed against error -------------------------------------------------------------------------
_RATE = re.compile(r"([\d,.]+)\s*(ms|s|profiles/s)")


def _cost_ms(row: dict) -> float | None:
    """ms per unit of a speed row (parsed from its rate: '8,025 profiles/s', '0.42 ms / evaluation')."""
    m = _RATE.search(row.get("rate", ""))
    if not m:
        return None
    v = float(m.group(1).replace(",", ""))
    if m.group(2) == "profiles/s":
        return 1e3 / v if v > 0 else None
    return v if m.group(2) == "ms" else 1e3 * v


def _short(stage: str, setting: str) -> str:
    if stage == "generator":
        return setting.split()[-1]
    if stage == "likelihood":
        m = re.search(r"O = \d+", setting)
        return m.group(0) if m else setting
    if stage == "chain path":
        return setting.split()[0]
    return setting


SPEED_UNITS = {"generator": ("f(x): ms per profile", "max |f - float64 f| (peak = 1)"),
               "likelihood": ("ms per likelihood evaluation", "Monte Carlo error (rms, peak = 1)"),
               "chain path": ("ms per profile", "max |reduced - literal| (peak = 1)")}


def speed_panels(results: dict, test: str | None) -> list[dict]:
    """Speed-against-error points of every stage: [{stage, xlabel, ylabel, metric, points:
    [(label, cost, error, error interval or None)]}]; a point with error 0 is the reference."""
    panels = []
    rows = (results.get("speed") or {}).get("rows") or []
    for stage in dict.fromkeys(r["stage"] for r in rows):
        pts = [(_short(stage, r["setting"]), _cost_ms(r), r["error"], None) for r in rows if r["stage"] == stage]
        metric = next(r["error_metric"] for r in rows if r["stage"] == stage)
        xl, yl = SPEED_UNITS.get(stage, ("ms", "error"))
        panels.append({"stage": stage, "xlabel": xl, "ylabel": yl, "metric": metric, "points": pts})
    cal = results.get("calibration") or {}
    pts = []
    for cls, c in cal.items():
        d = c["diagnostics"]
        ess = d.get("ess_min")
        if ess and d.get("seconds"):
            pts.append((f"{cls} (chain {d.get('steps_over_tau', float('nan')):.0f} x tau)", d["seconds"],
                        1.0 / np.sqrt(ess), None))
    if pts:
        panels.append({"stage": "calibration", "xlabel": "sampling time (s)",
                       "ylabel": "MC error of means (post. sd)", "metric": "1/sqrt(min ESS)", "points": pts})
    if test is not None:
        pts = []
        for name, s in results["strategies"].items():
            m = s["tests"].get(test)
            if m is not None:  # one run's cost; its error: the mean, bars the lowest-highest run
                runs = m.get("n_runs") or 1
                lo_hi = (m.get("seed_spread") or {}).get("balanced_accuracy") if runs > 1 else None
                pts.append((f"CNN {name}", s["train_seconds"] / runs, 1 - m["balanced_accuracy"],
                            [1 - lo_hi[1], 1 - lo_hi[0]] if lo_hi else None))
        for model, c in ((results.get("ceiling") or {}).get("models") or {}).items():
            m = c["tests"].get(test)
            if m is not None:
                runs = m.get("n_runs") or 1
                lo_hi = (m.get("seed_spread") or {}).get("balanced_accuracy") if runs > 1 else None
                pts.append((f"ceiling {model}", c["train_seconds"] / runs, 1 - m["balanced_accuracy"],
                            [1 - lo_hi[1], 1 - lo_hi[0]] if lo_hi else None))
        if pts:
            panels.append({"stage": "training", "xlabel": "training time of one run (s)",
                           "ylabel": "1 - balanced accuracy", "metric": f"on '{test}'", "points": pts})
    return panels


def _scale(ax, values, axis: str, room: float = 1.3):
    """Log axis for values spanning more than a factor 20, else linear from 0; ``room``:
    the share of the axis beyond the largest value (for labels right of the points)."""
    v = np.asarray([x for x in values if x is not None and x > 0], float)
    if not v.size:
        return
    if v.max() / v.min() > 20:
        getattr(ax, f"set_{axis}scale")("log")
        getattr(ax, f"set_{axis}lim")(v.min() / 2, v.max() * room ** 4)
    else:
        getattr(ax, f"set_{axis}lim")(0, v.max() * room)


def speed_figure(results: dict, test: str | None):
    """One panel per stage: cost against error (0 = the reference the others are
    compared with); training spans two panels, with a legend."""
    plt = pyplot()
    panels = speed_panels(results, test)
    if not panels:
        return None
    small = [p for p in panels if p["stage"] != "training"]
    train = next((p for p in panels if p["stage"] == "training"), None)
    nrow = int(np.ceil((len(small) + (2 if train else 0)) / 3))
    with figure_style():
        fig = plt.figure(figsize=(PAGE_WIDTH_IN, 3.4 * nrow + (1.2 if train else 0.3)))
        gs = fig.add_gridspec(nrow, 3)
        slots = [(i // 3, i % 3) for i in range(3 * nrow)]
        for p, (r, c) in zip(small, slots):
            ax = fig.add_subplot(gs[r, c])
            pts = [q for q in p["points"] if q[1] is not None]
            for i, (label, cost, err, _) in enumerate(pts):
                ax.plot(cost, err, "s" if err == 0 else "o", color=f"C{i % 10}", ms=7)
                ax.annotate(label + (" (reference)" if err == 0 else ""), (cost, err), textcoords="offset points",
                            xytext=(6, 5), fontsize=9)
            _scale(ax, [q[1] for q in pts], "x", room=2.2)
            ax.set_ylim(0, max([q[2] for q in pts] + [1e-12]) * 1.35)
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
            ax.set_title(p["stage"], loc="left")
            ax.set_xlabel(p["xlabel"])
            ax.set_ylabel(p["ylabel"])
        if train:
            k = len(small)
            r, c = slots[k]
            if c == 2:  # no room for two panels on this row
                r, c = r + 1, 0
            ax = fig.add_subplot(gs[r, c:c + 2] if c <= 1 else gs[r, c])
            for i, (label, cost, err, ci) in enumerate(train["points"]):
                yerr = None if ci is None else np.array([[max(err - ci[0], 0)], [max(ci[1] - err, 0)]])
                ax.errorbar(cost, err, yerr=yerr, fmt="o" if label.startswith("CNN") else "^",
                            color=colour(label.split()[-1], i), ms=7, label=label)
            ax.axhline(0.5, **REFERENCE_STYLE, label="chance")
            _scale(ax, [q[1] for q in train["points"]], "x")
            ax.set_ylim(0, max([0.75] + [(q[3] or [0, q[2]])[1] * 1.1 for q in train["points"]]))
            ax.set_title(f"training (error {train['metric']}: mean of the runs, bars lowest-highest run)",
                         loc="left")
            ax.set_xlabel(train["xlabel"])
            ax.set_ylabel(train["ylabel"])
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize=9)
        fig.tight_layout()
    return fig
