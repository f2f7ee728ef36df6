"""Pictures of range profiles (matplotlib, no display needed)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def save_figure(fig, path, dpi: int = 110):
    """Write a matplotlib figure to ``path`` atomically (format from the suffix, PNG by
    default) and close it, whatever happens; returns the path. The one place that
    saves figures."""
    import matplotlib.pyplot as plt

    from .io import atomic_write

    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    try:
        return atomic_write(path, lambda fh: fig.savefig(fh, format=fmt, dpi=dpi))
    finally:
        plt.close(fig)


def plot_profiles(profiles: np.ndarray, labels: np.ndarray, path=None, title: str = "",
                  n_examples: int = 3, ax=None):
    """Per class: median profile with its 10-90% band and a few examples.

    profiles: (N, L); labels: (N,). Writes ``path`` (PNG) when given; returns the figure.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    classes = sorted(set(np.asarray(labels).tolist()))
    if ax is None:
        fig, axes = plt.subplots(len(classes), 1, figsize=(8, 2.6 * len(classes)), sharex=True, squeeze=False)
        axes = axes[:, 0]
    else:
        fig, axes = ax.figure, [ax] * len(classes)
    bins = np.arange(profiles.shape[1]) - profiles.shape[1] // 2
    for axis, cls in zip(axes, classes):
        p = profiles[np.asarray(labels) == cls]
        lo, med, hi = np.percentile(p, [10, 50, 90], axis=0)
        axis.fill_between(bins, lo, hi, alpha=0.3, label=f"{cls} 10-90% (n={len(p)})")
        axis.plot(bins, med, lw=1.5, label=f"{cls} median")
        for row in p[:n_examples]:
            axis.plot(bins, row, lw=0.6, alpha=0.7)
        axis.set_ylabel("normalised magnitude")
        axis.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("bin relative to peak")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    if path is not None:
        save_figure(fig, path)
    return fig
