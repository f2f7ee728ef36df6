"""Mode jumps of the SMC sampler (mdaug.inference.samplers.modes, with the toolbox's Student-t
mixture and Laplace covariance): the mixture's density is
exact on the circle, the Laplace covariance is right on a quadratic, jumps give a
mode no other move can reach its posterior weight, and the mode finder polishes
to optima and keeps its state (the resume test with jumps is in
test_inference_runs.py)."""
import numpy as np
import pytest
from scipy.special import logsumexp

from mdaug.generator import load_reference, profiles
from mdaug.inference.likelihood.fitted_phases import LogPosterior
from mdaug.inference.samplers.modes import ModeFinder
from mdaug.inference.samplers.toolbox import StudentMixture, cap_cov, hessian, laplace_covariance
from mdaug.inference.samplers.tempering import run_smc


def test_mixture_density_is_normalised_on_the_circle_and_matches_its_draws():
    rng = np.random.default_rng(0)
    # phase scale 2 rad: about a sixth of the t draws fall outside [-pi, pi) and are redrawn
    cov = np.array([[2.0**2, 0.6], [0.6, 1.0]])
    mix = StudentMixture.build([[2.5, 0.0], [-1.0, 3.0]], [cov, 0.3 * cov], phase_cols=[0], rng=rng, n_mc=20000)
    assert mix.log_mass[0] < np.log(0.9)  # truncation matters for this component
    n, half = 400_000, 40.0
    u = np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(-half, half, n)])
    integral = np.mean(np.exp(mix.logpdf(u))) * 2 * np.pi * 2 * half
    assert integral == pytest.approx(1.0, abs=0.03)
    draws = mix.sample(50_000, rng)
    assert np.all((draws[:, 0] >= -np.pi) & (draws[:, 0] < np.pi))
    region = lambda x: (x[:, 0] > 2.0) & (x[:, 1] > 0.0)  # noqa: E731 (straddles no wrap; mode 0's upper half)
    p_density = np.mean(np.exp(mix.logpdf(u)) * region(u)) * 2 * np.pi * 2 * half
    assert region(draws).mean() == pytest.approx(p_density, abs=0.015)


def test_hessian_and_laplace_covariance_of_a_quadratic():
    cov = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1e6]])  # third direction ~flat
    prec = np.linalg.inv(cov)
    loglik = lambda th: -0.5 * np.einsum("ni,ij,nj->n", th, prec, th)  # noqa: E731
    h = hessian(loglik, np.zeros(3), np.array([0.1, 0.1, 0.1]))
    np.testing.assert_allclose(h, -prec, atol=1e-8)
    got = laplace_covariance(h, np.ones(3), max_sd=np.array([10.0, 10.0, 5.0]))
    np.testing.assert_allclose(got[:2, :2], cov[:2, :2], rtol=1e-6)
    assert got[2, 2] == pytest.approx(25.0)  # capped at max_sd
    np.testing.assert_allclose(np.diag(cap_cov(cov, np.full(3, 1.0))), [1.0, 1.0, 1.0])


NARROW, BROAD = np.array([5.0, 5.0]), np.array([-4.0, -4.0])


def two_modes(theta):
    """Uniform prior on [-10, 10]^2; likelihood 0.5 N(BROAD, 1) + 0.5 N(NARROW, 0.02^2):
    the narrow mode holds half the posterior but 4e-6 of the prior, so no prior draw
    lands in it and no single-coordinate or DE move reaches it."""
    lp = np.where(np.all(np.abs(theta) <= 10, axis=1), 0.0, -np.inf)
    comps = []
    for mu, sd in ((BROAD, 1.0), (NARROW, 0.02)):
        d2 = ((theta - mu) ** 2).sum(1)
        comps.append(np.log(0.5) - 0.5 * d2 / sd**2 - np.log(2 * np.pi * sd**2))
    return lp, logsumexp(np.array(comps), axis=0)


class KnownModes:
    """The mode-finder interface with fixed modes (as if the fit had found them)."""

    def __init__(self):
        self.mix = StudentMixture.build([BROAD, NARROW], [np.eye(2) * 2.0**2, np.eye(2) * 0.05**2], [],
                                     np.random.default_rng(0))

    def update(self, theta, beta, rng):
        return 0

    def mixture(self, beta, rng):
        return self.mix

    def state(self):
        return {}

    def load(self, state):
        pass


def test_jumps_give_an_unreachable_narrow_mode_its_weight():
    prior = lambda n, rng: rng.uniform(-10, 10, size=(n, 2))  # noqa: E731
    bounds = (np.full(2, -10.0), np.full(2, 10.0))
    without = run_smc(two_modes, prior, 600, 1, bounds=bounds, p_redraw=0.3)
    assert np.mean(without.particles[:, 0] > 0) < 0.05  # the narrow mode is missed
    shares, lz = [], []
    for seed in range(3):
        r = run_smc(two_modes, prior, 600, seed, bounds=bounds, p_redraw=0.2, modes=KnownModes(), p_jump=0.2)
        right = r.particles[:, 0] > 0
        shares.append(right.mean())
        lz.append(r.log_z)
        np.testing.assert_allclose(r.particles[right].std(axis=0), 0.02, rtol=0.3)
    assert abs(np.mean(shares) - 0.5) < 0.08, shares
    assert abs(np.mean(lz) - np.log(1 / 400)) < 0.3, lz


@pytest.fixture(scope="module")
def heli_profile():
    rng = np.random.default_rng(5)
    return np.abs(profiles(load_reference("HELI").to_array())[0] + 0.01 * rng.standard_normal(400))


def test_mode_finder_polishes_to_optima_and_keeps_its_state(heli_profile):
    from mdaug.inference.likelihood.base import prepare_measured
    from mdaug.inference.space.layout import Layout
    from mdaug.inference.space.priors import Priors
    from mdaug.radar import RadarConfig

    heli = load_reference("HELI")
    data, _ = prepare_measured(heli_profile, RadarConfig(), "peak")
    layout = Layout(1, 1, Priors.from_reference(heli))
    post = LogPosterior(data, layout, sigma_bounds=(1e-3, 0.1))
    rng = np.random.default_rng(0)
    start = layout.theta_from_z(layout.z_from_physics(heli.to_array()), [np.log(0.01)])
    finder = ModeFinder(post, n_polish=3, polish_budget=300, seed_thetas=start)
    evals = finder.update(layout.sample_prior(50, rng, (1e-3, 0.1)), 0.0, rng)
    assert evals > 300 and 1 <= len(finder.means) <= 4
    # polishing raised every particle it started from; the reference start is the best mode
    assert finder.values[0] == pytest.approx(post(finder.means[:1])[0])
    assert finder.values[0] >= post(start)[0] - 1.0
    sd = np.sqrt(np.diagonal(finder.covs, axis1=1, axis2=2))
    corr = finder.covs / sd[:, :, None] / sd[:, None, :]
    assert np.all(np.isfinite(finder.covs)) and np.all(np.linalg.eigvalsh(corr) > 0)
    again = ModeFinder(post)
    again.load(finder.state())
    x = layout.sample_prior(5, rng, (1e-3, 0.1))
    a, b = finder.mixture(0.5, np.random.default_rng(1)), again.mixture(0.5, np.random.default_rng(1))
    np.testing.assert_array_equal(a.logpdf(x), b.logpdf(x))
