"""The command line as a front end: help, global options, interrupts, progress,
the run summary, leftovers of killed writes, and the layering it sits on."""
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import mdaug
from mdaug.cli import build_parser, main, verbs
from mdaug.radar import atomic_savez, atomic_write
from mdaug.radar.io import stale_parts
from mdaug.radar.progress import QUIET_ENV, progress_bar, progress_enabled

ROOT = Path(mdaug.__file__).parent
LIBRARY = ("radar", "generator", "inference", "classify", "reports")


def subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return parser, action.choices


# ---- help ------------------------------------------------------------------------------------
def test_every_option_of_every_verb_explains_itself():
    parser, subs = subparsers()
    assert set(subs) == set(verbs()) == {"simulate", "process", "calibrate", "train-estimator", "sbc", "augment",
                                         "train", "evaluate",
                                         "sweep", "baseline", "run"}
    for name, p in [("mdaug", parser), *subs.items()]:
        for action in p._actions:
            if action.dest == "help":
                continue
            what = f"mdaug {name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help and action.help.strip(), f"{what} has no help text"
            flag = action.nargs == 0  # store_true, version
            if action.option_strings and not flag and not action.required and action.dest != "verb":
                assert "default" in action.help, f"{what}: help does not state the default"
        text = p.format_help()
        assert "%%" not in text and "==SUPPRESS==" not in text and "%(" not in text, name


@pytest.mark.parametrize("verb", ["evaluate", "augment", "calibrate", "simulate", "run"])
def test_verb_help_exits_0_and_shows_units_and_defaults(verb, capsys):
    assert main([verb, "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "%%" not in out and "--threads" in out and "--quiet" in out
    if verb == "evaluate":
        assert "95% intervals" in out
    if verb == "simulate":
        assert "--range-m LO,HI" in out and "m (default: 3,8 m)" in out and "(default: -30,30 deg)" in out
    if verb == "augment":
        assert "--n-per-class N" in out and "(default: 16000)" in out and "--seed" in out
    if verb == "calibrate":
        for opt in ("--max-steps", "--walkers", "--fit-budget"):
            assert opt in out
        assert re.search(r"--max-steps N emcee step budget, steps per walker \(default: \w+.*; --quick: 1000\)", out)


def test_option_choices_match_the_library():
    from mdaug.cli import data
    from mdaug.cli import options as common
    from mdaug.generator import PHASE_TREATMENTS, SIGN_POLICIES
    from mdaug.generator.chain import SCENE_PHASES
    from mdaug.radar import NORMALISATIONS

    assert common.ACQUISITION_PHASES == PHASE_TREATMENTS and common.SIGN_POLICIES == SIGN_POLICIES
    assert set(common.NUISANCE_PHASES) == {"relative", *PHASE_TREATMENTS}
    assert common.NORMALISATIONS == NORMALISATIONS and data.SCENE_PHASES == SCENE_PHASES


def test_mdaug_help_lists_the_verbs_quickly():
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "mdaug", "--help"], capture_output=True, text=True, check=True).stdout
    assert time.perf_counter() - t0 < 10
    assert all(v in out for v in verbs())


# ---- global options before and after the verb -------------------------------------------
@pytest.mark.parametrize("argv, threads, quiet", [
    (["augment", "--out", "x.npz"], 1, False),
    (["--threads", "3", "augment", "--out", "x.npz"], 3, False),
    (["augment", "--threads", "2", "--out", "x.npz"], 2, False),
    (["--threads", "3", "augment", "--out", "x.npz", "--threads", "2"], 2, False),
    (["--quiet", "augment", "--out", "x.npz"], 1, True),
    (["augment", "-q", "--out", "x.npz"], 1, True),
    (["--threads", "2", "-q", "run"], 2, True),
])
def test_global_options_before_and_after_the_verb(argv, threads, quiet, monkeypatch):
    monkeypatch.delenv("MDAUG_THREADS", raising=False)
    args = build_parser().parse_args(argv)
    assert args.threads == threads and args.quiet is quiet


def test_augment_accepts_threads_and_quiet_after_the_verb(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(QUIET_ENV, raising=False)
    out = tmp_path / "a.npz"
    assert main(["augment", "--classes", "HELI,QUAD", "--n-per-class", "3", "--out", str(out), "--threads", "1",
                 "--quiet"]) == 0
    assert out.is_file() and "wrote" in capsys.readouterr().out
    assert QUIET_ENV not in os.environ  # --quiet applies to that one command


# ---- interrupts: one line, the verb's own advice, 130 ------------------------------------
def _interrupt(*_a, **_k):
    raise KeyboardInterrupt


@pytest.mark.parametrize("verb, target, argv, says, never", [
    ("augment", "mdaug.generator.dataset.make_dataset", ["--classes", "HELI,QUAD", "--n-per-class", "3"],
     "augment does not resume", "rerun to resume"),
    ("calibrate", "mdaug.inference.calibrate.calibrate", ["--class", "HELI"],
     "chain checkpoint", None),
    ("sweep", "mdaug.classify.protocol.sigma_p_sweep", ["--n-per-class", "3"],
     "run the same command again to resume", None),
    ("run", "mdaug.reports.study.Study.run", ["--quick"], "run the same command again to resume", None),
    ("train", "mdaug.classify.nb_fit", ["--model", "nb"], "no partial file", None),
])
def test_interrupt_prints_one_line_and_exits_130(verb, target, argv, says, never, tmp_path, capsys, monkeypatch):
    rng = np.random.default_rng(1)
    meas = tmp_path / "m.npz"
    prof = np.abs(rng.normal(0.1, 0.02, (6, 400)))
    prof[:, 200] = 1
    atomic_savez(meas, profiles=prof, labels=np.array(["HELI", "QUAD"] * 3))
    out = tmp_path / "out"
    if target == "mdaug.classify.nb_fit":
        from mdaug.classify.models import NaiveBayesClassifier

        monkeypatch.setattr(NaiveBayesClassifier, "_fit", _interrupt)
    else:
        import importlib

        module, _, name = target.rpartition(".")
        if verb == "run":
            module, name = "mdaug.reports.study", None
            from mdaug.reports.study import Study

            monkeypatch.setattr(Study, "run", _interrupt)
        if name:
            monkeypatch.setattr(importlib.import_module(module), name, _interrupt)
    full = {"augment": ["augment", "--out", str(out)], "calibrate": ["calibrate", str(meas), "--out", str(out)],
            "sweep": ["sweep", "--test", str(meas), "--out", str(out)], "run": ["run", "--out", str(out)],
            "train": ["train", str(meas), "--out", str(out)]}[verb]
    assert main(full + argv) == 130
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"mdaug {verb}: interrupted; ") and says in lines[0]
    assert never is None or never not in lines[0]


# ---- progress --------------------------------------------------------------------------------
def test_progress_only_on_a_terminal_and_never_when_quiet(monkeypatch, terminal):
    monkeypatch.delenv(QUIET_ENV, raising=False)
    assert not progress_enabled()  # pytest's stderr is not a terminal
    assert progress_enabled(True) and not progress_enabled(False)
    tty = terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    assert progress_enabled()
    for _ in progress_bar(range(3), desc="steps", unit="step"):
        pass
    assert "steps" in tty.text and "3/3" in tty.text and "<" in tty.text  # elapsed<remaining (the ETA)
    monkeypatch.setenv(QUIET_ENV, "1")
    assert not progress_enabled() and not progress_enabled(True)
    before = len(tty.parts)
    for _ in progress_bar(range(3), desc="quiet", progress=True):
        pass
    assert len(tty.parts) == before


def test_cnn_shows_epochs_and_validation_accuracy_on_a_terminal(monkeypatch, terminal):
    from mdaug.classify import make_classifier

    monkeypatch.delenv(QUIET_ENV, raising=False)
    tty = terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    rng = np.random.default_rng(0)
    x, y = rng.random((60, 400)), np.array(["A", "B"] * 30)
    make_classifier("cnn", epochs=2, batch_size=16, random_state=0).fit(x, y)
    assert "CNN epochs" in tty.text and "2/2" in tty.text and "val acc" in tty.text


def test_sweep_shows_its_cells_and_the_study_its_stages(monkeypatch, tmp_path, terminal):
    from mdaug.classify import sigma_p_sweep
    from mdaug.cli.study import StageProgress
    from mdaug.reports.study import stage_names
    from mdaug.reports.cache import StageCache
    from mdaug.reports.config import StudyConfig

    monkeypatch.delenv(QUIET_ENV, raising=False)
    tty = terminal()
    monkeypatch.setattr(sys, "stderr", tty)
    rng = np.random.default_rng(0)

    def make_train(sigma, seed):
        return rng.random((40, 400)), np.array(["A", "B"] * 20)

    tests = {"t": (rng.random((10, 400)), np.array(["A", "B"] * 5))}
    sigma_p_sweep(make_train, tests, sigma_ps=(0.0, 0.1), models=("nb", "xgb"), n_boot=0)
    assert "sigma_P sweep cells" in tty.text and "4/4" in tty.text
    cfg = StudyConfig()
    names = stage_names(cfg)
    assert names[0] == "data" and "calibrate_HELI" in names and "speed" in names
    listener = StageProgress(["a", "b"])
    cache = StageCache(tmp_path, log=lambda *_: None, listener=listener)
    cache.run("a", "k", lambda: {"x": 1})
    StageCache(tmp_path, log=lambda *_: None, listener=listener).run("a", "k", lambda: {"x": 2})  # cached: once
    cache.run("b", "k", lambda: {"x": 3})
    listener.close()
    assert "study stages" in tty.text and "2/2" in tty.text and listener.done == {"a", "b"}


# ---- the run summary ----------------------------------------------------------------------------
def test_run_summary_is_a_table_without_python_dicts():
    from mdaug.cli.study import summary

    m = {"accuracy": 0.75, "balanced_accuracy": 0.7, "n": 136, "ci": {"balanced_accuracy": [0.68, 0.82]},
         "per_class": {"HELI": {"recall": 0.5}, "QUAD": {"recall": 0.9}}}
    results = {"config": {"classes": ["HELI", "QUAD"]},
               "selection": {"set": "select", "what": "held-out acquisitions"},
               "best_strategy": {"name": "sigma_p_fit"},
               "strategies": {"sigma_p_fit": {"sigma_p": 0.2, "tests": {"select": m, "new": m}},
                              "tsaug": {"sigma_p": None, "tests": {"new": m}}},
               "ceiling": {"models": {"xgb": {"tests": {"new": m}}}},
               "calibration": {"HELI": {"converged": False, "diagnostics": {"reason": "NOT CONVERGED: budget"}},
                               "QUAD": {"converged": True, "diagnostics": {}}}}
    text = summary(results)
    assert "{" not in text and "}" not in text
    lines = text.splitlines()
    assert lines[0].split() == ["strategy", "test", "n", "balanced", "acc.", "95%", "CI", "recall", "HELI",
                                "recall", "QUAD"]
    assert re.match(r"^CNN sigma_p_fit \(sigma_p 0.2\) \*\s+new\s+136\s+0.700\s+\[0.680, 0.820\]\s+0.50\s+0.90$",
                    lines[2]), lines[2]
    assert any(line.startswith("ceiling xgb") for line in lines)
    assert "calibration HELI: likelihood route: NOT converged; SBC: no SBC stored (budget)" in text
    assert "calibration QUAD: likelihood route: converged; SBC: no SBC stored" in text


# ---- files left by killed writers, file modes -------------------------------------------------------
WRITER = textwrap.dedent("""
    import sys, time
    from mdaug.radar import atomic_write
    def write(fh):
        fh.write(b"partial")
        fh.flush()
        print("writing", flush=True)
        time.sleep(60)
    atomic_write(sys.argv[1], write)
""")


def test_a_part_file_left_by_kill_9_is_removed_by_the_next_write(tmp_path):
    target = tmp_path / "data.npz"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(target)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        parts = list(tmp_path.glob(".data.npz.*.part"))
        assert len(parts) == 1 and str(proc.pid) in parts[0].name
        assert stale_parts(target) == []  # its writer is alive: not stale
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert stale_parts(target) == parts  # the writer is gone
    atomic_write(target, lambda fh: fh.write(b"complete"))
    assert target.read_bytes() == b"complete"
    assert list(tmp_path.iterdir()) == [target]


def test_old_part_files_without_a_pid_expire(tmp_path):
    from mdaug.radar import io

    target = tmp_path / "x.json"
    old, new = tmp_path / ".x.json.abc123.part", tmp_path / ".x.json.def456.part"
    old.write_bytes(b"1")
    new.write_bytes(b"2")
    os.utime(old, (time.time() - io.STALE_SECONDS - 10,) * 2)
    assert stale_parts(target) == [old]


def test_the_posterior_netcdf_gets_the_usual_file_mode(tmp_path):
    import arviz as az

    from mdaug.inference.result.posterior import CalibrationResult

    res = object.__new__(CalibrationResult)
    res.idata = az.from_dict(posterior={"x": np.zeros((1, 5))})
    out = res.save(tmp_path / "post.nc")
    mask = os.umask(0)
    os.umask(mask)
    assert (out.stat().st_mode & 0o777) == (0o666 & ~mask)
    assert list(tmp_path.iterdir()) == [out]


# ---- layering ----------------------------------------------------------------------------------------
def test_library_packages_know_nothing_of_the_command_line():
    import ast

    for pkg in LIBRARY:
        assert not (ROOT / pkg / "commands.py").exists()
        for path in (ROOT / pkg).rglob("*.py"):
            text = path.read_text()
            assert "argparse" not in text, path
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.ImportFrom):  # imports point down: no reach-up, no cli
                    assert not (node.level == 2 and node.module is None), f"{path}: from .. import"
                    assert "cli" not in (node.module or "").split("."), path
                elif isinstance(node, ast.Import):
                    assert not any("cli" in a.name.split(".") for a in node.names), path
    assert not (ROOT / "cli.py").exists() and (ROOT / "cli" / "__init__.py").is_file()
