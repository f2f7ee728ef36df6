"""Tempered SMC sampler (mdaug.inference.samplers.tempering): bimodal toy targets with known
mode weights and evidence, phases on the circle, resume, and the calibrate path."""
import warnings

import numpy as np
import pytest
from scipy.special import i0e, logsumexp

from mdaug.generator import load_reference, profiles
from mdaug.inference import CalibrationResult, CalibrationSettings, calibrate
from mdaug.inference.samplers.tempering import next_beta, run_smc
from mdaug.inference.samplers.toolbox import systematic_resample

BOX = 10.0
WEIGHTS = np.array([0.3, 0.7])
MODES = np.array([[-4.0, -4.0], [4.0, 4.0]])
SD = 0.3


def mixture_target(theta):
    """Uniform prior on [-10, 10]^2 (log density up to its constant), likelihood a
    normalised 2-D Gaussian mixture (weights 0.3, 0.7): posterior mode weights are
    0.3 / 0.7 and the evidence is 1 / 400 (the mixture's mass lies inside the box)."""
    lp = np.where(np.all(np.abs(theta) <= BOX, axis=1), 0.0, -np.inf)
    d2 = ((theta[:, None, :] - MODES[None]) ** 2).sum(-1)
    ll = logsumexp(np.log(WEIGHTS) - 0.5 * d2 / SD**2 - np.log(2 * np.pi * SD**2), axis=1)
    return lp, ll


def box_prior(n, rng):
    return rng.uniform(-BOX, BOX, size=(n, 2))


@pytest.mark.parametrize("p_redraw", [0.0, 0.3])
def test_bimodal_mixture_weights_and_evidence_are_recovered(p_redraw):
    fr, lz = [], []
    bounds = (np.full(2, -BOX), np.full(2, BOX))
    for seed in range(4):
        r = run_smc(mixture_target, box_prior, 1000, seed, bounds=bounds, p_redraw=p_redraw)
        assert r.converged and r.betas[-1] == 1.0 and r.particles.shape == (1000, 2)
        right = r.particles[:, 0] > 0
        fr.append(right.mean())
        lz.append(r.log_z)
        # both modes populated with their own shape (sd 0.3 per coordinate)
        for side, mode in ((~right, MODES[0]), (right, MODES[1])):
            np.testing.assert_allclose(r.particles[side].std(axis=0), SD, rtol=0.2)
            np.testing.assert_allclose(r.particles[side].mean(axis=0), mode, atol=0.1)
    # sd of one run's weight ~0.023 (binomial 0.015 x SMC inflation, measured over 20 seeds):
    # the mean of 4 runs is within 4 of its sds (0.012)
    assert abs(np.mean(fr) - WEIGHTS[1]) < 0.045, fr
    assert all(abs(f - WEIGHTS[1]) < 0.1 for f in fr), fr
    # evidence: log Z = log(1/400); run-to-run sd ~0.06
    assert abs(np.mean(lz) - np.log(1 / (2 * BOX) ** 2)) < 0.12, lz


def test_phase_mixture_across_the_wrap():
    """One phase (uniform on the circle) with a von Mises mixture straddling +-pi
    (weight 0.6 at 3.0 rad, 0.4 at -1.0 rad) and one linear N(0, 1) coordinate in a
    [-5, 5] box: log Z = -ln(2 pi x 10)."""
    kappa, mus, w = 20.0, np.array([3.0, -1.0]), np.array([0.6, 0.4])

    def target(theta):
        lp = np.where(np.abs(theta[:, 1]) <= 5.0, 0.0, -np.inf)
        log_vm = kappa * np.cos(theta[:, :1] - mus) - np.log(2 * np.pi * i0e(kappa)) - kappa
        ll = logsumexp(np.log(w) + log_vm, axis=1) - 0.5 * theta[:, 1] ** 2 - 0.5 * np.log(2 * np.pi)
        return lp, ll

    prior = lambda n, rng: np.column_stack([rng.uniform(-np.pi, np.pi, n), rng.uniform(-5, 5, n)])  # noqa: E731
    fr, lz = [], []
    for seed in range(3):
        r = run_smc(target, prior, 1000, seed, phase_cols=[0])
        phi = r.particles[:, 0]
        assert np.all((phi >= -np.pi) & (phi < np.pi))
        near = np.cos(phi - 3.0) > 0
        fr.append(near.mean())
        lz.append(r.log_z)
        # the mode at 3.0 rad spans the wrap: particles on both sides of +-pi
        assert np.any(phi[near] > 3.0) and np.any(phi[near] < -3.0)
    assert abs(np.mean(fr) - 0.6) < 0.06, fr
    assert abs(np.mean(lz) + np.log(20 * np.pi)) < 0.15, lz


def test_next_beta_and_resampling():
    rng = np.random.default_rng(0)
    ll = rng.normal(0, 50, size=500)
    b = next_beta(ll, 0.0, 250)
    lw = b * ll
    wt = np.exp(lw - lw.max())
    assert 0 < b < 1 and wt.sum() ** 2 / (wt**2).sum() == pytest.approx(250, rel=1e-3)
    assert next_beta(np.zeros(10), 0.3, 5) == 1.0  # flat likelihood: straight to beta = 1
    w = np.array([0.1, 0.0, 0.6, 0.3])
    idx = systematic_resample(w, rng)
    counts = np.bincount(idx, minlength=4)
    assert counts[1] == 0 and np.all(np.abs(counts - 4 * w) < 1)  # systematic: within 1 of N w


def test_interrupted_run_resumes_to_the_same_particles(tmp_path):
    full = run_smc(mixture_target, box_prior, 400, 7, backend_path=tmp_path / "a.npz", fp="toy")
    calls = {"n": 0}

    def flaky(theta):
        calls["n"] += 1
        if calls["n"] == 60:
            raise KeyboardInterrupt
        return mixture_target(theta)

    with pytest.raises(KeyboardInterrupt):
        run_smc(flaky, box_prior, 400, 7, backend_path=tmp_path / "b.npz", fp="toy")
    resumed = run_smc(mixture_target, box_prior, 400, 7, backend_path=tmp_path / "b.npz", fp="toy")
    assert 0 < resumed.resumed_at < len(full.betas) - 1
    np.testing.assert_array_equal(resumed.particles, full.particles)
    assert resumed.log_z == full.log_z
    with pytest.raises(ValueError, match="different problem"):
        run_smc(mixture_target, box_prior, 400, 7, backend_path=tmp_path / "b.npz", fp="other")
    bogus = tmp_path / "c.npz"
    bogus.write_text("not a checkpoint")
    with pytest.raises(ValueError, match="c.npz"):
        run_smc(mixture_target, box_prior, 400, 7, backend_path=bogus, fp="toy")


def test_settings_validate_the_sampler():
    with pytest.raises(ValueError, match="sampler"):
        CalibrationSettings(sampler="pt")
    with pytest.raises(ValueError, match="smc_ess"):
        CalibrationSettings(sampler="smc", smc_ess=1.5)


def test_calibrate_with_smc_is_complete_and_resumable(tmp_path):
    heli = load_reference("HELI")
    rng = np.random.default_rng(3)
    y = np.abs(profiles(heli.to_array())[0] + 0.01 * rng.standard_normal(400))
    s = CalibrationSettings.quick(sampler="smc", n_particles=200, smc_ess=0.5, n_starts=1, fit_budget=300,
                                  polish_budget=200, smc_polish=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(y, "HELI", settings=s, random_state=2, backend_path=tmp_path / "c.h5")
        again = calibrate(y, "HELI", settings=s, random_state=2, backend_path=tmp_path / "c.h5")
    d = res.diagnostics
    assert d["sampler"] == "smc" and d["smc_n_particles"] == 200 and d["smc_betas"][-1] == 1.0
    assert res.n_draws == 200 and np.all(np.isfinite(res.draws()))
    assert "SMC:" in res.report() and "tempering stages" in res.report()
    assert d["smc_modes"] >= 1 and "modes known to the jumps" in res.report()  # mode jumps on by default
    # a rerun on the finished checkpoint resumes at its last stage and gives the same draws
    assert again.diagnostics["resumed_at"] == d["smc_stages"]
    np.testing.assert_array_equal(again.draws(), res.draws())
    res.save(tmp_path / "p.nc")
    back = CalibrationResult.load(tmp_path / "p.nc", class_name="HELI", n_engines=1)
    assert back.diagnostics["smc_log_z"] == pytest.approx(d["smc_log_z"])
    assert res.plot_corner(tmp_path / "c.png").exists() and res.plot_trace(tmp_path / "t.png").exists()
    # the noise level (1% of the peak) is recovered
    assert 0.007 < res.summary().loc["sigma@0", "mean"] < 0.013


def test_the_time_budget_ends_the_run_within_a_sweep_flagged():
    """A slow target (10 ms an evaluation, a sweep of 40): --time-budget 0.5 s ends the run
    within a sweep of it, not converged, saying so; without a budget it runs on."""
    import time

    def slow(theta):
        time.sleep(0.01)
        return mixture_target(theta)

    t0 = time.perf_counter()
    r = run_smc(slow, box_prior, 40, 0, time_budget=0.5, max_sweeps=40)
    took = time.perf_counter() - t0
    assert took < 0.5 + 0.5, took  # within a sweep or two of the budget
    assert not r.converged and "time budget of 0.5 s" in r.reason and r.betas[-1] < 1.0
    fast = run_smc(mixture_target, box_prior, 200, 0, time_budget=60.0)
    assert fast.converged and "time budget" not in fast.reason
