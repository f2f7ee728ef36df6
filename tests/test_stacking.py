"""The stacked route: the weight stacking chooses, the mixture's draws, and its SBC
derived from two routes' runs on the same drones (a conjugate toy with known answers)."""
import numpy as np
import pytest
from scipy import integrate, optimize, stats

from mdaug.inference.amortized.stacked import mix_draws, mixture_log_density
from mdaug.inference.diagnostics.routes import run
from mdaug.inference.diagnostics.stacking import stacked_row, stacking_weight
from mdaug.inference.diagnostics.yardsticks import honest


def _best_weight(sd_a, sd_b):
    """The weight that maximises E log(w N(x; 0, sd_a) + (1 - w) N(x; 0, sd_b)), x ~ N(0, 1), by quadrature."""
    def loss(w):
        f = lambda x: stats.norm.pdf(x) * np.log(w * stats.norm.pdf(x, 0, sd_a) + (1 - w) * stats.norm.pdf(x, 0, sd_b))
        return -integrate.quad(f, -12, 12)[0]
    return optimize.minimize_scalar(loss, bounds=(1e-6, 1 - 1e-6), method="bounded").x


def test_the_stacking_weight_is_the_mixture_that_predicts_the_truth_best():
    x = np.random.default_rng(0).standard_normal(40000)
    a, b = stats.norm.logpdf(x, 0, 0.5), stats.norm.logpdf(x, 0, 2.0)  # too narrow, too wide
    w = stacking_weight(a, b)
    assert 0.2 < w < 0.8 and w == pytest.approx(_best_weight(0.5, 2.0), abs=0.02)
    # the mixture beats both routes on the log score, by the objective it maximised
    assert -np.mean(mixture_log_density(a, b, w)) < min(-a.mean(), -b.mean())
    exact = stats.norm.logpdf(x)
    assert stacking_weight(exact, b) > 0.97  # an exact route takes (nearly) all the weight
    assert stacking_weight(b, exact) < 0.03
    with pytest.raises(ValueError, match="equal-length"):
        stacking_weight(a, b[:-1])
    with pytest.raises(ValueError, match="density 0"):
        stacking_weight(np.array([-np.inf, 0.0]), np.array([-np.inf, 0.0]))


def test_mixture_draws_take_each_component_at_its_weight():
    rng = np.random.default_rng(1)
    a, b = np.zeros((50, 2)), np.ones((7, 2))
    d, share = mix_draws(a, b, 0.8, 20000, rng)
    assert d.shape == (20000, 2) and share == pytest.approx((d[:, 0] == 0).mean())
    assert share == pytest.approx(0.8, abs=0.01)
    for bad in (0.0, 1.0):
        with pytest.raises(ValueError, match="weight must be in"):
            mix_draws(a, b, bad, 3, rng)
    with pytest.raises(ValueError, match="same width"):
        mix_draws(a, np.ones((3, 3)), 0.5, 3, rng)


class _Route:
    """Conjugate toy: theta ~ N(0, 1), x_i ~ N(theta, 1), posterior N(sum x / (n + 1), 1 / (n + 1)),
    drawn (and with its density) at ``scale`` x the exact sd."""

    def __init__(self, scale):
        self.scale = scale

    def _moments(self, x):
        return x.sum() / (len(x) + 1), self.scale * np.sqrt(1 / (len(x) + 1))

    def __call__(self, x, n, s):
        m, sd = self._moments(x)
        return m + sd * np.random.default_rng(s).standard_normal((n, 1)), True

    def log_density(self, u, x, s):
        m, sd = self._moments(x)
        return stats.norm.logpdf(u[0], m, sd)


def _rows(n_truths, seed, scales, draw_seed=None, keep_draws=False):
    rng = np.random.default_rng(seed)
    truths = rng.normal(size=(n_truths, 1))
    data = [t + rng.normal(size=5) for t in truths[:, 0]]
    return {k: run(_Route(k), truths, data, ["theta"], seed=seed if draw_seed is None else draw_seed,
                   to_unbounded=lambda q: q, keep_draws=keep_draws) for k in scales}


def test_the_stacked_rows_widths_are_the_mixtures_where_both_routes_kept_their_draws():
    from types import SimpleNamespace

    from mdaug.inference.estimator_job import add_stacked, trimmed_row

    w = 0.7
    rows = _rows(600, 21, (0.5, 2.0), keep_draws=True)
    truths = rows[0.5]["truths"][:, 0]
    # the exact mixture's 90% interval: w N(m, (0.5 s)^2) + (1 - w) N(m, (2 s)^2), s the exact sd
    x95 = optimize.brentq(lambda x: w * stats.norm.cdf(x / 0.5) + (1 - w) * stats.norm.cdf(x / 2.0) - 0.95, 0, 10)
    exact = np.median(2 * x95 * np.sqrt(1 / 6) / np.abs(truths))
    row = stacked_row(rows[0.5], rows[2.0], w)
    assert row["width_over_truth"]["theta"] == pytest.approx(exact, rel=0.1)
    assert rows[0.5]["width_over_truth"]["theta"] < row["width_over_truth"]["theta"] < rows[2.0]["width_over_truth"][
        "theta"]
    bare = stacked_row(*_rows(50, 22, (0.5, 2.0)).values(), w)
    assert "width_over_truth" not in bare and "tarp_atc" not in bare  # no draws, no widths, no TARP
    # a table's rows: the stacked one derived with its widths, the draws dropped from every row before it is stored
    table = {"smc": rows[0.5], "amortized": rows[2.0]}
    add_stacked(SimpleNamespace(stacking_weight=w, label_free=SimpleNamespace(to_unbounded=lambda q: q)), table,
                ("smc", "stacked"))
    assert table["stacked"]["width_over_truth"] == row["width_over_truth"]
    assert table["stacked"]["tarp_atc"] == pytest.approx(row["tarp_atc"])
    assert not any("draws" in r or "truths" in r for r in table.values())
    assert "width_over_truth" in trimmed_row({**table["stacked"], "verdict": "honest"})
    narrow = rows[0.5]["coverage_by_quantity"]["theta"]["0.90"]  # a row keeps its least covered quantities
    assert trimmed_row(table["smc"])["lowest_coverage"] == [["theta", narrow]] and narrow < 0.75


def test_a_stacked_narrow_and_wide_route_is_honest_and_beats_both_where_the_weight_was_not_chosen():
    fit = _rows(400, 11, (0.5, 2.0))  # the weight's drones
    w = stacking_weight(-np.asarray(fit[0.5]["log_score_by_drone"]), -np.asarray(fit[2.0]["log_score_by_drone"]))
    held = _rows(1500, 12, (0.5, 2.0, 1.0))  # other drones: the gate's
    row = stacked_row(held[0.5], held[2.0], w, sources=("narrow", "wide"))
    assert not honest(held[0.5])  # the narrow route alone is overconfident
    assert honest(row) and "verdict" not in row  # the route table's caller judges it
    # its shape is a mixture's: the wide route's tails (outer share under 0.10), the narrow one's core
    assert row["outer_share"] < 0.06 and row["coverage"]["0.50"] < 0.47
    assert row["log_score"] < min(held[0.5]["log_score"], held[2.0]["log_score"])
    assert row["log_score"] > held[1.0]["log_score"] - 0.02  # no better than the exact posterior
    assert row["derived_from"] == ["narrow", "wide"] and row["n_replicates"] == 1500
    # two exact routes stacked are exact: coverage 0.90 of the mixture's CDF, flat ranks
    same, again = _rows(1500, 13, (1.0,))[1.0], _rows(1500, 13, (1.0,), draw_seed=10 ** 6)[1.0]  # other draws
    exact = stacked_row(same, again, 0.5)
    assert exact["coverage"]["0.90"] == pytest.approx(0.90, abs=0.025) and exact["pooled_p"] > 1e-3
    other = run(_Route(1.0), np.zeros((1, 1)), [np.zeros(5)], ["theta"], seed=0, to_unbounded=lambda q: q)
    with pytest.raises(ValueError, match="same drones"):
        stacked_row(same, other, 0.5)
    with pytest.raises(ValueError, match="weight must be in"):
        stacked_row(same, same, 1.0)


def test_the_stacked_rows_tarp_is_its_mixtures():
    """TARP of the mixture's own draws: near 0 for two exact routes stacked; negative (the
    truth too often outside: overconfident) for a narrow route with itself, positive for a wide one."""
    rows = _rows(400, 31, (0.5, 1.0, 2.0), keep_draws=True)
    other = _rows(400, 31, (1.0,), draw_seed=10 ** 6, keep_draws=True)[1.0]  # the exact route's other draws
    ident = lambda q: q  # noqa: E731
    exact = stacked_row(rows[1.0], other, 0.5, to_unbounded=ident)
    narrow = stacked_row(rows[0.5], rows[0.5], 0.5, to_unbounded=ident)
    wide = stacked_row(rows[2.0], rows[2.0], 0.5, to_unbounded=ident)
    assert abs(exact["tarp_atc"]) < 0.03 and exact["tarp_ks_p"] > 0.5
    assert narrow["tarp_atc"] < -0.05 < 0.03 < wide["tarp_atc"]
    assert narrow["tarp_atc"] == pytest.approx(rows[0.5]["tarp_atc"], abs=0.02)  # a route with itself: its own
