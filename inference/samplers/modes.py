"""Mode jumps for the tempered SMC sampler: local optima found by polishing
particles, and a Student-t mixture centred on them used as an independence
proposal.

Why: on a single HELI profile the posterior has modes of similar height that
differ in several coordinates at once (measured: the alpha-beta line placed 1.4 or
3 bins from the tone, with its amplitude, phase and the tone offset all moving
together). Single-coordinate redraws and differential-evolution moves never make
that joint step, so a mode the tempering did not populate early stays empty and
the posterior misses it (SBC: the truth lands in modes holding no particle).
An independence Metropolis-Hastings step from a mixture q over the known modes (the
toolbox's one Laplace approximation + Student-t mixture,
:func:`.toolbox.laplace_at` and :class:`.toolbox.StudentMixture`),
accepted with ratio pi(x') q(x) / (pi(x) q(x')), moves particles between modes
and gives each mode its posterior mass whatever q's weights are; q only has to
cover the modes.

Phases: a component is a Student-t on the wrapped difference to its centre,
truncated to [-pi, pi) in every phase coordinate (:class:`.toolbox.StudentMixture`).
"""
from __future__ import annotations

import numpy as np

from ...generator.model import wrap_phase
from .toolbox import INFLATE, StudentMixture, cap_cov, laplace_at

MAX_MODES = 16
SAME_MODE = 0.02  # optima closer than this (max |difference| / prior width) are one mode


def merge_modes(thetas: np.ndarray, values: np.ndarray, width: np.ndarray, phase_cols,
                max_modes: int = MAX_MODES) -> tuple[np.ndarray, np.ndarray]:
    """Distinct optima, best first: thetas (n, dim) with values (n,) (higher is better);
    two are one mode when every coordinate differs by less than SAME_MODE x width
    (phases compared on the circle). Returns (modes (K, dim), values (K,))."""
    order = np.argsort(-np.asarray(values))
    keep: list[int] = []
    cols = np.asarray(phase_cols, int)
    for i in order:
        ok = True
        for j in keep:
            diff = thetas[i] - thetas[j]
            if cols.size:
                diff[cols] = wrap_phase(diff[cols])
            if np.max(np.abs(diff) / width) < SAME_MODE:
                ok = False
                break
        if ok:
            keep.append(int(i))
        if len(keep) == max_modes:
            break
    return thetas[keep], np.asarray(values)[keep]


DISCOVER_AT = (0.0, 1e-3, 1e-2, 0.1, 0.5)
"""Tempering levels (beta) at which particles are polished to look for new optima."""


class ModeFinder:
    """The optima of a :class:`..likelihood.fitted_phases.LogPosterior` found so far, each with its
    log posterior and Laplace covariance, and the mode mixture built from them.

    At the first stage whose beta reaches each of ``discover_at``, ``n_polish``
    particles drawn from the population are polished by ``LN_BOBYQA``
    (``polish_budget`` evaluations each, the fit's objective: sigma profiled out);
    new optima (see :func:`merge_modes`) get a Hessian of the log-likelihood.
    ``seed_thetas``: optima known beforehand (the fit's starts). At tempering level
    beta a component's covariance is the Laplace covariance / beta (the tempered
    likelihood is wider), inflated by ``INFLATE`` and capped at 0.3 prior widths.
    """

    def __init__(self, post, *, n_polish: int = 8, polish_budget: int = 800, discover_at=DISCOVER_AT,
                 seed_thetas=None, max_sd_share: float = 0.3):
        lay = post.layout
        self.post, self.n_polish, self.polish_budget = post, int(n_polish), int(polish_budget)
        self.discover_at = tuple(discover_at)
        lo, hi = lay.theta_bounds()
        self.width = hi - lo
        self.max_sd = max_sd_share * self.width
        d = lay.dim
        self.means, self.values, self.covs = np.empty((0, d)), np.empty(0), np.empty((0, d, d))
        self.n_discoveries = 0
        self._pending = None if seed_thetas is None else np.atleast_2d(np.asarray(seed_thetas, float))

    # ---- state (checkpoints) ----------------------------------------------------
    def state(self) -> dict:
        return {"means": self.means, "values": self.values, "covs": self.covs,
                "n_discoveries": np.array(self.n_discoveries)}

    def load(self, state: dict) -> None:
        if state:
            self.means, self.values, self.covs = state["means"], state["values"], state["covs"]
            self.n_discoveries = int(state["n_discoveries"])
            self._pending = None

    # ---- finding ------------------------------------------------------------------
    def polish(self, thetas: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, int]:
        """Local optima (n, dim) reached from thetas (n, dim) and the evaluations used."""
        import nlopt

        from ..fit import run_one

        post = self.post
        lo, hi = post.fit_bounds()
        d = len(lo)
        out, evals = [], 0
        for th in np.atleast_2d(thetas):
            u0 = np.clip((th[:d] - lo) / (hi - lo), 0.0, 1.0)
            u, _, n = run_one(nlopt, "LN_BOBYQA", post, lo, hi, u0, self.polish_budget,
                               int(rng.integers(2**31 - 1)))
            v = post.canonical_fit((lo + (hi - lo) * u)[None])
            out.append(post.theta_from_fit(v)[0])
            evals += n + 1
        return np.array(out), evals

    def add(self, optima: np.ndarray) -> int:
        """Merge optima (n, dim) into the known modes; new ones get a Laplace covariance.
        Returns the evaluations used."""
        lay = self.post.layout
        values = self.post(optima)
        optima, values = optima[np.isfinite(values)], values[np.isfinite(values)]
        if not len(optima):
            return len(values)
        allm = np.concatenate([self.means, optima])
        allv = np.concatenate([self.values, values])
        modes, vals = merge_modes(allm, allv, self.width, lay.phase_cols)
        covs, evals = [], len(values)
        for mu in modes:
            known = np.flatnonzero(np.all(self.means == mu, axis=1)) if len(self.means) else []
            if len(known):
                covs.append(self.covs[known[0]])
                continue
            cov, n = laplace_at(self.post, lay, mu, log_f=self.post.log_likelihood, max_sd=self.max_sd)
            evals += n
            covs.append(cov)
        self.means, self.values, self.covs = modes, vals, np.array(covs)
        return evals

    def update(self, theta: np.ndarray, beta: float, rng: np.random.Generator) -> int:
        """Called once per SMC stage with the resampled population at level beta:
        polish particles when beta has reached the next discovery level."""
        evals = 0
        if self._pending is not None:
            evals += self.add(self._pending)
            self._pending = None
        while self.n_discoveries < len(self.discover_at) and beta >= self.discover_at[self.n_discoveries]:
            self.n_discoveries += 1
            uniq = np.unique(theta, axis=0)
            pick = uniq[rng.choice(len(uniq), size=min(self.n_polish, len(uniq)), replace=False)]
            optima, n = self.polish(pick, rng)
            evals += n + self.add(optima)
        return evals

    def mixture(self, beta: float, rng: np.random.Generator) -> StudentMixture | None:
        """The equal-weight mixture over the known modes at tempering level beta."""
        if not len(self.means):
            return None
        covs = [cap_cov(c * INFLATE**2 / max(beta, 1e-12), self.max_sd) for c in self.covs]
        return StudentMixture.build(self.means, covs, self.post.layout.phase_cols, rng)
