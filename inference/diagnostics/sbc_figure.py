"""The SBC figure: rank histograms of every label-free quantity (a flat histogram
inside the band an honest posterior keeps 99% of the time) and the coverage curve
(share of truths inside the central interval against its level)."""
from __future__ import annotations

import numpy as np


def sbc_figure(summaries: dict, path, title: str = "") -> str:
    """Write the figure of SBC summaries {route: summary} (one row per route) to path."""
    import matplotlib.pyplot as plt
    from scipy import stats

    from ...radar.plots import save_figure

    routes = [r for r, s in summaries.items() if isinstance(s, dict) and "ranks" in s]
    names = summaries[routes[0]]["names"]
    n_q = len(names)
    cols = min(n_q, 8)
    rows_per = -(-n_q // cols)
    fig, axes = plt.subplots(len(routes) * rows_per, cols + 1, figsize=(1.6 * (cols + 1) + 1, 1.6 * rows_per *
                                                                          len(routes) + 0.6), squeeze=False)
    for r, route in enumerate(routes):
        s = summaries[route]
        ranks = np.asarray(s["ranks"])
        n, n_rank = len(ranks), s["n_rank"]
        bins = 10
        lo, hi = stats.binom.ppf([0.005, 0.995], n, 1 / bins)
        for j in range(rows_per * cols):
            ax = axes[r * rows_per + j // cols, j % cols]
            if j >= n_q:
                ax.axis("off")
                continue
            ax.axhspan(lo, hi, color="0.85")
            ax.hist(ranks[:, j], bins=np.linspace(0, n_rank + 1, bins + 1), color="C0" if r == 0 else "C1")
            parts = names[j].split()
            ax.set_title(parts[2][0] + parts[1] + parts[2][1:] if len(parts) == 3 else names[j], fontsize=7)
            ax.set_xticks([])
            ax.tick_params(labelsize=6)
        ax = axes[r * rows_per, cols]
        levels = [float(k) for k in s["coverage"]]
        ax.plot([0, 1], [0, 1], color="0.5", lw=0.8)
        for q, cov in s["coverage_by_quantity"].items():
            ax.plot(levels, [cov[k] for k in s["coverage"]], color="C0" if r == 0 else "C1", lw=0.5, alpha=0.5)
        ax.plot(levels, [s["coverage"][k] for k in s["coverage"]], color="k", lw=1.2)
        ax.set_title(f"{route}: coverage", fontsize=7)
        ax.tick_params(labelsize=6)
        for extra in range(1, rows_per):
            axes[r * rows_per + extra, cols].axis("off")
        axes[r * rows_per, 0].set_ylabel(f"{route}\nrank counts", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    return str(save_figure(fig, path))
