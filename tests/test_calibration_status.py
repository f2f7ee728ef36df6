"""One status vocabulary (issue 39 item 1): the terminal report, the corner plot's title,
the study's results.json record, its HTML report and the README's line say the same
words about one calibration; and the corner plot (item 8) shows the brightest engine's
label-free lines, the truth where known and a legend that fits the route."""
import json

import numpy as np
import pytest

from mdaug.generator import IDX, N_PARAMS, load_reference
from mdaug.generator.acquisition import Acquisition
from mdaug.inference.diagnostics.yardsticks import honest
from mdaug.inference.result.posterior import FORMAT, CalibrationResult, import_arviz
from mdaug.inference.result.status import calibration_status
from mdaug.inference.space.priors import SHARED, Priors
from mdaug.radar import RadarConfig

HONEST_SBC = {"outer_share": 0.11, "coverage90_range": [0.87, 0.93], "n_replicates": 300, "pooled_p": 3.6e-7}
OVERCONFIDENT_SBC = {"outer_share": 0.164, "coverage90_range": [0.70, 0.89], "n_replicates": 100, "pooled_p": 8e-19}


def _amortized_diag(route: str, converged: bool, out_of_range: bool = False) -> dict:
    """Diagnostics as calibrate_amortized writes them (the fields the status reads)."""
    smc = {"converged": converged, "likelihood": "summary", "seconds": 20.0, "evaluations": 40000,
           "particles": 3600, "stages": 6, "acceptance_last": 0.3, "unique_share": 0.8, "log_evidence": -12.0,
           "reason": ("SMC reached beta = 1 in 6 stages, 40000 likelihood evaluations" if converged else
                      "NOT CONVERGED: the time budget of 20 s ended the run at beta 0.4")}
    d = {"sampler": "amortized" if route == "amortized" else "smc", "route": route, "amortized_seconds": 0.02,
         "amortized_inside_prior": 0.97, "seconds": 20.0,
         "estimator": {"class": "QUAD", "ramps": 4, "simulations": 100, "simulator": "scene",
                       "sbc": {"amortized": HONEST_SBC, "smc": OVERCONFIDENT_SBC, "stacked": HONEST_SBC}},
         "smc": smc, "out_of_range": out_of_range,
         "out_of_range_why": ("the two learned posteriors disagree on 2 of 8 quantities: the measurements are unlike "
                              "the estimator's training set") if out_of_range else "",
         "identified": {}, "identified_ratio": 0.5}
    if route == "stacked":  # the file's mixture: 0.79 x the smc run + 0.21 x the amortized posterior
        d["stacked"] = {"weight": 0.79, "smc_share": 0.78, "stacking": {"weight": 0.79, "drones": 300}}
    if route == "amortized":
        d.update(converged=True, reason="amortized posterior: exact draws from the trained estimator")
    else:
        d.update(converged=converged, reason=smc["reason"])
    return d


def _result(diag: dict, cls: str = "QUAD", n: int = 400, seed: int = 0) -> CalibrationResult:
    """A small amortized CalibrationResult: draws scattered around the class reference
    (every engine's Gamma jittered, so each draw has a brightest engine)."""
    ref = load_reference(cls)
    pr = Priors.from_reference(ref)
    e = ref.n_engines
    rng = np.random.default_rng(seed)
    x = np.repeat(ref.to_array()[None], n, axis=0).reshape(n, e, N_PARAMS)
    x = x * np.exp(0.03 * rng.standard_normal(x.shape))
    for name, (lo, hi) in pr.bounds.items():
        if name in IDX:
            x[..., IDX[name]] = np.clip(x[..., IDX[name]], lo, hi)
    az = import_arviz()
    post = {name: x[None, :, :, IDX[name]] for name in ("Gamma",) + SHARED}
    idata = az.from_dict(posterior=post, dims={name: ["engine"] for name in post})
    meta = {"format": FORMAT, "class_name": cls, "n_engines": e, "n_measurements": 3, "priors": pr.to_dict(),
            "radar": RadarConfig().to_dict(), "acquisition": Acquisition.measured(4).to_dict(),
            "likelihood": {"likelihood": "simulation-based"}, "marginal": True, "amortized": True,
            "fit": {}, "best_fit": np.median(x.reshape(n, -1), axis=0).tolist(), "diagnostics": diag}
    idata.posterior.attrs["mdaug"] = json.dumps(meta, default=float)
    return CalibrationResult(idata)


def _corner_figure(res, path, monkeypatch, **kw):
    """Draw the corner plot and keep its figure (the title and legend read back)."""
    import mdaug.radar.plots as radar_plots

    kept = {}
    save = radar_plots.save_figure

    def keep(fig, p, **k):
        kept["fig"] = fig
        kept["texts"] = [t.get_text() for sub in fig.subfigs for t in ([sub._suptitle] if sub._suptitle else [])]
        kept["legend"] = [t.get_text() for sub in fig.subfigs for lg in sub.legends for t in lg.get_texts()]
        kept["axes"] = len(fig.axes)
        kept["xlabels"] = [ax.get_xlabel() for ax in fig.axes if ax.get_xlabel()]
        kept["green"] = [ln.get_xdata()[0] for ax in fig.axes for ln in ax.lines
                         if ln.get_color() == "C2" and ax.get_xlabel() == "f1 (Hz)"]
        return save(fig, p, **k)

    monkeypatch.setattr(radar_plots, "save_figure", keep)
    res.plot_corner(path, **kw)
    return kept


class _NoFigures:
    """The report's figure holder, drawing nothing (the calibration page's text alone)."""

    def embed(self, *a, **k):
        return ""


def _study_record(res) -> dict:
    """The calibration's record as the study writes it into results.json."""
    from mdaug.reports.jobs import calibration_record
    from mdaug.reports.results_file import jsonable

    return json.loads(json.dumps(jsonable(calibration_record(res))))


CASES = [  # (route, converged, out of range) -> the words every place must print
    ("amortized", True, False, "amortized route: exact draws; SBC: honest"),
    ("smc", False, True, "smc route: NOT converged; SBC: overconfident; out of range"),
    ("smc", True, False, "smc route: converged; SBC: overconfident"),
    ("stacked", True, False, "stacked route: converged; SBC: honest"),
]


@pytest.mark.parametrize("route,converged,oor,headline", CASES)
def test_terminal_corner_title_and_results_json_say_the_same_words(route, converged, oor, headline, tmp_path,
                                                                   monkeypatch):
    res = _result(_amortized_diag(route, converged, oor))
    st = calibration_status(res)
    assert st.headline == headline
    # the terminal report
    text = res.report()
    assert f"status: {headline}" in text
    assert ("NOT CONVERGED" in text) is False  # one spelling: 'NOT converged'
    if not converged:
        assert "WARNING: NOT converged: the time budget of 20 s ended" in text
    # the corner plot's title, read back from the figure
    kept = _corner_figure(res, tmp_path / "c.png", monkeypatch)
    assert any(headline in t for t in kept["texts"]), kept["texts"]
    # the record in results.json: the same status, and the same status read back from it
    rec = _study_record(res)
    assert rec["status"]["headline"] == headline and rec["converged"] == st.converged
    assert calibration_status(rec).headline == headline
    # the report page and the README line print it from the record
    from mdaug.reports.markup import Html
    from mdaug.reports.page_calibration import calibration_section
    from mdaug.reports.readme import _calibration_text

    page = calibration_section({"calibration": {"QUAD": rec}}, _NoFigures(), Html(), tmp_path)
    assert f"QUAD: <span class='{'ok' if st.trusted else 'warn'}'>{headline}</span>" in page
    assert f"QUAD {headline}" in _calibration_text("QUAD", rec)
    if oor:
        assert "out of range: the two learned posteriors disagree" in page and "out of range" in text
    if route == "stacked":  # the weight in every place, and the README line's smc part after it
        words = "stacked: 0.79 x tempered SMC from the amortized posterior on "
        assert words in st.route_words and "0.21 x the amortized posterior" in st.route_words
        assert "stacked route: 0.79 x the smc route's posterior + 0.21 x the" in text
        assert words in _calibration_text("QUAD", rec)
        assert _calibration_text("QUAD", rec).endswith("; its smc run: 3600 particles, 6 stages, distinct share 0.80")


def test_honesty_is_the_yardsticks_gate_and_the_rank_test_is_words():
    """'honest' is exactly the gate of diagnostics.yardsticks; a failing rank test beside
    a passing gate is said in words, not as a second verdict."""
    st = calibration_status(_amortized_diag("amortized", True))
    assert honest(HONEST_SBC) and st.honesty == "honest" and st.passed
    assert st.rank_note.startswith("the rank histograms are not flat (p = 3.6e-07): the shape of the posterior "
                                   "differs from the simulator's, though its outer share and coverage pass")
    assert "honest: on 300 simulated drones, outer-10% share 0.110 (at most 0.13" in st.sbc_words
    # coverage 0.84 < 0.85: overconfident by the gate, though the outer share passes
    d = _amortized_diag("amortized", True)
    d["estimator"]["sbc"]["amortized"] = {**HONEST_SBC, "coverage90_range": [0.84, 0.92], "pooled_p": 0.3}
    st = calibration_status(d)
    assert not honest(d["estimator"]["sbc"]["amortized"]) and st.honesty == "overconfident" and not st.trusted
    assert st.rank_note == "the rank histograms are flat (p = 0.3)"
    del d["estimator"]["sbc"]["amortized"]
    assert calibration_status(d).honesty == "no SBC stored"
    # the closed-form route: its sampler, its chain, no SBC stored
    st = calibration_status({"sampler": "smc", "converged": False, "reason": "NOT CONVERGED: ESS 40"})
    assert (st.route, st.headline) == ("likelihood", "likelihood route: NOT converged; SBC: no SBC stored")
    assert st.convergence_detail == "ESS 40" and "tempered SMC" in st.route_words
    # the smc route names the likelihood it sampled
    assert "summary likelihood" in calibration_status(_amortized_diag("smc", True)).route_words
    # a file of an earlier release, whose sampled route was nlopt + emcee, keeps its words
    old = _amortized_diag("smc", True)
    old["emcee"] = old.pop("smc")
    old.update(route="emcee", sampler="emcee")
    old["estimator"]["sbc"]["emcee"] = old["estimator"]["sbc"].pop("smc")
    st = calibration_status(old)
    assert st.headline == "emcee route: converged; SBC: overconfident"
    assert st.route_words == "nlopt + emcee on the estimator's summary likelihood"


def test_the_check_route_keeps_its_own_words():
    st = calibration_status(_amortized_diag("amortized", True))
    assert st.check == "smc route, run as a check: converged" and st.check_detail.startswith("SMC reached beta = 1")
    d = _amortized_diag("amortized", True)
    d["smc"]["converged"], d["smc"]["reason"] = False, "NOT CONVERGED: budget"
    st = calibration_status(d)
    assert st.check == "smc route, run as a check: NOT converged" and st.check_detail == "budget"
    assert st.headline == "amortized route: exact draws; SBC: honest"  # the check is not the route used
    d["check"], d["best_fit_from"] = False, "smc"  # run for the best fit only (a file with a summary likelihood)
    assert calibration_status(d).check == "smc route, run for the best fit: NOT converged"
    assert "  WARNING: smc route, run for the best fit: NOT converged (budget)" in calibration_status(d).lines()
    d["check"] = True
    assert calibration_status(d).check == "smc route, run for the best fit and as a check: NOT converged"
    del d["smc"]
    assert calibration_status(d).check == ""


def test_a_misfit_is_one_word_in_every_place(tmp_path):
    """The check's word in the status, the terminal report, results.json, the report page
    and the README line; a misfit is not trusted; no record: 'not checked'."""
    from mdaug.inference.result.status import FITS, MISFIT, NOT_CHECKED
    from mdaug.reports.markup import Html
    from mdaug.reports.page_calibration import calibration_section
    from mdaug.reports.readme import _calibration_text

    d = _amortized_diag("amortized", True)
    assert calibration_status(d).predictive == NOT_CHECKED and "predictive" not in calibration_status(d).headline
    names = ["band 1-2 bins: mean", "band 81-199 bins: mean"]
    d["estimator"]["users"] = {"drones": 50, "log_score": -1.83, "lines": [0.99, 0.71, 0.58, 0.25]}
    d["predictive"] = {"names": names, "observed": [-1.0, -2.0], "mean": [-1.0, -3.0], "sd": [0.1, 0.1],
                       "z": [0.2, 10.0], "quantile": [0.5, 1.0], "z_limit": 2.8, "n_draws": 200,
                       "n_measurements": 3, "word": MISFIT, "flagged": names[1:],
                       "why": "band 81-199 bins: mean at z = +10.0", "seconds": 1.5}
    res = _result(d)
    st = calibration_status(res)
    headline = "amortized route: exact draws; SBC: honest; predictive check: misfit"
    assert st.predictive == MISFIT and st.headline == headline and not st.trusted
    assert ("2 statistics of the measurements against 200 posterior draws measured 3 times each, largest |z| 10.0 "
            "(limit 2.8); beyond it: band 81-199 bins: mean at z = +10.0") in st.predictive_facts
    text = res.report()
    assert f"status: {headline}" in text and "  WARNING: posterior predictive check: misfit: 2 statistics" in text
    rec = _study_record(res)
    assert rec["status"]["predictive"] == MISFIT and rec["status"]["predictive_words"] == st.predictive_words
    assert calibration_status(rec).headline == headline

    page = calibration_section({"calibration": {"QUAD": rec}}, _NoFigures(), Html(), tmp_path)
    assert f"QUAD: <span class='warn'>{headline}</span>" in page
    assert "<b>Posterior predictive check</b>: <span class='warn'>misfit</span>: 2 statistics" in page
    # statistic by statistic: the one beyond the limit marked, in the terminal and on the page
    row = [ln for ln in text.splitlines() if ln.startswith("band 81-199 bins: mean")][0]
    assert row.split()[4:] == ["-2.000", "-3.000", "0.100", "10.000", "1.000", "beyond", "the", "limit"]
    assert "band 1-2 bins: mean" in text and "beyond" not in [ln for ln in text.splitlines()
                                                              if ln.startswith("band 1-2 bins: mean")][0]
    assert ('<tr class="warn"><td>band 81-199 bins: mean</td><td class=\'n\'>-2.000</td>'
            "<td class='n'>-3.000 &plusmn; 0.100</td><td class='n'>10.0</td>") in page
    users = ("on 50 simulated drones like a user's (the specimen model), the file's route table: log score -1.83 "
             "nats; the brightest engine's lines 1-4 at 0.99 / 0.71 / 0.58 / 0.25 x the truth (median 90% width)")
    assert f"<li><b>Drones like a user's</b>: {Html.esc(users)}.</li>" in page and f"  {users}" in text
    assert rec["status"]["users_facts"] == users
    assert f"QUAD {headline}" in _calibration_text("QUAD", rec)
    d["predictive"].update(word=FITS, z=[0.2, 1.0], flagged=[], why="")
    st = calibration_status(d)
    assert st.predictive == FITS and st.trusted and st.headline == "amortized route: exact draws; SBC: honest"
    assert st.lines()[-1] == ("  posterior predictive check: fits: 2 statistics of the measurements against 200 "
                              "posterior draws measured 3 times each, largest |z| 1.0 (limit 2.8)")


def test_corner_shows_the_brightest_engine_with_truths_and_a_legend_for_the_route(tmp_path, monkeypatch):
    res = _result(_amortized_diag("amortized", True), cls="QUAD")
    ref = load_reference("QUAD").to_array()
    kept = _corner_figure(res, tmp_path / "c.png", monkeypatch, truths=ref)
    assert kept["axes"] == 64  # one 8 x 8 corner: the brightest engine's four lines, frequency and amplitude
    assert sorted(set(kept["xlabels"])) == sorted([f"f{j} (Hz)" for j in range(1, 5)]
                                                  + [f"A{j} (mm)" for j in range(1, 5)])
    assert not any("Gamma" in s or "lnG" in s for s in kept["xlabels"])
    assert "true values (the simulated drone)" in kept["legend"]
    assert not any("best fit" in t for t in kept["legend"])  # an amortized posterior has no global fit
    # the truth drawn is the brightest engine's lowest line (QUAD's engine 3: Gamma 0.011)
    xe = ref.reshape(-1, N_PARAMS)
    from mdaug.inference.space.priors import engine_lines

    w, _, _ = engine_lines(xe[np.argmax(xe[:, IDX["Gamma"]])])
    assert kept["green"] and np.isclose(kept["green"][0], w.min() / (2 * np.pi))
    # every engine on request; no truths: no truth in the legend
    kept = _corner_figure(res, tmp_path / "all.png", monkeypatch, engines="all")
    assert kept["axes"] == 4 * 64 and not any("true" in t for t in kept["legend"])
    with pytest.raises(ValueError, match="engines"):
        res.plot_corner(tmp_path / "x.png", engines="faint")


def test_the_route_used_brings_its_row_on_drones_like_a_users():
    """The file's stored specimen row of a route (log score, lines 1-4), as `sbc --stored`
    prints it; None where the file stores none."""
    from mdaug.inference.amortized.shipped import find

    row = find("HELI", Acquisition.measured(32), RadarConfig()).users_row("smc")
    assert row["drones"] == 50 and len(row["lines"]) == 4 and row["lines"] == sorted(row["lines"], reverse=True)
    assert 0.1 < row["lines"][3] < row["lines"][0] < 3.0 and np.isfinite(row["log_score"])
    assert find("QUAD", Acquisition.measured(1), RadarConfig()).users_row("amortized") is None
