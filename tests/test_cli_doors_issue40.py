"""Every door, second pass (issue 40), one kind per section: counts bounded by the
parser, sizes checked before work, estimator files as untrusted input, options that
do not apply, signals inside samplers, leftovers, the user's names in messages, data
sanity at the calibration boundary. Each refusal: exit status 2, ONE line naming the
option or the file and field, the inputs' bytes unchanged and nothing left behind
(the ``refused`` fixture of conftest.py)."""
import argparse

import numpy as np
import pytest

from mdaug.radar import atomic_savez

LABELS = np.array(["HELI"] * 10 + ["QUAD"] * 10)


def _profiles(n=20, seed=0):
    x = np.abs(np.random.default_rng(seed).normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    return x


@pytest.fixture
def io_dirs(tmp_path):
    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    out.mkdir()
    atomic_savez(d / "m.npz", profiles=_profiles(), labels=LABELS, ramps_per_frame=np.array(4))
    return d, out


# ---- 1. counts: bounded by the parser, one helper ------------------------------------------------
def _count_options():
    """(verb, option, action) of every option of every verb whose value is an integer."""
    from mdaug.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for verb, p in sub.choices.items():
        for action in p._actions:
            if not action.option_strings or action.type is None or not callable(action.type):
                continue
            try:
                value = action.type("7")
            except (argparse.ArgumentTypeError, ValueError, TypeError):
                continue
            if isinstance(value, int) and not isinstance(value, bool):
                found.append((verb, action.option_strings[-1], action))
    return found


def test_every_integer_option_is_a_count_of_the_one_helper():
    options = _count_options()
    assert len(options) > 30
    loose = [(v, o) for v, o, a in options if not a.type.__name__.startswith("count_")]
    assert not loose, f"integer options not parsed by cli.common.count: {loose}"


@pytest.mark.parametrize("verb,option", [(v, o) for v, o, _ in _count_options()])
def test_a_count_below_its_bound_is_refused_by_the_parser(verb, option, io_dirs, refused):
    d, out = io_dirs
    action = next(a for v, o, a in _count_options() if (v, o) == (verb, option))
    lo = int(action.type.__name__.split("_")[1])
    bad = str(lo - 1) if lo > 0 else "-1"
    line = refused([verb, option, bad], d, out, [f"argument {option}", f"got {bad}"], seconds=5)
    assert "expected" in line


@pytest.mark.parametrize("argv,must", [
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--sbc-truths", "-1"],
     ["argument --sbc-truths: expected an integer >= 0, got -1"]),
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--sbc-route-truths", "-3"],
     ["argument --sbc-route-truths", "got -3"]),
    (["sbc", "--class", "HELI", "--ramps", "4", "--route-truths", "-2"], ["argument --route-truths", "got -2"]),
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--simulations", "2000001"],
     ["argument --simulations: expected an integer from 100 to 2,000,000"]),
    (["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p.nc", "--engines", "0"],
     ["argument --engines", "'auto'"]),
])
def test_the_issue_counts(argv, must, io_dirs, refused):
    d, out = io_dirs
    refused([a.format(d=d, o=out) for a in argv], d, out, must, seconds=5)


# ---- 2. sizes: one check before any work; the radar's bound on K first ---------------------------
@pytest.fixture
def size_dirs(io_dirs):
    d, out = io_dirs
    atomic_savez(d / "k1001.npz", profiles=_profiles(), labels=LABELS, ramps_per_frame=np.array(1001))
    (d / "k1001.toml").write_text('[data]\ncalibration = { HELI = "k1001.npz", QUAD = "k1001.npz" }\n'
                                  'test = { new = "k1001.npz" }\n')
    return d, out


TRAIN = ["train-estimator", "--class", "HELI", "--out", "{o}/e.zip"]
SIZE_CASES = [
    ("train-days", [*TRAIN, "--ramps", "1000", "--simulations", "2000000"], ["--simulations 2,000,000", "would take"]),
    ("train-radar-k", [*TRAIN, "--ramps", "1001"], ["--ramps = 1001: more ramps per frame than the radar runs",
                                                    "max_ramps_per_frame is 1000"]),
    ("train-route-sbc", [*TRAIN, "--ramps", "4", "--sbc-truths", "1000", "--sbc-route-truths", "1000"],
     ["--sbc-route-truths 1,000", "would take"]),
    ("sbc-truths", ["sbc", "--class", "HELI", "--ramps", "4", "--truths", "1000000000"],
     ["--truths 1,000,000,000", "would take"]),
    ("sbc-specimens", ["sbc", "--class", "HELI", "--ramps", "4", "--truths", "3", "--specimens", "1000000000"],
     ["--specimens 1,000,000,000", "would take"]),
    ("sbc-route-days", ["sbc", "--class", "HELI", "--ramps", "4", "--truths", "3000", "--route-truths", "3000"],
     ["--route-truths 3,000 (with --time-budget 60)", "would take"]),
    ("sbc-route-beyond-truths", ["sbc", "--class", "HELI", "--ramps", "4", "--truths", "3", "--route-truths", "5"],
     ["--route-truths 5 exceeds --truths 3"]),
    ("sbc-radar-k", ["sbc", "--class", "HELI", "--ramps", "1001"], ["--ramps = 1001", "max_ramps_per_frame"]),
    ("simulate-radar-k", ["simulate", "--class", "HELI", "--acquisitions", "1", "--ramps", "1001", "--out",
                          "{o}/s.npz"], ["--ramps = 1001", "max_ramps_per_frame"]),
    ("augment-radar-k", ["augment", "--classes", "HELI", "--n-per-class", "10", "--ramps", "1001", "--out",
                         "{o}/a.npz"], ["--ramps = 1001", "max_ramps_per_frame"]),
    ("run-radar-k", ["run", "--ramps", "1001", "--out", "{o}/study"], ["--ramps = 1001", "max_ramps_per_frame"]),
    ("calibrate-file-k", ["calibrate", "{d}/k1001.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k1001.npz: field 'ramps_per_frame' = 1001", "max_ramps_per_frame"]),
    ("run-file-k", ["run", "--config", "{d}/k1001.toml", "--out", "{o}/study"],
     ["k1001.toml: ", "k1001.npz: field 'ramps_per_frame' = 1001", "max_ramps_per_frame"]),
]


@pytest.mark.parametrize("case", SIZE_CASES, ids=[c[0] for c in SIZE_CASES])
def test_sizes_are_refused_before_work(case, size_dirs, refused):
    _, argv, must = case
    d, out = size_dirs
    refused([a.format(d=d, o=out) for a in argv], d, out, must, seconds=10)


def test_the_radar_bound_comes_before_the_time_estimate():
    from mdaug.cli.common import ramps_factor

    assert ramps_factor("--ramps", 1000) == ("--ramps", 1000, 32)
    with pytest.raises(ValueError, match=r"^f\.npz: field 'ramps_per_frame' = 10000000: more ramps"):
        ramps_factor("f.npz: field 'ramps_per_frame'", 10 ** 7)


# ---- 4. options that do not apply: refused by name -------------------------------------------------
CAL = ["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p.nc", "--method", "likelihood"]
APPLY_CASES = [
    ("particles-with-emcee", [*CAL, "--particles", "100"], ["--particles applies to --sampler laplace or smc",
                                                            "samples with emcee"]),
    ("walkers-with-smc", [*CAL, "--sampler", "smc", "--walkers", "40"], ["--walkers applies to --sampler emcee",
                                                                         "samples with smc"]),
    ("ramps-drawn-beyond-k", [*CAL, "--ramps-drawn", "8"], ["--ramps-drawn 8: more ramps than the data's K = 4",
                                                            "m.npz: field 'ramps_per_frame'"]),
    ("fitted-on-random-phases", [*CAL, "--likelihood", "fitted"], ["--likelihood fitted", "phases uniform"]),
    ("specimen-width-with-population", ["augment", "--population", "HELI={d}/m.npz", "--specimen-width", "1",
                                        "--n-per-class", "5", "--out", "{o}/a.npz"],
     ["--specimen-width applies to", "not to --population"]),
    ("n-new-unknown-class", ["run", "--config", "{d}/n_new.toml", "--out", "{o}/study"],
     ["n_new.toml: simulation.n_new names unknown class 'DRONE'"]),
    ("select-alone", ["run", "--config", "{d}/select.toml", "--out", "{o}/study"],
     ["select.toml: data.select is given but data.calibration and data.test are not"]),
    ("select-unknown-class", ["run", "--config", "{d}/select_class.toml", "--out", "{o}/study"],
     ["select_class.toml: data.select names unknown class 'DRONE'"]),
]


@pytest.mark.parametrize("case", APPLY_CASES, ids=[c[0] for c in APPLY_CASES])
def test_options_that_do_not_apply_are_refused(case, io_dirs, refused):
    _, argv, must = case
    d, out = io_dirs
    (d / "n_new.toml").write_text("[simulation]\nn_new = { HELI = 5, DRONE = 3 }\n")
    (d / "select.toml").write_text('[data]\nselect = { HELI = "m.npz", QUAD = "m.npz" }\n')
    (d / "select_class.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\n'
                                         'select = { DRONE = "m.npz", QUAD = "m.npz" }\ntest = { new = "m.npz" }\n')
    refused([a.format(d=d, o=out) for a in argv], d, out, must, seconds=10)


# ---- 3. estimator files: untrusted input, all the way ----------------------------------------------
class _Payload:
    """A pickle that would create a file if it were ever run."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        import pathlib

        return pathlib.Path.touch, (pathlib.Path(self.marker),)


@pytest.fixture(scope="module")
def estimators(tmp_path_factory):
    """Tampered copies of the shipped HELI K = 4 estimator (and a K = 32 one), in one folder."""
    import json
    import os
    import pickle
    import shutil
    import zipfile

    from mdaug.inference.amortized.shipped import shipped_path

    d = tmp_path_factory.mktemp("estimators")
    with zipfile.ZipFile(shipped_path("HELI", 4)) as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(members["meta.json"])

    def write(name, **change):
        m = dict(members)
        m.update({k.replace("_", "."): v if isinstance(v, bytes) else json.dumps(v).encode()
                  for k, v in change.items()})
        with zipfile.ZipFile(d / name, "w", zipfile.ZIP_DEFLATED) as z:
            for k, v in m.items():
                z.writestr(k, v)

    def edited(**fields):
        return {**json.loads(members["meta.json"]), **fields}

    write("pickle.zip", posterior_pt=pickle.dumps(_Payload(d / "RAN")))
    write("garbage.zip", ratio_pt=b"garbage" * 100)
    write("list.zip", ratio_pt=_torch_bytes([1, 2]))
    write("bomb.zip", meta_json=b" " * (64 * 2 ** 20) + b"{}")  # 64 MB of spaces, deflated to ~64 KB
    write("target.zip", meta_json=edited(target=99))
    write("class.zip", meta_json=edited(spec={**meta["spec"], "class_name": "QUAD"}))
    write("class_foo.zip", meta_json=edited(spec={**meta["spec"], "class_name": "FOO"}))
    write("nan_prior.zip", meta_json=json.dumps(edited(prior={**meta["prior"], "gamma0": float("nan")})).encode())
    write("seed.zip", meta_json=edited(seed="zero"))
    write("json.zip", meta_json=b"{not json")
    os.symlink("/dev/zero", d / "dev.zip")
    os.mkfifo(d / "fifo.zip")
    shutil.copy(shipped_path("HELI", 32), d / "k32.zip")
    atomic_savez(d / "m.npz", profiles=_profiles(3), labels=np.array(["HELI"] * 3), ramps_per_frame=np.array(4))
    return d


def _torch_bytes(obj) -> bytes:
    import io

    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


ESTIMATOR_CASES = [
    ("pickle", "pickle.zip", ["pickle.zip: member 'posterior.pt' is not a state dict of plain tensors",
                              "refused without being run"]),
    ("garbage-weights", "garbage.zip", ["garbage.zip: member 'ratio.pt' is not a state dict"]),
    ("not-a-state-dict", "list.zip", ["list.zip: member 'ratio.pt' is not a table of named tensors"]),
    ("zip-bomb-meta", "bomb.zip", ["bomb.zip: member 'meta.json' declares 67,108,866 bytes", "at most"]),
    ("unknown-target", "target.zip", ["target.zip: meta.json field 'target' is 99: not a target version"]),
    ("class-name-edited", "class.zip", ["class.zip: meta.json field 'spec.class_name' is 'QUAD' but its field "
                                        "'prior' is class HELI's"]),
    ("class-name-unknown", "class_foo.zip", ["class_foo.zip: meta.json field 'spec.class_name' is 'FOO'"]),
    ("nan-prior", "nan_prior.zip", ["nan_prior.zip: meta.json field 'prior' holds NaN"]),
    ("seed-text", "seed.zip", ["seed.zip: meta.json field 'seed' is 'zero'"]),
    ("meta-not-json", "json.zip", ["json.zip: member 'meta.json' is not JSON"]),
    ("device", "dev.zip", ["dev.zip: is a device, not an estimator file", "not read"]),
    ("fifo", "fifo.zip", ["fifo.zip: is a FIFO, not an estimator file"]),
    ("folder", ".", ["is a folder, not an estimator file"]),
    ("sbc-ramps-against-file", "k32.zip", ["--ramps 4 with --estimator", "k32.zip: acquisition field 'ramps' is 4 "
                                           "but the estimator was trained for 32"]),
]


@pytest.mark.parametrize("case", ESTIMATOR_CASES, ids=[c[0] for c in ESTIMATOR_CASES])
def test_sbc_reads_an_estimator_file_as_untrusted_input(case, estimators, tmp_path, refused):
    _, name, must = case
    out = tmp_path / "out"
    out.mkdir()
    refused(["sbc", "--class", "HELI", "--ramps", "4", "--truths", "2", "--estimator", str(estimators / name),
             "--json", str(out / "s.json")], estimators, out, must, seconds=15)
    assert not (estimators / "RAN").exists()


@pytest.mark.parametrize("name,must", [("pickle.zip", ["member 'posterior.pt'"]), ("dev.zip", ["is a device"]),
                                       ("class.zip", ["'spec.class_name' is 'QUAD'"])])
def test_calibrate_reads_an_estimator_file_as_untrusted_input(name, must, estimators, tmp_path, refused):
    out = tmp_path / "out"
    out.mkdir()
    refused(["calibrate", str(estimators / "m.npz"), "--class", "HELI", "--out", str(out / "p.nc"),
             "--estimator", str(estimators / name)], estimators, out, must, seconds=15)
    assert not (estimators / "RAN").exists()


# ---- 5. SIGTERM and Ctrl-C inside emcee: the one line only -------------------------------------------
@pytest.mark.parametrize("signum", ["SIGTERM", "SIGINT"])
def test_a_signal_inside_emcees_log_probability_prints_nothing_and_reads_as_itself(signum, capfd):
    """The signal lands while emcee calls the log-probability (the closed-form route,
    the population's hyper-posterior: both run_ensemble): emcee's parameter dump and
    traceback are never printed, the run stops at the step's end, and the interrupt
    reads as a SIGTERM (143) or a Ctrl-C (130)."""
    import os
    import signal

    from mdaug.inference.samplers.emcee_run import run_ensemble
    from mdaug.inference.settings import CalibrationSettings
    from mdaug.radar.workers import terminate_as_interrupt, was_terminated

    sig = getattr(signal, signum)
    calls = []

    def log_post(theta):
        calls.append(len(theta))
        if len(calls) == 5:
            os.kill(os.getpid(), sig)  # delivered now, inside emcee's call
        return -0.5 * np.sum(theta ** 2, axis=1)

    settings = CalibrationSettings(progress=False, time_budget=60).with_plugin("emcee", max_steps=2000)
    p0 = np.random.default_rng(0).normal(size=(8, 2))
    with pytest.raises(KeyboardInterrupt) as info, terminate_as_interrupt():
        run_ensemble(log_post, p0, settings, seed=0)
    assert was_terminated(info.value) == (signum == "SIGTERM")
    assert 5 <= len(calls) <= 7  # stopped at the end of the step the signal landed in
    out, err = capfd.readouterr()
    assert "emcee" not in err + out and "Traceback" not in err + out and "params" not in err + out, err
    assert signal.getsignal(signal.SIGTERM) is not None


# ---- 6. leftovers: a refused run leaves nothing; a folder in use is never replaced ------------------
def test_files_that_disagree_on_k_are_refused_before_the_folder_exists(io_dirs, refused):
    d, out = io_dirs
    atomic_savez(d / "k8.npz", profiles=_profiles(), labels=LABELS, ramps_per_frame=np.array(8))
    (d / "k.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\ntest = { new = "k8.npz" }\n')
    refused(["run", "--config", str(d / "k.toml"), "--out", str(out / "study")], d, out,
            ["k8.npz says 8 ramp(s) per frame but", "m.npz says 4"], seconds=20)


def test_a_study_refused_after_its_folder_was_made_leaves_no_skeleton(io_dirs, refused, monkeypatch):
    """A refusal in the data stage (after the study's folder, its subfolders and
    stages/study.json were made) removes them all; a folder that existed is kept."""
    from mdaug.reports.study import Study

    def refuse(self, executor=None):
        raise ValueError("x.npz: field 'profiles' refused in the data stage")

    monkeypatch.setattr(Study, "data", refuse)
    d, out = io_dirs
    (d / "s.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\ntest = { new = "m.npz" }\n')
    refused(["run", "--config", str(d / "s.toml"), "--out", str(out / "study")], d, out,
            ["refused in the data stage"], seconds=20)
    (out / "empty").mkdir()  # a folder that existed: kept, and left as it was
    refused(["run", "--config", str(d / "s.toml"), "--out", str(out / "empty")], d, out,
            ["refused in the data stage"], seconds=20)


def test_a_study_folder_in_use_is_refused_even_with_overwrite(tmp_path, refused):
    """A folder whose stages/run.lock names a live process is never replaced: the
    refusal names the owner's pid, and --overwrite is not offered."""
    import json
    import socket
    import subprocess
    import sys

    from mdaug.reports.identity import _started, study_in_use

    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    out.mkdir()
    study = out / "study"
    (study / "stages").mkdir(parents=True)
    (study / "stages" / "study.json").write_text(json.dumps({"key": "another study", "config": "x.toml"}))
    owner = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = {"pid": owner.pid, "host": socket.gethostname(), "started": _started(owner.pid)}
        (study / "stages" / "run.lock").write_text(json.dumps(lock))
        for extra in ([], ["--overwrite"]):
            line = refused(["run", "--quick", "--out", str(study), *extra], d, out,
                           [f"--out is in use by another mdaug run (pid {owner.pid}", "never replaced"], seconds=10)
            assert "give --overwrite" not in line
        assert study_in_use(study)["pid"] == owner.pid
    finally:
        owner.kill()
        owner.wait()
    assert study_in_use(study) is None  # its owner gone: a stale lock, taken over by the next run


def test_the_lock_is_taken_and_given_back(tmp_path):
    import os

    from mdaug.reports.identity import check_not_in_use, study_lock

    with study_lock(tmp_path / "s") as lock:
        assert lock.is_file() and str(os.getpid()) in lock.read_text()
        check_not_in_use(tmp_path / "s")  # our own lock
    assert not lock.exists()


def test_a_failed_train_estimator_leaves_neither_its_work_folder_nor_out(tmp_path, monkeypatch, refused):
    import mdaug.inference.estimator_job as job

    def failing(spec, n, work, out, **kw):
        (work / "sims").mkdir(parents=True)
        (work / "sims" / "shard-0.npz").write_bytes(b"x")
        out.write_bytes(b"half an estimator")
        raise ValueError("the SBC failed: something went wrong")

    monkeypatch.setattr(job, "train_estimator", failing)
    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    out.mkdir()
    refused(["train-estimator", "--class", "HELI", "--ramps", "4", "--simulations", "100", "--out",
             str(out / "e.zip")], d, out, ["the SBC failed"], seconds=10)
    refused(["train-estimator", "--class", "HELI", "--ramps", "4", "--simulations", "100", "--out",
             str(out / "e.zip"), "--work", str(out / "a" / "b" / "w")], d, out, ["the SBC failed"], seconds=10)


def test_an_uncreatable_work_folder_is_named_by_its_option(tmp_path, refused):
    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    out.mkdir()
    (out / "file").write_text("a file, not a folder")
    refused(["train-estimator", "--class", "HELI", "--ramps", "4", "--out", str(out / "e.zip"), "--work",
             str(out / "file" / "w")], d, out, ["--work"], seconds=10)


# ---- 7. messages name the user's option or file field, not an internal object ------------------------
def _save_population(path, ramps):
    """A population file of the right layout (values need not mean anything) whose acquisition states K."""
    import json

    from mdaug.generator import load_reference
    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.population.model import SPREADS, Hyperprior, PopulationModel
    from mdaug.inference.space.priors import Priors

    ref = load_reference("HELI")
    model, x0 = PopulationModel(1), ref.to_array()
    rng = np.random.default_rng(0)
    meta = {"format": "mdaug-population-1", "class_name": "HELI", "n_engines": 1, "gamma0": float(x0[0]),
            "priors": Priors.from_reference(ref).to_dict(), "specimens": ["0", "1"],
            "hyperprior": Hyperprior().scales, "coords": model.names,
            "acquisition": Acquisition.measured(ramps).to_dict(), "drones_converged": [True, True],
            "identified": [[True] * model.p] * 2,
            "diagnostics": {"tau": [1.0], "steps": 10, "converged": True, "acceptance": 0.3}}
    atomic_savez(path, meta=np.array(json.dumps(meta)), spreads=np.abs(rng.normal(0.05, 0.01, (40, len(SPREADS)))),
                 mu=np.tile(model.transform(x0[None]), (40, 1)), measured=np.ones(model.p, bool),
                 pool=np.tile(x0, (6, 1)), pool_drone=np.repeat([0, 1], 3),
                 drone_means=np.tile(model.transform(x0[None]), (2, 1)), reference=x0)


def test_a_k_read_from_a_calibration_file_is_named_by_file_and_field(io_dirs, refused):
    d, out = io_dirs
    _save_population(d / "pop.npz", 1001)
    line = refused(["augment", "--population", f"HELI={d / 'pop.npz'}", "--n-per-class", "5", "--out",
                    str(out / "a.npz")], d, out, ["pop.npz: acquisition field 'ramps' = 1001", "max_ramps_per_frame"])
    assert "Acquisition." not in line and "SceneConfig" not in line and "RadarConfig" not in line


@pytest.mark.parametrize("argv", [["simulate", "--class", "HELI", "--acquisitions", "1", "--ramps", "5000", "--out",
                                   "{o}/s.npz"],
                                  ["run", "--ramps", "5000", "--out", "{o}/study"],
                                  ["augment", "--classes", "HELI", "--n-per-class", "5", "--ramps", "5000", "--out",
                                   "{o}/a.npz"]])
def test_no_internal_object_is_named_for_an_option(argv, io_dirs, refused):
    d, out = io_dirs
    line = refused([a.format(o=out) for a in argv], d, out, ["--ramps = 5000"], seconds=10)
    assert not any(w in line for w in ("SceneConfig", "Acquisition.", "RadarConfig"))


# ---- 8. data that cannot be what they claim, at the calibration boundary -----------------------------
@pytest.fixture
def odd_data(io_dirs):
    d, out = io_dirs
    x = _profiles()
    same = x.copy()
    same[[2, 4, 6]] = same[0]  # four identical HELI profiles (rows 0, 2, 4, 6)
    atomic_savez(d / "same.npz", profiles=same, labels=LABELS, ramps_per_frame=np.array(4))
    flat = x.copy()
    flat[[1, 3]] = 0.25
    atomic_savez(d / "flat.npz", profiles=flat, labels=LABELS, ramps_per_frame=np.array(4))
    off = x.copy()
    off[5, 200], off[5, 260] = 0.1, 2.0  # peak 60 bins off the centre
    atomic_savez(d / "off.npz", profiles=off, labels=LABELS, ramps_per_frame=np.array(4))
    for name in ("same", "flat", "off"):
        (d / f"{name}.toml").write_text(f'[data]\ncalibration = {{ HELI = "{name}.npz", QUAD = "m.npz" }}\n'
                                        'test = { new = "m.npz" }\n')
    _save_population(d / "pop_ids.npz", 4)
    import json

    arrays = dict(np.load(d / "pop_ids.npz"))
    meta = json.loads(str(arrays.pop("meta")))
    meta["specimens"] = ["a", "a"]
    atomic_savez(d / "pop_ids.npz", meta=np.array(json.dumps(meta)), **arrays)
    return d, out


SANITY_CASES = [
    ("identical", ["calibrate", "{d}/same.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["same.npz: field 'profiles' holds 4 identical profiles of class HELI (row(s) 0, 2, 4, 6)", "3 are copies, not independent"]),
    ("constant", ["calibrate", "{d}/flat.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["flat.npz: field 'profiles' holds 2 constant profile(s) of class HELI (row(s) 1, 3)", "no signal"]),
    ("off-centre", ["calibrate", "{d}/off.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["off.npz: field 'profiles' holds 1 of 10 profile(s) of class HELI whose peak lies more than 4 bins",
      "row(s) 5 at bin(s) 260"]),
    ("identical-one-drone", ["calibrate", "{d}/same.npz", "--class", "HELI", "--specimen", "0", "--out", "{o}/p.nc"],
     ["same.npz: field 'profiles' holds 4 identical profiles"]),
    ("identical-population", ["calibrate", "{d}/same.npz", "--class", "HELI", "--population", "--out", "{o}/p.npz"],
     ["same.npz: field 'profiles' holds 4 identical"]),
    ("study-identical", ["run", "--config", "{d}/same.toml", "--out", "{o}/study"],
     ["same.toml: data.calibration.HELI: ", "same.npz: field 'profiles' holds 4 identical profiles"]),
    ("study-constant", ["run", "--config", "{d}/flat.toml", "--out", "{o}/study"],
     ["flat.toml: data.calibration.HELI: ", "2 constant profile(s)"]),
    ("study-off-centre", ["run", "--config", "{d}/off.toml", "--out", "{o}/study"],
     ["off.toml: data.calibration.HELI: ", "peak lies more than 4 bins"]),
    ("population-duplicate-ids", ["augment", "--population", "HELI={d}/pop_ids.npz", "--n-per-class", "5", "--out",
                                  "{o}/a.npz"],
     ["pop_ids.npz: field 'meta' key 'specimens' names 2 drones with 1 repeated id(s) ('a')"]),
]


@pytest.mark.parametrize("case", SANITY_CASES, ids=[c[0] for c in SANITY_CASES])
def test_data_that_cannot_be_what_they_claim_are_refused(case, odd_data, refused):
    _, argv, must = case
    d, out = odd_data
    refused([a.format(d=d, o=out) for a in argv], d, out, must, seconds=15)


def test_the_sanity_check_passes_real_data():
    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.simulate import SimulationSpec, simulate
    from mdaug.inference.sanity import check_calibration_profiles

    _, y = simulate(SimulationSpec("QUAD", Acquisition.measured(4), 5), 3, 0)
    for k in range(3):
        check_calibration_profiles(y[k], "sim", "QUAD")


def test_a_chain_too_short_for_tau_never_reports_an_impossible_ratio():
    """--max-steps 4 reported '18014398509481984.0 x max tau': tau is at least one
    stored step, and a chain too short to estimate it says so."""
    import re

    from mdaug.inference.samplers.emcee_run import _tau, run_ensemble
    from mdaug.inference.settings import CalibrationSettings

    rng = np.random.default_rng(0)
    assert np.all(_tau(rng.normal(size=(3, 8, 3)), (), 2) == 2.0)  # emcee's estimator gives 0 here
    for steps in (2, 4, 6):
        settings = CalibrationSettings(progress=False).with_plugin("emcee", max_steps=steps, check_every=2)
        run = run_ensemble(lambda t: -0.5 * np.sum(t ** 2, axis=1), rng.normal(size=(8, 2)), settings, seed=steps)
        assert not run.converged and np.all(run.tau >= 1), run.reason
        assert "e+" not in run.reason, run.reason
        ratio = re.search(r"ended at ([0-9.]+) x max tau", run.reason)
        assert ratio is None and "too few to estimate" in run.reason or float(ratio.group(1)) <= steps, run.reason


def test_a_test_set_that_is_a_calibration_file_is_warned_of(io_dirs, capsys, monkeypatch):
    from mdaug.cli import main
    from mdaug.reports.study import Study

    def refuse(self, executor=None):
        raise ValueError("stopped here by the test")

    monkeypatch.setattr(Study, "data", refuse)
    d, out = io_dirs
    atomic_savez(d / "t.npz", profiles=_profiles(seed=1), labels=LABELS, ramps_per_frame=np.array(4))
    (d / "s.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\ntest = { new = "m.npz", '
                              'other = "t.npz" }\n')
    assert main(["run", "--config", str(d / "s.toml"), "--out", str(out / "study")]) == 2
    text = capsys.readouterr()
    notes = [line for line in text.out.splitlines() if line.startswith("note: ")]
    assert len(notes) == 1 and "data.test.new" in notes[0], text.out
    assert "is also the calibration file of HELI, QUAD" in notes[0] and "other" not in notes[0]
    err = text.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mdaug run: error: stopped here"), err


def test_sbc_checks_the_estimators_class_against_class(estimators, tmp_path, refused):
    out = tmp_path / "out"
    out.mkdir()
    refused(["sbc", "--class", "QUAD", "--ramps", "4", "--truths", "2", "--estimator", str(estimators / "k32.zip")],
            estimators, out, ["k32.zip: meta.json field 'spec.class_name' is 'HELI'", "class 'QUAD'"], seconds=15)
