"""The posterior predictive check (issue 41 item 1): its statistics, its limit, that it passes
data the posterior's drones make and flags data they do not (its one word in every place:
tests/test_calibration_status.py)."""
import json

import numpy as np
import pytest

from mdaug.generator import load_reference
from mdaug.generator.acquisition import Acquisition
from mdaug.generator.specimens import SpecimenSpread
from mdaug.inference.amortized.simulate import measure
from mdaug.inference.diagnostics.predictive import BANDS, PredictiveCheck, predictive_check, statistics, z_limit
from mdaug.inference.result.status import FITS, MISFIT
from mdaug.radar import RadarConfig

RADAR = RadarConfig()


def _flat(levels, lines=None):
    """Profiles (M, 400), peak 1 at bin 200, every other bin at 10**level (one level per
    measurement); ``lines``: {offset: level} set on both sides in every measurement."""
    p = np.empty((len(levels), 400))
    for i, lv in enumerate(levels):
        p[i] = 10.0 ** lv
    for off, lv in (lines or {}).items():
        p[:, 200 + off] = p[:, 200 - off] = 10.0 ** lv
    p[:, 200] = 1.0
    return p


def test_statistics_of_known_profiles():
    names, v = statistics(_flat([-3.0, -2.0, -4.0]), RADAR)
    assert names[:5] == [f"band {lo}-{hi} bins: mean" for lo, hi in BANDS]
    assert len(names) == 10 and v.shape == (10,)
    np.testing.assert_allclose(v[:5], -3.0)  # the mean over measurements of each band's mean log10
    np.testing.assert_allclose(v[5:], 1.0)  # the cube root of the variance over the measurements of (-3, -2, -4)
    _, v = statistics(_flat([-3.0, -1.0, -5.0]), RADAR)
    np.testing.assert_allclose(v[5:], np.cbrt(4.0))
    # one measurement: no spreads; a stack of sets keeps its leading shape
    assert len(statistics(_flat([-3.0]), RADAR)[0]) == 5
    assert statistics(np.stack([_flat([-3.0, -2.0])] * 4), RADAR)[1].shape == (4, 10)
    # a line at offset 40 lifts its own statistic: the mean within half a resolution cell of it
    cell = RADAR.fft_points / RADAR.samples_per_chirp
    w = 40 * 2 * np.pi * RADAR.bin_hz  # rad/s whose first sideband sits 40 bins from the peak
    names, v = statistics(_flat([-3.0, -3.0], {40: -1.0}), RADAR, lines=[w, 1e9])
    assert names[-1] == "line 1 (40 bins)" and len(names) == 11  # a line beyond the profile is left out
    width = int(np.floor(40 + cell / 2)) - int(np.ceil(40 - cell / 2)) + 1
    np.testing.assert_allclose(v[-1], (-1.0 + (width - 1) * -3.0) / width)


def test_the_limit_is_two_sided_bonferroni():
    from scipy.stats import norm

    assert z_limit(1) == pytest.approx(norm.isf(0.005))
    assert z_limit(14) == pytest.approx(3.39, abs=0.01)
    assert z_limit(14) > z_limit(10) > z_limit(1)
    with pytest.raises(ValueError, match="need >= 1 statistic"):
        z_limit(0)


@pytest.fixture(scope="module")
def drone():
    ref = load_reference("HELI")
    x = SpecimenSpread().apply(ref.to_array()[None], np.random.default_rng(3))[0]
    acq = Acquisition.measured(4)
    return x, acq, measure(x[None], 5, acq, RADAR, np.random.default_rng(4))[0].astype(float)


def test_data_the_drones_make_fit_and_a_raised_floor_or_moved_lines_do_not(drone):
    x, acq, y = drone
    draws = np.repeat(x[None], 50, axis=0)  # a posterior at the truth: the predictive is the data's own law
    ok = predictive_check(draws, y, acq, RADAR, n_draws=120, random_state=1)
    assert ok.word == FITS and ok.flagged == [] and ok.why == ""
    assert max(map(abs, ok.z)) < ok.z_limit and len(ok.names) == 10 and ok.n_measurements == 5
    assert all(0.0 <= q <= 1.0 for q in ok.quantile)
    # the same seed, the same check; plain data round trip
    again = predictive_check(draws, y, acq, RADAR, n_draws=120, random_state=1)
    assert again.z == ok.z
    assert type(ok).from_dict(json.loads(json.dumps(ok.to_dict()))) == ok
    # a noise floor 10 times higher than any drone of the posterior makes: the floor's band is flagged
    high = y + 0.01
    bad = predictive_check(draws, high / high.max(1, keepdims=True), acq, RADAR, n_draws=120, random_state=1)
    assert bad.word == MISFIT and bad.flagged[0] == "band 81-199 bins: mean"
    assert bad.why.startswith("band 81-199 bins: mean at z = +")
    # a posterior whose drone vibrates 3 times faster: its sidebands are not where the data's are
    fast = x.copy()
    from mdaug.generator import IDX
    for name in ("w_a", "w_b"):
        fast[IDX[name]] *= 3.0
    moved = predictive_check(np.repeat(fast[None], 50, axis=0), y, acq, RADAR, n_draws=120, random_state=1)
    assert moved.word == MISFIT


def test_refusals(drone):
    x, acq, y = drone
    with pytest.raises(ValueError, match="needs >= 20 draws, got 5"):
        predictive_check(x[None], y, acq, RADAR, n_draws=5)
    with pytest.raises(ValueError, match="needs measurements of shape"):
        predictive_check(x[None], y[0], acq, RADAR)


def test_the_spread_statistic_keeps_the_limits_level():
    """Band levels drawn Gaussian per measurement (5 a set): the spread statistic's z
    beyond the 14-statistic limit happens about as often as the limit's level says (a log
    of the spread would put 6 times that in its left tail)."""
    rng = np.random.default_rng(0)
    sets = 20000
    levels = -3.0 + 0.1 * rng.standard_normal((sets, 5))
    p = np.broadcast_to(10.0 ** levels[..., None], (sets, 5, 21)).copy()  # 21 bins: bands 1-2 and 3-10
    p[..., 10] = 1.0
    names, v = statistics(p, RADAR)
    assert names == ["band 1-2 bins: mean", "band 3-10 bins: mean", "band 1-2 bins: spread", "band 3-10 bins: spread"]
    spread = v[:, 2]
    z = (spread - spread.mean()) / spread.std()
    level = 0.01 / 14  # two-sided, what z_limit(14) allows one statistic
    assert np.mean(np.abs(z) > z_limit(14)) < 2 * level
    log_z = np.log(spread)
    log_z = (log_z - log_z.mean()) / log_z.std()
    assert np.mean(np.abs(log_z) > z_limit(14)) > 4 * level  # what the log would have done


def test_the_reports_figure_marks_the_statistics_beyond_the_limit():
    from mdaug.reports.figures import predictive_figure

    assert predictive_figure({"diagnostics": {}}, "HELI") is None
    names = ["band 1-2 bins: mean", "band 81-199 bins: mean", "line 1 (4 bins)"]
    p = PredictiveCheck(names=names, observed=[0.0] * 3, mean=[0.0] * 3, sd=[1.0] * 3, z=[0.5, -6.0, 4.0],
                        quantile=[0.5] * 3, z_limit=3.0, n_draws=200, n_measurements=5).to_dict()
    fig = predictive_figure({"diagnostics": {"predictive": p}}, "HELI")
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == names
    hatched = [b for b in ax.patches if b.get_hatch()]
    assert sorted(round(b.get_width(), 6) for b in hatched) == [-6.0, 4.0]  # the two beyond |z| = 3
    assert sorted(ln.get_xdata()[0] for ln in ax.lines if ln.get_linestyle() == "--") == [-3.0, 3.0]
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_the_closed_form_route_is_checked_where_it_marginalises_the_phases(drone, tiny_posterior, tmp_path):
    """The closed-form likelihood's posterior gets the same check, kept in its file and said
    by its status and report; a fitted-phase posterior (the published chirp) is not checked."""
    import warnings

    from mdaug.inference.calibrate import calibrate
    from mdaug.inference.result.posterior import CalibrationResult
    from mdaug.inference.result.status import NOT_CHECKED, calibration_status
    from mdaug.inference.settings import CalibrationSettings

    x, acq, y = drone
    tiny = CalibrationSettings.quick(max_steps=20, fit_budget=50, n_starts=1, polish_budget=50, check_every=10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(y, "HELI", acquisition=acq, settings=tiny, random_state=0, predictive=40)
        unchecked = calibrate(y, "HELI", acquisition=acq, settings=tiny, random_state=0, predictive=0)
    p = res.diagnostics["predictive"]
    assert res.marginal and p["n_draws"] == 40 and p["n_measurements"] == 5 and len(p["names"]) == 14
    assert p["word"] in (FITS, MISFIT) and p["seconds"] > 0
    assert p["names"][-4:] == [n for n in p["names"] if n.startswith("line ")]  # the brightest engine's four lines
    np.testing.assert_allclose(res.draws(), unchecked.draws())  # the check draws from its own stream
    assert "predictive" not in unchecked.diagnostics
    res.save(tmp_path / "p.nc")
    back = CalibrationResult.load(tmp_path / "p.nc")
    assert back.diagnostics["predictive"]["z"] == p["z"]
    st = calibration_status(back)
    assert st.predictive == p["word"] and "14 statistics of the measurements against 40" in st.predictive_facts
    assert "posterior predictive check, statistic by statistic" in back.report()
    assert calibration_status(unchecked).predictive == NOT_CHECKED
    fitted = CalibrationResult.load(tiny_posterior)  # the published chirp: phases fitted, no replicates drawn
    assert not fitted.marginal and calibration_status(fitted).predictive == NOT_CHECKED
