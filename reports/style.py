"""One style for every figure of the study's report (and the calibration figures drawn
inside it): fonts readable at the width the page shows them, units on every axis,
legends for every mark that is not self-explanatory.

The rule that makes fonts readable: a figure is drawn at the size it is shown. The
report's column is :data:`PAGE_WIDTH_PX` pixels wide; a figure of width ``w`` inches
saved at :data:`DPI` is ``w * DPI`` pixels, so a figure no wider than
:data:`PAGE_WIDTH_IN` is shown at 1:1 and a 10-point font is 10 * DPI / 72 pixels
(about 14 px) on the page. Wider figures (the full corner plot) are linked, not
embedded, and opened at full size.

Use::

    from mdaug.reports.style import figure_style, save

    with figure_style():
        fig, ax = plt.subplots(figsize=(PAGE_WIDTH_IN, 3.5))
        ...
        save(fig, path)
"""
from __future__ import annotations

import contextlib

import numpy as np

DPI = 100
PAGE_WIDTH_PX = 1040
PAGE_WIDTH_IN = PAGE_WIDTH_PX / DPI
FONT_PT = 11
MIN_FONT_PT = 10

RC = {
    "font.size": FONT_PT,
    "axes.titlesize": FONT_PT + 1,
    "axes.labelsize": FONT_PT,
    "xtick.labelsize": MIN_FONT_PT,
    "ytick.labelsize": MIN_FONT_PT,
    "legend.fontsize": MIN_FONT_PT,
    "legend.title_fontsize": MIN_FONT_PT,
    "figure.titlesize": FONT_PT + 2,
    "figure.dpi": DPI,
    "savefig.dpi": DPI,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.frameon": False,
    "lines.linewidth": 1.6,
    "errorbar.capsize": 3,
}
"""matplotlib rcParams of the report's figures."""

# Colours: one per class and per strategy, the same in every figure.
CLASS_COLOURS = {"HELI": "#d95f02", "QUAD": "#1b9e77"}
STRATEGY_COLOURS = {"sigma_p_published": "#7570b3", "sigma_p_fit": "#e7298a", "posterior": "#66a61e",
                    "posterior_specimens": "#1f78b4", "tsaug": "#a6761d", "measured": "#000000"}
REFERENCE_STYLE = {"color": "0.35", "ls": "--", "lw": 1.2}
"""Reference lines (chance, ceiling, a class reference's value)."""

RAD_S_PER_HZ = 2.0 * np.pi
M_TO_MM = 1e3


def pyplot():
    """matplotlib.pyplot on the non-interactive backend (imported on first use)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def colour(name: str, i: int = 0) -> str:
    """The colour of a class or strategy (matplotlib's cycle for other names)."""
    return CLASS_COLOURS.get(name) or STRATEGY_COLOURS.get(name) or f"C{i % 10}"


@contextlib.contextmanager
def figure_style():
    """matplotlib with the report's rcParams (and the Agg backend) inside the block."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    with matplotlib.rc_context(RC):
        yield


def save(fig, path, dpi: int = DPI):
    """Write ``fig`` to ``path`` as PNG (atomic) and close it."""
    from ..radar.plots import save_figure

    return save_figure(fig, path, dpi=dpi)
