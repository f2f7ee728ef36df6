"""The ratio network's posterior: the target of the smc route on a file without a summary likelihood.

In the label-free coordinates u (:mod:`.target`): the calibration prior's density
there (:meth:`.target.LabelFree.log_prior_u`, in closed form: the uniform box pushed
through the label-free map) times the learned likelihood, the per-measurement ratio
network summed over the measurements as independent (log p(x | u) - log p(x)). Not
the amortized posterior's own density: the two are learned apart and judged by the
same SBC.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LearnedPosterior:
    """log prior + learned log-likelihood of label-free draws u (W, d); vectorised."""

    estimator: object
    profiles: np.ndarray

    def __post_init__(self):
        self.label_free = self.estimator.label_free
        self.emb = self.estimator.embed(self.profiles)
        self.dim = self.label_free.dim
        self.n_calls = 0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(u)
        lp = self.label_free.log_prior_u(u)
        ok = np.isfinite(lp)
        if ok.any():
            lp[ok] += self.estimator.log_likelihood_u(u[ok], self.emb).sum(axis=1)
        self.n_calls += len(u)
        return lp

    def vectors(self, u: np.ndarray) -> np.ndarray:
        """Class vectors (n, 13E) of draws u (the prior's labelling closest to the reference)."""
        x, _ = self.label_free.vectors(self.label_free.from_unbounded(u))
        return x
