"""Yardsticks beside SBC: is a posterior honest, and how sharp is it?

SBC alone cannot rank routes: the prior itself passes it. So every route is judged on
the same fresh drones by

* the **gate** (:func:`mdaug.inference.result.status.honest`, the one rule a status word
  is printed from too): not overconfident, i.e. an outer-10% share of at most
  ``OUTER_MAX`` and every quantity's 90% coverage at least ``COVERAGE_MIN`` (a
  posterior wider than the data allow passes; it loses on the next yardstick);
* the **log score** of the truth (:func:`log_score`): the mean of -log q(u_true | x)
  over drones, in the unbounded label-free coordinates u (lower is sharper *and*
  right). q is the route's own normalised density where it has one (``log_score_by``
  'exact': the amortized posterior's flow on the prior's support; the smc route's
  target normalised by the evidence its own run estimated, up to that estimate's Monte
  Carlo error), else a Gaussian fitted to the route's draws ('gaussian'; a draws-only
  route). The Gaussian's score is kept beside it for every route
  (``log_score_gaussian``: one density family, which reads a multimodal posterior's
  truths between modes as likely and a sharp posterior's rare far truths as costly);
* the median 90% width over the truth per quantity (:mod:`.routes`), beside the
  Cramer-Rao bound where the route has a likelihood.

:func:`mdaug.inference.diagnostics.routes.route_table` runs several routes on the same
drones and names the default: the best log score among the routes that pass the gate.
"""
from __future__ import annotations

import numpy as np

from ..result.status import COVERAGE_MIN, OUTER_MAX, honest, verdict  # noqa: F401 (the gate, one place)

def gaussian_log_density(samples: np.ndarray, points: np.ndarray, ridge: float = 1e-9) -> np.ndarray:
    """log N(point; mean, cov) of a Gaussian fitted to each replicate's draws:
    samples (S, R, d), points (R, d) -> (R,)."""
    s = np.asarray(samples, float)
    p = np.asarray(points, float)
    mean = s.mean(axis=0)
    dev = s - mean
    cov = np.einsum("sri,srj->rij", dev, dev) / (len(s) - 1)
    d = s.shape[-1]
    scale = np.trace(cov, axis1=1, axis2=2)[:, None, None] / d
    cov = cov + ridge * scale * np.eye(d)
    chol = np.linalg.cholesky(cov)
    r = np.linalg.solve(chol, (p - mean)[..., None])[..., 0]
    return -0.5 * (r * r).sum(-1) - np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(-1) - 0.5 * d * np.log(2 * np.pi)


def log_score(samples_u: np.ndarray, truths_u: np.ndarray, log_density: np.ndarray | None = None) -> dict:
    """Mean and per-drone -log q(u_true | x) (module doc): samples_u (S, R, d), truths_u
    (R, d); log_density (R,): the route's own log density at each truth, where it has one."""
    gauss = -gaussian_log_density(samples_u, truths_u)
    nl = gauss if log_density is None else -np.asarray(log_density, float)
    return {"log_score": float(np.mean(nl)), "log_score_median": float(np.median(nl)),
            "log_score_by_drone": nl.tolist(), "log_score_by": "gaussian" if log_density is None else "exact",
            "log_score_gaussian": float(np.mean(gauss))}
