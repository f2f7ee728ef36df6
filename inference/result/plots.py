"""The calibration's plots: the corner plot and the walkers' trace of a
:class:`~.posterior.CalibrationResult` (its methods ``plot_corner`` and ``plot_trace``
call these), in physical units."""
from __future__ import annotations

import numpy as np

from ...generator import IDX, N_PARAMS

PLOT_UNITS = {**{f"A_{r}": (f"A_{r} (mm)", 1e3) for r in "abpm"},
              **{f"w_{r}": (f"f_{r} (Hz)", 1 / (2 * np.pi)) for r in "ab"},
              **{f"C_{r}": (f"C_{r} (ratio)", 1.0) for r in "pm"},
              **{f"phi_{r}": (f"phi_{r} (rad)", 1.0) for r in "abpm"},
              "Gamma": ("Gamma (rel.)", 1.0), "lnG": ("lnG = ln(Gamma/Gamma_0)", 1.0),
              "offset": ("offset (bins)", 1.0), "carrier": ("carrier (x sum Gamma)", 1.0),
              "noise_db": ("noise floor (dB)", 1.0), "lnsigma": ("ln sigma (noise)", 1.0)}
"""Plot labels with units and the factor from the stored unit (m, rad/s) to the shown one."""


def plot_corner(res, path, max_params: int = 24):
    """Corner plot (corner) of the sampled parameters in physical units (amplitudes in
    mm, line frequencies f = w / 2 pi in Hz, phases of measurement 0 in rad), one
    corner per engine (at most ``max_params`` parameters each; the pairs across
    engines are not drawn), the best fit marked. Written atomically as PNG, sized to
    be read at full size (about 1 inch per parameter). Fonts follow the caller's
    matplotlib rcParams (the study's report draws it in :mod:`mdaug.reports.style`)."""
    import corner
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from ...radar.plots import save_figure

    data, names = res.plot_matrix()
    best = res.best_fit.reshape(res.n_engines, N_PARAMS)
    engines = []
    for k in range(res.n_engines):
        cols = [i for i, n in enumerate(names) if n.endswith(f"[{k}]") and np.std(data[:, i]) > 0][:max_params]
        if not cols:
            continue
        scale = [PLOT_UNITS[names[i].split("[")[0]][1] for i in cols]
        truths = [best[k, IDX[names[i].split("[")[0]]] * f for i, f in zip(cols, scale)]
        labels = [PLOT_UNITS[names[i].split("[")[0]][0] for i in cols]
        engines.append((k, data[:, cols] * np.asarray(scale), labels, truths))
    if not engines:
        raise ValueError("nothing to plot: no sampled parameter varies")
    size, left, bottom, top, right = 1.05, 1.0, 0.95, 0.45, 0.15  # inches: panel, margins
    ncol = 1 if len(engines) == 1 else 2
    nrow = int(np.ceil(len(engines) / ncol))
    kmax = max(e[1].shape[1] for e in engines)
    sub_w, sub_h = kmax * size + left + right, kmax * size + bottom + top
    head = 0.7
    fig = plt.figure(figsize=(ncol * sub_w, nrow * sub_h + head))
    grid = fig.subfigures(2, 1, height_ratios=[head, nrow * sub_h])
    subs = np.atleast_1d(grid[1].subfigures(nrow, ncol, squeeze=False).ravel())
    fs = matplotlib.rcParams["font.size"]
    for sub, (k, x, labels, truths) in zip(subs, engines):
        sub.subplots(x.shape[1], x.shape[1])
        corner.corner(x, fig=sub, labels=labels, truths=truths, truth_color="C3", quantiles=(0.05, 0.5, 0.95),
                      range=[0.99] * x.shape[1], show_titles=False, plot_datapoints=False, smooth=1.0,
                      max_n_ticks=3, label_kwargs={"fontsize": fs}, labelpad=0.12)
        for ax in sub.axes:
            ax.tick_params(labelsize=max(fs - 2, 8))
            ax.grid(False)
        sub.subplots_adjust(left=left / sub_w, right=1 - right / sub_w, bottom=bottom / sub_h,
                            top=1 - top / sub_h, wspace=0.06, hspace=0.06)
        if len(engines) > 1:
            sub.suptitle(f"engine {k}", x=left / sub_w, ha="left", y=1 - 0.1 / sub_h, va="top",
                         fontsize=fs + 2)
    status = "converged" if res.converged else "NOT converged"
    grid[0].suptitle(f"{res.class_name} posterior ({status}; {res.n_draws} draws"
                     + (", phases marginalised" if res.marginal else ", phases of measurement 0")
                     + "); line frequency f = w / 2 pi", fontsize=fs + 2, x=0.02, ha="left", y=0.9, va="top")
    grid[0].legend(handles=[Line2D([], [], color="C3", lw=1.5, label="best fit (global fit)"),
                            Line2D([], [], color="k", ls="--", lw=1, label="5%, 50%, 95% posterior quantiles")],
                   loc="lower left", bbox_to_anchor=(0.02, 0.0), ncol=2, fontsize=fs, frameon=False)
    return save_figure(fig, path, dpi=80)

def plot_trace(res, path):
    """Trace plot: every walker's path per sampled coordinate in physical units
    (phases as points: they wrap at +-pi), the log posterior, burn-in shaded."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ...radar.plots import save_figure

    tr = res.idata["chain_trace"]
    chain, steps = tr["theta"].values, tr["step"].values
    names = [str(n) for n in tr["coord"].values]
    n = len(names)
    ncol = 4
    nrow = int(np.ceil((n + 1) / ncol))
    height = 1.55 * nrow + 0.7
    fig, axes = plt.subplots(nrow, ncol, figsize=(10.4, height), sharex=True, squeeze=False)
    burn = res.diagnostics["burn"]
    fs = matplotlib.rcParams["font.size"]
    for i, ax in enumerate(axes.ravel()):
        if i < n:
            base = names[i].split("[")[0].split("@")[0]
            label, scale = PLOT_UNITS.get(base, (base, 1.0))
            unit = label[label.index("("):] if "(" in label else ""
            shown = names[i].replace("w_", "f_") if base.startswith("w_") else names[i]
            v = chain[:, :, i] * scale
            if base.startswith("phi_"):  # on the circle: points, not lines across the +-pi wrap
                ax.plot(np.repeat(steps, v.shape[1]), v.ravel(), ".", ms=1, color="k", alpha=0.3)
            else:
                ax.plot(steps, v, lw=0.4, alpha=0.35, color="k")
            ax.set_title(f"{shown} {unit}".strip(), fontsize=fs - 1, loc="left")
        elif i == n:
            ax.plot(steps, tr["lp"].values, lw=0.4, alpha=0.35, color="C0")
            ax.set_title("log posterior", fontsize=fs - 1, loc="left")
        else:
            ax.axis("off")
            continue
        ax.axvspan(0, burn, color="C3", alpha=0.12)
        ax.tick_params(labelsize=fs - 3)
    for c in range(ncol):  # the lowest panel of each column carries the step axis
        low = max(i for i in range(min(n + 1, nrow * ncol)) if i % ncol == c) if c <= n else None
        if low is not None:
            ax = axes.ravel()[low]
            ax.xaxis.set_tick_params(labelbottom=True)
            ax.set_xlabel("step", fontsize=fs - 2)
    title = textwrap.fill(f"{res.class_name}: walkers' paths (burn-in shaded; f = w / 2 pi). "
                          f"{res.diagnostics['reason']}", 120)
    lines = 1 + title.count("\n")
    fig.suptitle(title, fontsize=fs - 1, y=1 - 0.08 / height, va="top")
    fig.tight_layout()
    # the first row's panel titles clear of the suptitle
    fig.subplots_adjust(top=1 - (0.15 + lines * (fs - 1) * 1.35 / 72 + 0.3) / height)
    return save_figure(fig, path, dpi=100)
