"""Study figures that combine several layers' outputs."""
from __future__ import annotations

import numpy as np


def measured_vs_synthetic(measured: dict, synthetic: dict, path, normalisation: str = "peak"):
    """Per class, the median and 10-90% band of each source's profiles.

    measured: {class: (n, L) profiles}; synthetic: {source name: {class: (m, L)}}.
    All are normalised alike before plotting. Writes ``path`` (PNG).
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ..radar import atomic_write, normalise

    classes = list(measured)
    fig, axes = plt.subplots(len(classes), 1, figsize=(9, 3 * len(classes)), sharex=True, squeeze=False)
    for ax, cls in zip(axes[:, 0], classes):
        sources = {"measured": measured[cls], **{k: v[cls] for k, v in synthetic.items() if cls in v}}
        for name, p in sources.items():
            p = normalise(np.asarray(p, dtype=np.float64), normalisation)
            bins = np.arange(p.shape[1]) - p.shape[1] // 2
            lo, med, hi = np.percentile(p, [10, 50, 90], axis=0)
            line, = ax.plot(bins, med, lw=1.6 if name == "measured" else 1.0, label=f"{name} median (n={len(p)})")
            ax.fill_between(bins, lo, hi, color=line.get_color(), alpha=0.15)
        ax.set_title(cls)
        ax.set_xlim(-80, 80)
        ax.set_ylabel(f"magnitude ({normalisation})")
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("bin relative to peak (10-90% bands shaded)")
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=100))
    plt.close(fig)
    return path
