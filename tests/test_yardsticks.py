"""Yardsticks beside SBC on toys with known answers: the summary's covariance, the
Fisher information and Cramer-Rao bound, the log score and the route table's gate."""
import numpy as np
import pytest

from mdaug.inference.diagnostics.routes import route_table
from mdaug.inference.diagnostics.yardsticks import gaussian_log_density, honest
from mdaug.inference.emulator.model import cramer_rao, fisher_information
from mdaug.inference.emulator.summary import Whitening, folded_log_profile


def test_fisher_information_of_a_linear_gaussian_model_is_a_s_inverse_a():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 2))
    s = np.diag([0.5, 1.0, 2.0, 1.0, 0.3, 4.0])
    info = fisher_information(a, s)
    np.testing.assert_allclose(info, a.T @ np.linalg.inv(s) @ a, rtol=1e-12)
    # the bound is the covariance of the least-squares estimate (generalised LS)
    np.testing.assert_allclose(cramer_rao(info), np.linalg.inv(a.T @ np.linalg.inv(s) @ a), rtol=1e-10)


def test_fisher_information_of_a_variance_parameter():
    # x_i ~ N(0, sigma^2) for D i.i.d. components: I(sigma^2) = D / (2 sigma^4)
    d, var = 7, 2.5
    info = fisher_information(np.zeros((d, 1)), var * np.eye(d), dcov=np.eye(d)[None])
    assert info[0, 0] == pytest.approx(d / (2 * var ** 2))


def test_cramer_rao_of_an_unidentified_direction_is_infinite():
    info = np.array([[4.0, 0.0], [0.0, 0.0]])
    bound = cramer_rao(info)
    assert bound[0, 0] == pytest.approx(0.25)
    assert np.isinf(bound[1, 1])


def test_whitening_makes_the_within_drone_covariance_the_identity_and_orders_by_between():
    rng = np.random.default_rng(1)
    n, m, f = 400, 8, 5
    within = np.diag([1.0, 4.0, 0.25, 1.0, 2.0])
    means = rng.normal(size=(n, f)) * np.array([3.0, 0.1, 0.1, 1.0, 0.1])
    s = means[:, None, :] + rng.multivariate_normal(np.zeros(f), within, size=(n, m))
    w = Whitening.fit(s, 3)
    dev = (s - s.mean(1, keepdims=True)).reshape(-1, f) @ w.basis.T
    cov = dev.T @ dev / (n * (m - 1))
    np.testing.assert_allclose(cov, np.eye(3), atol=2e-5)  # the fit adds a ridge of 1e-6 x the mean variance
    assert list(w.between) == sorted(w.between, reverse=True)
    assert w.between[0] == pytest.approx(9.0, rel=0.25)  # var 9 along component 0, within 1


def test_folded_log_profile_averages_both_sides_and_refuses_too_many_offsets():
    p = np.full(21, 0.01)
    p[10] = 1.0
    p[12], p[8] = 0.1, 0.001
    s = folded_log_profile(p, 3)
    np.testing.assert_allclose(s, [-2.0, 0.5 * (-1 - 3), -2.0])
    with pytest.raises(ValueError, match="n_offsets must be in 1..10"):
        folded_log_profile(p, 11)


def test_gaussian_log_density_matches_scipy():
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(2)
    s = rng.normal(size=(5000, 1, 3)) @ np.array([[1.0, 0.3, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.5]])
    pt = np.array([[0.3, -0.2, 0.1]])
    ref = multivariate_normal(s[:, 0].mean(0), np.cov(s[:, 0], rowvar=False)).logpdf(pt[0])
    assert gaussian_log_density(s, pt)[0] == pytest.approx(ref, rel=1e-7)  # the ridge: 1e-9 x the mean variance


def _conjugate(n_truths=300, n_obs=5, seed=3):
    """theta ~ N(0, 1), x_i ~ N(theta, 1): posterior N(sum x / (n + 1), 1 / (n + 1))."""
    rng = np.random.default_rng(seed)
    truths = rng.normal(size=(n_truths, 1))
    data = [t + rng.normal(size=n_obs) for t in truths[:, 0]]

    def route(scale):
        def draw(x, n, s):
            r = np.random.default_rng(s)
            mean, sd = x.sum() / (len(x) + 1), np.sqrt(1 / (len(x) + 1))
            return mean + scale * sd * r.standard_normal((n, 1)), True
        return draw

    return truths, data, route


def test_route_table_passes_the_exact_posterior_fails_a_narrow_one_and_ranks_a_wide_one_below():
    truths, data, route = _conjugate()
    table = route_table({"exact": route(1.0), "narrow": route(0.5), "wide": route(2.0)}, truths, data,
                        ["theta"], to_unbounded=lambda q: q, n_rank=199)
    rows = table["rows"]
    assert honest(rows["exact"]) and rows["exact"]["verdict"] == "honest"
    assert 0.06 <= rows["exact"]["outer_share"] <= 0.14
    assert not honest(rows["narrow"]) and rows["narrow"]["verdict"] == "overconfident"
    assert rows["narrow"]["outer_share"] > 0.3
    assert honest(rows["wide"])  # conservative passes the gate...
    assert rows["wide"]["log_score"] > rows["exact"]["log_score"] + 0.3  # ...and loses on the log score
    assert table["default"] == "exact"
    # the exact posterior's log score is the expected entropy-plus-nothing: 0.5 log(2 pi e / 6)
    assert rows["exact"]["log_score"] == pytest.approx(0.5 * np.log(2 * np.pi * np.e / 6), abs=0.12)


def test_the_gates_noise_floor_is_how_often_exact_posteriors_fail_it():
    """Exact posteriors of d independent quantities, R truths each, 199 draws: the share of
    runs that fail the gate's coverage rule is :func:`exact_fail_chance`, and it falls with R."""
    from mdaug.inference.diagnostics.routes import coverage
    from mdaug.inference.result.status import COVERAGE_MIN, exact_fail_chance, noise_note

    rng = np.random.default_rng(4)
    runs, R, d = 400, 40, 8
    fails = 0
    for _ in range(runs):  # truth and draws from the same posterior: N(0, 1) per quantity
        cov = coverage(rng.standard_normal((199, R, d)), rng.standard_normal((R, d)), [str(j) for j in range(d)])
        fails += cov["coverage90_range"][0] < COVERAGE_MIN
    chance = exact_fail_chance(R, d)
    assert 0.6 < chance < 0.8  # 0.70: a 40-drone verdict on 8 quantities says little
    assert fails / runs == pytest.approx(chance, abs=4 * np.sqrt(chance * (1 - chance) / runs))
    assert exact_fail_chance(100, 35) == pytest.approx(0.94, abs=0.01)
    assert exact_fail_chance(300, 35) == pytest.approx(0.33, abs=0.01) and exact_fail_chance(3000, 35) < 1e-6
    assert exact_fail_chance(300, 35, n_draws=10 ** 6) == pytest.approx(0.08, abs=0.01)  # the 0.9 of many draws
    assert "chance 0.94" in noise_note(100, 35) and noise_note(3000, 8) == "" and noise_note(None, 8) == ""
    from mdaug.inference.result.status import lowest_coverage_chance

    assert lowest_coverage_chance(300, 35, 0.827) == pytest.approx(0.019, abs=0.002)  # QUAD's smc route's lowest
    assert lowest_coverage_chance(100, 35, 0.84) == pytest.approx(exact_fail_chance(100, 35))  # the same model
    with pytest.raises(ValueError, match="1 truth"):
        exact_fail_chance(0, 8)


def test_a_density_route_is_scored_by_its_own_density_and_beats_the_gaussian_fit_when_bimodal():
    """x_i ~ N(|theta|, 1) (20 of them), theta ~ N(0, 1): the posterior is N(|theta|; m, v) / (2 Phi(m / sqrt v)),
    m = n xbar / (n + 1), v = 1 / (n + 1), two mirrored modes. A route that knows its
    density is scored by it (exactly the mean of -log p(theta_true | x)); a Gaussian
    fitted to its draws straddles the modes and scores worse, and is kept beside it."""
    from scipy.stats import norm

    rng = np.random.default_rng(8)
    truths = rng.normal(size=(300, 1))
    data = [abs(t) + rng.normal(size=20) for t in truths[:, 0]]

    def moments(x):
        return x.sum() / (len(x) + 1), np.sqrt(1 / (len(x) + 1))

    def log_p(theta, x):
        m, sd = moments(x)
        return norm.logpdf(abs(theta), m, sd) - np.log(2 * norm.cdf(m / sd))

    def draw(x, n, s):
        r = np.random.default_rng(s)
        m, sd = moments(x)
        mag = m + sd * norm.ppf(r.uniform(norm.cdf(-m / sd), 1, n))  # N(m, sd) truncated to > 0
        return (mag * r.choice([-1.0, 1.0], n))[:, None], True

    def exact(x, n, s):
        return draw(x, n, s)

    exact.log_density = lambda u, x, s: log_p(u[0], x)
    rows = route_table({"draws": draw, "density": exact}, truths, data, ["theta"], to_unbounded=lambda q: q)["rows"]
    assert rows["density"]["log_score_by"] == "exact" and rows["draws"]["log_score_by"] == "gaussian"
    want = -np.mean([log_p(t, x) for t, x in zip(truths[:, 0], data)])
    assert rows["density"]["log_score"] == pytest.approx(want, rel=1e-12)
    assert rows["draws"]["log_score"] == rows["draws"]["log_score_gaussian"]
    assert rows["density"]["log_score_gaussian"] == pytest.approx(rows["draws"]["log_score"], abs=0.05)  # same draws
    assert rows["density"]["log_score"] < rows["draws"]["log_score"] - 0.4  # the fitted Gaussian misses the modes
    assert honest(rows["density"]) and honest(rows["draws"])  # the same draws: the same ranks


def test_the_widening_recovers_a_log_linear_scale_of_chi_square_gaps():
    from mdaug.inference.emulator.train import fit_widening

    rng = np.random.default_rng(4)
    u = rng.normal(size=(3000, 3)) * [1.0, 2.0, 0.5]
    true_logw = 0.4 + 0.6 * (u[:, 0] - u[:, 0].mean()) / u[:, 0].std()
    gaps = np.exp(true_logw) * rng.chisquare(8, size=len(u))
    w = fit_widening(u, gaps, 8)
    assert w["intercept"] == pytest.approx(0.4, abs=0.05)
    assert w["slope"][0] == pytest.approx(0.6, abs=0.05)
    assert abs(w["slope"][1]) < 0.05 and abs(w["slope"][2]) < 0.05


def test_the_widening_recovers_an_edge_widening_and_the_file_keeps_it():
    """Gaps that grow towards the prior's edges (log w quadratic in u) are recovered,
    and model.widen evaluates the fitted terms as fitted."""
    from types import SimpleNamespace

    from mdaug.inference.emulator.model import SummaryModel
    from mdaug.inference.emulator.train import fit_widening

    rng = np.random.default_rng(5)
    u = rng.normal(size=(4000, 2))
    t = (u - u.mean(0)) / u.std(0)
    true_logw = 0.3 + 0.5 * t[:, 1] ** 2
    gaps = np.exp(true_logw) * rng.chisquare(8, size=len(u))
    w = fit_widening(u, gaps, 8)
    assert w["quadratic"][1] == pytest.approx(0.5, abs=0.06)
    assert abs(w["quadratic"][0]) < 0.06 and abs(w["slope"][0]) < 0.06
    assert w["intercept"] == pytest.approx(0.3, abs=0.08)
    model = SummaryModel.__new__(SummaryModel)
    model.widening, model.label_free = w, SimpleNamespace(dim=2)
    got = np.log(model.widen(u[:50]))
    assert got == pytest.approx(np.clip(true_logw[:50], 0, 5), abs=0.15)
    assert "quadratic" not in fit_widening(u, gaps, 8, quadratic=False)


def test_a_raised_widening_is_w_to_the_power_times_the_scale_and_keeps_one_at_one():
    """raise_widening: log w' = power x log w + log scale wherever the clip does not bind;
    a drone the fit leaves at w = 1 (raw log w well below 0) stays at 1; the input is not
    changed; bad numbers are refused by name."""
    from types import SimpleNamespace

    from mdaug.inference.emulator.model import SummaryModel
    from mdaug.inference.emulator.train import raise_widening

    w = {"intercept": 0.2, "slope": [0.3, -0.1], "quadratic": [0.05, 0.0], "centre": [0.0, 0.0], "scale": [1.0, 1.0]}
    model = SummaryModel.__new__(SummaryModel)
    model.label_free = SimpleNamespace(dim=2)
    u = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, -1.0], [-3.0, 0.0]])
    model.widening = w
    log_w = np.log(model.widen(u))
    model.widening = raise_widening(w, power=2.5, scale=1.3)
    got = np.log(model.widen(u))
    raw = 0.2 + u @ [0.3, -0.1] + (u * u) @ [0.05, 0.0]  # before the clip
    assert got == pytest.approx(np.clip(2.5 * raw + np.log(1.3), 0, 5))
    assert got[:3] == pytest.approx(2.5 * log_w[:3] + np.log(1.3))  # where w > 1: w^2.5 x 1.3
    assert raw[3] < 0 and got[3] == 0.0  # a drone the fit leaves at w = 1 stays at 1
    assert w["intercept"] == 0.2 and w["slope"] == [0.3, -0.1]  # a copy
    back = raise_widening(raise_widening(w, 2.5, 1.3), 1 / 2.5, 1.3 ** (-1 / 2.5))  # undone
    for key in ("intercept", "slope", "quadratic"):
        assert back[key] == pytest.approx(w[key])
    for bad in ({"power": 0.0}, {"power": float("nan")}, {"scale": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            raise_widening(w, **bad)


def test_the_fisher_information_holds_the_widening_at_its_value_and_counts_no_slope_of_it():
    """A linear emulator (mean A u, covariance W / n, no error) widened by a w(u) that varies
    with u: the Fisher information is A' (w(u0) W / n)^-1 A, as for the constant w(u0); the
    widening's slope adds nothing."""
    from types import SimpleNamespace

    from mdaug.inference.emulator.model import SummaryModel

    rng = np.random.default_rng(6)
    a = rng.normal(size=(5, 2))
    wcov = np.diag([0.5, 1.0, 2.0, 1.5, 0.8])
    model = SummaryModel.__new__(SummaryModel)
    model.label_free, model.inflation = SimpleNamespace(dim=2), 1.0
    model.nets = lambda u, covariance=True: (np.atleast_2d(u) @ a.T, np.repeat(wcov[None], len(np.atleast_2d(u)), 0),
                                             np.zeros((len(np.atleast_2d(u)), 2)))
    model.widening = {"intercept": 0.4, "slope": [0.8, -0.5], "centre": [0.0, 0.0], "scale": [1.0, 1.0]}
    u0 = np.array([0.3, 0.2])
    w0 = model.widen(u0[None])[0]
    assert w0 > 1.5
    expected = a.T @ np.linalg.solve(w0 * wcov / 5, a)
    assert model.fisher(u0, 5) == pytest.approx(expected, rel=1e-6)


def test_likelihood_gaps_hold_the_covariance_at_the_plug_in_point_as_the_smc_route_does():
    """A linear emulator (mean A u) whose covariance grows with |u|: with the covariance held
    at a plug-in point p, twice the gap is the closed form r' C^-1 r - min_v (A v - z)' C^-1
    (A v - z), r = A u - z, C = W(p) / n; free in u it is not (the log-determinant moves)."""
    from types import SimpleNamespace

    from mdaug.inference.emulator.model import SummaryModel
    from mdaug.inference.emulator.train import likelihood_gaps

    rng = np.random.default_rng(8)
    a = rng.normal(size=(6, 2))
    w0 = np.diag([0.5, 1.0, 2.0, 1.5, 0.8, 1.2])

    def nets(u, covariance=True):
        u = np.atleast_2d(u)
        grow = 1.0 + (u * u).sum(1)
        return u @ a.T, w0[None] * grow[:, None, None], np.zeros((len(u), 2))

    model = SummaryModel.__new__(SummaryModel)
    model.label_free, model.inflation, model.widening, model.nets = SimpleNamespace(dim=2), 1.0, None, nets
    ut, p = np.array([0.4, -0.3]), np.array([0.1, 0.2])
    z = ut @ a.T + rng.normal(size=6) * 0.3
    c_inv = np.linalg.inv(w0 * (1.0 + p @ p) / 5)
    v = np.linalg.solve(a.T @ c_inv @ a, a.T @ c_inv @ z)
    r, rv = ut @ a.T - z, v @ a.T - z
    expected = r @ c_inv @ r - rv @ c_inv @ rv
    held = likelihood_gaps(model, ut[None], z[None], 5, max_eval=2000, plug_in=p[None])[0]
    assert held == pytest.approx(expected, rel=1e-4, abs=1e-6)
    free = likelihood_gaps(model, ut[None], z[None], 5, max_eval=2000)[0]
    assert abs(free - expected) > 0.05


def test_a_right_likelihoods_gap_counts_the_directions_the_data_identify():
    """reference_gaps on a linear Gaussian emulator of 3 quantities: twice the gap of
    summaries drawn from the model itself is chi-square(3) (mean 3) when the data identify
    all three, chi-square(2) when one quantity moves nothing (its likelihood flat), not
    chi-square(d); fit_widening against it finds no widening where the real gaps are the
    model's own, and w = 4 where they are 4 times larger."""
    from types import SimpleNamespace

    from mdaug.inference.emulator.model import SummaryModel
    from mdaug.inference.emulator.train import fit_widening, reference_gaps

    rng = np.random.default_rng(9)
    means = {}
    for flat in (False, True):
        a = rng.normal(size=(6, 3))
        if flat:
            a[:, 2] = 0.0
        model = SummaryModel.__new__(SummaryModel)
        model.label_free, model.inflation, model.widening = SimpleNamespace(dim=3), 1.0, None
        model.nets = lambda u, covariance=True, a=a: (np.atleast_2d(u) @ a.T, np.repeat(np.eye(6)[None], len(
            np.atleast_2d(u)), 0), np.zeros((len(np.atleast_2d(u)), 2)))
        u = np.zeros((60, 3))
        means[flat] = reference_gaps(model, u, u, 5, draws=4, seed=1, max_eval=400)
    assert np.mean(means[False]) == pytest.approx(3.0, rel=0.15)
    assert np.mean(means[True]) == pytest.approx(2.0, rel=0.15)
    k = np.full(400, 2.0)
    u = rng.normal(size=(400, 3))
    for true_w in (1.0, 4.0):
        w = fit_widening(u, true_w * rng.chisquare(k), k, quadratic=False)
        assert np.exp(w["intercept"]) == pytest.approx(true_w, rel=0.15)


def test_refit_widening_raises_the_files_own_fit_without_simulating(tmp_path, capsys):
    """tests/benchmarks/refit_widening.py with no drones: the shipped HELI K = 32 fit (its stated
    power 3 divided out) raised to 1.5 halves every coefficient of log w, the stale route table
    goes, the file says how; raised back to 3 it is the shipped widening again. A file with no
    summary likelihood is refused, naming it."""
    import importlib.util
    from pathlib import Path

    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import shipped_path

    path = Path(__file__).parent / "benchmarks" / "refit_widening.py"
    spec = importlib.util.spec_from_file_location("refit_widening", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    shipped = AmortizedEstimator.load(shipped_path("HELI", 32))
    assert shipped.meta["summary"]["training"]["widening_refit"]["power"] == 3.0
    none = ["--prior", "0", "--near", "0", "--specimens", "0"]
    assert bench.main(["--class", "HELI", "--ramps", "32", *none, "--power", "1.5", "--chosen-by", "a test",
                       "--out", str(tmp_path / "half.zip")]) == 0
    half = AmortizedEstimator.load(tmp_path / "half.zip")
    w0, w1 = shipped.summary.widening, half.summary.widening
    assert w1["intercept"] == pytest.approx(0.5 * w0["intercept"])
    assert w1["slope"] == pytest.approx(0.5 * np.asarray(w0["slope"]))
    assert w1["quadratic"] == pytest.approx(0.5 * np.asarray(w0["quadratic"]))
    record = half.meta["summary"]["training"]["widening_refit"]
    assert record["power"] == 1.5 and record["chosen_by"] == "a test" and record["raised_from"] == "heli-k32.zip"
    assert "route_table" not in half.meta["sbc"] and half.default_route == "amortized"
    assert bench.main(["--class", "HELI", "--ramps", "32", "--from-file", str(tmp_path / "half.zip"), *none,
                       "--power", "3", "--out", str(tmp_path / "back.zip")]) == 0
    back = AmortizedEstimator.load(tmp_path / "back.zip").summary.widening
    for key in ("intercept", "slope", "quadratic"):
        assert back[key] == pytest.approx(w0[key])
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:  # QUAD K = 1 ships no summary likelihood
        bench.main(["--class", "QUAD", "--ramps", "1", *none, "--out", str(tmp_path / "k1.zip")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "quad-k1.zip" in err and "summary likelihood" in err
    assert not (tmp_path / "k1.zip").exists()


def test_refit_widening_fits_kept_gaps_against_each_drones_own_reference(tmp_path):
    """refit_widening.py --gaps-in: gaps three times what a right likelihood shows at each drone
    (chi-square of each drone's own reference degrees), fitted against the plug-in points, give
    w = 3 wherever the plug-in point is; the file states how it was fitted. Fitted against
    chi-square(35) instead, the same gaps (median about 3 x 10) look right: w stays near 1."""
    import importlib.util
    from pathlib import Path

    from mdaug.inference.amortized.estimator import AmortizedEstimator

    path = Path(__file__).parent / "benchmarks" / "refit_widening.py"
    spec = importlib.util.spec_from_file_location("refit_widening", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rng = np.random.default_rng(3)
    n, d = 400, 35
    ref = rng.uniform(8.0, 14.0, n)
    kept = {"groups": np.array(["prior"]), "prior/gaps": 3.0 * rng.chisquare(ref), "prior/converged": np.ones(n, bool),
            "prior/truth": rng.normal(size=(n, d)), "prior/plug_in": rng.normal(size=(n, d)), "prior/reference": ref}
    np.savez(tmp_path / "gaps.npz", **kept)
    common = ["--class", "QUAD", "--ramps", "32", "--gaps-in", str(tmp_path / "gaps.npz"), "--linear"]
    assert bench.main([*common, "--reference", "own", "--against", "plug-in", "--out", str(tmp_path / "own.zip")]) == 0
    est = AmortizedEstimator.load(tmp_path / "own.zip")
    w = est.summary.widen(rng.normal(size=(200, d)))
    assert np.median(w) == pytest.approx(3.0, rel=0.15)
    record = est.meta["summary"]["training"]["widening_refit"]
    assert record["reference"] == "own" and record["against"] == "plug-in" and record["quadratic"] is False
    assert bench.main([*common, "--out", str(tmp_path / "chi2.zip")]) == 0
    w35 = AmortizedEstimator.load(tmp_path / "chi2.zip").summary.widen(rng.normal(size=(200, d)))
    assert np.median(w35) < 1.3


def test_summary_information_takes_the_derivatives_noise_off_the_bound():
    """tests/benchmarks/summary_information.py's bound on a linear Gaussian toy whose
    finite differences are noisy (no common random numbers): J' S^-1 J of the noisy J
    overstates the information (the bound comes out narrower than the truth's); with the
    noise term taken off it is the exact bound within its sampling error."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parent / "benchmarks" / "summary_information.py"
    spec = importlib.util.spec_from_file_location("summary_information", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rng = np.random.default_rng(0)
    p, d, n, step = 200, 3, 2000, 0.1
    a = rng.normal(size=(p, d)) * 0.3
    exact = 2 * 1.645 * np.sqrt(np.diag(np.linalg.inv(5 * a.T @ a)))
    draws = rng.normal(size=(n, p))
    diffs = np.stack([((a[:, j] * step + rng.normal(size=(n, p))) - (-a[:, j] * step + rng.normal(size=(n, p))))
                      / (2 * step) for j in range(d)], axis=-1)
    jac = diffs.mean(0)
    plain = 2 * 1.645 * np.sqrt(np.diag(np.linalg.inv(5 * jac.T @ jac)))
    assert np.all(plain < 0.95 * exact)
    assert bench.bound(diffs, draws, 5) == pytest.approx(exact, rel=0.15)


def test_nearest_drones_are_the_nearest_in_whitened_units():
    from mdaug.inference.emulator.train import nearest_drones

    z_train = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 5.0], [0.0, 2.0]])
    u_train = np.arange(4.0)[:, None] * [1.0, 10.0]
    got = nearest_drones(z_train, u_train, np.array([[0.9, 0.1], [4.0, 4.0]]), 2)
    assert got.shape == (2, 2, 2)
    assert got[0, :, 0].tolist() == [1.0, 0.0] and got[1, :, 0].tolist() == [2.0, 3.0]
    assert nearest_drones(z_train, u_train, np.zeros((3, 2)), 0).shape == (3, 0, 2)


def test_the_default_route_passes_on_the_prior_and_is_sharpest_where_users_are():
    from mdaug.inference.diagnostics.routes import default_route
    from mdaug.inference.estimator_job import name_default_route

    def row(outer, cov_lo, ls):
        return {"outer_share": outer, "coverage90_range": [cov_lo, 0.95], "log_score": ls}

    prior = {"amortized": row(0.11, 0.86, 9.0), "smc": row(0.10, 0.85, 11.0), "narrow": row(0.31, 0.60, 40.0)}
    users = {"amortized": row(0.0, 1.0, 6.8), "smc": row(0.0, 1.0, 4.0), "narrow": row(0.03, 0.9, -1.0)}
    assert default_route(prior) == "amortized"  # the prior drones' log score alone
    assert default_route(prior, users) == "smc"  # 'narrow' is sharper still, but fails the gate
    assert default_route({"narrow": prior["narrow"]}, users) is None
    # one rule for train-estimator, the sbc verb and the benchmark: the specimen drones where there are some
    sbc = {"route_table": {"drones": 200, "rows": prior}, "specimens": {"drones": 50, "rows": users}}
    name_default_route(sbc)
    assert sbc["route_table"]["default"] == "smc"
    assert sbc["route_table"]["default_by"] == "log score on 50 specimen drones"
    del sbc["specimens"]
    name_default_route(sbc)
    assert (sbc["route_table"]["default"], sbc["route_table"]["default_by"]) == ("amortized",
                                                                                "log score on 200 prior drones")
    sbc["route_table"]["rows"] = {"narrow": prior["narrow"]}
    name_default_route(sbc)
    assert (sbc["route_table"]["default"], sbc["route_table"]["default_by"]) == ("amortized",
                                                                                "no route passes the gate")
    sbc["route_table"]["rows"] = {"smc": prior["smc"], "narrow": prior["narrow"]}  # one passes: it says so
    name_default_route(sbc)
    assert (sbc["route_table"]["default"], sbc["route_table"]["default_by"]) == (
        "smc", "the only route that passes the gate on 200 prior drones")


def test_the_emulator_ensemble_is_the_mean_of_its_members_and_old_files_load_as_one():
    import torch

    from mdaug.inference.emulator.net import Emulator, fit

    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    u, sk = rng.normal(size=(200, 3)), rng.normal(size=(200, 5))
    target = np.c_[u[:, :1] + sk[:, :1], u[:, 1:2] * sk[:, 1:2]]
    nets = []
    for k in range(3):
        net = Emulator(3, 5, 2, hidden=8, depth=1)
        fit(net, u, sk, target, seed=k, epochs=3)
        nets.append(net)
    ens = Emulator.stack(nets)
    tu, ts = torch.as_tensor(u[:7], dtype=torch.float32), torch.as_tensor(sk[:7], dtype=torch.float32)
    with torch.no_grad():
        want = torch.stack([n(tu, ts) for n in nets]).mean(0)
        assert torch.allclose(ens(tu, ts), want, atol=1e-6)
        assert not torch.allclose(nets[0](tu, ts), nets[1](tu, ts))  # the members differ
    assert ens.config()["members"] == 3
    with pytest.raises(ValueError, match="one-member"):
        fit(ens, u, sk, target, seed=0, epochs=1)
    # a file written before the ensemble: one network under 'mlp.', in_mean (F,)
    old = {("mlp." + k[len("mlps.0."):] if k.startswith("mlps.0.") else k): (v[0] if k in ("in_mean", "in_sd") else v)
           for k, v in nets[0].state_dict().items()}
    one = Emulator(3, 5, 2, hidden=8, depth=1)
    one.load_state_dict(Emulator.upgrade_state(old))
    with torch.no_grad():
        assert torch.equal(one(tu, ts), nets[0](tu, ts))
