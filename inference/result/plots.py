"""The calibration's plots: the corner plot (the label-free lines, titled with the
calibration's status) and the walkers' trace of a
:class:`~.posterior.CalibrationResult` (its methods ``plot_corner`` and ``plot_trace``
call these), in physical units."""
from __future__ import annotations

import numpy as np

from ...generator import N_PARAMS
from .status import BEST_FIT_BESIDE, best_fit_beside

PLOT_UNITS = {**{f"A_{r}": (f"A_{r} (mm)", 1e3) for r in "abpm"},
              **{f"w_{r}": (f"f_{r} (Hz)", 1 / (2 * np.pi)) for r in "ab"},
              **{f"C_{r}": (f"C_{r} (ratio)", 1.0) for r in "pm"},
              **{f"phi_{r}": (f"phi_{r} (rad)", 1.0) for r in "abpm"},
              "Gamma": ("Gamma (rel.)", 1.0), "lnG": ("lnG = ln(Gamma/Gamma_0)", 1.0),
              "offset": ("offset (bins)", 1.0), "carrier": ("carrier (x sum Gamma)", 1.0),
              "noise_db": ("noise floor (dB)", 1.0), "lnsigma": ("ln sigma (noise)", 1.0)}
"""Plot labels with units and the factor from the stored unit (m, rad/s) to the shown one."""


ENGINE_CHOICES = ("brightest", "all")
"""``plot_corner``'s engines: the brightest engine only (the default) or every engine."""


def corner_title(res, status=None) -> str:
    """The corner plot's title: the class and the calibration's status line
    (:func:`.status.calibration_status`, the words every other place prints)."""
    from .status import calibration_status

    status = status if status is not None else calibration_status(res)
    return f"{res.class_name} posterior ({res.n_draws} draws): {status.headline}"


def corner_markers(res, truths) -> list[tuple[str, str, np.ndarray]]:
    """What the corner marks beside the quantiles: (label, colour, engine vectors (E, 13)).
    The true values where they are known (simulated data); the global fit only for the
    closed-form route, and the smc median where it is the best fit beside the amortized
    posterior (otherwise the best fit is the posterior median, which the 50% line shows)."""
    marks = []
    if truths is not None:
        marks.append(("true values (the simulated drone)", "C2", np.asarray(truths, float)))
    if not res.amortized:
        marks.append(("best fit (global fit)", "C3", res.best_fit))
    elif best_fit_beside(res.diagnostics):
        marks.append((f"best fit ({BEST_FIT_BESIDE})", "C3", res.best_fit))
    return [(label, c, x.reshape(-1)[: res.n_engines * N_PARAMS].reshape(res.n_engines, N_PARAMS))
            for label, c, x in marks]


def plot_corner(res, path, engines: str = "brightest", truths=None):
    """Corner plot of the posterior's label-free lines in physical units: per engine its
    four vibration lines sorted by frequency, f = w / 2 pi in Hz and amplitudes in mm
    (8 quantities; what the profiles identify, and what the estimator's SBC checks).
    ``engines``: 'brightest' (default: the brightest engine in each draw, the one the
    measurements identify) or 'all' (one corner per engine, in brightness order).
    ``truths``: the drone's true class vector (13E,) when the data are simulated (drawn
    in green); the closed-form route's global fit is drawn too (red). The title carries
    the calibration's status (:func:`corner_title`). Written atomically as PNG, about
    1.25 inch per quantity. Fonts follow the caller's matplotlib rcParams (the study's
    report draws it in :mod:`mdaug.reports.style`)."""
    import corner
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from ...radar.plots import save_figure
    from ..space.priors import label_free_lines

    if engines not in ENGINE_CHOICES:
        raise ValueError(f"engines must be one of {ENGINE_CHOICES}, got {engines!r}")
    lines = res.lines(by_brightness=True)  # (n, E, 4, 2)
    marks = [(label, c, label_free_lines(x[None], True)[0]) for label, c, x in corner_markers(res, truths)]
    shown = range(res.n_engines) if engines == "all" else range(1)
    labels = [f"f{j + 1} (Hz)" for j in range(4)] + [f"A{j + 1} (mm)" for j in range(4)]
    scale = np.array([1 / (2 * np.pi)] * 4 + [1e3] * 4)

    def flat(x):  # (..., 4, 2) -> (..., 8): frequencies then amplitudes, shown units
        return np.concatenate([x[..., 0], x[..., 1]], axis=-1) * scale

    panels = [(k, flat(lines[:, k]), [(label, c, flat(m[k])) for label, c, m in marks]) for k in shown]
    size, left, bottom, top, right = 1.25, 1.0, 0.95, 0.45, 0.15  # inches: panel, margins
    ncol = 1 if len(panels) == 1 else 2
    nrow = int(np.ceil(len(panels) / ncol))
    nq = len(labels)
    sub_w, sub_h = nq * size + left + right, nq * size + bottom + top
    head = 0.9
    fig = plt.figure(figsize=(ncol * sub_w, nrow * sub_h + head))
    grid = fig.subfigures(2, 1, height_ratios=[head, nrow * sub_h])
    subs = np.atleast_1d(grid[1].subfigures(nrow, ncol, squeeze=False).ravel())
    fs = matplotlib.rcParams["font.size"]
    for sub, (k, x, lines_k) in zip(subs, panels):
        sub.subplots(nq, nq)
        corner.corner(x, fig=sub, labels=labels, quantiles=(0.05, 0.5, 0.95), range=[0.99] * nq,
                      show_titles=False, plot_datapoints=False, smooth=1.0, max_n_ticks=3,
                      label_kwargs={"fontsize": fs}, labelpad=0.12)
        for _, colour, v in lines_k:
            corner.overplot_lines(sub, v, color=colour, lw=1.5)
        for ax in sub.axes:
            ax.tick_params(labelsize=max(fs - 2, 8))
            for t in ax.get_xticklabels():
                t.set_rotation(45)
            ax.grid(False)
        sub.subplots_adjust(left=left / sub_w, right=1 - right / sub_w, bottom=bottom / sub_h,
                            top=1 - top / sub_h, wspace=0.06, hspace=0.06)
        which = "brightest engine" if k == 0 else f"engine {k + 1} by brightness"
        sub.suptitle(which if len(panels) > 1 or res.n_engines > 1 else "", x=left / sub_w, ha="left",
                     y=1 - 0.1 / sub_h, va="top", fontsize=fs + 1)
    grid[0].suptitle(corner_title(res) + "\nlabel-free lines sorted by frequency, f = w / 2 pi"
                     + (f"; the brightest of {res.n_engines} engines in each draw (engines='all' for every one)"
                        if engines == "brightest" and res.n_engines > 1 else ""),
                     fontsize=fs + 1, x=0.02, ha="left", y=0.95, va="top")
    handles = [Line2D([], [], color=c, lw=1.5, label=label) for label, c, _ in marks]
    handles.append(Line2D([], [], color="k", ls="--", lw=1, label="5%, 50%, 95% posterior quantiles"))
    grid[0].legend(handles=handles, loc="lower left", bbox_to_anchor=(0.02, 0.0), ncol=len(handles), fontsize=fs,
                   frameon=False)
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
