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


def test_the_protocols_calibration_table_sets_the_settings_it_names(tmp_path):
    """[protocol.calibration] holds CalibrationSettings under their own names: each
    reaches the setting it names (max_steps the emcee plugin's), the emcee blocks are no
    longer than the step cap, a bad value is refused by the settings' own rule, named by
    its key, and a key of a 0.1 config is refused with its new place."""
    from mdaug.inference.settings import CalibrationSettings
    from mdaug.reports.config import CalibrationProtocol

    cfg = load_config(_write(tmp_path / "c.toml", "[protocol.calibration]\nmax_steps = 120\ntime_budget = 30\n"
                                                  "n_starts = 3\nfit_budget = 700\nn_acquisitions = 5\n"
                                                  "ramps_drawn = 2\nmethod = \"likelihood\"\n"))
    c = cfg.protocol.calibration
    assert c == CalibrationProtocol("likelihood", 120, 30.0, 3, 700, 5, 2)
    assert c.settings() == CalibrationSettings(time_budget=30.0, n_starts=3, fit_budget=700, n_acquisitions=5,
                                               ramps_drawn=2, max_steps=120, check_every=120)
    q = c.settings(quick=True)
    assert q.of("emcee").n_walkers == CalibrationSettings.quick().of("emcee").n_walkers and q.n_starts == 3
    for line, key in (("n_acquisitions = 1", "n_acquisitions"), ("max_steps = 0", "max_steps"),
                      ("time_budget = -1.0", "time_budget")):
        with pytest.raises(ValueError, match=f"protocol.calibration.{key}: "):
            load_config(_write(tmp_path / "p.toml", f"[protocol.calibration]\n{line}\n"))
    with pytest.raises(ValueError, match=r"\[protocol.calibration\] max_steps = 'many': expected an integer"):
        load_config(_write(tmp_path / "t.toml", "[protocol.calibration]\nmax_steps = \"many\"\n"))
    with pytest.raises(ValueError, match=r"\[protocol.calibration\]: unknown key\(s\) \['n_walker'\]"):
        load_config(_write(tmp_path / "u.toml", "[protocol.calibration]\nn_walker = 8\n"))
    for old, new in (("[protocol]\ncalibration_draws = 5", r"n_acquisitions in \[protocol.calibration\]"),
                     ("[protocol]\ncalibration_max_steps = 5", r"max_steps in \[protocol.calibration\]"),
                     ("[simulation]\nramps = 4", r"ramps \(top level\)")):
        with pytest.raises(ValueError, match=f"renamed; write it as {new}"):
            load_config(_write(tmp_path / "o.toml", old + "\n"))


def test_ramps_is_one_setting_for_the_scene_and_for_files_that_do_not_state_it(tmp_path):
    """K: the simulated scene's (32 when left out, 4 in the quick study), or, with
    measured files, that of files that do not state it; the study key of a 0.1 folder
    (K in [simulation]) is the key of the same study today."""
    from mdaug.reports.identity import study_key

    assert StudyConfig().scene_ramps == 32 and StudyConfig(ramps=8).scene_ramps == 8
    assert StudyConfig().quick_version().scene_ramps == 4
    assert load_config(_write(tmp_path / "k.toml", "ramps = 8\n")).scene_ramps == 8
    assert study_key(StudyConfig()) == "5c07c72e5a934bef"  # stages/study.json of a 0.1 default study
    assert study_key(StudyConfig(ramps=32)) == study_key(StudyConfig())
    assert study_key(StudyConfig(ramps=4)) != study_key(StudyConfig())
