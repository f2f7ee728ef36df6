"""Population calibration: the specimen model in log coordinates, the closed-form
marginal over the class mean, spread recovery, new drones, the population file."""
import numpy as np
import pytest

from mdaug.generator import load_reference
from mdaug.generator.specimens import SpecimenSpread
from mdaug.inference.population.model import (SPREADS, DroneSummary, Hyperprior, PopulationModel, log_marginal,
                                        sample_spreads)
from mdaug.inference.population.result import PopulationResult
from mdaug.radar.io import DataFileError


def _model(cls="HELI"):
    ref = load_reference(cls)
    x0 = ref.to_array()
    return PopulationModel(ref.n_engines), x0


def _drones(model, x0, spread, n, noise, rng):
    """n drones of the specimen model, each measured with Gaussian noise of sd ``noise`` in y."""
    xs = spread.apply(np.repeat(x0[None], n, 0), rng)
    ys = model.transform(xs)
    return [DroneSummary(str(d), np.ones(model.p, bool), ys[d] + noise * rng.standard_normal(model.p),
                         noise ** 2 * np.eye(model.p), xs[d:d + 1]) for d in range(n)]


def test_covariance_is_the_specimen_models_in_log_coordinates():
    """Sigma(spreads) matches the sample covariance of ln(SpecimenSpread.apply(x)) (small spreads)."""
    model, x0 = _model("QUAD")
    spreads = np.array([0.03, 0.01, 0.02, 0.02, 0.01])
    rng = np.random.default_rng(0)
    xs = SpecimenSpread(**dict(zip(SPREADS, spreads))).apply(np.repeat(x0[None], 40000, 0), rng)
    emp = np.cov(model.transform(xs), rowvar=False)
    sig = model.covariance(spreads)
    assert np.abs(emp - sig).max() < 0.08 * sig.max()
    freq = model.kinds == "frequency"
    # one motor-speed factor: every pair of frequencies (also across engines) covaries by speed^2
    assert np.allclose(sig[np.ix_(freq, freq)] - np.diag(np.diag(sig))[np.ix_(freq, freq)],
                       spreads[0] ** 2 * (1 - np.eye(freq.sum())))


def test_log_marginal_is_the_gaussian_integral_over_the_class_mean():
    """Two drones: the closed form equals N(m1 - m2; 0, A1 + A2) times the integral of
    mu's prior exp(t . mu) (t = 1 where the calibration prior is flat in x, 0 for the
    ln Gamma ratios) over mu's Gaussian N(m, V): exp(t . m + t V t / 2); mu | spreads
    is that Gaussian tilted, m + V t. One drone: exp(t . m1 + t A1 t / 2)."""
    model, _ = _model()
    rng = np.random.default_rng(1)
    p = model.p
    a = rng.standard_normal((p, p)) * 0.05
    c1, c2 = a @ a.T + 0.01 * np.eye(p), 0.02 * np.eye(p)
    m1, m2 = rng.standard_normal(p) * 0.1, rng.standard_normal(p) * 0.1
    d1 = DroneSummary("a", np.ones(p, bool), m1, c1, np.zeros((1, 13)))
    d2 = DroneSummary("b", np.ones(p, bool), m2, c2, np.zeros((1, 13)))
    spreads = np.array([[0.05, 0.02, 0.15, 0.15, 0.01], [0.1, 0.05, 0.3, 0.1, 0.05]])
    got, mu, P = log_marginal(spreads, [d1, d2], model, np.ones(p, bool))
    from scipy.stats import multivariate_normal
    t = model.linear_prior.astype(float)
    assert t.sum() == p - (model.kinds == "gamma").sum()  # flat in x but for the ln Gamma ratios
    for w, s in enumerate(spreads):
        sig = model.covariance(s)
        a1, a2 = c1 + sig, c2 + sig
        i1, i2 = np.linalg.inv(a1), np.linalg.inv(a2)
        v = np.linalg.inv(i1 + i2)
        m = v @ (i1 @ m1 + i2 @ m2)  # the precision-weighted mean of the two drones
        want = multivariate_normal(np.zeros(p), a1 + a2).logpdf(m1 - m2) + t @ m + 0.5 * t @ v @ t
        assert got[w] == pytest.approx(want, abs=1e-8)
        assert np.allclose(mu[w], m + v @ t)
    one, _, _ = log_marginal(spreads, [d1], model, np.ones(p, bool))
    for w, s in enumerate(spreads):
        assert one[w] == pytest.approx(t @ m1 + 0.5 * t @ (c1 + model.covariance(s)) @ t, abs=1e-8)


def test_spreads_recovered_from_many_well_measured_drones():
    """30 HELI drones drawn by the scene's specimen model, each measured to 1% in y:
    the hyper-posterior's 90% intervals hold the true speed, frequency, amplitude
    and skew spreads; gamma (no Gamma ratio in a one-engine class) stays at its prior."""
    model, x0 = _model()
    rng = np.random.default_rng(2)
    true = np.array([0.08, 0.03, 0.12, 0.15, 0.02])
    drones = _drones(model, x0, SpecimenSpread(**dict(zip(SPREADS, true))), 30, 0.01, rng)
    out = sample_spreads(drones, model, Hyperprior(), rng, max_steps=6000)
    q = np.quantile(out["spreads"], [0.05, 0.95], axis=0)
    for j, name in enumerate(SPREADS[:3] + ("skew",)):
        k = SPREADS.index(name)
        assert q[0, k] < true[k] < q[1, k], (name, q[:, k])
    g = SPREADS.index("gamma")
    prior = Hyperprior().scales["gamma"]
    assert 0.5 * prior < np.median(out["spreads"][:, g]) < 1.3 * prior  # half-normal median 0.674 x scale
    assert out["mu"].shape == (len(out["spreads"]), model.p)


def _result(model, x0, n_drones=3, seed=3):
    rng = np.random.default_rng(seed)
    drones = _drones(model, x0, SpecimenSpread(), n_drones, 0.02, rng)
    fit = sample_spreads(drones, model, Hyperprior(), rng, max_steps=3000)
    from mdaug.generator.acquisition import Acquisition
    pool = np.concatenate([d.draws for d in drones])
    from mdaug.inference.space.priors import Priors
    meta = {"format": "mdaug-population-1", "class_name": "HELI", "n_engines": 1, "gamma0": float(x0[0]),
            "priors": Priors.from_reference(load_reference("HELI")).to_dict(),
            "specimens": [d.specimen for d in drones], "hyperprior": Hyperprior().scales, "coords": model.names,
            "acquisition": Acquisition.measured(4).to_dict(), "drones_converged": [True] * n_drones,
            "identified": [d.mask.tolist() for d in drones],
            "diagnostics": {"tau": fit["tau"].tolist(), "steps": fit["steps"], "converged": fit["converged"],
                            "acceptance": fit["acceptance"]}}
    arrays = {"spreads": fit["spreads"], "mu": fit["mu"], "measured": fit["measured"], "pool": pool,
              "pool_drone": np.arange(len(pool)), "drone_means": model.transform(pool), "reference": x0}
    return PopulationResult(arrays, meta)


def test_new_drones_spread_around_the_class_mean(tmp_path):
    model, x0 = _model()
    res = _result(model, x0)
    x = res.draw_drones(4000, np.random.default_rng(0))
    assert x.shape == (4000, 13) and np.all(np.isfinite(x))
    assert np.all(res.inside_prior(x))  # truncated to the class's physics
    y = model.transform(x)
    freq = model.kinds == "frequency"
    # a new drone's frequencies move together (the common motor-speed factor)
    c = np.corrcoef(y[:, freq], rowvar=False)[0, 1]
    assert c > 0.3
    # its spread is at least the population's and the mean's uncertainty together
    sd = y.std(axis=0)
    assert np.all(sd[freq] > 0.5 * np.median(res.spreads()[:, 0]))
    # reproducible from the one seed
    assert np.array_equal(res.draw_drones(10, np.random.default_rng(5)), res.draw_drones(10, np.random.default_rng(5)))
    # saved and loaded unchanged
    path = res.save(tmp_path / "pop.npz")
    back = PopulationResult.load(path, class_name="heli")
    assert np.array_equal(back.draw_drones(10, np.random.default_rng(5)), res.draw_drones(10, np.random.default_rng(5)))
    assert "population of HELI: 3 drone(s)" in back.report()


def test_population_file_errors_name_file_and_field(tmp_path):
    model, x0 = _model()
    res = _result(model, x0, n_drones=2)
    arrays = dict(res.arrays)
    arrays["mu"] = arrays["mu"][:, :-1]
    bad = PopulationResult(arrays, res.meta).save(tmp_path / "bad.npz")
    with pytest.raises(DataFileError, match=r"bad.npz: field 'mu' has shape"):
        PopulationResult.load(bad)
    with pytest.raises(DataFileError, match="population of class 'HELI', expected 'QUAD'"):
        PopulationResult.load(res.save(tmp_path / "ok.npz"), class_name="QUAD")
    np.savez(tmp_path / "other.npz", profiles=np.zeros((2, 3)))
    with pytest.raises(DataFileError, match=r"other.npz: not a population file, missing field"):
        PopulationResult.load(tmp_path / "other.npz")


def test_one_drone_spreads_are_assumed():
    model, x0 = _model()
    res = _result(model, x0, n_drones=1)
    assert res.assumed
    assert all(r["status"] == "assumed" for r in res.summary())
    assert "assumed" in res.report()


@pytest.mark.slow
def test_population_sbc_runs_and_resumes(tmp_path):
    """Two small population SBC replicates (HELI, 2 drones x 3 acquisitions at K = 4,
    cheap calibrations): ranks of the 5 spreads and the unseen drone's lines within
    0..n_rank, and a rerun on the checkpoint does no new work."""
    from mdaug.inference import CalibrationSettings
    from mdaug.inference.diagnostics.population_sbc import run_population_sbc

    settings = CalibrationSettings(sampler="laplace", n_starts=1, fit_budget=200, polish_budget=100,
                                   n_particles=300, progress=False)
    ck = tmp_path / "sbc.jsonl"
    kw = dict(n_drones=2, n_acquisitions=3, ramps=4, settings=settings, seed=3, n_rank=19, checkpoint=ck)
    out = run_population_sbc("HELI", 2, **kw)
    ranks = out["all"]["ranks"]
    assert ranks.shape == (2, 5 + 8) and ranks.min() >= 0 and ranks.max() <= 19
    assert out["spreads"]["names"] == [f"spread:{n}" for n in SPREADS]
    assert len(ck.read_text().splitlines()) == 2
    again = run_population_sbc("HELI", 2, **kw)
    assert np.array_equal(again["all"]["ranks"], ranks)
    assert len(ck.read_text().splitlines()) == 2


def test_population_sbc_counts_a_refused_population(tmp_path, monkeypatch):
    """A population with a drone the calibration refuses (its posterior nearly all
    outside the prior) is counted and left out of the ranks, not a crash; when every
    population is refused the SBC says so by name."""
    import mdaug.inference.amortized.calibrate as amortized_calibrate
    from mdaug.inference.amortized.estimator import EstimatorError
    from mdaug.inference.diagnostics.population_sbc import run_population_sbc

    real = amortized_calibrate.calibrate_amortized
    calls = []

    def first_refused(*args, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise EstimatorError("drone 0: the amortized posterior put 3 of 40000 draws inside the prior")
        return real(*args, **kw)

    monkeypatch.setattr(amortized_calibrate, "calibrate_amortized", first_refused)
    kw = dict(n_drones=2, n_acquisitions=3, ramps=4, seed=3, n_rank=19, workers=1)
    out = run_population_sbc("HELI", 3, checkpoint=tmp_path / "a.jsonl", **kw)
    assert out["refused"]["count"] == 1 and out["refused"]["of"] == 3
    assert "3 of 40000 draws" in out["refused"]["first"]
    assert out["all"]["ranks"].shape[0] == 2

    def always_refused(*args, **kw):
        raise EstimatorError("drone 0: unlike anything in its training set")

    monkeypatch.setattr(amortized_calibrate, "calibrate_amortized", always_refused)
    with pytest.raises(ValueError, match="every one of 2 populations had a drone the calibration refused"):
        run_population_sbc("HELI", 2, checkpoint=tmp_path / "b.jsonl", **kw)


def test_study_data_keeps_each_calibration_drone(tmp_path):
    """simulation.calibration_drones = 2: each drone's first n_calibration acquisitions
    are calibrated on; the choices are made on a third drone no strategy is calibrated
    on (one fold of leave-one-drone-out); the stored sets say which drone each profile
    is of."""
    import dataclasses

    from mdaug.reports.config import StudyConfig
    from mdaug.reports.study import Study

    cfg = StudyConfig(seed=1, classes=("HELI",)).quick_version()
    cfg = dataclasses.replace(cfg, simulation=dataclasses.replace(cfg.simulation, calibration_drones=2,
                                                                  n_new={"HELI": 4}))
    study = Study(cfg, tmp_path / "s", log=lambda *_: None)
    study.data()
    n_cal, n_sel = cfg.simulation.n_calibration, cfg.simulation.n_select
    drones = study.load_drones("calibration_HELI", "HELI")
    assert drones.tolist() == ["0"] * n_cal + ["1"] * n_cal
    held = study.load_drones("select", "HELI")
    assert held.tolist() == ["2"] * (n_cal + n_sel)
    assert "no strategy was calibrated on" in study.selection_set(study.data())[2]
    job = study._calibration_job("HELI", study.acquisition(study.data()))
    assert job["drones"].tolist() == drones.tolist() and len(job["profiles"]) == 2 * n_cal


def test_population_sbc_compares_engines_in_a_label_free_order():
    """The unseen drone's per-engine quantities do not depend on which engine is called 0:
    any permutation of a QUAD's engines gives the same ordered vector (brightest first,
    the estimators' target order)."""
    from mdaug.generator import IDX, load_reference
    from mdaug.inference.diagnostics.population_sbc import engines_in_order
    from mdaug.inference.diagnostics.sbc import sbc_quantities

    x = load_reference("QUAD").to_array().reshape(4, 13)
    x[:, IDX["Gamma"]] = [0.3, 1.0, 0.05, 0.6]  # distinct brightnesses
    base = engines_in_order(x.ravel())
    for perm in ([3, 2, 1, 0], [1, 0, 3, 2], [2, 3, 0, 1]):
        assert np.array_equal(engines_in_order(x[perm].ravel()), base)
    assert base.reshape(4, 13)[:, IDX["Gamma"]].tolist() == [1.0, 0.6, 0.3, 0.05]
    assert np.array_equal(sbc_quantities(engines_in_order(x[[3, 1, 2, 0]].ravel()))[0], sbc_quantities(base)[0])


def test_a_drone_summary_is_its_likelihood_where_the_prior_is_flat():
    """A drone whose posterior is Gaussian in w (the prior is flat in w) is summarised in
    y = ln w at the likelihood's peak, ln m, with sd s / m; a Gaussian fitted in y with
    the prior's tilt divided out would sit about 1.5 (s / m)^2 lower."""
    from types import SimpleNamespace

    from mdaug.inference.population.model import summarise_drone
    from mdaug.inference.space.priors import Priors

    model, x0 = _model("HELI")
    rng = np.random.default_rng(3)
    m = {"w_a": x0[model.cols[model.names.index("w_a[0]")]], "w_b": x0[model.cols[model.names.index("w_b[0]")]]}
    s = {k: 0.1 * v for k, v in m.items()}  # a drone posterior 10% wide (the lines keep their order)
    draws = np.repeat(x0[None], 200_000, 0)
    for k in m:
        draws[:, model.cols[model.names.index(f"{k}[0]")]] = rng.normal(m[k], s[k], len(draws))
    result = SimpleNamespace(draws=lambda: draws, priors=Priors.from_reference(load_reference("HELI")))
    summary = summarise_drone(result, model, x0)
    at = {k: list(np.flatnonzero(summary.mask)).index(model.names.index(f"{k}[0]")) for k in m}
    for k, i in at.items():  # (the old tilt division: 1.5 x 0.1^2 = 0.015 lower)
        assert summary.mean[i] == pytest.approx(np.log(m[k]), abs=0.003)
        assert np.sqrt(summary.cov[i, i]) == pytest.approx(0.1, rel=0.03)  # (the relabelling trims the tails)
    corr = summary.cov[at["w_a"], at["w_b"]] / np.sqrt(summary.cov[at["w_a"], at["w_a"]] * summary.cov[at["w_b"], at["w_b"]])
    assert abs(corr) < 0.05  # independent draws stay about independent
