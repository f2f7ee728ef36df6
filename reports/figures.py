"""The report's figures, drawn from a finished study's results (and the measured and
synthetic profiles for :func:`measured_vs_synthetic`), all in the one style of
:mod:`.style`: sized to be shown at 1:1 in the report's column, units on every axis,
legends for every mark.

Each ``*_figure`` function returns a matplotlib figure (the report saves and embeds
it); :func:`measured_vs_synthetic` writes :func:`profiles_figure`'s PNG (the study's
``profiles_figure`` stage calls it).
"""
from __future__ import annotations

import numpy as np

from ..classify.protocol import row_ci
from .figures_speed import speed_figure, speed_panels  # noqa: F401  (the speed figure lives apart)
from .numbers import decimals
from .style import (M_TO_MM, PAGE_WIDTH_IN, RAD_S_PER_HZ, REFERENCE_STYLE, colour, figure_style, pyplot, save)


# ---- measured against synthetic profiles ---------------------------------------------------------
def profiles_figure(measured: dict, synthetic: dict, normalisation: str = "peak", bin_m: float | None = None,
                    half_width_bins: int = 80):
    """Per class, the median and 10-90% band of each source's profiles against range
    from the target in metres (a profile's bin is ``bin_m`` of chain range wide,
    :attr:`mdaug.radar.RadarConfig.bin_m`; the window is centred on the target, the
    view ``half_width_bins`` bins either side).

    measured: {class: (n, L) profiles}; synthetic: {source name: {class: (m, L)}}.
    All are normalised alike before plotting. Returns the matplotlib figure.
    """
    from ..radar import RadarConfig, normalise

    bin_m = RadarConfig().bin_m if bin_m is None else float(bin_m)
    classes = list(measured)
    plt = pyplot()
    with figure_style():
        fig, axes = plt.subplots(len(classes), 1, figsize=(PAGE_WIDTH_IN, 3.3 * len(classes) + 0.6),
                                 sharex=True, squeeze=False)
        for ax, cls in zip(axes[:, 0], classes):
            sources = {"measured": measured[cls], **{k: v[cls] for k, v in synthetic.items() if cls in v}}
            for i, (name, p) in enumerate(sources.items()):
                p = normalise(np.asarray(p, dtype=np.float64), normalisation)
                x = (np.arange(p.shape[1]) - p.shape[1] // 2) * bin_m
                lo, med, hi = np.percentile(p, [10, 50, 90], axis=0)
                c = colour(name.split(" ")[0], i)
                ax.plot(x, med, color=c, lw=2.2 if name == "measured" else 1.3,
                        label=f"{name} (n = {len(p)})", zorder=3 if name == "measured" else 2)
                ax.fill_between(x, lo, hi, color=c, alpha=0.18 if name == "measured" else 0.08, lw=0)
            ax.set_title(f"{cls}: median profile, 10-90% band shaded", loc="left")
            ax.set_xlim(-half_width_bins * bin_m, half_width_bins * bin_m)
            ax.set_ylabel(f"magnitude ({normalisation}-normalised)")
            ax.legend(loc="upper right", fontsize=9)
        axes[-1, 0].set_xlabel(f"range from the target (m; chain range, 1 bin = {1e3 * bin_m:.2f} mm)")
        fig.tight_layout()
    return fig


def measured_vs_synthetic(measured: dict, synthetic: dict, path, normalisation: str = "peak",
                          bin_m: float | None = None, half_width_bins: int = 80):
    """:func:`profiles_figure` written to ``path`` (PNG); returns ``path``."""
    save(profiles_figure(measured, synthetic, normalisation, bin_m, half_width_bins), path)
    return path


# ---- strategies ------------------------------------------------------------------------------------
def _ci(m: dict, key: str, cls: str | None = None):
    ci = m.get("ci") or {}
    if cls is not None:
        return ((ci.get("per_class") or {}).get(cls) or {}).get(key)
    return ci.get(key)


def _decimals(ci) -> int:
    return decimals(ci)


def _err(v, ci):
    if v is None:
        return np.array([[0.0], [0.0]])
    if not ci:
        return np.array([[0.0], [0.0]])
    return np.array([[max(v - ci[0], 0.0)], [max(ci[1] - v, 0.0)]])


def strategies_figure(results: dict, test: str, chosen, ceiling: tuple | None):
    """Balanced accuracy and per-class recall (95% intervals) of every strategy's CNN
    on set ``test`` (means over its training runs; the runs as small ticks); chance
    (0.5 balanced) and the ceiling drawn as lines.

    chosen: the chosen strategy's name, or the names tied on the selection set;
    ceiling: (label, balanced accuracy, [lo, hi]) or None."""
    plt = pyplot()
    chosen = [chosen] if isinstance(chosen, str) else list(chosen or [])
    mark = " (chosen)" if len(chosen) == 1 else " (tied choice)"
    classes = list(results["config"]["classes"])
    names = [n for n, s in results["strategies"].items() if test in s["tests"]]
    with figure_style():
        fig, ax = plt.subplots(figsize=(PAGE_WIDTH_IN, 0.62 * len(names) + 2.2))
        k = len(classes) + 1
        offsets = np.linspace(0.25, -0.25, k)
        for row, name in enumerate(names):
            m = results["strategies"][name]["tests"][test]
            y = len(names) - 1 - row
            b = m["balanced_accuracy"]
            ax.errorbar(b, y + offsets[0], xerr=_err(b, _ci(m, "balanced_accuracy")), fmt="D", color="k",
                        ms=7, label="balanced accuracy (mean of the runs)" if row == 0 else None, zorder=4)
            runs = [r["balanced_accuracy"] for r in m.get("runs") or []]
            if len(runs) > 1:
                ax.plot(runs, [y + offsets[0]] * len(runs), "|", color="0.35", ms=13, mew=1.6, zorder=5,
                        label="balanced accuracy of each run" if row == 0 else None)
            for j, cls in enumerate(classes):
                r = m["per_class"][cls]["recall"]
                if r is None:
                    continue
                ax.errorbar(r, y + offsets[j + 1], xerr=_err(r, _ci(m, "recall", cls)), fmt="o",
                            color=colour(cls, j), ms=5, label=f"recall {cls}" if row == 0 else None, zorder=3)
        ax.axvline(0.5, **REFERENCE_STYLE, label="chance (balanced accuracy 0.5)")
        if ceiling is not None:
            label, value, ci = ceiling
            ax.axvline(value, color="0.2", ls=":", lw=1.6, label=f"ceiling: {label}, balanced accuracy")
            if ci:
                ax.axvspan(ci[0], ci[1], color="0.5", alpha=0.12, lw=0, label="ceiling's 95% interval")
        ax.set_yticks(range(len(names)), [n + (mark if n in chosen else "") for n in reversed(names)])
        ax.set_ylim(-0.6, len(names) - 0.4)
        ax.set_xlim(-0.02, 1.02)
        ax.set_xlabel(f"share of the '{test}' set (bars: 95% bootstrap intervals)")
        ax.set_ylabel("CNN trained on")
        ax.grid(axis="y", visible=False)
        handles, labels = ax.get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=3, bbox_to_anchor=(0.5, 0.0))
        legend_rows = 1 + (len(labels) - 1) // 3
        fig.tight_layout(rect=(0, (0.3 * legend_rows + 0.1) / fig.get_figheight(), 1, 1))
    return fig


def confusion_figure(results: dict, test: str):
    """Every strategy's confusion matrix on set ``test`` (counts and row shares), each
    titled with its balanced accuracy and 95% interval."""
    plt = pyplot()
    names = [n for n, s in results["strategies"].items() if test in s["tests"]]
    ncol = min(len(names), 5)
    nrow = int(np.ceil(len(names) / ncol))
    with figure_style():
        fig, axes = plt.subplots(nrow, ncol, figsize=(PAGE_WIDTH_IN, 2.7 * nrow + 0.2), squeeze=False)
        for ax, name in zip(axes.ravel(), names):
            m = results["strategies"][name]["tests"][test]
            cm = np.asarray(m["confusion_matrix"], float)
            share = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
            labels = m["labels"]
            ax.imshow(share, vmin=0, vmax=1, cmap="Blues")
            for i in range(len(labels)):
                for j in range(len(labels)):
                    ax.text(j, i, f"{int(cm[i, j])}\n{share[i, j]:.0%}", ha="center", va="center", fontsize=10,
                            color="white" if share[i, j] > 0.6 else "black")
            ax.set_xticks(range(len(labels)), labels)
            ax.set_yticks(range(len(labels)), labels)
            ax.set_xlabel("predicted")
            ax.set_ylabel("true")
            ax.grid(False)
            ci = _ci(m, "balanced_accuracy")
            d = _decimals(ci)
            runs = m.get("n_runs") or 1
            ax.set_title(f"{name}" + (f" ({runs} runs)" if runs > 1 else "") + f"\nbalanced accuracy\n"
                         f"{m['balanced_accuracy']:.{d}f}"
                         + (f" [{ci[0]:.{d}f}, {ci[1]:.{d}f}]" if ci else ""), fontsize=10)
        for ax in axes.ravel()[len(names):]:
            ax.axis("off")
        fig.tight_layout()
    return fig


# ---- the sweeps --------------------------------------------------------------------------------------
PARAM_LABEL = {"sigma_p": "sigma_P (relative spread)", "width": "specimen width (x default spreads)"}


def sweeps_figure(results: dict, test: str | None):
    """Balanced accuracy against each strategy's setting (sigma_P, specimen width),
    one line per fast classifier: on the selection set (solid, with its 95% interval;
    the choice is made here) and on the test set ``test`` (dashed, for information)."""
    plt = pyplot()
    rows = results["candidates"]["rows"]
    sel = results["selection"]["set"]
    strategies = [s for s in dict.fromkeys(r["strategy"] for r in rows)]
    if not strategies:
        return None
    models = list(dict.fromkeys(r["model"] for r in rows))
    with figure_style():
        fig, axes = plt.subplots(1, len(strategies), figsize=(PAGE_WIDTH_IN, 4.4), squeeze=False, sharey=True)
        for ax, strat in zip(axes[0], strategies):
            param = next(r["parameter"] for r in rows if r["strategy"] == strat)
            for i, model in enumerate(models):
                for set_name, ls, marker in ((sel, "-", "o"), (test, "--", "x")):
                    if set_name is None:
                        continue
                    pts = sorted((r["value"], r["balanced_accuracy"], row_ci(r)) for r in rows
                                 if r["strategy"] == strat and r["model"] == model and r["test_set"] == set_name)
                    if not pts:
                        continue
                    x = np.array([p[0] for p in pts])
                    y = np.array([p[1] for p in pts])
                    ax.plot(x, y, ls=ls, marker=marker, color=f"C{i}",
                            label=f"{model}, {set_name}" + (" (choice)" if set_name == sel else " (information)"))
                    if set_name == sel and all(p[2] for p in pts):
                        lo = np.array([p[2][0] for p in pts])
                        hi = np.array([p[2][1] for p in pts])
                        ax.fill_between(x, lo, hi, color=f"C{i}", alpha=0.10, lw=0)
            ch = (results.get("choice") or {}).get(strat) or {}
            scores = sorted((float(v), sc) for v, sc in (ch.get("scores") or {}).items())
            if scores:
                ax.plot([v for v, _ in scores], [sc for _, sc in scores], "-", color="k", lw=2.4, marker="s",
                        label=f"mean on {sel} (ranks the choice)", zorder=4)
            if ch.get("value") is not None:
                ax.axvline(ch["value"], color="k", lw=1.0, alpha=0.6, label="chosen value")
            ax.axhline(0.5, **REFERENCE_STYLE, label="chance")
            ax.set_title(strat, loc="left")
            ax.set_xlabel(PARAM_LABEL.get(param, param))
            values = sorted({r["value"] for r in rows if r["strategy"] == strat})
            if len(values) == 1:
                ax.set_xlim(values[0] - 0.5, values[0] + 0.5)
        axes[0, 0].set_ylabel("balanced accuracy")
        axes[0, 0].set_ylim(0.0, 1.0)
        handles, labels = {}, {}
        for ax in axes[0]:
            for h, lab in zip(*ax.get_legend_handles_labels()):
                handles.setdefault(lab, h)
        labels = list(handles)
        fig.legend([handles[k] for k in labels], labels, loc="lower center", ncol=3, bbox_to_anchor=(0.5, 0.0))
        legend_rows = 1 + (len(labels) - 1) // 3
        fig.tight_layout(rect=(0, (0.3 * legend_rows + 0.1) / fig.get_figheight(), 1, 1))
    return fig


# ---- calibration -------------------------------------------------------------------------------------
def posterior_lines_figure(cal: dict, cls: str):
    """The label-free posterior of a class, one panel per engine: each vibration line's
    frequency (Hz) and amplitude (mm), median with its 5-95% posterior interval in both
    directions, and the class reference's line frequencies (dashed)."""
    plt = pyplot()
    lines = cal["lines"]
    fq = np.asarray(lines["frequency_q"], float) / RAD_S_PER_HZ  # (3, E, 4) Hz
    aq = np.asarray(lines["amplitude_q"], float) * M_TO_MM        # (3, E, 4) mm
    ref = np.asarray(lines.get("reference_frequency") or np.full(fq.shape[1:], np.nan), float) / RAD_S_PER_HZ
    e = fq.shape[1]
    ncol = min(e, 2)
    nrow = int(np.ceil(e / ncol))
    with figure_style():
        fig, axes = plt.subplots(nrow, ncol, figsize=(PAGE_WIDTH_IN, 2.9 * nrow + 0.9), squeeze=False)
        fmax = np.nanmax([np.nanmax(fq[2]), np.nanmax(ref) if np.isfinite(ref).any() else 0.0]) * 1.08
        amax = np.nanmax(aq[2]) * 1.15
        for k, ax in enumerate(axes.ravel()):
            if k >= e:
                ax.axis("off")
                continue
            for j, f in enumerate(ref[k] if k < len(ref) else []):
                if np.isfinite(f):
                    ax.axvline(f, **REFERENCE_STYLE, label="class reference's lines" if j == 0 else None)
            med_f, med_a = fq[1, k], aq[1, k]
            xerr = np.vstack([med_f - fq[0, k], fq[2, k] - med_f]).clip(min=0)
            yerr = np.vstack([med_a - aq[0, k], aq[2, k] - med_a]).clip(min=0)
            ax.errorbar(med_f, med_a, xerr=xerr, yerr=yerr, fmt="o", color=colour(cls), ms=6,
                        label="posterior: median, 5-95%")
            ax.set_xlim(0, fmax)
            ax.set_ylim(0, amax)
            ax.set_title(f"engine {k}" if e > 1 else f"{cls}: the four vibration lines", loc="left")
            ax.set_ylabel("amplitude (mm)")
            ax.set_xlabel("line frequency (Hz)")
        handles, labels = axes.ravel()[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=2, bbox_to_anchor=(0.5, 0.0))
        fig.tight_layout(rect=(0, 0.45 / fig.get_figheight(), 1, 1))
    return fig


def predictive_figure(cal: dict, cls: str):
    """The posterior predictive check of a class (:mod:`mdaug.inference.diagnostics.predictive`):
    each statistic's z (the measurements against the posterior's replicates, in predictive
    sd), the limit beyond which it is a misfit dashed, bars beyond it hatched; None where the
    check did not run."""
    from ..inference.diagnostics.predictive import ALPHA
    from ..inference.result.status import predictive_record

    p = predictive_record(cal.get("diagnostics") or {})
    if p is None:
        return None
    plt = pyplot()
    z, lim = np.asarray(p["z"], float), float(p["z_limit"])
    n = len(z)
    with figure_style():
        fig, ax = plt.subplots(figsize=(PAGE_WIDTH_IN, 0.28 * n + 1.3))
        y = np.arange(n)[::-1]
        beyond = np.isin(p["names"], p["flagged"])
        ax.barh(y, z, color=colour(cls), height=0.7)
        if beyond.any():
            ax.barh(y[beyond], z[beyond], color="none", edgecolor="k", hatch="//", height=0.7,
                    label="beyond the limit: a misfit")
        for s in (-lim, lim):
            ax.axvline(s, **REFERENCE_STYLE, label=f"limit |z| = {lim:.1f} (family-wise {ALPHA:g})" if s > 0 else None)
        ax.axvline(0, color="0.6", lw=0.8)
        ax.set_yticks(y, p["names"])
        span = max(1.25 * lim, 1.1 * float(np.max(np.abs(z))))
        ax.set_xlim(-span, span)
        ax.set_xlabel("z: (measured - predictive mean) / predictive sd")
        ax.set_title(f"{cls}: the measurements against {p['n_draws']} posterior draws, each measured "
                     f"{p['n_measurements']} times", loc="left")
        ax.legend(loc="lower right")
        fig.tight_layout()
    return fig
