"""Study configuration and executors: fail before any work, same results anywhere."""
import numpy as np
import pytest

from mdaug.cli import main
from mdaug.reports.cache import StageCache, settings_key
from mdaug.reports.config import StudyConfig, load_config
from mdaug.reports.executor import SerialExecutor, make_executor


def _square_with_seed(item):
    rng = np.random.default_rng(item["seed"])
    return item["x"] ** 2 + rng.integers(1000)


def test_executors_agree_including_a_dask_local_cluster():
    items = [{"x": x, "seed": 100 + x} for x in range(6)]
    want = SerialExecutor().map(_square_with_seed, items)
    for ex in (make_executor(2), make_executor(1, scheduler="local")):
        try:
            assert list(ex.map(_square_with_seed, items)) == want  # map yields, in order
        finally:
            ex.close()


def _write(path, text):
    path.write_text(text)
    return path


def test_config_with_unknown_class_fails_naming_it(tmp_path):
    cfg = _write(tmp_path / "s.toml", 'classes = ["HELI", "BLIMP"]\n')
    with pytest.raises(ValueError, match=r"s.toml: classes: unknown class 'BLIMP'"):
        load_config(cfg)


def test_config_with_missing_file_fails_before_any_work(tmp_path, capsys):
    cfg = _write(tmp_path / "s.toml", '[data]\ncalibration = { HELI = "h.npz", QUAD = "q.npz" }\n'
                                      'test = { new = "nowhere.npz" }\n')
    (tmp_path / "h.npz").write_bytes(b"x")
    (tmp_path / "q.npz").write_bytes(b"x")
    out = tmp_path / "study"
    assert main(["run", "--config", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "data.test.new: file not found" in err and "nowhere.npz" in err
    assert not out.exists()


def test_config_unknown_key_and_bad_toml(tmp_path):
    with pytest.raises(ValueError, match=r"\[protocol\]: unknown key\(s\) \['epochs'\]"):
        load_config(_write(tmp_path / "a.toml", "[protocol]\nepochs = 3\n"))
    with pytest.raises(ValueError, match="not valid TOML"):
        load_config(_write(tmp_path / "b.toml", "seed = = 1\n"))
    with pytest.raises(ValueError, match="protocol.sigma_p must be"):
        load_config(_write(tmp_path / "c.toml", "[protocol]\nsigma_p = [0.1, 1.5]\n"))


def test_calibration_class_must_be_a_study_class(tmp_path):
    (tmp_path / "h.npz").write_bytes(b"x")
    cfg = _write(tmp_path / "s.toml", '[data]\ncalibration = { DRONE = "h.npz" }\ntest = { new = "h.npz" }\n')
    with pytest.raises(ValueError, match="unknown class 'DRONE'"):
        load_config(cfg)


def test_quick_version_is_small_and_keeps_the_seed():
    q = StudyConfig(seed=5).quick_version()
    assert q.quick and q.seed == 5 and q.protocol.cnn_n_per_class < StudyConfig().protocol.cnn_n_per_class


def test_stage_cache_resumes_and_recomputes_on_a_new_key(tmp_path):
    calls = []
    cache = StageCache(tmp_path, log=lambda *_: None)
    compute = lambda: calls.append(1) or {"v": len(calls)}  # noqa: E731
    assert cache.run("s", settings_key(1), compute) == {"v": 1}
    again = StageCache(tmp_path, log=lambda *_: None)
    assert again.run("s", settings_key(1), compute) == {"v": 1} and again.resumed == ["s"]
    assert again.run("s", settings_key(2), compute) == {"v": 2}
    assert len(calls) == 2


def test_the_protocol_sets_the_calibration_settings_it_names(tmp_path):
    """The protocol's calibration fields are calibration settings under their study
    names (reports.config.CALIBRATION_SETTINGS): each reaches the setting it names, the
    emcee blocks are no longer than the step cap, and a bad value is refused by the
    settings' own rule, named by the protocol field."""
    from mdaug.inference.settings import CalibrationSettings
    from mdaug.reports.config import CALIBRATION_SETTINGS, ProtocolConfig

    p = ProtocolConfig(calibration_max_steps=120, calibration_time_budget=30.0, calibration_starts=3,
                       calibration_fit_budget=700, calibration_draws=5, calibration_ramps_drawn=2)
    s = p.calibration_settings()
    assert s == CalibrationSettings(time_budget=30.0, n_starts=3, fit_budget=700, n_acquisitions=5, ramps_drawn=2,
                                    max_steps=120, check_every=120)
    named = {f for f in vars(p) if f.startswith("calibration_") and f != "calibration_method"}
    assert set(CALIBRATION_SETTINGS) == named
    q = p.calibration_settings(quick=True)
    assert q.of("emcee").n_walkers == CalibrationSettings.quick().of("emcee").n_walkers and q.n_starts == 3
    for line, field in (("calibration_draws = 1", "calibration_draws"),
                        ("calibration_max_steps = 0", "calibration_max_steps"),
                        ("calibration_time_budget = -1.0", "calibration_time_budget")):
        with pytest.raises(ValueError, match=f"protocol.{field}: "):
            load_config(_write(tmp_path / "p.toml", f"[protocol]\n{line}\n"))
