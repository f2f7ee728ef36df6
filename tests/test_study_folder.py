"""A study folder knows its study, its stage records read back or are computed again
and hold paths relative to the folder; cached drone posteriors are keyed by every
option that changes them (issue 31; the refusal table is test_cli_doors.py)."""
import json

import pytest


# ---- the study's folder -----------------------------------------------------------------------------
def test_a_folder_of_another_study_is_refused_by_name_and_the_same_study_passes(tmp_path, refused):
    from mdaug.reports.config import StudyConfig
    from mdaug.reports.identity import check_study_folder, claim

    other = StudyConfig(seed=5).quick_version()
    out = tmp_path / "study"
    (out / "stages").mkdir(parents=True)
    claim(out, other)
    (out / "models").mkdir()
    (out / "models" / "cnn_posterior_run0.zip").write_bytes(b"the other study's model")
    line = refused(["run", "--quick", "--seed", "3", "--out", str(out)], tmp_path, out,
                   [f"{out}: --out holds another study", "seed 5 -> 3", "--overwrite"], seconds=10)
    assert "defaults" in line
    assert check_study_folder(out, StudyConfig(seed=5).quick_version()) is False  # the same study: resumes
    assert check_study_folder(out, StudyConfig(seed=3).quick_version(), overwrite=True) is True


def test_a_folder_without_its_record_is_known_by_its_data_stage(tmp_path, refused):
    from mdaug.reports.cache import StageCache
    from mdaug.reports.config import StudyConfig
    from mdaug.reports.identity import study_key

    out = tmp_path / "old"
    StageCache(out, log=lambda *_: None).store("data", study_key(StudyConfig(seed=1)), {"sets": {}}, 1.0)
    refused(["run", "--seed", "2", "--out", str(out)], tmp_path, out, ["--out holds another study"], seconds=10)


def test_overwrite_removes_the_study_files_and_nothing_else(tmp_path):
    from mdaug.reports.identity import STUDY_FILES, clear_study

    out = tmp_path / "s"
    for name in STUDY_FILES:
        if name.endswith("/"):
            (out / name / "x").mkdir(parents=True)
        else:
            out.mkdir(exist_ok=True)
            (out / name).write_text("x")
    (out / "notes.txt").write_text("mine")
    clear_study(out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


def test_a_corrupt_stage_file_is_named_and_computed_again(tmp_path):
    from mdaug.reports.cache import StageCache

    said = []
    cache = StageCache(tmp_path, log=said.append)
    cache.run("a", "k", lambda: {"x": 1})
    for bad in (b'{"key": "k", "seconds": 1, "res', b"\xff\xfe not utf-8", b"[1, 2]", b'{"key": "k", "result": 5}',
                b""):
        (tmp_path / "stages" / "a.json").write_bytes(bad)
        said.clear()
        again = StageCache(tmp_path, log=said.append)
        assert again.run("a", "k", lambda: {"x": 2}) == {"x": 2}
        assert any("a.json does not read back" in s and "computing the stage again" in s for s in said), said
        assert StageCache(tmp_path, log=lambda *_: None).run("a", "k", lambda: {"x": 3}) == {"x": 2}  # stored again


def test_stage_records_hold_paths_relative_to_the_study_folder(tmp_path, monkeypatch):
    import shutil

    from mdaug.reports.cache import StageCache

    first = tmp_path / "a" / "study"
    (first / "posteriors").mkdir(parents=True)
    (first / "posteriors" / "HELI.nc").write_text("posterior")
    monkeypatch.chdir(tmp_path / "a")
    StageCache("study", log=lambda *_: None).run("calibrate_HELI", "k", lambda: {
        "posterior": "study/posteriors/HELI.nc", "cls": "HELI", "n": [1, "x/y"]})
    record = json.loads((first / "stages" / "calibrate_HELI.json").read_text())
    assert record["result"]["posterior"] == {"study_path": "posteriors/HELI.nc"}
    assert record["result"]["cls"] == "HELI" and record["result"]["n"] == [1, "x/y"]
    # resumed from another working directory, and from the folder moved elsewhere
    monkeypatch.chdir(tmp_path)
    got = StageCache("a/study", log=lambda *_: None).run("calibrate_HELI", "k", lambda: {"posterior": "recomputed"})
    assert got["posterior"] == "a/study/posteriors/HELI.nc"
    shutil.move(str(first), str(tmp_path / "moved"))
    got = StageCache(tmp_path / "moved", log=lambda *_: None).run("calibrate_HELI", "k", lambda: {"posterior": "x"})
    assert open(got["posterior"]).read() == "posterior"


# ---- cached work keyed by every option that changes it -------------------------------------------------
def test_a_drone_posterior_is_reused_only_under_the_same_options():
    """calibrate --population reuses a drone's posterior when the measurements and every
    option that changes it agree (engines, seed, sampler, settings, acquisition with its
    noise), not threads or progress bars."""
    from mdaug.cli.calibrate_population import reuse_key
    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.settings import CalibrationSettings

    s, acq = CalibrationSettings.quick(), Acquisition.measured(4)
    key = reuse_key(None, 7, s, acq)
    assert key == reuse_key(None, 7, s.replace(threads=2, progress=True), acq)
    assert json.loads(json.dumps(key)) == key  # as the file records it
    for other in (reuse_key(2, 7, s, acq), reuse_key(None, 8, s, acq), reuse_key(None, 7, s.replace(sampler="smc"), acq),
                  reuse_key(None, 7, s.replace(fit_budget=s.fit_budget + 1), acq),
                  reuse_key(None, 7, s, acq.replace(noise_db=(-60.0, -50.0))),
                  reuse_key(None, 7, s, acq.replace(carrier=(0.0, 0.5)))):
        assert other != key


@pytest.mark.slow
def test_calibrate_population_reuses_only_under_the_same_options(tmp_path, capsys):
    from mdaug.cli import main

    fast = ["--method", "likelihood", "--sampler", "laplace", "--starts", "1", "--fit-budget", "60", "--particles",
            "200", "--allow-unconverged"]
    assert main(["simulate", "--class", "HELI", "--specimens", "2", "--acquisitions", "4", "--ramps", "4", "--seed",
                 "2", "--out", str(tmp_path / "d.npz")]) == 0
    cal = ["calibrate", str(tmp_path / "d.npz"), "--class", "HELI", "--population", *fast, "--out",
           str(tmp_path / "pop.npz")]
    assert main(cal) == 0
    capsys.readouterr()
    assert main([*cal, "--seed", "5"]) == 0
    text = capsys.readouterr().out
    assert "reused" not in text and "was calibrated with other seed; calibrating again" in text
    assert main([*cal, "--seed", "5"]) == 0
    text = capsys.readouterr().out
    assert "drone 0: reused" in text and "same measurements, engines, seed, sampler" in text


def test_a_stage_record_of_another_shape_is_computed_again(tmp_path):
    from mdaug.reports.cache import StageCache

    said = []
    StageCache(tmp_path, log=lambda *_: None).store("calibrate_HELI", "k", {"cls": "HELI"}, 1.0)
    got = StageCache(tmp_path, log=said.append).run("calibrate_HELI", "k", lambda: {"posterior": "p"},
                                                    needs=("posterior",))
    assert got == {"posterior": "p"} and any("lacks ['posterior']" in s for s in said), said


def test_a_change_in_what_a_strategy_draws_recomputes_candidates_and_cnns_not_data(tmp_path, monkeypatch):
    """A folder made before a release that changed a strategy's source (DRAWS_REVISION)
    keeps its data and calibrations and computes its candidates and CNNs again."""
    import mdaug.reports.study as study_mod
    from mdaug.reports.config import StudyConfig

    cfg = StudyConfig(seed=7).quick_version()
    now = study_mod.Study(cfg, tmp_path / "now", log=lambda *_: None)
    monkeypatch.setattr(study_mod, "DRAWS_REVISION", study_mod.DRAWS_REVISION + 1)
    later = study_mod.Study(cfg, tmp_path / "later", log=lambda *_: None)
    assert (later.key, later.calib_key) == (now.key, now.calib_key)
    assert later.cand_key != now.cand_key and later.cnn_key != now.cnn_key
