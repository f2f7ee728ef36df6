"""Simulation-based calibration (Talts et al. 2018) of the whole calibration pipeline.

For each replicate: draw theta from the prior, simulate data exactly as the
likelihood assumes (model profile + Gaussian noise of the drawn sigma), run the
fit + MCMC, and record the rank of the true value among ``n_rank`` posterior draws
for every test quantity (shared parameters, ln sigma, range offset, and cos / sin of
every phase: ranks need an ordering, which a circle lacks), and of the log
posterior itself (the data-dependent quantity Modrak et al. 2023 recommend: it
ranks high when the sampler misses a mode the truth sits in). When the pipeline
samples the true posterior the ranks are uniform on 0..n_rank; the statistic is a
chi-square test of uniformity over ``n_bins`` rank bins per quantity (p-values),
plus the pooled chi-square over all quantities.

The noise prior is narrowed (``sigma``) to levels where the data say something;
the SBC then checks the pipeline at those levels only.
"""
from __future__ import annotations

import numpy as np

from ..generator import ClassParams, load_reference
from ..radar import RadarConfig
from .calibrate import run_calibration, start_vector
from .likelihood import LogPosterior
from .priors import Layout, Priors
from .settings import CalibrationSettings


def sbc_quantities(layout: Layout, theta: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """theta (n, dim) -> (n, q) quantities whose ranks SBC checks, and their names."""
    theta = np.atleast_2d(theta)
    names = layout.z_names() + [f"ln_sigma@{m}" for m in range(layout.M)]
    phase = np.zeros(layout.dim, bool)
    phase[layout.phase_cols] = True
    lin = theta[:, ~phase]
    ang = theta[:, phase]
    q = np.concatenate([lin, np.cos(ang), np.sin(ang)], axis=1)
    pn = [n for n, p in zip(names, phase) if p]
    return q, [n for n, p in zip(names, phase) if not p] + [f"cos {n}" for n in pn] + [f"sin {n}" for n in pn]


def run_sbc(reference: ClassParams | str = "HELI", n_replicates: int = 20, *,
            settings: CalibrationSettings | None = None,
            seed=0, sigma=(0.005, 0.03), n_rank: int = 99, n_bins: int = 5, n_engines: int | None = None,
            radar: RadarConfig = RadarConfig(), progress=None, prior_overrides: dict | None = None) -> dict:
    """Run SBC; returns ranks (R, q), names, p-values per quantity, pooled chi-square
    p-value, the share of converged runs and the settings used. prior_overrides:
    name=(lo, hi) bounds passed to :meth:`.priors.Priors.from_reference` (the truths
    are drawn from, and the calibrations use, that prior)."""
    from scipy import stats

    ref = load_reference(reference) if isinstance(reference, str) else reference
    settings = (settings or CalibrationSettings.quick()).replace(sigma_min=sigma[0], sigma_max=sigma[1])
    e = ref.n_engines if n_engines is None else int(n_engines)
    priors = Priors.from_reference(ref, radar, alignment=settings.alignment, **(prior_overrides or {}))
    layout = Layout(e, 1, priors, settings.range_offset)
    root = np.random.SeedSequence(seed)
    ranks, converged, names = [], [], None
    for i, ss in enumerate(root.spawn(n_replicates)):
        sim_ss, run_ss = ss.spawn(2)
        rng = np.random.default_rng(sim_ss)
        truth = layout.sample_prior(1, rng, sigma)
        z, ln_sig = layout.split_theta(truth)
        post0 = LogPosterior(np.zeros((1, radar.slice_length)), layout, radar, normalisation=settings.normalisation,
                             dtype=settings.dtype, sigma_bounds=sigma, alignment=settings.alignment)
        data = post0.model(z)[0] + np.exp(ln_sig[0])[:, None] * rng.standard_normal((1, radar.slice_length))
        post = LogPosterior(data, layout, radar, normalisation=settings.normalisation, dtype=settings.dtype,
                            sigma_bounds=sigma, alignment=settings.alignment)
        res = run_calibration(post, ref, settings, run_ss, start_vector(ref, e))
        draws_theta = _result_theta(res, layout)
        pick = np.linspace(0, len(draws_theta) - 1, n_rank).round().astype(int)
        q_true, names = sbc_quantities(layout, truth)
        q_draw, _ = sbc_quantities(layout, draws_theta[pick])
        # the log posterior as one more test quantity: a sampler that misses a mode
        # holding the truth ranks the truth's log posterior above its draws'
        q_true = np.append(q_true, post(truth))
        q_draw = np.column_stack([q_draw, post(draws_theta[pick])])
        names = names + ["log posterior"]
        ranks.append(np.sum(q_draw < q_true, axis=0))
        converged.append(res.converged)
        if progress:
            progress(i + 1, n_replicates)
    ranks = np.array(ranks)
    edges = np.linspace(0, n_rank + 1, n_bins + 1)
    counts = np.stack([np.histogram(ranks[:, j], bins=edges)[0] for j in range(ranks.shape[1])])
    expected = n_replicates / n_bins
    chi2 = ((counts - expected) ** 2 / expected).sum(axis=1)
    pvals = stats.chi2.sf(chi2, n_bins - 1)
    pooled = stats.chi2.sf(chi2.sum(), (n_bins - 1) * len(chi2))
    return {"ranks": ranks, "names": names, "p_values": dict(zip(names, map(float, pvals))),
            "pooled_p": float(pooled), "chi2": dict(zip(names, map(float, chi2))), "n_rank": n_rank,
            "converged_share": float(np.mean(converged)), "settings": settings.to_dict(),
            "min_p": float(pvals.min()), "n_replicates": n_replicates}


def _result_theta(res, layout: Layout) -> np.ndarray:
    """The sampled coordinates (n, dim) of a result's draws, in sampler order."""
    post = res.idata.posterior
    cols = []
    names = layout.z_names()
    for n in names:
        base, rest = n.split("[", 1) if "[" in n else (n, "")
        if base.startswith("phi_"):
            k, m = int(rest.split("]")[0]), int(n.split("@")[1])
            cols.append(post[base].values[0, :, m, k])
        elif base.startswith("offset@"):
            cols.append(post["offset"].values[0, :, int(base.split("@")[1])])
        elif base == "lnG":
            k = int(rest.split("]")[0])
            cols.append(np.log(post["Gamma"].values[0, :, k] / layout.priors.gamma0))
        else:
            k = int(rest.split("]")[0])
            cols.append(post[base].values[0, :, k])
    for m in range(layout.M):
        cols.append(np.log(post["sigma"].values[0, :, m]))
    return np.column_stack(cols)
