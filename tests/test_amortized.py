"""The amortized calibration: label-free target, networks, training, estimator files,
SBC machinery (on a toy simulator whose posterior is known), the smc route and
the calibrate verb. Tiny networks and budgets: seconds."""
import json
import zipfile

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from mdaug.generator import load_reference  # noqa: E402
from mdaug.generator.acquisition import Acquisition  # noqa: E402
from mdaug.inference.amortized.estimator import AmortizedEstimator, EstimatorError  # noqa: E402
from mdaug.inference.amortized.nets import NetConfig  # noqa: E402
from mdaug.inference.amortized.simulate import SimulationSpec, simulate  # noqa: E402
from mdaug.inference.amortized.target import DroneSpace, LabelFree  # noqa: E402
from mdaug.inference.emulator.train import EmulatorConfig  # noqa: E402
from mdaug.generator import IDX  # noqa: E402
from mdaug.inference.space.priors import Priors, engine_lines  # noqa: E402

TINY = NetConfig(channels=(2, 4, 4, 4), trial_out=8, set_hidden=16, set_out=8, flow_hidden=16, flow_transforms=2,
                 ratio_hidden=16)
TINY_SUMMARY = EmulatorConfig(n_offsets=64, n_components=4, hidden=16, depth=1, members=2, cov_hidden=16, epochs=3, cov_epochs=3,
                              n_calibration=3, n_starts=1)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny HELI K=4 estimator, trained for two epochs, and its file."""
    from mdaug.inference.estimator_job import train_estimator
    from mdaug.inference.amortized.train import TrainConfig

    torch.set_num_threads(1)
    d = tmp_path_factory.mktemp("est")
    spec = SimulationSpec("HELI", Acquisition.measured(4), 4)
    est = train_estimator(spec, 120, d / "work", d / "heli-k4.zip", seed=3, device="cpu", net_cfg=TINY,
                          train_cfg=TrainConfig(batch=32, max_epochs=2), sbc_truths=0, shard_size=60,
                          near_simulations=60, summary_cfg=TINY_SUMMARY, progress=False, log=lambda m: None)
    return est, d / "heli-k4.zip"


@pytest.mark.parametrize("cls", ["HELI", "QUAD"])
def test_label_free_round_trip_keeps_every_line(cls):
    ref = load_reference(cls)
    pr = Priors.from_reference(ref)
    space, lf = DroneSpace(ref.n_engines, pr), LabelFree(ref.n_engines, pr, ref.to_array())
    x = space.vectors(space.sample_prior(500, np.random.default_rng(0)))
    q = lf.quantities(x)
    assert q.shape == (500, 8 * ref.n_engines + ref.n_engines - 1)
    np.testing.assert_allclose(lf.from_unbounded(lf.to_unbounded(q)), q, rtol=1e-9)
    x2, ok = lf.vectors(q)
    assert ok.all()  # every prior draw has a labelling the prior allows
    np.testing.assert_allclose(lf.quantities(x2), q, rtol=1e-9)
    # the mapped vectors carry the same lines (f(x) unchanged): compare sorted line sets per engine
    w1, a1, _ = engine_lines(x.reshape(500, ref.n_engines, 13))
    w2, a2, _ = engine_lines(x2.reshape(500, ref.n_engines, 13))
    np.testing.assert_allclose(np.sort(w1.reshape(500, -1), 1), np.sort(w2.reshape(500, -1), 1), rtol=1e-9)
    np.testing.assert_allclose(np.sort(a1.reshape(500, -1), 1), np.sort(a2.reshape(500, -1), 1), rtol=1e-9)
    # lines are sorted in q: an engine's frequencies increase
    w = q[:, :4]
    assert np.all(np.diff(w, axis=1) > 0)


@pytest.mark.parametrize("cls, engines, n_is", [("HELI", 1, 200000), ("QUAD", 2, 300000)])
def test_label_free_prior_density_is_normalised(cls, engines, n_is):
    """The closed-form prior density in u integrates to one: importance sampling from a
    Gaussian fitted to prior draws. HELI: one engine; two engines of the QUAD prior: with
    the Gamma-ratio part for the brightness order (the re-referencing cut never acts on two)."""
    from scipy.stats import multivariate_normal

    ref = load_reference(cls)
    pr = Priors.from_reference(ref)
    space, lf = DroneSpace(engines, pr), LabelFree(engines, pr, ref.to_array())
    rng = np.random.default_rng(0)
    u = lf.to_unbounded(lf.quantities(space.vectors(space.sample_prior(20000, rng))))
    assert np.all(np.isfinite(lf.log_prior_u(u)))
    mu, cov = u.mean(0), 1.5 * np.cov(u.T)
    z = rng.multivariate_normal(mu, cov, n_is)
    w = np.exp(lf.log_prior_u(z) - multivariate_normal(mu, cov).logpdf(z))
    assert abs(w.mean() - 1.0) < 4 * w.std() / np.sqrt(len(w)) + 0.02


def test_engines_are_ordered_by_brightness():
    """QUAD: q does not depend on the order of the engines in the vector; engine 0 of q
    is the brightest (Gamma ratios <= 0, decreasing), and its lines are its own."""
    from mdaug.generator import IDX

    ref = load_reference("QUAD")
    pr = Priors.from_reference(ref)
    space, lf = DroneSpace(4, pr), LabelFree(4, pr, ref.to_array())
    x = space.vectors(space.sample_prior(200, np.random.default_rng(1))).reshape(200, 4, 13)
    q = lf.quantities(x.reshape(200, -1))
    np.testing.assert_allclose(lf.quantities(x[:, [2, 0, 3, 1]].reshape(200, -1)), q, rtol=1e-12)
    lng = q[:, lf.gamma_columns]
    assert [lf.names[c] for c in lf.gamma_columns] == ["lnG[1]", "lnG[2]", "lnG[3]"]
    assert np.all(lng <= 0) and np.all(np.diff(lng, axis=1) <= 0)
    brightest = np.argmax(x[..., IDX["Gamma"]], axis=1)
    w_bright, _, _ = engine_lines(x[np.arange(200), brightest][:, None])
    np.testing.assert_allclose(q[:, :4], np.sort(w_bright[:, 0], axis=1), rtol=1e-12)


def test_quantities_outside_the_prior_are_flagged():
    ref = load_reference("HELI")
    pr = Priors.from_reference(ref)
    lf = LabelFree(1, pr, ref.to_array())
    q = lf.quantities(ref.to_array()[None])
    q_bad = q.copy()
    q_bad[0, 4:8] = 10 * pr.bounds["A_a"][1]  # every amplitude far above its bound
    _, ok = lf.vectors(np.vstack([q, q_bad]))
    assert ok.tolist() == [True, False]


def test_the_prior_density_keeps_only_labellings_whose_lowest_roll_engine_may_be_the_reference():
    """The line density under the prior's cut (engines re-referenced to the one of lowest
    w_a, whose Gamma ratios to the others must stay in range) against a brute-force sum
    over every combination of the engines' labellings: c(l_0) ... c(l_3) where the engine
    of the lowest w_a is an allowed reference. With every engine allowed it is the plain
    product of the engines' sums; with none it is 0."""
    import itertools

    rng = np.random.default_rng(4)
    n, e, m = 5, 3, 4
    weights = rng.uniform(size=(n, e, m)) * (rng.uniform(size=(n, e, m)) < 0.7)
    roll = rng.uniform(1.0, 10.0, size=(n, e, m))
    refs = rng.uniform(size=(n, e)) < 0.6
    got = LabelFree._lines_given_cut(weights, roll, refs)
    for i in range(n):
        want = 0.0
        for combo in itertools.product(range(m), repeat=e):
            rolls = [roll[i, k, combo[k]] for k in range(e)]
            if refs[i, int(np.argmin(rolls))]:
                want += np.prod([weights[i, k, combo[k]] for k in range(e)])
        assert got[i] == pytest.approx(want, rel=1e-12, abs=1e-300)
    every = LabelFree._lines_given_cut(weights, roll, np.ones((n, e), bool))
    np.testing.assert_allclose(every, weights.sum(axis=2).prod(axis=1), rtol=1e-12)
    assert np.all(LabelFree._lines_given_cut(weights, roll, np.zeros((n, e), bool)) == 0)


def test_gamma_ratios_no_engine_could_reference_are_flagged():
    """QUAD: Gamma ratios spread wider than the prior allows around any engine are outside
    the support: flagged by vectors (not rendered at Gamma ~ 1e51) and -inf in the density."""
    ref = load_reference("QUAD")
    pr = Priors.from_reference(ref)
    lf = LabelFree(4, pr, ref.to_array())
    q = lf.quantities(ref.to_array()[None])
    hi = pr.bounds["lnG"][1]
    cols = lf.gamma_columns
    wide = q.copy()
    wide[0, cols] = [-0.5, -1.0, -2.2 * hi]  # the faintest engine below every other's range
    x, ok = lf.vectors(np.vstack([q, wide]))
    assert ok.tolist() == [True, False]
    lp = lf.log_prior_u(lf.to_unbounded(np.vstack([q, wide])))
    assert np.isfinite(lp[0]) and lp[1] == -np.inf


def test_simulation_is_seeded_and_shaped():
    spec = SimulationSpec("HELI", Acquisition.measured(4), 3)
    x1, y1 = simulate(spec, 4, 7)
    x2, y2 = simulate(spec, 4, 7)
    assert y1.shape == (4, 3, 400) and y1.dtype == np.float32
    np.testing.assert_array_equal(y1, y2)
    np.testing.assert_allclose(y1.max(axis=2), 1.0)  # peak-normalised
    assert np.all(np.argmax(y1, axis=2) == 200)  # peak-centred, as a measured file is prepared


def test_subset_masks_keep_between_one_and_all():
    from mdaug.inference.amortized.train import subset_mask

    m = subset_mask(2000, 6, torch.Generator().manual_seed(0), "cpu")
    kept = (~m).sum(1)
    assert kept.min() == 1 and kept.max() == 6
    assert abs(kept.float().mean().item() - 3.5) < 0.15  # uniform over 1..6


def test_estimator_file_round_trip(tiny, tmp_path):
    est, path = tiny
    back = AmortizedEstimator.load(path)
    spec = est.spec
    _, y = simulate(spec, 1, 11)
    u = est.label_free.to_unbounded(est.label_free.quantities(spec.space().vectors(
        spec.space().sample_prior(5, np.random.default_rng(2)))))
    np.testing.assert_allclose(back.log_prob_u(u, y[0]), est.log_prob_u(u, y[0]), rtol=1e-5, atol=1e-5)
    emb = back.embed(y[0])
    np.testing.assert_allclose(back.log_likelihood_u(u, emb), est.log_likelihood_u(u, est.embed(y[0])), atol=1e-5)
    assert back.meta["n_simulations"] == 120 and back.meta["spec"]["acquisition"]["ramps"] == 4
    assert {"posterior", "ratio"} <= set(back.meta["training"])


def test_log_prob_with_one_embedding_is_sbis_log_prob(tiny):
    """log_prob_u embeds the measurements once; sbi's log_prob embeds them per draw:
    the same densities, also for the shipped estimators' flow."""
    import torch

    from mdaug.inference.amortized.shipped import find

    est, _ = tiny
    for e in (est, find("HELI", est.spec.acquisition.replace(ramps=32))):
        _, y = simulate(est.spec, 1, 4)
        u = e.sample_u(y[0], 50, 3, strict=False)[0]
        with torch.inference_mode():
            t = torch.as_tensor(u, dtype=torch.float32)
            want = e.posterior.log_prob(t[:, None, :], condition=e.condition(y[0])).reshape(-1).double().numpy()
        np.testing.assert_allclose(e.log_prob_u(u, y[0]), want, rtol=1e-5, atol=1e-4)


def test_posterior_is_invariant_to_the_order_of_measurements(tiny):
    est, _ = tiny
    _, y = simulate(est.spec, 1, 5)
    u = np.random.default_rng(0).normal(size=(6, est.label_free.dim))
    a = est.log_prob_u(u, y[0])
    b = est.log_prob_u(u, y[0][::-1].copy())
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    c = est.log_prob_u(u, y[0][:2])  # fewer measurements: another posterior
    assert not np.allclose(a, c, atol=1e-4)


def test_tampered_or_truncated_estimator_is_refused(tiny, tmp_path):
    _, path = tiny
    data = path.read_bytes()
    cut = tmp_path / "cut.zip"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(EstimatorError, match="cut.zip: not a readable mdaug estimator"):
        AmortizedEstimator.load(cut)
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    for name, change, text in [
        ("nometa.zip", lambda m: m.pop("meta.json"), "member 'meta.json' missing"),
        ("format.zip", lambda m: m.__setitem__("meta.json", m["meta.json"].replace(b"mdaug-estimator-1", b"x")),
         "field 'format'"),
        ("weights.zip", lambda m: m.__setitem__("ratio.pt", members["posterior.pt"]), "member 'ratio.pt'"),
    ]:
        m = dict(members)
        change(m)
        p = tmp_path / name
        with zipfile.ZipFile(p, "w") as z:
            for k, v in m.items():
                z.writestr(k, v)
        with pytest.raises(EstimatorError, match=text):
            AmortizedEstimator.load(p)


def test_a_tempered_flow_draws_what_its_density_says_and_the_file_keeps_its_temperature(tiny, tmp_path):
    """At temperature T the draws are the flow's transform of T x a standard normal and
    log_prob_u is their density: importance weights back to the T = 1 flow average 1."""
    est, _ = tiny
    _, y = simulate(est.spec, 1, 21)
    hot = est.at_temperature(1.5)
    assert est.temperature == 1.0 and hot.temperature == 1.5 and hot.posterior is est.posterior
    torch.manual_seed(0)
    with torch.inference_mode():
        u = hot._flow_draws(4000, hot.condition(y[0]))
        cold = est._flow_draws(4000, est.condition(y[0]))
    w = np.exp(est.log_prob_u(u, y[0]) - hot.log_prob_u(u, y[0]))
    assert w.mean() == pytest.approx(1.0, abs=0.1)
    assert np.all(u.std(0) > cold.std(0))  # every quantity wider
    hot.save(tmp_path / "hot.zip")
    back = AmortizedEstimator.load(tmp_path / "hot.zip")
    assert back.temperature == 1.5
    np.testing.assert_allclose(back.log_prob_u(u[:5], y[0]), hot.log_prob_u(u[:5], y[0]), rtol=1e-6)
    with zipfile.ZipFile(tmp_path / "hot.zip") as z:
        members = {n: z.read(n) for n in z.namelist()}
    for bad in (0.5, 9.0, "1.2", float("nan")):
        meta = json.loads(members["meta.json"])
        meta["temperature"] = bad
        p = tmp_path / "bad.zip"
        with zipfile.ZipFile(p, "w") as z:
            for k, v in {**members, "meta.json": json.dumps(meta).encode()}.items():
                z.writestr(k, v)
        with pytest.raises(EstimatorError, match=r"bad.zip: meta.json field 'temperature' must be a number from 1 "
                                                 r"to 4, got"):
            AmortizedEstimator.load(p)


def test_an_estimator_of_another_target_version_is_refused(tmp_path):
    """A QUAD estimator whose quantities order the engines by their lowest line (target
    version 1) is refused by field, with the command that retrains it."""
    from mdaug.inference.amortized.shipped import shipped_path

    with zipfile.ZipFile(shipped_path("QUAD", 4)) as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(members["meta.json"])
    meta["target"] = 1
    members["meta.json"] = json.dumps(meta).encode()
    old = tmp_path / "old.zip"
    with zipfile.ZipFile(old, "w") as z:
        for k, v in members.items():
            z.writestr(k, v)
    with pytest.raises(EstimatorError, match=r"old.zip: meta.json field 'target' is 1: .* retrain with: "
                                             r"mdaug train-estimator --class QUAD --ramps 4"):
        AmortizedEstimator.load(old)


def test_data_of_another_acquisition_or_class_is_refused(tiny):
    from mdaug.inference.amortized.shipped import find
    from mdaug.radar import RadarConfig

    est, path = tiny
    y = np.ones((3, 400))
    with pytest.raises(EstimatorError, match=r"acquisition field 'ramps' is 32 .* trained for 4; train one with: "
                                             r"mdaug train-estimator --class HELI --ramps 32"):
        est.check_data(y, Acquisition.measured(32), RadarConfig(), "data.npz")
    with pytest.raises(EstimatorError, match="11 measurements; the estimator takes 1 to 4"):
        est.check_data(np.ones((11, 400)), Acquisition.measured(4), RadarConfig(), "data.npz")
    with pytest.raises(EstimatorError, match="'spec.class_name' is 'HELI'; the data are of class 'QUAD'"):
        find("QUAD", Acquisition.measured(4), path=path)
    with pytest.raises(EstimatorError, match="no shipped estimator for class HELI at K = 7"):
        find("HELI", Acquisition.measured(7))


def test_sbc_machinery_on_a_toy_with_a_known_posterior():
    """theta ~ N(0, 1), 5 measurements x ~ N(theta, 1): the exact posterior is
    N(sum x / 6, 1 / 6). Exact draws pass; draws 3x too narrow fail."""
    from mdaug.inference.diagnostics.routes import run

    rng = np.random.default_rng(0)
    truths = rng.normal(size=(300, 2))
    data = truths[:, None, :] + rng.normal(size=(300, 5, 2))

    def exact(y, n, s, shrink=1.0):
        r = np.random.default_rng(s)
        return y.sum(0) / 6 + r.normal(size=(n, 2)) * np.sqrt(1 / 6) * shrink, True

    ok = run(exact, truths, data, ["a", "b"], n_rank=99, prior_q=rng.normal(size=(4000, 2)))
    assert 0.06 <= ok["outer_share"] <= 0.14
    assert 0.85 <= ok["coverage"]["0.90"] <= 0.95
    assert ok["pooled_p"] > 0.001
    assert abs(ok["tarp_atc"]) < 0.1
    assert ok["width_over_truth"]["a"] < ok["prior_width_over_truth"]["a"]
    bad = run(lambda y, n, s: exact(y, n, s, 1 / 3), truths, data, ["a", "b"], n_rank=99)
    assert bad["outer_share"] > 0.4
    assert bad["coverage"]["0.90"] < 0.6


def test_training_resumes_from_its_checkpoint(tmp_path):
    from mdaug.inference.amortized.train import TrainConfig, fit

    g = torch.Generator().manual_seed(0)
    u = torch.randn(200, 1, generator=g)
    x = u[:, None, :].expand(200, 3, 1) + 0.1 * torch.randn(200, 3, 1, generator=g)

    def loss(net, ub, xb):  # regress u on the mean of the kept measurements
        keep = ~torch.isnan(xb[..., 0])
        mean = torch.nan_to_num(xb[..., 0]).sum(1) / keep.sum(1)
        return ((net(mean[:, None]) - ub) ** 2).mean()

    cfg = TrainConfig(batch=50, max_epochs=4, patience=100)
    torch.manual_seed(0)
    net = torch.nn.Linear(1, 1)
    log = fit(net, loss, u, x, cfg, 1, checkpoint=tmp_path / "ck.pt", progress=False)
    assert log.epochs == 4 and log.history[-1][1] < log.history[0][1]
    more = fit(net, loss, u, x, TrainConfig(batch=50, max_epochs=6, patience=100), 1, checkpoint=tmp_path / "ck.pt",
               progress=False)
    assert more.resumed_at == 4 and more.epochs == 6 and len(more.history) == 6


def test_smc_route_on_the_ratio_network_stays_in_the_prior(tiny):
    """A file without a summary likelihood: the smc route's target is the ratio network's
    posterior, and its particles stay on the prior's support."""
    from mdaug.inference.amortized.ratio_posterior import LearnedPosterior
    from mdaug.inference.amortized.tempered import sample_tempered
    from mdaug.inference.settings import CalibrationSettings

    est, _ = tiny
    _, y = simulate(est.spec, 1, 9)
    u, _ = est.sample_u(y[0], 300, 1, strict=False)
    post = LearnedPosterior(est, y[0])
    run = sample_tempered(post, lambda v: est.log_prob_u(v, y[0]), u, CalibrationSettings(progress=False,
                                                                                           time_budget=20), 4)
    s = run.draws()
    assert s.shape == (300, post.dim) and post.dim == 8
    assert np.all(np.isfinite(post.label_free.log_prior_u(s)))
    assert post.n_calls > 300 and run.reason  # it moved the particles; converged or says why not
    assert run.extra["smc_stages"] >= 1


# ---- the calibrate verb ---------------------------------------------------------------------------
def _folders(tmp_path):
    """(inputs, outputs) folders of a refusal test (the refused fixture hashes both)."""
    inputs, out = tmp_path / "in", tmp_path / "out"
    inputs.mkdir()
    out.mkdir()
    return inputs, out


def _profile_file(path, profiles, cls="HELI", ramps=4):
    np.savez(path, profiles=profiles, labels=np.array([cls] * len(profiles)), ramps_per_frame=np.array(ramps))
    return path


def test_calibrate_verb_writes_an_amortized_posterior(tiny, tmp_path, capsys):
    from mdaug.cli import main
    from mdaug.inference import CalibrationResult

    est, path = tiny
    _, y = simulate(est.spec, 1, 21)
    data = _profile_file(tmp_path / "heli.npz", y[0][:3])
    out = tmp_path / "post.nc"
    status = main(["calibrate", str(data), "--class", "HELI", "--out", str(out), "--estimator", str(path),
                   "--time-budget", "20", "--seed", "5"])
    text = capsys.readouterr()
    assert status == 0, text.err
    assert "posterior used by the strategies: amortized" in text.out
    # the file has a summary likelihood: its smc route runs beside, for the best fit only (no draws kept)
    assert "tempered SMC from the amortized posterior on the summary likelihood (run for the best fit)" in text.out
    res = CalibrationResult.load(out, class_name="HELI")  # check_content: variables, dims, prior bounds
    assert res.amortized and res.marginal and res.n_measurements == 3
    assert res.draws().shape == (4000, 13)
    assert "other_route" not in res.idata.groups()
    assert res.acquisition.ramps == 4
    checked = tmp_path / "checked.nc"
    status = main(["calibrate", str(data), "--class", "HELI", "--out", str(checked), "--estimator", str(path),
                   "--time-budget", "20", "--seed", "5", "--check-route"])
    text = capsys.readouterr()
    assert status == 0, text.err
    assert ("tempered SMC from the amortized posterior on the summary likelihood (run for the best fit and as a "
            "check)") in text.out
    assert "other_route" in CalibrationResult.load(checked, class_name="HELI").idata.groups()
    assert "temperature" not in text.out  # the flow as trained: nothing to say
    hot = tmp_path / "hot.zip"
    est.at_temperature(1.2).save(hot)
    assert main(["calibrate", str(data), "--class", "HELI", "--out", str(tmp_path / "hot.nc"), "--estimator",
                 str(hot), "--time-budget", "20", "--seed", "5"]) == 0
    assert "its draws inside the prior, drawn at temperature 1.2 (the file's" in capsys.readouterr().out
    assert CalibrationResult.load(tmp_path / "hot.nc", class_name="HELI").diagnostics["estimator"]["temperature"] == 1.2
    knobbed = tmp_path / "knobs.nc"  # --route-knob: the smc route's knobs over the file's and the defaults
    assert main(["calibrate", str(data), "--class", "HELI", "--out", str(knobbed), "--estimator", str(path),
                 "--time-budget", "20", "--seed", "5", "--route-knob", "route_max_sweeps=3", "--route-knob",
                 "n_particles=60", "--route-knob", "route_ess=0.8", "--route-knob", "route_moves=on"]) == 0
    text = capsys.readouterr().out
    ran = CalibrationResult.load(knobbed, class_name="HELI").diagnostics["smc"]["route_settings"]
    assert ran == {"route_moves": True, "route_ess": 0.8, "route_p_move": 0.9, "route_max_sweeps": 3, "n_particles": 60}
    assert ("its tempering: ESS share 0.8 a stage, sweeps until a particle has moved with probability 0.9 (at most "
            "3), moves across the golf course on") in text


def test_calibrate_verb_refuses_what_the_estimator_cannot_take(tiny, tmp_path, refused):
    est, path = tiny
    _, y = simulate(est.spec, 1, 22)
    inputs, out = _folders(tmp_path)
    nan = y[0][:3].copy()
    nan[1, 5] = np.nan
    bad = _profile_file(inputs / "nan.npz", nan)
    k7 = _profile_file(inputs / "k7.npz", y[0][:3], ramps=7)
    quad = _profile_file(inputs / "quad.npz", y[0][:3], cls="QUAD")
    good = _profile_file(inputs / "good.npz", y[0][:3])
    post = str(out / "p.nc")
    refused(["calibrate", str(bad), "--class", "HELI", "--out", post, "--estimator", str(path)], inputs, out,
            ["nan.npz", "NaN"])
    refused(["calibrate", str(k7), "--class", "HELI", "--out", post], inputs, out,
            ["no shipped estimator for class HELI at K = 7", "mdaug train-estimator --class HELI --ramps 7"])
    refused(["calibrate", str(quad), "--class", "QUAD", "--out", post, "--estimator", str(path)], inputs, out,
            ["spec.class_name", "'QUAD'"])
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--estimator", str(path),
             "--likelihood", "marginal"], inputs, out, ["--likelihood applies to --method likelihood"])
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--estimator", str(path),
             "--max-steps", "200"], inputs, out, ["--max-steps applies to --method likelihood"])  # emcee's knob
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--estimator", str(inputs / "none.zip")],
            inputs, out, ["none.zip"])
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--route-knob", "route_ess=1.5"], inputs, out,
            ["--route-knob", "route_ess must be a number in (0, 1), got 1.5"])
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--route-knob", "ess=0.9"], inputs, out,
            ["'ess=0.9': expected NAME=VALUE with NAME one of route_moves, route_ess"])
    refused(["calibrate", str(good), "--class", "HELI", "--out", post, "--method", "likelihood", "--route-knob",
             "route_ess=0.8"], inputs, out, ["--route-knob applies to --method amortized"])


def test_calibrate_refuses_too_many_measurements_of_one_drone(tmp_path, refused):
    inputs, out = _folders(tmp_path)
    rng = np.random.default_rng(0)
    y = rng.uniform(0.01, 1.0, size=(70, 400))
    many = _profile_file(inputs / "many.npz", y)
    for method in ("amortized", "likelihood"):
        refused(["calibrate", str(many), "--class", "HELI", "--method", method, "--out", str(out / "p.nc")], inputs,
                out, ["many.npz", "field 'profiles' holds 70 measurements", "at most 64"])


def test_train_estimator_and_sbc_verbs(tmp_path, capsys, refused):
    """train-estimator writes a checked estimator and resumes from its work folder; sbc
    reads it and writes strict JSON; cuda without a GPU is refused before any work."""
    import json

    from mdaug.cli import main

    out = tmp_path / "h.zip"
    argv = ["train-estimator", "--class", "HELI", "--ramps", "4", "--simulations", "100", "--measurements", "3",
            "--epochs", "1", "--sbc-truths", "0", "--near-simulations", "20", "--summary-epochs", "2", "--out", str(out)]
    assert main(argv) == 0, capsys.readouterr().err
    meta = AmortizedEstimator.load(out).meta
    assert meta["n_simulations"] == 100
    assert meta["command"].startswith("mdaug train-estimator --class HELI --ramps 4 --simulations 100")
    assert AmortizedEstimator.load(out).summary is not None  # trained beside the networks
    assert meta.get("temperature", 1.0) == 1.0 and "temperature_fit" not in meta  # not asked for
    assert main(argv[:-1] + [str(tmp_path / "h2.zip"), "--work", f"{out}.work", "--no-summary",
                             "--temperature-truths", "4"]) == 0
    text = capsys.readouterr().out
    assert "resumed at epoch 1" in text and "temperature" in text
    hot = AmortizedEstimator.load(tmp_path / "h2.zip")
    fit = hot.meta["temperature_fit"]
    assert hot.temperature == fit["temperature"] and fit["drones"] == 4 and f"{fit['temperature']:g}" in fit["rows"]
    js = tmp_path / "sbc.json"
    assert main(["sbc", "--class", "HELI", "--ramps", "4", "--estimator", str(out), "--truths", "3",
                 "--route-truths", "2", "--specimens", "2", "--time-budget", "5", "--json", str(js)]) == 0
    text = capsys.readouterr().out
    data = json.loads(js.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"))
    assert data["amortized"]["n_replicates"] == 3 and data["smc"]["n_replicates"] == 2
    assert set(data["specimens"]["rows"]) == {"amortized", "smc"} and data["specimens"]["drones"] == 2
    table = data["route_table"]
    assert table["default"] in ("amortized", "smc") and table["default_by"] in (
        "log score on 2 specimen drones", "no route passes the gate",
        "the only route that passes the gate on 2 prior drones")
    assert f"HELI K=4 default route: {table['default']} ({table['default_by']})" in text
    assert "HELI K=4 smc on 2 specimen drones: log score" in text
    assert table["route_settings"] == data["specimens"]["route_settings"] == {
        "route_moves": False, "route_ess": 0.7, "route_p_move": 0.9, "route_max_sweeps": 20, "n_particles": 1000}
    assert ("the smc route's knobs (the settings', else the file's, else the defaults): ESS share 0.7 a stage, "
            "sweeps until a particle has moved with probability 0.9 (at most 20), moves across the golf course off, "
            "1000 particles") in text
    assert "(an exact posterior fails this rule on 3 drones and 8 quantities with chance" in text  # noise floor
    if not torch.cuda.is_available():
        empty = tmp_path / "empty"
        empty.mkdir()
        refused(["train-estimator", "--class", "HELI", "--ramps", "4", "--device", "cuda", "--out",
                 str(empty / "x.zip")], empty, empty, ["device 'cuda'", "no GPU"])


def test_training_starts_from_a_files_weights_and_keeps_its_summary(tiny, tmp_path):
    """--start-from: a budget of 0 keeps the file's networks bit for bit (and its summary
    likelihood); one epoch moves them from there, and the start's own weights stay."""
    from mdaug.inference.amortized.train import TrainConfig
    from mdaug.inference.estimator_job import started_from, train_estimator

    est, _ = tiny
    before = {k: v.clone() for k, v in est.posterior.state_dict().items()}
    kw = dict(seed=9, device="cpu", net_cfg=TINY, train_cfg=TrainConfig(batch=32, max_epochs=1), sbc_truths=0,
              shard_size=50, start=est, progress=False, log=lambda m: None)
    kept = train_estimator(est.spec, 100, tmp_path / "w0", tmp_path / "kept.zip", post_budget=0, ratio_budget=0, **kw)
    for k, v in kept.posterior.state_dict().items():
        assert torch.equal(v, before[k]), k
    loaded = AmortizedEstimator.load(tmp_path / "kept.zip")
    assert loaded.summary is not None and loaded.meta["summary"] == est.meta["summary"]
    assert loaded.meta["training"]["posterior"]["epochs"] == 0 and loaded.meta["n_simulations"] == 100
    assert loaded.meta["training"]["start_from"]["summary"] == "kept"
    moved = train_estimator(est.spec, 100, tmp_path / "w1", tmp_path / "moved.zip", **kw)
    assert any(not torch.equal(v, before[k]) for k, v in moved.posterior.state_dict().items())
    for k, v in est.posterior.state_dict().items():
        assert torch.equal(v, before[k]), k  # the start itself is untouched
    with pytest.raises(ValueError, match="'spec.n_measurements' is 4; this training needs 6"):
        started_from(est, SimulationSpec("HELI", Acquisition.measured(4), 6), TINY, "cpu")
    with pytest.raises(ValueError, match="'net.channels'"):
        started_from(est, est.spec, NetConfig(), "cpu")


def test_sbc_specimens_without_a_route_table_run_the_amortized_route_alone(tiny, tmp_path, capsys):
    from mdaug.cli import main

    _, path = tiny
    js = tmp_path / "s.json"
    assert main(["sbc", "--class", "HELI", "--ramps", "4", "--estimator", str(path), "--truths", "3",
                 "--specimens", "4", "--json", str(js)]) == 0
    text = capsys.readouterr().out
    data = json.loads(js.read_text())
    assert "route_table" not in data and set(data["specimens"]["rows"]) == {"amortized"}
    assert data["specimens"]["drones"] == 4 and data["specimens"]["rows"]["amortized"]["n_replicates"] == 4
    assert set(data["specimens"]["crb_width_over_truth"]) == set(data["amortized"]["width_over_truth"])
    assert "HELI K=4 amortized on 4 specimen drones: log score" in text and "default route" not in text


def test_sbc_stored_prints_what_the_shipped_file_says_and_simulates_nothing(tmp_path, capsys):
    """`mdaug sbc --stored`: the gate's lines, specimen rows and default route that named
    QUAD K = 32's stacked route, read from the file (the README quotes them)."""
    from mdaug.cli import main

    js = tmp_path / "stored.json"
    assert main(["sbc", "--class", "QUAD", "--ramps", "32", "--stored", "--json", str(js)]) == 0
    text = capsys.readouterr().out
    data = json.loads(js.read_text())
    assert data["route_table"]["default"] == "stacked" and data["stacked"]["n_replicates"] == 200
    assert "QUAD K=32: the SBC stored in the shipped estimator (default route stacked)" in text
    assert f"QUAD K=32 stacked: outer-10% share {data['stacked']['outer_share']:.3f}" in text
    stacked = data["specimens"]["rows"]["stacked"]["log_score"]
    widths = " ".join(f"{v:.2f}" for v in list(data["specimens"]["rows"]["stacked"]["width_over_truth"].values())[:4])
    assert f"QUAD K=32 stacked on 20 specimen drones: log score {stacked:.2f} (exact), lines' median 90% " \
           f"width / truth {widths} " in text  # the mixture's widths, from both routes' draws
    assert stacked < data["specimens"]["rows"]["amortized"]["log_score"]  # why it is the default
    assert "QUAD K=32 default route: stacked (the only route that passes the gate on 200 prior drones)" in text
    table = next(line for line in text.splitlines() if line.startswith("QUAD K=32 route table on 200 drones: "))
    assert "amortized overconfident" in table and "smc overconfident" in table and "stacked honest" in table
    smc = sorted((c["0.90"], q) for q, c in data["smc"]["coverage_by_quantity"].items())
    assert smc[0][0] < 0.85  # the smc route fails the coverage rule; its printout names where
    assert (f"QUAD K=32 smc: outer-10% share {data['smc']['outer_share']:.3f}" in text and
            f"  least covered (90%): {smc[0][1]} {smc[0][0]:.2f}, {smc[1][1]} {smc[1][0]:.2f}," in text)


def test_sbc_stored_alone_lists_every_shipped_file_by_its_default_route(capsys, tmp_path, refused):
    """`mdaug sbc --stored` without --class and --ramps: one row per shipped file, its
    default route's stored SBC with the gate's word, in class and K order."""
    from pathlib import Path

    from mdaug.cli import main
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import DATA, available
    from mdaug.inference.result.status import honest

    assert main(["sbc", "--stored"]) == 0
    printed = capsys.readouterr().out
    assert printed.strip() in (Path(__file__).parents[1] / "README.md").read_text()  # the README quotes it whole
    rows = [ln for ln in printed.splitlines() if ln.split(" ")[0].endswith(".zip")]
    assert [r.split()[0] for r in rows] == sorted((f"{s}.zip" for s in available()),
                                                  key=lambda n: (n.split("-k")[0], int(n[:-4].split("-k")[1])))
    for r in rows:
        est = AmortizedEstimator.load(DATA / r.split()[0])
        s = est.meta["sbc"][est.default_route]
        assert r.split()[1:4] == [est.default_route, str(s["n_replicates"]), f"{s['outer_share']:.3f}"]
        assert ("overconfident" in r) == (not honest(s))
    heli32 = next(r for r in rows if r.startswith("heli-k32.zip"))
    assert "smc" in heli32 and "honest" in heli32 and heli32.split()[-4:] == ["0.99", "0.71", "0.58", "0.25"]
    # --class or --ramps alone, or a file given: one line saying both are needed, nothing written
    inputs, out = _folders(tmp_path)
    refused(["sbc", "--class", "HELI", "--stored"], inputs, out,
            ["--class and --ramps: both are needed", "`mdaug sbc --stored` alone lists every shipped estimator"])
    refused(["sbc", "--stored", "--json", str(out / "s.json")], inputs, out, ["(with --json"])
    refused(["sbc", "--stored", "--specimens", "5"], inputs, out, ["(with --specimens 5)"])


def test_sbc_stored_refuses_a_file_without_sbc_and_a_figure(tiny, tmp_path, refused):
    _, path = tiny  # trained with sbc_truths=0: no SBC stored
    inputs, out = _folders(tmp_path)
    base = ["sbc", "--class", "HELI", "--ramps", "4", "--stored"]
    refused(base + ["--estimator", str(path), "--json", str(out / "s.json")], inputs, out,
            [f"--estimator {path}: the file stores no SBC", "field 'sbc'"])
    refused(base + ["--figure", str(out / "s.png")], inputs, out, ["--figure", "without --stored"])
    refused(base + ["--specimens", "5"], inputs, out, ["--specimens 5: --stored simulates no drones"])


def test_start_from_is_checked_before_any_work(tiny, tmp_path, refused):
    _, path = tiny
    inputs, out = _folders(tmp_path)
    base = ["train-estimator", "--class", "HELI", "--ramps", "4", "--measurements", "4", "--out", str(out / "e.zip")]
    refused(base + ["--start-from", str(path)], inputs, out, [f"--start-from {path}", "'net.channels'"])
    refused(base + ["--posterior-budget", "0"], inputs, out, ["--posterior-budget 0 trains nothing", "--start-from"])
    refused(base + ["--start-from", str(out / "none.zip")], inputs, out, ["--start-from", "none.zip"])


def test_calibrate_refuses_a_trace_of_the_amortized_route_before_any_work(tiny, tmp_path, refused):
    est, path = tiny
    _, y = simulate(est.spec, 1, 23)
    inputs, out = _folders(tmp_path)
    good = _profile_file(inputs / "good.npz", y[0][:3])
    refused(["calibrate", str(good), "--class", "HELI", "--out", str(out / "p.nc"), "--estimator", str(path),
             "--trace", str(out / "t.png")], inputs, out, ["--trace applies to --method likelihood"])


def test_out_of_range_is_judged_against_the_estimators_own_drones():
    """QUAD keeps about a quarter of its draws inside the prior on its own simulated
    drones: that share is typical there, not a sign of foreign data; a tenth of it is."""
    from mdaug.inference.amortized.calibrate import _out_of_range

    ref = load_reference("HELI")
    lf = LabelFree(1, Priors.from_reference(ref), ref.to_array())
    x = np.repeat(ref.to_array()[None], 10, axis=0)
    assert _out_of_range(lf, x, None, 0.22, 0.22) == (False, "")
    flagged, why = _out_of_range(lf, x, None, 0.03, 0.22)
    assert flagged and "3%" in why and "22%" in why
    far = x.copy()
    far[:, 2] *= 2.0  # w_a doubled in the other route: the two disagree on lines
    assert _out_of_range(lf, x, far, 0.7, 0.7)[0]


def test_simulation_shards_resume_under_older_keys_and_refuse_another_seed(tmp_path):
    """A work folder's shards are reused when their key names the same simulations,
    also when it was written under an older field name (the radar's ramps_per_frame,
    now max_ramps_per_frame); another seed is refused by name."""
    import json

    from mdaug.inference.amortized.simulate import SimulationSpec, simulate_shards
    from mdaug.radar import atomic_savez

    spec = SimulationSpec("HELI", Acquisition.measured(1), 2)
    folder = tmp_path / "sims"
    paths = simulate_shards(folder, spec, 4, seed=3, shard_size=2)
    first = {p.name: np.load(p)["vectors"] for p in paths}

    def legacy(key: str) -> str:
        d = json.loads(key)
        d["spec"]["radar"]["ramps_per_frame"] = d["spec"]["radar"].pop("max_ramps_per_frame")
        return json.dumps(d, sort_keys=True)

    stamp = folder / "simulation.json"
    stamp.write_text(json.dumps({"key": legacy(json.loads(stamp.read_text())["key"])}))
    with np.load(paths[0]) as f:
        arrays = {k: f[k] for k in f.files}
    atomic_savez(paths[0], **{**arrays, "key": np.array(legacy(str(arrays["key"])))})
    logged = []
    again = simulate_shards(folder, spec, 4, seed=3, shard_size=2, log=logged.append)
    assert logged == [f"simulations: 2 of 2 shards found in {folder}, reused"]
    assert all(np.array_equal(np.load(p)["vectors"], first[p.name]) for p in again)
    with pytest.raises(ValueError, match="holds simulations of another spec or seed"):
        simulate_shards(folder, spec, 4, seed=4, shard_size=2)


def test_the_summary_likelihood_round_trips_through_the_estimator_file(tiny):
    est, path = tiny
    back = AmortizedEstimator.load(path)
    assert est.summary is not None and back.summary is not None
    assert back.likelihood_name == "summary" and back.default_route == "amortized"  # no route table: sbc_truths=0
    u = est.label_free.to_unbounded(est.label_free.quantities(est.spec.space().vectors(
        est.spec.space().sample_prior(4, np.random.default_rng(5)))))
    m1, c1 = est.summary.moments(u, 5)
    m2, c2 = back.summary.moments(u, 5)
    np.testing.assert_allclose(m2, m1, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(c2, c1, rtol=1e-6, atol=1e-6)
    assert c1.shape == (4, 4, 4) and np.all(np.linalg.eigvalsh(c1) > 0)
    meta = back.meta["summary"]
    assert meta["inflation"] >= 1 and meta["training"]["near_simulations"] == 60
    assert meta["error_net"] == {"dim": est.label_free.dim, "hidden": 32}


def test_summary_model_returns_the_files_likelihood_or_refuses_naming_the_source(tiny):
    import copy

    est, path = tiny
    assert est.summary_model(str(path)) is est.summary
    bare = copy.copy(est)
    bare.summary = None
    with pytest.raises(EstimatorError) as info:
        bare.summary_model("heli-k4.zip")
    msg = str(info.value)
    assert msg.startswith("heli-k4.zip: carries no summary likelihood (class HELI, K = 4)")
    assert "mdaug train-estimator --class HELI --ramps 4" in msg


def _rewrite(path, tmp_path, name, change):
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(members["meta.json"])
    change(members, meta)
    members["meta.json"] = json.dumps(meta).encode()
    p = tmp_path / name
    with zipfile.ZipFile(p, "w") as z:
        for k, v in members.items():
            z.writestr(k, v)
    return p


@pytest.mark.parametrize("name, change, text", [
    ("nosum.zip", lambda m, meta: m.pop("summary.pt"), "member 'summary.pt' is missing"),
    ("nometa.zip", lambda m, meta: meta.pop("summary"), "field 'summary' is missing"),
    ("infl.zip", lambda m, meta: meta["summary"].__setitem__("inflation", 0.5), "'summary.inflation' must be a finite"),
    ("nan.zip", lambda m, meta: meta["summary"].__setitem__("inflation", float("nan")), "'summary.inflation'"),
    ("err.zip", lambda m, meta: meta["summary"].__setitem__("error_net", {"dim": 8}), "'summary.error_net' must hold"),
    ("dim.zip", lambda m, meta: meta["summary"]["net"].__setitem__("dim", 9), "'summary.net.dim' is 9"),
    ("route.zip", lambda m, meta: meta.__setitem__("default_route", "fast"), "field 'default_route' is 'fast'"),
    ("weights.zip", lambda m, meta: m.__setitem__("summary.pt", m["ratio.pt"]), "member 'summary.pt'"),
    ("knobs.zip", lambda m, meta: meta.__setitem__("route_settings", [0.9]), "field 'route_settings' is list"),
    ("ess.zip", lambda m, meta: meta.__setitem__("route_settings", {"route_ess": 1.5}),
     r"field 'route_settings': route_ess must be a number in \(0, 1\), got 1.5"),
    ("sweeps.zip", lambda m, meta: meta.__setitem__("route_settings", {"route_max_sweeps": 2.5}),
     "route_max_sweeps must be an integer >= 2"),
    ("moves.zip", lambda m, meta: meta.__setitem__("route_settings", {"route_moves": "yes"}),
     "route_moves must be true or false"),
    ("unknown.zip", lambda m, meta: meta.__setitem__("route_settings", {"ess": 0.9}), "unknown route knob"),
    ("stack.zip", lambda m, meta: meta.__setitem__("stacking", {"weight": 1.5}),
     r"field 'stacking.weight' must be a number in \(0, 1\), got 1.5"),
    ("stackless.zip", lambda m, meta: meta.__setitem__("default_route", "stacked"),
     "field 'default_route' is 'stacked' but the file has no field 'stacking'"),
])
def test_a_damaged_summary_likelihood_is_refused_by_field(tiny, tmp_path, name, change, text):
    _, path = tiny
    bad = _rewrite(path, tmp_path, name, change)
    with pytest.raises(EstimatorError, match=f"{name}: .*{text}" if "member" not in text else text):
        AmortizedEstimator.load(bad)


def test_routes_over_a_file_pickle_and_run_in_workers_as_in_one_process(tiny):
    import pickle

    from mdaug.inference.diagnostics.routes import run
    from mdaug.inference.estimator_job import Route
    from mdaug.inference.settings import CalibrationSettings

    est, path = tiny
    with pytest.raises(TypeError, match="give its file's path"):
        pickle.dumps(Route("amortized", est))
    route = pickle.loads(pickle.dumps(Route("amortized", path)))
    lf = est.label_free
    x, y = simulate(est.spec, 3, 8)
    truths = lf.quantities(x)
    one = run(route, truths, y, lf.names, n_rank=19, seed=4, to_unbounded=lf.to_unbounded)
    two = run(Route("amortized", path), truths, y, lf.names, n_rank=19, seed=4, workers=2,
              to_unbounded=lf.to_unbounded)
    assert one["ranks"] == two["ranks"]  # drone i's draws depend on seed + i only
    # the amortized route is a density: its log score is exact, the same in workers
    assert one["log_score_by"] == two["log_score_by"] == "exact"
    assert one["log_score_by_drone"] == pytest.approx(two["log_score_by_drone"], rel=1e-6)
    want = [-est.truncated_log_prob_u(u[None], yi, 4 + i)[0]
            for i, (u, yi) in enumerate(zip(lf.to_unbounded(truths), y))]
    assert one["log_score_by_drone"] == pytest.approx(want, rel=1e-6)
    # the smc route's density comes from its own run (evidence and start share), in workers too
    smc = [run(Route("smc", path, CalibrationSettings(progress=False)), truths[:2], y[:2], lf.names, n_rank=19,
               seed=4, to_unbounded=lf.to_unbounded, workers=w) for w in (1, 2)]
    assert smc[0]["log_score_by"] == "exact" and np.all(np.isfinite(smc[0]["log_score_by_drone"]))
    assert smc[0]["log_score_by_drone"] == pytest.approx(smc[1]["log_score_by_drone"], rel=1e-9)


def test_the_truncated_density_is_the_flows_over_its_mass_inside_the_prior(tiny):
    """truncated_log_prob_u = log q(u | x) - log(share of q's draws inside the prior),
    the share the sampler itself measures (same seed), and never below log q."""
    est, _ = tiny
    _, y = simulate(est.spec, 1, 21)
    u, _ = est.sample_u(y[0], 30, 5)
    _, inside = est.sample_u(y[0], 1024, 9, strict=False)
    got = est.truncated_log_prob_u(u, y[0], 9)
    assert 0 < inside <= 1
    np.testing.assert_allclose(got, est.log_prob_u(u, y[0]) - np.log(inside), rtol=1e-9)
    assert np.all(got >= est.log_prob_u(u, y[0]))


def test_tempered_smc_from_a_wide_proposal_weighs_distant_modes_right():
    """Two modes 0.3 / 0.7, 6 sd apart: SMC from a broad q gives each its weight and
    width, where walkers started in one mode would stay there."""
    from scipy.stats import multivariate_normal as mvn

    from mdaug.inference.amortized.tempered import sample_tempered
    from mdaug.inference.settings import CalibrationSettings

    a, b = np.array([-3.0, 0.0]), np.array([3.0, 1.0])

    class Bimodal:
        def __call__(self, u):
            u = np.atleast_2d(u)
            lp = np.logaddexp(np.log(0.3) + mvn(a, 0.25).logpdf(u), np.log(0.7) + mvn(b, 0.25).logpdf(u))
            return np.where(np.all(np.abs(u) < 10, axis=1), lp, -np.inf)

    q = mvn([0.0, 0.0], 16.0)
    start = q.rvs(1000, random_state=np.random.default_rng(1))
    run = sample_tempered(Bimodal(), q.logpdf, start, CalibrationSettings(progress=False), 3)
    d = run.draws()
    right = d[:, 0] > 0
    assert run.converged and d.shape == (1000, 2)
    assert right.mean() == pytest.approx(0.7, abs=0.06)
    assert d[right].mean(0) == pytest.approx(b, abs=0.1) and d[~right].mean(0) == pytest.approx(a, abs=0.15)
    assert d[right].std(0) == pytest.approx([0.5, 0.5], rel=0.15)
    with pytest.raises(ValueError, match="even number"):
        sample_tempered(Bimodal(), q.logpdf, start[:5], CalibrationSettings(progress=False), 3)
    # the route's tempering knobs come from the SMC plugin: slower tempering takes more stages,
    # and no stage sweeps more than route_max_sweeps
    slow = CalibrationSettings(progress=False).with_plugin("smc", route_ess=0.95, route_p_move=0.99,
                                                           route_max_sweeps=3)
    run_slow = sample_tempered(Bimodal(), q.logpdf, start, slow, 3)
    assert run_slow.converged and len(run_slow.extra["smc_betas"]) > len(run.extra["smc_betas"])
    assert max(run_slow.extra["smc_sweeps"]) == 3
    with pytest.raises(ValueError, match="route_ess"):
        CalibrationSettings().with_plugin("smc", route_ess=1.0)


def test_the_smc_routes_density_is_the_normalised_posterior_from_its_own_evidence():
    """The target known only up to a constant (here + 5 nats), q restricted to a box:
    the run's evidence and q's share inside give back the normalised posterior's log
    density at any point, the bookkeeping the route table's exact log score relies on."""
    from scipy.stats import multivariate_normal as mvn

    from mdaug.inference.amortized.tempered import log_density, sample_tempered
    from mdaug.inference.settings import CalibrationSettings

    a, b = np.array([-3.0, 0.0]), np.array([3.0, 1.0])

    def exact(u):
        u = np.atleast_2d(u)
        return np.logaddexp(np.log(0.3) + mvn(a, 0.25).logpdf(u), np.log(0.7) + mvn(b, 0.25).logpdf(u))

    def post(u):  # unnormalised, zero outside the box
        u = np.atleast_2d(u)
        return np.where(np.all(np.abs(u) < 7, axis=1), exact(u) + 5.0, -np.inf)

    q = mvn([0.0, 0.0], 16.0)
    start = q.rvs(2000, random_state=np.random.default_rng(1))
    run = sample_tempered(post, q.logpdf, start, CalibrationSettings(progress=False), 3)
    run.extra["start_inside_share"] = float(np.mean(np.all(np.abs(start) < 7, axis=1)))
    assert run.converged and 0.8 < run.extra["start_inside_share"] < 0.9
    pts = np.array([[3.0, 1.0], [-3.0, 0.0], [2.5, 1.5], [-3.4, -0.3], [0.0, 0.5]])
    got = log_density(pts, post, q.logpdf, run)
    np.testing.assert_allclose(got, exact(pts), atol=0.15)  # the evidence's Monte Carlo error
    assert log_density(np.array([[8.0, 0.0]]), post, q.logpdf, run)[0] == -np.inf


def test_smc_route_on_the_summary_likelihood_reports_its_run_and_status(tiny):
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.result.status import calibration_status
    from mdaug.inference.settings import CalibrationSettings

    est, _ = tiny
    _, y = simulate(est.spec, 1, 21)
    settings = CalibrationSettings(time_budget=20, progress=False).with_plugin("smc", n_particles=200)
    res = calibrate_amortized(y[0], "HELI", acquisition=est.spec.acquisition, estimator=est, route="smc",
                              settings=settings, random_state=2, check=True)
    d = res.diagnostics
    assert d["route"] == "smc" and d["smc"]["likelihood"] == "summary" and d["smc"]["particles"] == 200
    assert set(d["smc"]["crb"]) == set(est.label_free.names) and all(v > 0 for v in d["smc"]["crb"].values())
    assert "summary likelihood" in res.meta["likelihood"]["likelihood"]
    assert "other_route" in res.idata.groups()  # the check: the amortized draws beside
    status = calibration_status(res)
    assert status.route == "smc" and status.route_words.startswith("tempered SMC from the amortized posterior on")
    assert status.headline.startswith("smc route: ")
    assert "tempered SMC from the amortized posterior on the summary likelihood (the route used): 200 particles" \
        in res.report()
    assert ("its tempering: ESS share 0.7 a stage, sweeps until a particle has moved with probability 0.9 (at most "
            "20), moves across the golf course off") in res.report()  # the defaults: the file states none


def test_the_stacked_route_mixes_the_two_routes_at_the_files_weight(tiny, tmp_path):
    """A file with a stacking weight has the stacked route: its draws are the smc route's
    at that share and the amortized posterior's for the rest, the report and the status
    say so, and its SBC row is derived from the two routes' runs on the same drones; a
    file without a weight refuses the route by name."""
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.estimator_job import estimator_sbc
    from mdaug.inference.result.status import calibration_status
    from mdaug.inference.settings import CalibrationSettings

    est, path = tiny
    _, y = simulate(est.spec, 1, 21)
    settings = CalibrationSettings(time_budget=20, progress=False).with_plugin("smc", n_particles=200)
    with pytest.raises(EstimatorError, match="the stacked route needs a stacking weight, and the file .* states none"):
        calibrate_amortized(y[0], "HELI", acquisition=est.spec.acquisition, estimator=est, route="stacked",
                            settings=settings)
    stack = {"weight": 0.7, "drones": 40, "chosen_by": "test"}
    stacked = AmortizedEstimator.load(_rewrite(path, tmp_path, "stacked.zip", lambda m, meta: meta.update(
        stacking=stack, default_route="stacked")))
    assert stacked.stacking_weight == 0.7 and stacked.default_route == "stacked"
    res = calibrate_amortized(y[0], "HELI", acquisition=est.spec.acquisition, estimator=stacked, settings=settings,
                              random_state=2, n_draws=4000)
    d = res.diagnostics
    assert d["route"] == "stacked" and d["stacked"]["weight"] == 0.7 and d["converged"] == d["smc"]["converged"]
    assert d["stacked"]["smc_share"] == pytest.approx(0.7, abs=0.03) and res.draws().shape == (4000, 13)
    status = calibration_status(res)
    assert status.route == "stacked" and status.route_words.startswith(
        "stacked: 0.70 x tempered SMC from the amortized posterior on the estimator's summary likelihood + 0.30 x")
    text = res.report()
    assert "stacked route: 0.70 x the smc route's posterior + 0.30 x the amortized posterior" in text
    assert "(stacked in the route used)" in text and "on 40 held-out simulated drones" in text
    out = estimator_sbc(stacked, 3, seed=4, route_truths=3, routes=("amortized", "stacked"),
                        route_settings=settings, log=lambda m: None, specimens=2)
    rows = out["route_table"]["rows"]
    assert set(rows) == set(out["specimens"]["rows"]) == {"amortized", "smc", "stacked"}  # it brings its two runs
    assert out["stacked"]["derived_from"] == ["smc", "amortized"] and out["stacked"]["weight"] == 0.7
    assert rows["stacked"]["verdict"] in ("honest", "overconfident") and rows["stacked"]["n_replicates"] == 3


def test_the_smc_route_runs_with_the_files_knobs_unless_the_settings_set_them(tiny, tmp_path):
    """A file states the knobs its route table was made with (meta ``route_settings``): a
    calibration takes them where the settings leave a knob unset, the settings' own where
    set, and the built-in defaults where neither does; the run records what it ran with,
    and adopting a route table writes its knobs into the file."""
    from mdaug.inference.amortized.tempered import smc_route
    from mdaug.inference.estimator_job import adopt_route_table
    from mdaug.inference.samplers.smc import ROUTE_DEFAULTS
    from mdaug.inference.settings import CalibrationSettings

    est, path = tiny
    _, y = simulate(est.spec, 1, 21)
    knobs = {"route_ess": 0.95, "route_max_sweeps": 3, "n_particles": 120}
    own = AmortizedEstimator.load(_rewrite(path, tmp_path, "own.zip", lambda m, meta: meta.update(route_settings=knobs)))
    plain = CalibrationSettings(time_budget=20, progress=False)
    _, run = smc_route(own, y[0], plain, 1, 2)
    ran = run.extra["route_settings"]
    assert ran == {**ROUTE_DEFAULTS, **knobs}  # the file's, the defaults for the rest
    assert run.chain.shape[1] == 120 and max(run.extra["smc_sweeps"]) <= 3
    _, run = smc_route(own, y[0], plain.with_plugin("smc", route_max_sweeps=5, n_particles=80), 1, 2)
    assert run.extra["route_settings"] == {**ROUTE_DEFAULTS, "route_ess": 0.95, "route_max_sweeps": 5,
                                           "n_particles": 80}  # the settings' own win
    _, run = smc_route(est, y[0], plain.with_plugin("smc", n_particles=80), 1, 2)
    assert run.extra["route_settings"] == {**ROUTE_DEFAULTS, "n_particles": 80}  # a file without knobs
    table = {"drones": 3, "default": "smc", "route_settings": dict(ran), "rows": {}}
    copy = AmortizedEstimator.load(path)
    copy.meta["sbc"] = {"route_table": table}
    adopt_route_table(copy)
    assert copy.meta["default_route"] == "smc" and copy.meta["route_settings"] == ran
    copy.save(tmp_path / "adopted.zip")
    assert AmortizedEstimator.load(tmp_path / "adopted.zip").meta["route_settings"] == ran


@pytest.mark.filterwarnings("ignore:.*unlike the estimator's training set")  # a tiny, two-epoch estimator
def test_the_best_fit_beside_the_amortized_route_is_the_summary_likelihoods_smc_median(tiny):
    """A file with a summary likelihood, amortized route: the smc route still runs, for
    the best fit only (its draws are not stored unless asked as a check); with the check
    its draws are the other route, and the best fit is their median, not the amortized
    posterior's; fit=False leaves the amortized median and runs nothing else."""
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.result.status import calibration_status
    from mdaug.inference.settings import CalibrationSettings

    est, _ = tiny
    _, y = simulate(est.spec, 1, 22)
    settings = CalibrationSettings(time_budget=20, progress=False).with_plugin("smc", n_particles=200)
    kw = dict(acquisition=est.spec.acquisition, estimator=est, route="amortized", settings=settings, random_state=4)
    fit = calibrate_amortized(y[0], "HELI", **kw)
    d = fit.diagnostics
    assert d["route"] == "amortized" and d["best_fit_from"] == "smc" and d["smc"]["particles"] == 200
    assert "other_route" not in fit.idata.groups()
    assert calibration_status(fit).check.startswith("smc route, run for the best fit: ")
    assert "(run for the best fit): 200 particles" in fit.report()
    assert "best fit (sigma_p_fit's centre): the smc route's median" in fit.report()
    checked = calibrate_amortized(y[0], "HELI", check=True, **kw)
    assert checked.groups == ("posterior", "other_route") and fit.groups == ("posterior",)
    other = checked.draws(group="other_route")  # the smc draws, kept as the other route
    assert other.shape == (checked.idata.other_route["Gamma"].size, 13) and np.all(other[:, IDX["phi_a"]] == 0)
    with pytest.raises(ValueError, match="group must be one of posterior for this result, got 'other_route'"):
        fit.draws(group="other_route")
    np.testing.assert_array_equal(checked.route_draws("smc"), other)  # the route the posterior is not
    np.testing.assert_array_equal(checked.route_draws("amortized"), checked.draws())
    with pytest.raises(ValueError, match="route 'smc': this result holds the amortized route's draws only"):
        fit.route_draws("smc")
    lf = est.label_free
    assert checked.diagnostics["best_fit_median"] == "label-free"
    np.testing.assert_allclose(lf.quantities(checked.best_fit[None])[0], np.median(lf.quantities(other), axis=0))
    np.testing.assert_allclose(fit.best_fit, checked.best_fit)  # the same seeds: the same smc run
    assert not np.allclose(lf.quantities(fit.best_fit[None])[0], np.median(lf.quantities(fit.draws()), axis=0))
    assert "(run for the best fit and as a check)" in checked.report()
    assert calibration_status(checked).check.startswith("smc route, run for the best fit and as a check: ")
    plain = calibrate_amortized(y[0], "HELI", fit=False, **kw)
    assert plain.diagnostics["best_fit_from"] == "amortized" and "smc" not in plain.diagnostics
    np.testing.assert_allclose(lf.quantities(plain.best_fit[None])[0], np.median(lf.quantities(plain.draws()), axis=0))


def test_the_best_fit_is_the_label_free_median_not_a_mix_of_labellings():
    """Draws of one drone whose lines carry two labellings (roll and pitch swapped in
    half of them, as a posterior over label-free lines does): the component-wise
    median of the class vectors lands between the lines, the label-free median is the
    drone; medians that no labelling fits fall back to the component-wise median."""
    from mdaug.inference.amortized.calibrate import label_free_median

    ref = load_reference("HELI")
    pr = Priors.from_reference(ref)
    lf = LabelFree(1, pr, ref.to_array())
    q0 = lf.quantities(ref.to_array()[None])
    wp, ap, _, _, cp, cm, valid = lf._labellings(q0[:, :4], q0[:, 4:8])
    w_ref, _, _ = engine_lines(ref.to_array()[None])
    second = next(k for k in np.flatnonzero(valid[0]) if not np.allclose(wp[0, k], w_ref[0]))  # another labelling
    alt = ref.to_array().copy()
    for role, col in enumerate("abpm"):
        alt[IDX[f"A_{col}"]] = ap[0, second, role]
    alt[IDX["w_a"]], alt[IDX["w_b"]], alt[IDX["C_p"]], alt[IDX["C_m"]] = *wp[0, second, :2], cp[0, second], cm[0, second]
    rng = np.random.default_rng(0)
    q = q0 * (1 + 0.01 * rng.standard_normal((400, q0.shape[1])))
    q[:, :4] = np.sort(q[:, :4], axis=1)
    x, ok = lf.vectors(q)
    swapped, ok2 = LabelFree(1, pr, alt).vectors(q)  # the same lines, the other labelling
    assert ok.all() and ok2.all() and not np.allclose(x, swapped)
    mixed = np.concatenate([x[:200], swapped[200:]])
    np.testing.assert_allclose(lf.quantities(mixed), q, rtol=1e-9)  # label-free: the same draws
    best, how = label_free_median(lf, mixed)
    assert how == "label-free"
    np.testing.assert_allclose(lf.quantities(best[None])[0], np.median(q, axis=0), rtol=1e-9)
    err = lambda v: np.max(np.abs(lf.quantities(v[None])[0, :4] / q0[0, :4] - 1))  # noqa: E731
    assert err(np.median(mixed, axis=0)) > 0.1 > 0.03 > err(best)
    bad = x.copy()
    bad[:, [IDX[f"A_{r}"] for r in "abpm"]] = 10 * pr.bounds["A_a"][1]  # amplitudes no labelling allows
    _, how = label_free_median(lf, bad)
    assert how == "component-wise"


def test_a_plugged_in_covariance_is_held_for_every_u(tiny):
    """With plug_in, the likelihood is the Gaussian of mu(u) under the one covariance at
    the plug-in point: differences between two u are half their chi-square differences
    under it, and at the plug-in point it equals the u-dependent likelihood."""
    from mdaug.inference.emulator.posterior import EmulatedPosterior

    est, _ = tiny
    lf, model = est.label_free, est.summary
    _, y = simulate(est.spec, 1, 33)
    u = lf.to_unbounded(lf.quantities(est.spec.space().vectors(est.spec.space().sample_prior(
        3, np.random.default_rng(9)))))
    held = EmulatedPosterior(model, y[0], plug_in=u[0])
    free = EmulatedPosterior(model, y[0])
    assert held.log_likelihood(u[:1]) == pytest.approx(free.log_likelihood(u[:1]), rel=1e-9, abs=1e-9)
    _, cov = model.moments(u[:1], len(y[0]))
    r = model.mean(u) - held.z
    chi = np.einsum("ni,ij,nj->n", r, np.linalg.inv(cov[0]), r)
    ll = held.log_likelihood(u)
    assert ll[1] - ll[2] == pytest.approx(-0.5 * (chi[1] - chi[2]), rel=1e-6, abs=1e-8)
    with pytest.raises(ValueError, match=f"plug_in must hold {lf.dim} coordinates"):
        EmulatedPosterior(model, y[0], plug_in=u[0][:2])
