"""The output guard and the size bounds, one table each (beside test_cli_bad_inputs.py).

Every case must end, within seconds and before any work, with exit status 2 and ONE
line ``mdaug VERB: error: ...`` naming the paths (both of them when two collide) or
the option, with no input modified (hashed before and after) and nothing left in the
output folder."""
import os
import shutil

import numpy as np
import pytest

from mdaug.radar import atomic_savez

LABELS = np.array(["HELI", "QUAD"] * 10)


@pytest.fixture(scope="module")
def d(tmp_path_factory, tiny_posterior):
    d = tmp_path_factory.mktemp("guard_inputs")
    rng = np.random.default_rng(0)
    x = np.abs(rng.normal(0.1, 0.05, (20, 400)))
    x[:, 200] = 1.0
    atomic_savez(d / "m.npz", profiles=x, labels=LABELS)
    atomic_savez(d / "t.npz", profiles=x[:6], labels=LABELS[:6])
    from mdaug.classify import make_classifier, save_model

    save_model(make_classifier("nb").fit(x, LABELS), d / "nb.zip")
    cube = rng.normal(size=(11, 8, 504)).astype(np.float32)
    np.savez(d / "raw.npz", cube=cube, label="HELI")
    np.savez(d / "raw2.npz", cube=cube, label="QUAD")
    shutil.copy(tiny_posterior, d / "post.nc")
    os.symlink(d / "m.npz", d / "link.npz")  # a symbolic link to an input
    os.link(d / "m.npz", d / "hard.npz")  # a hard link to it
    (d / "sub").mkdir()
    (d / "sw").mkdir()
    atomic_savez(d / "sw" / "sweep.csv", profiles=x, labels=LABELS)  # an input where sweep writes its table
    (d / "study" / "data").mkdir(parents=True)
    atomic_savez(d / "study" / "data" / "new.npz", profiles=x, labels=LABELS)
    (d / "in_study.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\n'
                                     'test = { new = "study/data/new.npz" }\n')
    atomic_savez(d / "x.nc.chain.h5.fit.json", profiles=x, labels=LABELS)  # named like calibrate's fit file
    bad = os.fsdecode(b"caf\xe9.npz")  # a Latin-1 file name, not UTF-8
    shutil.copy(d / "m.npz", os.path.join(os.fsencode(d), b"caf\xe9.npz"))
    assert os.path.exists(d / bad)
    return d


TRAIN = ["train", "{d}/m.npz", "--model", "nb"]
CAL = ["calibrate", "{d}/m.npz", "--class", "HELI"]

# (case id, argv, substrings of the one error line)
GUARD = [
    # ---- an output is an input (the examples, then more of the kind) ----
    ("train-out-is-data", [*TRAIN, "--out", "{d}/m.npz"], ["{d}/m.npz: --out would overwrite the input DATA {d}/m.npz"]),
    ("train-out-dotdot", [*TRAIN, "--out", "{d}/sub/../m.npz"], ["--out would overwrite the input DATA"]),
    ("train-out-symlink", [*TRAIN, "--out", "{d}/link.npz"], ["link.npz: --out would overwrite", "m.npz"]),
    ("train-out-hardlink", [*TRAIN, "--out", "{d}/hard.npz"], ["hard.npz: --out would overwrite", "m.npz"]),
    ("train-data-is-symlink", ["train", "{d}/link.npz", "--model", "nb", "--out", "{d}/m.npz"],
     ["m.npz: --out would overwrite the input DATA {d}/link.npz"]),
    ("process-out-is-raw", ["process", "{d}/raw.npz", "--out", "{d}/raw.npz"], ["--out would overwrite the input RAW"]),
    ("process-out-is-second-raw", ["process", "{d}/raw.npz", "{d}/raw2.npz", "--out", "{d}/raw2.npz"],
     ["raw2.npz: --out would overwrite the input RAW {d}/raw2.npz"]),
    ("augment-out-is-fit", ["augment", "--fit", "HELI={d}/post.nc", "--out", "{d}/post.nc"],
     ["{d}/post.nc: --out would overwrite the input --fit HELI={d}/post.nc"]),
    ("augment-plot-is-posterior", ["augment", "--posterior", "HELI={d}/post.nc", "--out", "{o}/a.npz", "--plot",
                                   "{d}/post.nc"], ["--plot would overwrite the input --posterior HELI="]),
    ("augment-plot-is-out", ["augment", "--out", "{o}/a.npz", "--plot", "{o}/a.npz"],
     ["--plot and --out {o}/a.npz are the same file"]),
    ("evaluate-json-is-model", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--json", "{d}/nb.zip"],
     ["nb.zip: --json would overwrite the input MODEL {d}/nb.zip"]),
    ("evaluate-json-is-test", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--json", "{d}/t.npz"],
     ["--json would overwrite the input TEST {d}/t.npz"]),
    ("evaluate-plot-is-test", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--plot", "{d}/t.npz"],
     ["--plot would overwrite the input TEST"]),
    ("evaluate-json-is-plot", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--json", "{o}/r.json", "--plot", "{o}/r.json"],
     ["--plot and --json {o}/r.json are the same file"]),
    ("baseline-out-is-out-set", ["baseline", "{d}/m.npz", "--out", "{o}/b.zip", "--out-set", "{o}/b.zip"],
     ["--out-set and --out {o}/b.zip are the same file"]),
    ("baseline-json-is-out", ["baseline", "{d}/m.npz", "--out", "{o}/b.zip", "--json", "{o}/b.zip"],
     ["--json and --out {o}/b.zip are the same file"]),
    ("baseline-out-set-is-data", ["baseline", "{d}/m.npz", "--out-set", "{d}/m.npz"],
     ["--out-set would overwrite the input DATA"]),
    ("baseline-out-is-test", ["baseline", "{d}/m.npz", "--out", "{d}/t.npz", "--test", "{d}/t.npz"],
     ["--out would overwrite the input --test {d}/t.npz"]),
    ("calibrate-out-is-measured", [*CAL, "--out", "{d}/m.npz"], ["--out would overwrite the input MEASURED"]),
    ("calibrate-corner-is-measured", [*CAL, "--out", "{o}/p.nc", "--corner", "{d}/m.npz"],
     ["--corner would overwrite the input MEASURED"]),
    ("calibrate-backend-is-measured", [*CAL, "--out", "{o}/p.nc", "--backend", "{d}/m.npz"],
     ["--backend would overwrite the input MEASURED"]),
    ("calibrate-trace-is-corner", [*CAL, "--out", "{o}/p.nc", "--corner", "{o}/c.png", "--trace", "{o}/c.png"],
     ["--trace and --corner {o}/c.png are the same file"]),
    ("calibrate-backend-is-out", [*CAL, "--out", "{o}/p.h5", "--backend", "{o}/p.h5"],
     ["--backend and --out {o}/p.h5 are the same file"]),
    ("calibrate-measured-is-fit-file", ["calibrate", "{d}/x.nc.chain.h5.fit.json", "--class", "HELI",
                                        "--out", "{d}/x.nc"],
     ["x.nc.chain.h5.fit.json: --backend would overwrite the input MEASURED"]),
    ("sweep-test-where-sweep-writes", ["sweep", "--test", "{d}/sw/sweep.csv", "--out", "{d}/sw"],
     ["sweep.csv: --out would overwrite the input --test {d}/sw/sweep.csv"]),
    ("run-data-inside-study-folder", ["run", "--config", "{d}/in_study.toml", "--out", "{d}/study"],
     ["new.npz: the input [data] test.new lies in {d}/study/data"]),
    # ---- formats: refused at once, not after the work ----
    ("calibrate-corner-txt", [*CAL, "--out", "{o}/p.nc", "--corner", "{o}/c.txt"],
     ["c.txt: --corner must be a figure ending in .png", "'.txt'"]),
    ("calibrate-trace-pgf", [*CAL, "--out", "{o}/p.nc", "--trace", "{o}/t.pgf"], ["t.pgf: --trace must be a figure"]),
    ("calibrate-out-npz", [*CAL, "--out", "{o}/p.npz"], ["p.npz: --out must be a NetCDF posterior ending in .nc"]),
    ("calibrate-backend-nc", [*CAL, "--out", "{o}/p.nc", "--backend", "{o}/b.nc"],
     ["b.nc: --backend must be an HDF5 chain checkpoint"]),
    ("augment-out-csv", ["augment", "--out", "{o}/a.csv"], ["a.csv: --out must be an NPZ file ending in .npz"]),
    ("augment-plot-doc", ["augment", "--out", "{o}/a.npz", "--plot", "{o}/p.docx"], ["p.docx: --plot must be a figure"]),
    ("simulate-out-mat", ["simulate", "--class", "HELI", "--acquisitions", "2", "--out", "{o}/s.mat"],
     ["s.mat: --out must be an NPZ file"]),
    ("process-out-nc", ["process", "{d}/raw.npz", "--out", "{o}/p.nc"], ["p.nc: --out must be an NPZ file"]),
    ("train-out-npz", [*TRAIN, "--out", "{o}/m.npz"], ["m.npz: --out must be a model ZIP ending in .zip"]),
    ("evaluate-json-txt", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--json", "{o}/m.txt"],
     ["m.txt: --json must be a JSON file"]),
    ("baseline-out-set-zip", ["baseline", "{d}/m.npz", "--out-set", "{o}/s.zip"], ["s.zip: --out-set must be an NPZ"]),
    # ---- file names that are not UTF-8 ----
    ("train-out-latin1-name", [*TRAIN, "--out", "{o}/" + os.fsdecode(b"mod\xe8le.zip")],
     ["mod\\xe8le.zip: --out: the file name is not valid UTF-8"]),
    ("train-data-latin1-name", ["train", "{d}/" + os.fsdecode(b"caf\xe9.npz"), "--model", "nb", "--out", "{o}/m.zip"],
     ["caf\\xe9.npz: DATA: the file name is not valid UTF-8"]),
]

BIG = "1000000000000"
AUG = ["augment", "--out", "{o}/a.npz"]
SIM = ["simulate", "--class", "HELI", "--out", "{o}/s.npz"]
SWEEP = ["sweep", "--test", "{d}/t.npz", "--out", "{o}/sw", "--n-per-class", "20", "--sigma-p", "0"]

# (case id, argv, substrings): every size or count option, far beyond reason
SIZES = [
    ("augment-ramps", [*AUG, "--n-per-class", "10", "--ramps", "1000000000"], ["--ramps = 1000000000: more ramps per frame than the radar runs", "max_ramps_per_frame is 1000"]),
    ("augment-ramps-through-chain", [*AUG, "--n-per-class", "10", "--through-chain", "--ramps", "10000000"],
     ["--ramps = 10000000", "max_ramps_per_frame is 1000"]),
    ("augment-mti-depth-chain", [*AUG, "--n-per-class", "10", "--through-chain", "--mti-depth", "1000000000"],
     ["--mti-depth", "of memory"]),
    ("augment-n-per-class-time", [*AUG, "--n-per-class", "100000000", "--acquisition", "measured", "--ramps", "32"],
     ["--n-per-class 100,000,000"]),
    ("augment-n-per-class-fit", ["augment", "--fit", "HELI={d}/post.nc", "--out", "{o}/a.npz", "--n-per-class", BIG],
     ["--n-per-class 1,000,000,000,000"]),
    ("simulate-acquisitions", [*SIM, "--acquisitions", BIG], ["--acquisitions 1,000,000,000,000"]),
    ("simulate-two-classes", ["simulate", "--class", "HELI,QUAD", "--out", "{o}/s.npz", "--acquisitions",
                              "10000000000"], ["--acquisitions 10,000,000,000"]),
    ("simulate-ramps", [*SIM, "--acquisitions", "5", "--ramps", "1000000"], ["--ramps = 1000000", "max_ramps_per_frame is 1000"]),
    ("simulate-frames", [*SIM, "--acquisitions", "5", "--frames", "1000000000"], ["--frames 1,000,000,000"]),
    ("simulate-clutter", [*SIM, "--acquisitions", "5", "--clutter", "100000000"], ["--clutter 100,000,000"]),
    ("simulate-n-angle", [*SIM, "--acquisitions", "5", "--n-angle", "100000000000"], ["--n-angle 100,000,000,000"]),
    ("simulate-keep-cubes", [*SIM, "--acquisitions", "100000", "--ramps", "1000", "--keep-cubes"],
     ["of memory", "stored ramp frames"]),
    ("simulate-specimens", [*SIM, "--acquisitions", "5", "--specimens", BIG],
     ["--specimens 1,000,000,000,000 exceeds --acquisitions 5"]),
    ("process-n-angle", ["process", "{d}/raw.npz", "--out", "{o}/p.npz", "--n-angle", "100000000000"],
     ["--n-angle 100,000,000,000"]),
    ("calibrate-walkers", [*CAL, "--out", "{o}/p.nc", "--walkers", "100000000000"], ["--walkers 100,000,000,000"]),
    ("calibrate-particles", [*CAL, "--out", "{o}/p.nc", "--sampler", "smc", "--particles", "10000000000"],
     ["--particles 10,000,000,000"]),
    ("calibrate-draws", [*CAL, "--out", "{o}/p.nc", "--draws", "1000000", "--ramps-drawn", "1000"],
     ["--draws 1,000,000", "of memory"]),
    ("calibrate-ramps-drawn", [*CAL, "--out", "{o}/p.nc", "--ramps-drawn", BIG], ["--ramps-drawn"]),
    ("calibrate-fit-budget", [*CAL, "--out", "{o}/p.nc", "--fit-budget", "100000000000"], ["--fit-budget"]),
    ("calibrate-starts", [*CAL, "--out", "{o}/p.nc", "--starts", "1000000000"], ["--starts 1,000,000,000"]),
    ("calibrate-max-steps", [*CAL, "--out", "{o}/p.nc", "--max-steps", "1000000000000000000000"],
     ["--max-steps 1,000,000,000,000,000,000,000"]),
    ("run-workers", ["run", "--out", "{o}/study", "--workers", "1000000000"], ["--workers 1,000,000,000"]),
    ("calibrate-time-budget", [*CAL, "--out", "{o}/p.nc", "--time-budget", "1e9"], ["--time-budget"]),
    ("train-epochs", ["train", "{d}/m.npz", "--model", "cnn", "--out", "{o}/m.zip", "--epochs", BIG], ["--epochs"]),
    ("train-trees", ["train", "{d}/m.npz", "--model", "xgb", "--out", "{o}/m.zip", "--n-estimators", BIG],
     ["--n-estimators"]),
    ("evaluate-n-boot", ["evaluate", "{d}/nb.zip", "{d}/t.npz", "--n-boot", "10000000000000"], ["--n-boot"]),
    ("sweep-n-boot", [*SWEEP, "--n-boot", BIG], ["--n-boot"]),
    ("sweep-ramps", [*SWEEP, "--ramps", "1000000000"], ["--ramps = 1000000000", "max_ramps_per_frame is 1000"]),
    ("sweep-epochs", [*SWEEP, "--models", "cnn", "--epochs", BIG], ["--epochs"]),
    ("sweep-trees", [*SWEEP, "--models", "xgb", "--n-estimators", BIG], ["--n-estimators"]),
    ("sweep-workers", [*SWEEP, "--workers", BIG], ["--workers"]),
    ("baseline-epochs", ["baseline", "{d}/m.npz", "--out", "{o}/b.zip", "--n-per-class", "20", "--epochs", BIG],
     ["--epochs"]),
    ("baseline-n-per-class-time", ["baseline", "{d}/m.npz", "--out", "{o}/b.zip", "--n-per-class", "100000000"],
     ["--n-per-class 100,000,000"]),
    ("baseline-folds", ["baseline", "{d}/m.npz", "--folds", "11"], ["--folds 11", "m.npz holds only 10 profile(s)"]),
    ("run-ramps", ["run", "--out", "{o}/study", "--ramps", "1000000"], ["--ramps = 1000000", "max_ramps_per_frame is 1000"]),
]


def test_the_tables_are_large_and_ids_unique():
    assert len(GUARD) >= 35 and len(SIZES) >= 30
    ids = [c[0] for c in GUARD + SIZES]
    assert len(set(ids)) == len(ids)


@pytest.mark.parametrize("case", GUARD + SIZES, ids=[c[0] for c in GUARD + SIZES])
def test_refused_before_any_work(case, d, tmp_path, refused):
    _, argv, must = case
    out = tmp_path / "out"
    out.mkdir()
    refused([a.format(d=d, o=out) for a in argv], d, out, [m.format(d=d, o=out) for m in must], seconds=10)


def test_the_guard_accepts_distinct_paths_and_a_resumed_checkpoint(d, tmp_path):
    """The same guard lets a normal command through: inputs read, outputs distinct, an
    existing checkpoint (an output that is reused) allowed."""
    from mdaug.cli.guard import Output, check_paths

    (tmp_path / "p.nc.chain.h5").write_bytes(b"old chain")
    check_paths(inputs=[("MEASURED", d / "m.npz")],
                outputs=[Output("--out", tmp_path / "p.nc", "posterior"), Output("--corner", tmp_path / "c.png", "plot"),
                         Output("--backend", tmp_path / "p.nc.chain.h5", "checkpoint")])
    check_paths(inputs=[("DATA", d / "m.npz")], outputs=[Output("--out", tmp_path / "model", "model")])  # no suffix


def test_sizes_that_fit_pass(d, tmp_path, capsys):
    """The bounds refuse only the unreasonable: the published sizes pass."""
    from mdaug.cli.common import SECONDS_FAST_RAMP, check_size

    check_size(("--n-per-class", 16000, 16000), ("--ramps", 32, 32), seconds_each=4 * SECONDS_FAST_RAMP)
    check_size(("--n-per-class", 16000, 16000), bytes_each=2 * 400 * 8 * 3)
