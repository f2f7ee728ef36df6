"""Choosing the amortized posterior's temperature (mdaug.inference.temperature) on a
conjugate toy whose exact posterior is known: a flow 0.7 x too narrow is overconfident at
T = 1, and the choice is the temperature that undoes it, not a wider one that also passes."""
import numpy as np
from scipy.stats import norm

from mdaug.inference.temperature import GRID, fit_temperature


class _Identity:
    names = ["theta"]

    def to_unbounded(self, q):
        return np.asarray(q, float)

    def from_unbounded(self, u):
        return np.asarray(u, float)


class NarrowToy:
    """theta ~ N(0, 1), x_i ~ N(theta, 1): posterior N(sum x / (n + 1), 1 / (n + 1)); this
    'flow' draws it ``shrink`` x too narrow at T = 1, T x wider at temperature T."""

    label_free = _Identity()

    def __init__(self, shrink: float, temperature: float = 1.0):
        self.shrink, self.temperature = shrink, temperature

    def at_temperature(self, t):
        return NarrowToy(self.shrink, t)

    def _moments(self, x):
        return x.sum() / (len(x) + 1), self.shrink * self.temperature / np.sqrt(len(x) + 1)

    def sample_u(self, x, n, seed, strict=True):
        m, sd = self._moments(x)
        return (m + sd * np.random.default_rng(seed).standard_normal((n, 1))), 1.0

    def truncated_log_prob_u(self, u, x, seed):
        m, sd = self._moments(x)
        return norm.logpdf(np.asarray(u)[:, 0], m, sd)


def test_the_temperature_that_undoes_a_too_narrow_flow_is_chosen():
    rng = np.random.default_rng(11)
    truths = rng.normal(size=(400, 1))
    data = [t + rng.normal(size=5) for t in truths[:, 0]]
    fit = fit_temperature(NarrowToy(0.7), truths, data, seed=3, log=lambda m: None)
    rows = fit["rows"]
    assert list(rows) == [f"{t:g}" for t in GRID[: len(rows)]] and fit["drones"] == 400
    assert rows["1"]["verdict"] == "overconfident" and rows["1"]["outer_share"] > 0.2
    assert fit["passed"] and fit["temperature"] in (1.4, 1.5)  # 0.7 T = 1 at T = 1.43
    last = list(rows)[-1]  # the search stops past the log score's minimum
    assert float(last) > fit["temperature"] and rows[last]["verdict"] == "honest"  # wider passes the gate...
    assert rows[last]["log_score"] > rows[f"{fit['temperature']:g}"]["log_score"]  # ...and loses on the score
    assert all(r["log_score_by"] == "exact" for r in rows.values())


def test_a_right_flow_keeps_temperature_one_and_none_passing_takes_the_nearest():
    rng = np.random.default_rng(12)
    truths = rng.normal(size=(400, 1))
    data = [t + rng.normal(size=5) for t in truths[:, 0]]
    assert fit_temperature(NarrowToy(1.0), truths, data, seed=3, log=lambda m: None)["temperature"] == 1.0
    far = fit_temperature(NarrowToy(0.3), truths, data, grid=(1.0, 1.5, 2.0), seed=3, log=lambda m: None)
    assert not far["passed"] and far["temperature"] == 2.0  # 0.6 x the posterior: the nearest to passing
    assert len(far["rows"]) == 3  # no stop before a temperature passes
