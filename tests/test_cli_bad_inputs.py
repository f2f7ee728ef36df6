"""Bad inputs through the command line, one table: every case must end with exit
status 2 and ONE stderr line ``mdaug VERB: error: ...`` that names the file, field
or option (the substrings below), no traceback, and no output file or folder left
behind. Everything fails before any real work, so the table runs in seconds."""
import datetime
import io
import json
import zipfile

import numpy as np
import pytest

from mdaug.cli import main
from mdaug.radar import atomic_savez

CLASSES = np.array(["HELI"] * 10 + ["QUAD"] * 10)


def _profiles(rng, n=20, bins=400):
    x = np.abs(rng.normal(0.1, 0.05, (n, bins)))
    x[:, bins // 2] = 1.0 + rng.uniform(0, 0.1, n)
    return x


def _toml(d, name, text):
    path = d / name
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    """Input files of every kind, good and bad, in one folder."""
    d = tmp_path_factory.mktemp("inputs")
    rng = np.random.default_rng(0)
    good = _profiles(rng)
    atomic_savez(d / "m.npz", profiles=good, labels=CLASSES)
    atomic_savez(d / "heli.npz", profiles=good[:3], labels=CLASSES[:3])
    atomic_savez(d / "zero.npz", profiles=np.zeros((20, 400)), labels=CLASSES)
    some = good.copy()
    some[[3, 5]] = 0.0
    atomic_savez(d / "some_zero.npz", profiles=some, labels=CLASSES)
    atomic_savez(d / "short.npz", profiles=good[:, :399], labels=CLASSES)
    nan = good.copy()
    nan[4, 7] = np.nan
    atomic_savez(d / "nan.npz", profiles=nan, labels=CLASSES)
    atomic_savez(d / "neg.npz", profiles=good - 0.5, labels=CLASSES)
    atomic_savez(d / "one_class.npz", profiles=good, labels=np.array(["HELI"] * 20))
    atomic_savez(d / "drone.npz", profiles=good, labels=np.array(["HELI", "DRONE"] * 10))
    atomic_savez(d / "count.npz", profiles=good, labels=CLASSES[:19])
    np.savez(d / "pickled.npz", profiles=np.array([object()] * 3, dtype=object), labels=CLASSES[:3])
    (d / "garbage.npz").write_bytes(b"not an archive at all" * 10)
    (d / "garbage.mat").write_bytes(b"MATLAB? no" * 20)
    (d / "garbage.nc").write_bytes(b"\x89HDF nope" * 30)
    (d / "empty.npz").write_bytes(b"")
    (d / "nolabel.csv").write_text("a,b,c\n1,2,3\n")
    (d / "text.csv").write_text("b0,b1,label\n1,x,HELI\n")
    (d / "a").mkdir()
    (d / "b").mkdir()
    atomic_savez(d / "a" / "t.npz", profiles=good, labels=CLASSES)
    atomic_savez(d / "b" / "t.npz", profiles=good, labels=CLASSES)
    # models: a working naive Bayes, a non-zip, a zip without meta, a tampered CNN
    from mdaug.classify import make_classifier, save_model

    save_model(make_classifier("nb").fit(good, CLASSES), d / "nb.zip")
    (d / "notzip.zip").write_bytes(b"PK? no")
    with zipfile.ZipFile(d / "nometa.zip", "w") as zf:
        zf.writestr("weights.bin", b"123")
    import torch

    from mdaug.classify.cnn import CNNClassifier

    buf = io.BytesIO()
    torch.save({"w": torch.zeros(3), "when": datetime.date(2020, 1, 1)}, buf)  # a Python object inside
    meta = {"format": "mdaug-classifier", "format_version": 1, "kind": "cnn", "params": CNNClassifier().params(),
            "classes": ["HELI", "QUAD"], "n_features": 400, "weights": "model.pt"}
    with zipfile.ZipFile(d / "tampered.zip", "w") as zf:
        zf.writestr("meta.json", json.dumps(meta))
        zf.writestr("model.pt", buf.getvalue())
    # raw acquisitions
    cube = rng.normal(size=(11, 8, 504)).astype(np.float32)
    np.savez(d / "raw_rank2.npz", cube=cube[0], label="HELI")
    nan_cube = cube.copy()
    nan_cube[1, 2, 3] = np.nan
    np.savez(d / "raw_nan.npz", cube=nan_cube, label="HELI")
    np.savez(d / "raw_zero.npz", cube=np.zeros((11, 8, 504), np.int16), label="HELI")
    np.savez(d / "raw_few.npz", cube=cube[:5], label="HELI")
    np.savez(d / "raw_nolabel.npz", cube=cube)
    np.savez(d / "raw_labels.npz", cubes=np.stack([cube, cube]), labels=np.array(["A", "B", "C"]))
    np.savez(d / "raw_nocube.npz", data=cube)
    np.savez(d / "raw_object.npz", cube=np.array([object()], dtype=object))
    np.savez(d / "raw_ok.npz", cube=cube, label="HELI")
    # study configs
    for name, text in {
        "fifty.toml": '[protocol]\ncnn_epochs = "fifty"\n',
        "sigma_str.toml": '[protocol]\nsigma_p = "0.2"\n',
        "sigma_list.toml": '[protocol]\nsigma_p = [0.1, "x"]\n',
        "workers.toml": 'workers = "two"\n',
        "data5.toml": "data = 5\n",
        "protcol.toml": "[protcol]\ncnn_epochs = 3\n",
        "seed_abc.toml": 'seed = "abc"\n',
        "seed_float.toml": "seed = 1.5\n",
        "seed_bool.toml": "seed = true\n",
        "seed_neg.toml": "seed = -3\n",
        "classes_str.toml": 'classes = "HELI"\n',
        "classes_blimp.toml": 'classes = ["HELI", "BLIMP"]\n',
        "top_key.toml": "epochs = 3\n",
        "proto_key.toml": "[protocol]\nepochs = 3\n",
        "nuisance.toml": '[protocol]\nstrategies = ["foo"]\n',
        "sigma_range.toml": "[protocol]\nsigma_p = [0.1, 1.5]\n",
        "patience.toml": '[protocol]\ncnn_patience = "x"\n',
        "n_new5.toml": "[simulation]\nn_new = 5\n",
        "n_new_str.toml": '[simulation]\nn_new = { HELI = "x" }\n',
        "calib5.toml": "[data]\ncalibration = 5\n",
        "missing_test.toml": '[data]\ncalibration = { HELI = "heli.npz", QUAD = "m.npz" }\n'
                             'test = { new = "nowhere.npz" }\n',
        "zero_test.toml": '[data]\ncalibration = { HELI = "heli.npz", QUAD = "m.npz" }\ntest = { new = "zero.npz" }\n',
        "short_test.toml": '[data]\ncalibration = { HELI = "heli.npz", QUAD = "m.npz" }\n'
                           'test = { new = "short.npz" }\n',
        "calib_only.toml": '[data]\ncalibration = { HELI = "heli.npz", QUAD = "m.npz" }\n',
        "quick_str.toml": 'quick = "yes"\n',
        "models.toml": '[protocol]\nmodels = ["svm", "foo"]\n',
        "norm.toml": '[protocol]\nnormalisation = "x"\n',
        "precision.toml": '[protocol]\ncnn_precision = "fp16"\n',
        "ramps0.toml": "ramps = 0\n",
        "old_ramps.toml": "[protocol]\nacquisition_ramps = 4\n",
        "protocol5.toml": "protocol = 5\n",
        "bad.toml": "seed = = 1\n",
        "scheduler.toml": "scheduler = 5\n",
        "nboot.toml": "[protocol]\nn_boot = -1\n",
    }.items():
        _toml(d, name, text)
    return d


AUG = ["augment", "--out", "{o}/x.npz", "--n-per-class", "5"]
SIM = ["simulate", "--class", "HELI", "--acquisitions", "2", "--out", "{o}/s.npz"]
CAL = ["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p.nc"]
TRAIN = ["train", "{d}/m.npz", "--model", "nb", "--out", "{o}/m.zip"]
EVAL = ["evaluate", "{d}/nb.zip", "{d}/m.npz"]
SWEEP = ["sweep", "--test", "{d}/m.npz", "--out", "{o}/sw", "--n-per-class", "5"]
BASE = ["baseline", "{d}/m.npz", "--out", "{o}/b.zip"]


def run_cfg(name):
    return ["run", "--config", "{d}/" + name, "--out", "{o}/study"]


# (case id, argv, substrings every error must contain[, substrings it must not contain])
CASES = [
    # ---- global options ----
    ("threads-0-before", ["--threads", "0", *AUG], ["argument --threads", "positive integer"]),
    ("threads-neg-after", [*AUG, "--threads", "-1"], ["argument --threads"]),
    ("threads-word", ["--threads", "two", *AUG], ["argument --threads", "'two'"]),
    ("unknown-verb", ["fly"], ["invalid choice: 'fly'"]),
    ("missing-out", ["augment"], ["required", "--out"]),
    ("unknown-option", [*AUG, "--sigma", "0.1"], ["unrecognized arguments", "--sigma"]),
    # ---- augment ----
    ("aug-class", [*AUG, "--classes", "HELI,BLIMP"], ["unknown class 'BLIMP'"]),
    ("aug-classes-empty", [*AUG, "--classes", ","], ["argument --classes"]),
    ("aug-classes-twice", [*AUG, "--classes", "HELI,HELI"], ["argument --classes", "twice"]),
    ("aug-sigma-neg", [*AUG, "--sigma-p", "-0.1"], ["argument --sigma-p", "[0, 1]"]),
    ("aug-sigma-big", [*AUG, "--sigma-p", "1.5"], ["argument --sigma-p"]),
    ("aug-sigma-nan", [*AUG, "--sigma-p", "nan"], ["argument --sigma-p"]),
    ("aug-sigma-word", [*AUG, "--sigma-p", "x"], ["argument --sigma-p"]),
    ("aug-n-0", [*AUG, "--n-per-class", "0"], ["argument --n-per-class", "positive integer"]),
    ("aug-n-neg", [*AUG, "--n-per-class", "-5"], ["argument --n-per-class"]),
    ("aug-n-float", [*AUG, "--n-per-class", "2.5"], ["argument --n-per-class"]),
    ("aug-n-huge", [*AUG, "--n-per-class", "1000000000000"],
     ["--n-per-class 1,000,000,000,000", "of memory", "available"]),
    ("aug-jitter-neg", [*AUG, "--range-jitter", "-1"], ["argument --range-jitter"]),
    ("aug-jitter-inf", [*AUG, "--range-jitter", "inf"], ["argument --range-jitter"]),
    ("aug-ramps-0", [*AUG, "--ramps", "0"], ["argument --ramps"]),
    ("aug-phases", [*AUG, "--phases", "spiral"], ["argument --phases", "invalid choice"]),
    ("aug-normalisation", [*AUG, "--normalisation", "max"], ["argument --normalisation"]),
    ("aug-dtype", [*AUG, "--dtype", "float16"], ["argument --dtype"]),
    ("aug-sign", [*AUG, "--sign-policy", "drop"], ["argument --sign-policy"]),
    ("aug-seed-neg", [*AUG, "--seed", "-1"], ["argument --seed", ">= 0"]),
    ("aug-out-missing-folder", ["augment", "--out", "{o}/missing/x.npz"], ["x.npz: cannot write, folder"]),
    ("aug-out-is-folder", ["augment", "--out", "{o}"], ["cannot write, it is a folder"]),
    ("aug-plot-missing-folder", [*AUG, "--plot", "{o}/missing/p.png"], ["p.png: cannot write"]),
    ("aug-posterior-form", [*AUG, "--posterior", "HELI"], ["argument --posterior", "CLASS=FILE"]),
    ("aug-posterior-missing", [*AUG, "--posterior", "HELI={d}/nowhere.nc"],
     ["nowhere.nc: posterior file not found"]),
    ("aug-posterior-garbage", [*AUG, "--posterior", "HELI={d}/garbage.nc"], ["garbage.nc: not a NetCDF posterior"]),
    ("aug-posterior-twice", [*AUG, "--posterior", "HELI={d}/a.nc", "--posterior", "heli={d}/b.nc"],
     ["--fit/--posterior/--population name a class twice"]),
    ("aug-posterior-and-sigma", [*AUG, "--posterior", "HELI={d}/garbage.nc", "--sigma-p", "0.1"],
     ["--sigma-p applies to sigma_P sources", "not to --posterior"]),
    # ---- simulate ----
    ("sim-class", ["simulate", "--class", "PLANE", "--acquisitions", "2", "--out", "{o}/s.npz"],
     ["unknown class 'PLANE'"]),
    ("sim-acq-0", ["simulate", "--class", "HELI", "--acquisitions", "0", "--out", "{o}/s.npz"],
     ["argument --acquisitions"]),
    ("sim-acq-missing", ["simulate", "--class", "HELI", "--out", "{o}/s.npz"], ["required", "--acquisitions"]),
    ("sim-specimens-0", [*SIM, "--specimens", "0"], ["argument --specimens"]),
    ("sim-range-one", [*SIM, "--range-m", "5"], ["argument --range-m", "LOW,HIGH"]),
    ("sim-range-order", [*SIM, "--range-m", "8,3"], ["argument --range-m", "LOW <= HIGH"]),
    ("sim-range-far", [*SIM, "--range-m", "3,50"], ["--range-m 3,50", "unambiguous range"]),
    ("sim-snr-nan", [*SIM, "--snr-db", "nan"], ["argument --snr-db"]),
    ("sim-ramps-0", [*SIM, "--ramps", "0"], ["argument --ramps"]),
    ("sim-frames-3", [*SIM, "--frames", "3"], ["--frames 3", "mti_depth + 1"]),
    ("sim-azimuth-3", [*SIM, "--azimuth-deg=1,2,3"], ["argument --azimuth-deg"]),
    ("sim-clutter-neg", [*SIM, "--clutter", "-1"], ["argument --clutter"]),
    ("sim-yaw-neg", [*SIM, "--yaw-deg", "-5"], ["argument --yaw-deg"]),
    ("sim-dtype", [*SIM, "--dtype", "float16"], ["argument --dtype"]),
    ("sim-n-angle", [*SIM, "--n-angle", "1"], ["argument --n-angle"]),
    ("sim-rel-threshold", [*SIM, "--rel-threshold-db=5"], ["argument --rel-threshold-db", "<= 0"]),
    ("sim-out-missing-folder", ["simulate", "--class", "HELI", "--acquisitions", "2", "--out", "{o}/no/s.npz"],
     ["s.npz: cannot write"]),
    # ---- process ----
    ("proc-missing", ["process", "{d}/nowhere.npz", "--out", "{o}/p.npz"], ["nowhere.npz: file not found"]),
    ("proc-empty", ["process", "{d}/empty.npz", "--out", "{o}/p.npz"], ["empty.npz: file is empty"]),
    ("proc-garbage", ["process", "{d}/garbage.npz", "--out", "{o}/p.npz"], ["garbage.npz: not a readable NPZ"]),
    ("proc-no-cube", ["process", "{d}/raw_nocube.npz", "--out", "{o}/p.npz"], ["raw_nocube.npz: missing field 'cube'"]),
    ("proc-rank2", ["process", "{d}/raw_rank2.npz", "--out", "{o}/p.npz"], ["raw_rank2.npz: field 'cube' has rank 2"]),
    ("proc-nan-3d-index", ["process", "{d}/raw_nan.npz", "--out", "{o}/p.npz"],
     ["raw_nan.npz: field 'cube' holds NaN", "index (1, 2, 3) of shape (11, 8, 504)"]),
    ("proc-all-zero", ["process", "{d}/raw_zero.npz", "--out", "{o}/p.npz"],
     ["raw_zero.npz: field 'cube' is all zeros"], ["--edge keep"]),
    ("proc-few-frames", ["process", "{d}/raw_few.npz", "--out", "{o}/p.npz"], ["raw_few.npz", "MTI needs"]),
    ("proc-object", ["process", "{d}/raw_object.npz", "--out", "{o}/p.npz"], ["raw_object.npz", "unpickle"]),
    ("proc-no-label", ["process", "{d}/raw_nolabel.npz", "--out", "{o}/p.npz"], ["raw_nolabel.npz", "--label"]),
    ("proc-label-count", ["process", "{d}/raw_labels.npz", "--out", "{o}/p.npz"],
     ["raw_labels.npz: field 'labels'"]),
    ("proc-out-missing-folder", ["process", "{d}/raw_ok.npz", "--out", "{o}/no/p.npz"], ["p.npz: cannot write"]),
    ("proc-max-targets", ["process", "{d}/raw_ok.npz", "--out", "{o}/p.npz", "--max-targets", "0"],
     ["argument --max-targets"]),
    ("proc-edge", ["process", "{d}/raw_ok.npz", "--out", "{o}/p.npz", "--edge", "sideways"], ["argument --edge"]),
    # ---- calibrate ----
    ("cal-missing", ["calibrate", "{d}/nowhere.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["nowhere.npz: file not found"]),
    ("cal-class-absent", ["calibrate", "{d}/heli.npz", "--class", "QUAD", "--out", "{o}/p.nc"],
     ["heli.npz: field 'labels' holds no profile of class 'QUAD'"]),
    ("cal-all-zero", ["calibrate", "{d}/zero.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["zero.npz: field 'profiles'", "all zeros", "rows 0, 1"]),
    ("cal-399", ["calibrate", "{d}/short.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["short.npz: field 'profiles' has 399-bin"]),
    ("cal-negative", ["calibrate", "{d}/neg.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["neg.npz: field 'profiles' holds negative values"]),
    ("cal-nan", ["calibrate", "{d}/nan.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["nan.npz: field 'profiles' holds NaN"]),
    ("cal-engines-0", [*CAL, "--engines", "0"], ["argument --engines"]),
    ("cal-engines-word", [*CAL, "--engines", "x"], ["argument --engines", "'auto'"]),
    ("cal-walkers-1", [*CAL, "--walkers", "1"], ["argument --walkers"]),
    ("cal-max-steps-0", [*CAL, "--max-steps", "0"], ["argument --max-steps"]),
    ("cal-fit-budget-0", [*CAL, "--fit-budget", "0"], ["argument --fit-budget"]),
    ("cal-sampler", [*CAL, "--sampler", "pt"], ["argument --sampler", "invalid choice: 'pt'"]),
    ("cal-particles-1", [*CAL, "--particles", "1"], ["argument --particles"]),
    ("cal-fit-algorithm", [*CAL, "--fit-algorithm", "GN_FOO"], ["argument --fit-algorithm"]),
    ("cal-predictive-word", [*CAL, "--predictive", "many"], ["argument --predictive", "0, or an integer from 20"]),
    ("cal-predictive-5", [*CAL, "--predictive", "5"], ["--predictive: expected 0 (no check) or at least 20 draws, "
                                                       "got 5"]),
    ("cal-out-missing-folder", ["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/no/p.nc"],
     ["p.nc: cannot write"]),
    ("cal-corner-missing-folder", [*CAL, "--corner", "{o}/no/c.png"], ["c.png: cannot write"]),
    # ---- train ----
    ("train-missing", ["train", "{d}/nowhere.npz", "--model", "nb", "--out", "{o}/m.zip"],
     ["nowhere.npz: file not found"]),
    ("train-all-zero", ["train", "{d}/zero.npz", "--model", "nb", "--out", "{o}/m.zip"],
     ["zero.npz: field 'profiles': 20 of 20 profile(s) are all zeros"]),
    ("train-some-zero", ["train", "{d}/some_zero.npz", "--model", "svm", "--out", "{o}/m.zip"],
     ["some_zero.npz: field 'profiles'", "rows 3, 5"]),
    ("train-one-class", ["train", "{d}/one_class.npz", "--model", "nb", "--out", "{o}/m.zip"],
     ["one_class.npz: field 'labels' holds only"]),
    ("train-label-count", ["train", "{d}/count.npz", "--model", "nb", "--out", "{o}/m.zip"],
     ["count.npz: field 'labels' has 19 entries"]),
    ("train-nan", ["train", "{d}/nan.npz", "--model", "nb", "--out", "{o}/m.zip"], ["nan.npz: field 'profiles'",
                                                                                     "NaN"]),
    ("train-csv-header", ["train", "{d}/nolabel.csv", "--model", "nb", "--out", "{o}/m.zip"],
     ["nolabel.csv: CSV header has no 'label' column"]),
    ("train-csv-text", ["train", "{d}/text.csv", "--model", "nb", "--out", "{o}/m.zip"],
     ["text.csv: line 2: field 'profiles' is not numeric"]),
    ("train-mat-garbage", ["train", "{d}/garbage.mat", "--model", "nb", "--out", "{o}/m.zip"],
     ["garbage.mat: not a readable MATLAB file"]),
    ("train-pickled", ["train", "{d}/pickled.npz", "--model", "nb", "--out", "{o}/m.zip"],
     ["pickled.npz", "refusing to unpickle"]),
    ("train-model", ["train", "{d}/m.npz", "--model", "forest", "--out", "{o}/m.zip"], ["argument --model"]),
    ("train-epochs-0", [*TRAIN, "--epochs", "0"], ["argument --epochs"]),
    ("train-batch-0", [*TRAIN, "--batch-size", "0"], ["argument --batch-size"]),
    ("train-patience-0", [*TRAIN, "--patience", "0"], ["argument --patience"]),
    ("train-estimators-0", [*TRAIN, "--n-estimators", "0"], ["argument --n-estimators"]),
    ("train-cnn-399", ["train", "{d}/short.npz", "--model", "cnn", "--out", "{o}/m.zip"],
     ["short.npz: field 'profiles' has 399-bin profiles; the CNN"]),
    ("train-out-missing-folder", ["train", "{d}/m.npz", "--model", "nb", "--out", "{o}/no/m.zip"],
     ["m.zip: cannot write"]),
    # ---- evaluate ----
    ("eval-model-missing", ["evaluate", "{d}/nowhere.zip", "{d}/m.npz"], ["nowhere.zip: model file not found"]),
    ("eval-model-notzip", ["evaluate", "{d}/notzip.zip", "{d}/m.npz"], ["notzip.zip: not an mdaug model file"]),
    ("eval-model-nometa", ["evaluate", "{d}/nometa.zip", "{d}/m.npz"], ["nometa.zip", "no meta.json"]),
    ("eval-model-is-data", ["evaluate", "{d}/m.npz", "{d}/m.npz"], ["m.npz", "not an mdaug model file"]),
    ("eval-tampered-cnn", ["evaluate", "{d}/tampered.zip", "{d}/m.npz"],
     ["tampered.zip: weights member 'model.pt' is not a plain tensor state dict"], ["weights_only", "WeightsUnpickler"]),
    ("eval-test-missing", ["evaluate", "{d}/nb.zip", "{d}/nowhere.npz"], ["nowhere.npz: file not found"]),
    ("eval-test-zero", ["evaluate", "{d}/nb.zip", "{d}/zero.npz"], ["zero.npz: field 'profiles'", "all zeros"]),
    ("eval-test-some-zero", ["evaluate", "{d}/nb.zip", "{d}/some_zero.npz"], ["some_zero.npz", "rows 3, 5"]),
    ("eval-test-399", ["evaluate", "{d}/nb.zip", "{d}/short.npz"], ["short.npz: field 'profiles'", "399 bins"]),
    ("eval-test-labels", ["evaluate", "{d}/nb.zip", "{d}/drone.npz"], ["drone.npz: field 'labels'", "'DRONE'"]),
    ("eval-n-boot", [*EVAL, "--n-boot", "-1"], ["argument --n-boot"]),
    ("eval-json-missing-folder", [*EVAL, "--json", "{o}/no/m.json"], ["m.json: cannot write"]),
    ("eval-plot-is-folder", [*EVAL, "--plot", "{o}"], ["cannot write, it is a folder"]),
    # ---- sweep ----
    ("sweep-sigma-big", [*SWEEP, "--sigma-p", "0.1,2"], ["argument --sigma-p", "[0, 1]"]),
    ("sweep-sigma-word", [*SWEEP, "--sigma-p", "x"], ["argument --sigma-p"]),
    ("sweep-models", [*SWEEP, "--models", "svm,forest"], ["argument --models", "forest"]),
    ("sweep-test-missing", ["sweep", "--test", "{d}/nowhere.npz", "--out", "{o}/sw"], ["nowhere.npz: file not found"]),
    ("sweep-test-399", ["sweep", "--test", "{d}/short.npz", "--out", "{o}/sw"], ["short.npz: field 'profiles' has 399"]),
    ("sweep-test-class", ["sweep", "--test", "{d}/drone.npz", "--out", "{o}/sw"], ["drone.npz: field 'labels'",
                                                                                   "DRONE"]),
    ("sweep-test-zero", ["sweep", "--test", "{d}/zero.npz", "--out", "{o}/sw"], ["zero.npz", "all zeros"]),
    ("sweep-test-same-name", ["sweep", "--test", "{d}/a/t.npz,{d}/b/t.npz", "--out", "{o}/sw"],
     ["--test", "share the name 't'"]),
    ("sweep-out-is-file", ["sweep", "--test", "{d}/m.npz", "--out", "{d}/m.npz"], ["m.npz: --out must be a folder"]),
    ("sweep-n-0", [*SWEEP, "--n-per-class", "0"], ["argument --n-per-class"]),
    ("sweep-n-huge", [*SWEEP, "--n-per-class", "1000000000000"], ["--n-per-class 1,000,000,000,000", "of memory"]),
    ("sweep-workers-0", [*SWEEP, "--workers", "0"], ["argument --workers"]),
    ("sweep-classes", [*SWEEP, "--classes", "HELI,BLIMP"], ["unknown class 'BLIMP'"]),
    ("sweep-n-boot", [*SWEEP, "--n-boot", "-1"], ["argument --n-boot"]),
    # ---- baseline ----
    ("base-no-out", ["baseline", "{d}/m.npz"], ["--out MODEL", "--folds K"]),
    ("base-folds-1", ["baseline", "{d}/m.npz", "--folds", "1"], ["argument --folds"]),
    ("base-data-missing", ["baseline", "{d}/nowhere.npz", "--out", "{o}/b.zip"], ["nowhere.npz: file not found"]),
    ("base-data-zero", ["baseline", "{d}/zero.npz", "--out", "{o}/b.zip"], ["zero.npz", "all zeros"]),
    ("base-data-399", ["baseline", "{d}/short.npz", "--out", "{o}/b.zip"], ["short.npz", "399-bin", "CNN"]),
    ("base-test-missing", [*BASE, "--test", "{d}/nowhere.npz"], ["nowhere.npz: file not found"]),
    ("base-test-class", [*BASE, "--test", "{d}/drone.npz"], ["drone.npz: field 'labels'", "DRONE"]),
    ("base-test-without-out", ["baseline", "{d}/m.npz", "--folds", "3", "--test", "{d}/m.npz"], ["--test", "--out"]),
    ("base-n-huge", [*BASE, "--n-per-class", "1000000000000"], ["--n-per-class 1,000,000,000,000", "of memory"]),
    # ---- run (the study): the whole config is checked before the output folder exists ----
    ("run-config-missing", run_cfg("nowhere.toml"), ["nowhere.toml: config file not found"]),
    ("run-config-bad-toml", run_cfg("bad.toml"), ["bad.toml: not valid TOML"]),
    ("run-cnn-epochs-fifty", run_cfg("fifty.toml"), ["fifty.toml: [protocol] cnn_epochs = 'fifty': expected an integer"]),
    ("run-sigma-string", run_cfg("sigma_str.toml"), ["sigma_str.toml: [protocol] sigma_p = '0.2': expected a list"]),
    ("run-sigma-list-x", run_cfg("sigma_list.toml"), ["sigma_list.toml: [protocol] sigma_p[1] = 'x': expected a number"]),
    ("run-workers-two", run_cfg("workers.toml"), ["workers.toml: workers = 'two': expected an integer"]),
    ("run-data-5", run_cfg("data5.toml"), ["data5.toml: data = 5: expected a table ([data] section)"]),
    ("run-protcol", run_cfg("protcol.toml"),
     ["protcol.toml: unknown section 'protcol'; known: data, protocol, simulation"]),
    ("run-seed-abc", run_cfg("seed_abc.toml"), ["seed_abc.toml: seed = 'abc': expected an integer"],
     ["unrecognized seed string"]),
    ("run-seed-float", run_cfg("seed_float.toml"), ["seed_float.toml: seed = 1.5: expected an integer"]),
    ("run-seed-bool", run_cfg("seed_bool.toml"), ["seed_bool.toml: seed = true: expected an integer"]),
    ("run-seed-negative", run_cfg("seed_neg.toml"), ["seed_neg.toml: seed = -3: expected an integer >= 0"]),
    ("run-classes-string", run_cfg("classes_str.toml"), ["classes_str.toml: classes = 'HELI': expected a list"]),
    ("run-classes-unknown", run_cfg("classes_blimp.toml"), ["classes_blimp.toml: classes: unknown class 'BLIMP'"]),
    ("run-top-key", run_cfg("top_key.toml"), ["top_key.toml: unknown key(s) ['epochs']"]),
    ("run-protocol-key", run_cfg("proto_key.toml"), ["proto_key.toml [protocol]: unknown key(s) ['epochs']"]),
    ("run-nuisance", run_cfg("nuisance.toml"), ["nuisance.toml: protocol.strategies: unknown ['foo']"]),
    ("run-sigma-range", run_cfg("sigma_range.toml"), ["sigma_range.toml: protocol.sigma_p must be"]),
    ("run-patience-str", run_cfg("patience.toml"), ["patience.toml: [protocol] cnn_patience = 'x'"]),
    ("run-n-new-5", run_cfg("n_new5.toml"), ["n_new5.toml: [simulation] n_new = 5: expected a table of integers"]),
    ("run-n-new-str", run_cfg("n_new_str.toml"), ["n_new_str.toml: [simulation] n_new.HELI = 'x'"]),
    ("run-calibration-5", run_cfg("calib5.toml"), ["calib5.toml: [data] calibration = 5: expected a table"]),
    ("run-test-missing", run_cfg("missing_test.toml"), ["missing_test.toml: data.test.new: file not found"]),
    ("run-test-zero", run_cfg("zero_test.toml"), ["zero.npz: field 'profiles'", "all zeros"]),
    ("run-test-399", run_cfg("short_test.toml"), ["short_test.toml: data.test.new", "short.npz", "399-bin"]),
    ("run-calibration-only", run_cfg("calib_only.toml"), ["calib_only.toml: data.calibration is given but data.test"]),
    ("run-quick-string", run_cfg("quick_str.toml"), ["quick_str.toml: quick = 'yes': expected true or false"]),
    ("run-models", run_cfg("models.toml"), ["models.toml: protocol.models: unknown ['foo']"]),
    ("run-normalisation", run_cfg("norm.toml"), ["norm.toml: protocol.normalisation"]),
    ("run-precision", run_cfg("precision.toml"), ["precision.toml: protocol.cnn_precision"]),
    ("run-ramps-0", run_cfg("ramps0.toml"), ["ramps0.toml: ramps = 0: expected an integer >= 1"]),
    ("run-ramps-renamed", run_cfg("old_ramps.toml"), ["old_ramps.toml: [protocol] acquisition_ramps: renamed; "
                                                      "write it as ramps (top level)"]),
    ("run-protocol-5", run_cfg("protocol5.toml"), ["protocol5.toml: protocol = 5: expected a table"]),
    ("run-scheduler-int", run_cfg("scheduler.toml"), ["scheduler.toml: scheduler = 5: expected a string"]),
    ("run-n-boot", run_cfg("nboot.toml"), ["nboot.toml: protocol.n_boot must be >= 0"]),
    ("run-workers-0", ["run", "--workers", "0", "--out", "{o}/study"], ["argument --workers"]),
    ("run-seed-cli", ["run", "--seed", "abc", "--out", "{o}/study"], ["argument --seed"]),
    ("run-out-is-file", ["run", "--out", "{d}/m.npz"], ["m.npz: --out must be a folder"]),
]


def test_the_suite_is_large_and_ids_are_unique():
    assert len(CASES) >= 90
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input(case, d, tmp_path, capsys):
    _, argv, must, *rest = case
    out = tmp_path / "out"
    out.mkdir()
    inputs_before = sorted(p.name for p in d.rglob("*"))
    args = [a.format(d=d, o=out) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    verb = next((a for a in args if not a.startswith("-") and a in {
        "augment", "simulate", "process", "calibrate", "train", "evaluate", "sweep", "baseline", "run"}), None)
    assert len(lines) == 1, err
    assert lines[0].startswith((f"mdaug {verb}: error: ", "mdaug: error: ")), err  # before the verb: mdaug's
    assert "Traceback" not in err
    for text in must:
        assert text.format(d=d, o=out) in lines[0], lines[0]
    for text in (rest[0] if rest else ()):
        assert text not in err, err
    assert list(out.iterdir()) == []  # no output file or folder left behind
    assert sorted(p.name for p in d.rglob("*")) == inputs_before  # nor anything beside the inputs
