"""Calibration: parametrisation, likelihood, fit, MCMC, results, posterior augmentation."""
import warnings

import numpy as np
import pytest

from mdaug.generator import IDX, N_PARAMS, load_reference, profiles
from mdaug.inference.likelihood.base import LogPosteriorBase
from mdaug.inference import (CalibrationResult, CalibrationSettings, Layout, LogPosterior, PosteriorAugmenter,
                             Priors, calibrate, prepare_measured)
from mdaug.inference.fit import global_fit
from mdaug.radar import DataFileError, RadarConfig

RADAR = RadarConfig()
HELI = load_reference("HELI")


def heli_truth():
    """A HELI vector 5-10% away from the reference (the reference starts the fit)."""
    x = HELI.to_array().copy()
    x[[IDX["A_a"], IDX["w_a"], IDX["w_b"], IDX["C_p"]]] *= [1.08, 0.95, 1.05, 0.97]
    return x


def noisy_profile(x, noise, seed):
    rng = np.random.default_rng(seed)
    return np.abs(profiles(x)[0] + noise * rng.standard_normal(RADAR.slice_length))


def make_post(y, engines=1, **kw):
    pri = Priors.from_reference(HELI)
    data, _ = prepare_measured(y, RADAR, "peak")
    return LogPosterior(data, Layout(engines, data.shape[0], pri, kw.pop("range_offset", True)), RADAR, **kw)


# ---- parametrisation and likelihood --------------------------------------------------------
def test_layout_round_trip_and_mirror_symmetry(rng):
    post = make_post(noisy_profile(heli_truth(), 0.01, 0), engines=2)
    lay = post.layout
    lo, hi = lay.z_bounds()
    z = rng.uniform(lo, hi, size=(6, lay.dim_z))
    x, off = lay.physics(z)
    assert x.shape == (6, 1, 26) and off.shape == (6, 1)
    np.testing.assert_allclose(lay.z_from_physics(x[0, 0], off[0]), z[0], rtol=1e-12, atol=1e-12)
    zc = lay.canonical(z)
    xc, _ = lay.physics(zc)
    e = xc.reshape(6, 2, N_PARAMS)
    assert np.all(e[:, :, IDX["w_a"]] <= e[:, :, IDX["w_b"]])  # roll/pitch mirror removed
    assert np.all(np.diff(e[:, :, IDX["w_a"]], axis=1) > 0)  # engine permutation removed
    # the mirror images give the same profile (up to float32 rounding), hence the same misfit
    np.testing.assert_allclose(post.model(zc), post.model(z), atol=2e-5)
    theta = lay.theta_from_z(zc, np.full((6, 1), np.log(0.01)))
    lp = lay.log_prior(theta, (1e-4, 1.0))
    assert np.all(np.isfinite(lp[np.all(np.abs(lay.split_theta(theta)[0][:, lay.n_shared:lay.n_shared + 1]) <= 1, 1)]))


@pytest.mark.parametrize("cls,engines,meas", [("HELI", 1, 1), ("HELI", 1, 2), ("QUAD", 4, 1)])
def test_relabelling_the_lines_is_an_exact_symmetry(cls, engines, meas, rng):
    from mdaug.inference.space.priors import PERMUTATIONS

    ref = load_reference(cls)
    lay = Layout(engines, meas, Priors.from_reference(ref))
    post = LogPosterior(np.ones((meas, RADAR.slice_length)), lay, RADAR, dtype="float64")
    th = lay.sample_prior(40, rng, (0.005, 0.03))
    eng, perm = rng.integers(0, engines, 40), rng.integers(0, 24, 40)
    new, log_jac = lay.relabel(th, eng, perm)
    np.testing.assert_allclose(post.model(lay.split_theta(new)[0]), post.model(lay.split_theta(th)[0]), atol=1e-12)
    # the inverse permutation undoes it and its Jacobian cancels
    inv = np.array([PERMUTATIONS.index(tuple(np.argsort(PERMUTATIONS[i]))) for i in perm])
    back, log_jac_back = lay.relabel(new, eng, inv)
    np.testing.assert_allclose(back, th, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(log_jac + log_jac_back, 0.0, atol=1e-12)
    # the random move only proposes labellings inside the prior (or stays put)
    prop, _ = lay.random_relabel(th, rng)
    assert np.all(np.isfinite(lay.log_prior(prop, (0.005, 0.03))))


def test_scale_is_not_identifiable_and_gamma0_is_fixed():
    y = noisy_profile(heli_truth(), 0.01, 1)
    p1 = make_post(y)
    pri = Priors.from_reference(HELI).replace(gamma0=7.3)
    data, _ = prepare_measured(y, RADAR, "peak")
    p2 = LogPosterior(data, Layout(1, 1, pri), RADAR)
    z = p1.layout.z_from_physics(heli_truth())[None]
    np.testing.assert_allclose(p1.misfit(z), p2.misfit(z), rtol=1e-6)  # float32 f(x)
    assert p1.layout.physics(z)[0][0, 0, IDX["Gamma"]] == HELI.to_array()[IDX["Gamma"]]
    assert "Gamma" not in " ".join(p1.layout.z_names())


def test_log_posterior_is_vectorised_and_matches_pointwise(rng):
    post = make_post(noisy_profile(heli_truth(), 0.01, 2))
    theta = post.layout.sample_prior(8, rng, (1e-3, 0.1))
    batch = post(theta)
    rows = np.array([post(t[None])[0] for t in theta])
    np.testing.assert_allclose(batch, rows, rtol=1e-10)
    np.testing.assert_allclose(post.pointwise(theta).sum(axis=(1, 2)), batch, rtol=1e-9)  # flat prior inside
    outside = theta.copy()
    outside[:, post.layout.shared_col(0, "A_a")] = -1.0
    assert np.all(post(outside) == -np.inf)
    # phases are periodic: shifting one by 2 pi changes nothing
    shifted = theta.copy()
    shifted[:, post.layout.phase_cols[0]] += 2 * np.pi
    np.testing.assert_allclose(post(shifted), batch, rtol=1e-9)


def test_measured_profile_errors_and_recentring():
    good = noisy_profile(heli_truth(), 0.01, 3)
    with pytest.raises(ValueError, match="expected 400"):
        prepare_measured(good[:300], RADAR, "peak")
    with pytest.raises(ValueError, match="all zeros"):
        prepare_measured(np.zeros((2, 400)), RADAR, "peak")
    bad = good.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        prepare_measured(bad, RADAR, "peak")
    with pytest.raises(ValueError, match="dB"):
        prepare_measured(good - 0.5, RADAR, "peak")
    rolled = np.roll(good, 7)
    data, shifts = prepare_measured(rolled, RADAR, "peak")
    assert shifts.tolist() == [7] and np.argmax(data[0]) == 200 and data.max() == 1.0


# ---- fit -----------------------------------------------------------------------------------
def test_fit_matches_the_truth_on_a_noise_free_profile():
    truth = heli_truth()
    post = make_post(profiles(truth)[0])
    s = CalibrationSettings(n_starts=2, fit_budget=800, polish_budget=4000)
    start = post.layout.z_from_physics(HELI.to_array())
    fit = global_fit(post, s, np.random.SeedSequence(0), start=start)
    zt = post.layout.z_from_physics(truth)
    grid = np.repeat(zt[None], 161, axis=0)
    grid[:, -1] = np.linspace(-4, 4, 161)  # the truth at its best window offset
    # the landscape is rough with rival modes, so the fit need not land on the truth,
    # but it must fit at least as well (within 5 nats) and improve on its start
    assert fit.misfit <= post.misfit(grid).min() + 5.0
    assert fit.misfit < post.misfit(start[None])[0] - 1000
    for name in ("w_a", "w_b"):
        j = post.layout.shared_col(0, name)
        assert abs(fit.best_z[j] / zt[j] - 1) < 0.15, name
    assert 1 <= fit.n_agree <= 2 and fit.evals.sum() <= 2 * (800 + 4000) + 4000 + 10  # + polish of the start


class _DoubleWell(LogPosteriorBase):
    """A stand-in posterior whose misfit has two equally deep, distant minima."""

    def __init__(self, layout):
        self.layout, self.n_bins = layout, 400
        lo, hi = layout.z_bounds()
        self.a = lo + 0.25 * (hi - lo)
        self.b = lo + 0.75 * (hi - lo)
        self.b[layout.shared_col(0, "w_b")] = hi[layout.shared_col(0, "w_b")] * 0.9
        self.a = layout.canonical(self.a)[0]
        self.b = layout.canonical(self.b)[0]
        self.scale = hi - lo

    def misfit(self, z):
        da = np.sum(((z - self.a) / self.scale) ** 2, axis=1)
        db = np.sum(((z - self.b) / self.scale) ** 2, axis=1)
        return 1e4 * np.minimum(da, db)

    def ssr(self, z):
        return np.ones((len(z), 1))

    # the fit space of a fitted-phase likelihood (see mdaug.inference.fit)
    def fit_bounds(self):
        return self.layout.z_bounds()

    def fit_objective(self, z):
        return self.misfit(z)

    def canonical_fit(self, z):
        return self.layout.canonical(z)

    def fit_noise(self, z):
        return np.ones((len(z), 1))


def test_fit_reports_multimodality():
    lay = make_post(noisy_profile(heli_truth(), 0.01, 4), range_offset=False).layout
    well = _DoubleWell(lay)
    s = CalibrationSettings(n_starts=4, fit_budget=400, polish_budget=600)
    fit = global_fit(well, s, np.random.SeedSequence(5), start=well.b)
    ends = [min(np.abs(z - well.a).max(), np.abs(z - well.b).max()) for z in fit.starts_z]
    near_a = [np.abs((z - well.a) / well.scale).max() < 0.05 for z in fit.starts_z]
    assert max(ends) < 0.05 * well.scale.max()
    assert any(near_a) and not all(near_a)  # the starts found both wells ...
    assert fit.multimodal and fit.n_agree < 4 and any("multimodal" in n for n in fit.notes)  # ... and say so


# ---- full calibration (quick) -------------------------------------------------------------
@pytest.fixture(scope="module")
def quick_heli():
    """Three single-chirp measurements of one drone at three rotor phases (the published
    acquisition, phases fitted per measurement, physics shared)."""
    truth = heli_truth()
    rng = np.random.default_rng(11)
    ys = []
    for m in range(3):
        x = truth.copy()
        x[[IDX["phi_a"], IDX["phi_b"], IDX["phi_p"], IDX["phi_m"]]] = rng.uniform(-np.pi, np.pi, 4)
        ys.append(noisy_profile(x, 0.01, 11 + m))
    y = np.stack(ys)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(y, "HELI", settings=CalibrationSettings.quick(max_steps=3000), random_state=7)
    return truth, res


def test_quick_calibration_result_is_complete_and_honest(quick_heli):
    truth, res = quick_heli
    d = res.diagnostics
    assert res.class_name == "HELI" and res.n_engines == 1
    assert res.draws().shape == (res.n_draws, 13) and np.all(np.isfinite(res.draws()))
    assert np.all(res.draws()[:, IDX["Gamma"]] == HELI.to_array()[IDX["Gamma"]])  # fixed scale
    for key in ("tau", "ess", "acceptance_mean", "steps_over_tau", "n_fit_starts_agreeing", "identified"):
        assert key in d
    assert all(isinstance(v, float) for v in d["tau"].values())
    # converged means >= 50 tau; the quick run is shorter and must say so
    assert res.converged == (d["steps_over_tau"] >= 50)
    if not res.converged:
        assert "NOT CONVERGED" in d["reason"] and "WARNING" in res.report()
    np.testing.assert_allclose(d["ess_min"], min(d["ess"].values()))
    table = res.summary()
    phases = table[table["kind"] == "circular"]
    assert np.all(np.abs(phases["mean"]) <= np.pi) and np.all(phases["q05"] <= phases["q95"])
    assert table.loc["Gamma[0]", "kind"] == "fixed"


@pytest.mark.slow
def test_recovery_of_the_lines_from_five_scene_acquisitions():
    """Recovery (issue acceptance): 5 acquisitions of the reference drone through the scene
    simulator and the chain at K = 32, calibrated by the shipped estimator; the 90%
    intervals of the four line frequencies (sorted, label-free) hold the truth."""
    from mdaug.generator.acquisition import Acquisition
    from mdaug.generator.chain import SceneConfig, simulate_campaign
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.space.priors import engine_lines

    camp = simulate_campaign("HELI", 1, 5, 11, scene=SceneConfig().with_acquisition(ramps=32).with_specimens(width=0.0))
    res = calibrate_amortized(camp.profiles, "HELI", acquisition=Acquisition.measured(32), route="amortized",
                              random_state=1)
    w_true = np.sort(engine_lines(HELI.to_array().reshape(1, 13))[0][0])
    lo, hi = np.quantile(res.lines()[:, 0, :, 0], [0.05, 0.95], axis=0)
    assert np.all((lo <= w_true) & (w_true <= hi)), (lo, w_true, hi)


def test_labellings_are_sampled_with_their_prior_weights(quick_heli):
    """HELI's roll line and its alpha-beta line can trade places (C_m stays inside its
    prior): the data cannot tell them apart, and the prior weights the two labellings
    by 1 / (S D) (the Jacobian from line frequencies to (w_a, w_b, C_p, C_m)),
    0.626 / 0.374 at the reference. The relabelling move reaches that split; without
    it the chain keeps the fit's labelling."""
    lay = Layout(1, 1, Priors.from_reference(HELI))
    th = lay.theta_from_z(lay.z_from_physics(HELI.to_array()), [np.log(0.01)])
    other, log_jac = lay.random_relabel(th, np.random.default_rng(0))
    x_other, _ = lay.physics(lay.split_theta(other)[0])
    assert x_other[0, 0, IDX["w_a"]] == pytest.approx(HELI.to_array()[IDX["C_m"]] * (3.98e3 - 2.69e3))
    assert np.exp(log_jac[0]) / (1 + np.exp(log_jac[0])) == pytest.approx(0.374, abs=0.002)
    back, log_jac_back = lay.random_relabel(other, np.random.default_rng(1))  # the only other labelling
    np.testing.assert_allclose(back, th, rtol=1e-12)
    assert log_jac_back[0] == pytest.approx(-log_jac[0])
    # the relabelling kernel alone (the symmetry move of both samplers) leaves the prior's
    # labelling weights invariant: a chain of its proposals spends 0.374 of its time swapped
    rng, state, swapped_steps = np.random.default_rng(2), th, 0
    for _ in range(4000):
        prop, lj = lay.random_relabel(state, rng)
        if np.log(rng.uniform()) < lj[0]:
            state = prop
        swapped_steps += lay.physics(lay.split_theta(state)[0])[0][0, 0, IDX["w_a"]] < 2000
    assert swapped_steps / 4000 == pytest.approx(0.374, abs=0.03)
    _, res = quick_heli
    # the label-free view agrees across the two labellings: same lines, sorted by frequency
    lines = res.lines()
    assert lines.shape == (res.n_draws, 1, 4, 2) and np.all(np.diff(lines[..., 0], axis=-1) >= 0)
    swapped = res.idata.posterior["w_a"].values[0, :, 0] < 2000
    if swapped.any() and (~swapped).any():
        np.testing.assert_allclose(np.median(lines[swapped, 0, :2, 0], axis=0),
                                   np.median(lines[~swapped, 0, :2, 0], axis=0), rtol=0.02)


def test_save_load_round_trip_and_errors(quick_heli, tmp_path):
    _, res = quick_heli
    path = res.save(tmp_path / "post.nc")
    back = CalibrationResult.load(path, class_name="heli", n_engines=1)
    np.testing.assert_array_equal(back.draws(), res.draws())
    assert back.diagnostics == res.diagnostics and back.converged == res.converged
    with pytest.raises(DataFileError, match="class 'HELI', expected 'QUAD'"):
        CalibrationResult.load(path, class_name="QUAD")
    with pytest.raises(DataFileError, match="1 engine"):
        CalibrationResult.load(path, n_engines=4)
    junk = tmp_path / "junk.nc"
    junk.write_text("not netcdf")
    with pytest.raises(DataFileError, match="junk.nc"):
        CalibrationResult.load(junk)
    with pytest.raises(DataFileError, match="not found"):
        CalibrationResult.load(tmp_path / "missing.nc")
    assert not list(tmp_path.glob(".*tmp"))  # atomic write left nothing behind


def test_plots_are_written(quick_heli, tmp_path):
    _, res = quick_heli
    for fn, name in ((res.plot_corner, "c.png"), (res.plot_trace, "t.png")):
        out = fn(tmp_path / name)
        assert (tmp_path / name).stat().st_size > 5000 and str(out).endswith(name)


def test_posterior_augmenter_draws_beyond_the_chain(quick_heli, tmp_path):
    _, res = quick_heli
    n = res.n_draws + 500
    pool = np.concatenate([res.draws(measurement=m) for m in range(res.n_measurements)])
    plain = PosteriorAugmenter(res, random_state=3).sample(n)
    assert plain.profiles.shape == (n, 400) and plain.params.shape == (n, 13)
    # the default is the plain bootstrap: every vector is one of the posterior's draws
    j = IDX["w_a"]
    assert np.isin(plain.params[:, j], pool[:, j]).all()
    # this result's acquisition draws no nuisances: a repeated draw renders the same profile
    n_rows, n_renders = len(np.unique(plain.params, axis=0)), len(np.unique(plain.profiles, axis=0))
    assert 0.99 * n_rows <= n_renders <= n_rows < n
    aug = PosteriorAugmenter(res, random_state=3, jitter=0.1)
    batch = aug.sample(n)
    assert len(np.unique(batch.params[:, j])) == n  # jitter: no repeated rows
    assert not np.isin(batch.params[:, j], pool[:, j]).any()
    same = PosteriorAugmenter(res, random_state=3, jitter=0.1).sample(n)
    np.testing.assert_array_equal(same.params, batch.params)
    mean, sd = res.draws().mean(0), res.draws().std(0)
    assert abs(batch.params[:, j].mean() - mean[j]) < 0.2 * sd[j]
    assert batch.params[:, j].std() == pytest.approx(sd[j] * np.sqrt(1 + 0.1**2), rel=0.1)
    assert np.all(batch.params[:, [IDX["A_a"], IDX["w_b"]]] >= 0)
    assert aug.settings()["strategy"] == "posterior" and aug.label == "HELI"
    path = res.save(tmp_path / "p.nc")
    with pytest.raises(DataFileError, match="expected 'QUAD'"):
        PosteriorAugmenter(path, label="QUAD")
