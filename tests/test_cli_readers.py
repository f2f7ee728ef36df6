"""Files that are almost right, one table (beside test_cli_bad_inputs.py): every reader
checks dtype, shape and metadata against content and names the file and field; OS
errors name the path. Every case ends with exit status 2 and ONE line, no input
modified (hashed before and after), nothing left in the output folder.

Then the messages that must be true: calibrate's interrupt, baseline's training
count, an undefined precision, the sweep's peeking pick, calibrate's units, augment's
bar through the chain."""
import errno
import json
import shutil
import zipfile

import numpy as np
import pytest

from mdaug.radar import atomic_savez

LABELS = np.array(["HELI", "QUAD"] * 10)


def _profiles(n=20):
    x = np.abs(np.random.default_rng(0).normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    return x


def _edit_posterior(src, dst, edit):
    """Copy the posterior NetCDF ``src`` to ``dst`` and apply ``edit(posterior HDF5 group,
    meta dict)`` in place with h5py (milliseconds, where arviz takes seconds a file)."""
    import h5py

    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        g = f["posterior"]
        meta = json.loads(g.attrs["mdaug"])
        edit(g, meta)
        g.attrs["mdaug"] = json.dumps(meta)


def _model(d, name, edit_meta=None, member=None):
    """A copy of the naive Bayes model with meta.json edited (or a member replaced)."""
    with zipfile.ZipFile(d / "nb.zip") as zf:
        meta = json.loads(zf.read("meta.json"))
        blob = zf.read("model.skops")
    if edit_meta:
        edit_meta(meta)
    with zipfile.ZipFile(d / name, "w") as zf:
        zf.writestr("meta.json", json.dumps(meta))
        zf.writestr(member or meta.get("weights", "model.skops"), blob)


@pytest.fixture(scope="module")
def d(tmp_path_factory, tiny_posterior):
    d = tmp_path_factory.mktemp("reader_inputs")
    x = _profiles()
    atomic_savez(d / "m.npz", profiles=x, labels=LABELS)
    atomic_savez(d / "complex.npz", profiles=x + 1j, labels=LABELS)
    atomic_savez(d / "num_labels.npz", profiles=x, labels=np.arange(20) % 2 * 1.0)
    atomic_savez(d / "table_labels.npz", profiles=x, labels=np.stack([LABELS, LABELS], axis=1))
    atomic_savez(d / "latin1_labels.npz", profiles=x, labels=np.array([b"H\xc9LI", b"QUAD"] * 10))
    atomic_savez(d / "settings_text.npz", profiles=x, labels=LABELS, settings=np.array("not json {"))
    atomic_savez(d / "settings_list.npz", profiles=x, labels=LABELS, settings=np.array("[1, 2]"))
    atomic_savez(d / "settings_classes.npz", profiles=x, labels=LABELS,
                 settings=np.array(json.dumps({"classes": ["HELI", "PLANE"]})))
    atomic_savez(d / "param_row.npz", profiles=x, labels=LABELS, param_row=np.arange(7))
    atomic_savez(d / "ramps_text.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array("many"))
    atomic_savez(d / "acq_disagrees.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(4),
                 acquisition=np.array(json.dumps({"ramps": 8})))
    rows = "\n".join(",".join(f"{v:.3f}" for v in r) + f",{lab}" for r, lab in zip(x, LABELS))
    header = ",".join(f"b{i}" for i in range(400)) + ",label\n"
    (d / "utf16.csv").write_bytes((header + rows).encode("utf-16"))
    (d / "latin1.csv").write_bytes((header + rows.replace("HELI", "HÉLI")).encode("latin-1"))
    cube = np.random.default_rng(1).normal(size=(11, 8, 504))
    np.savez(d / "raw_int64.npz", cube=(cube * 1e6).astype(np.int64), label="HELI")
    np.savez(d / "raw_overflow.npz", cube=cube * 1e39, label="HELI")
    np.savez(d / "raw_num_label.npz", cube=cube.astype(np.float32), label=np.array(3.0))
    (d / "folder.npz").mkdir()
    (d / "folder.nc").mkdir()
    (d / "folder.zip").mkdir()
    (d / "utf16.toml").write_bytes("seed = 1\n".encode("utf-16"))
    from mdaug.classify import make_classifier, save_model

    save_model(make_classifier("nb").fit(x, LABELS), d / "nb.zip")
    _model(d, "kind_mismatch.zip", lambda m: m.update(kind="xgb"))
    _model(d, "one_class.zip", lambda m: m.update(classes=["HELI"]))
    _model(d, "features.zip", lambda m: m.update(n_features=300))
    _model(d, "three_classes.zip", lambda m: m.update(classes=["HELI", "QUAD", "BLIMP"]))
    _model(d, "norm.zip", lambda m: m.update(normalisation="db"))
    _model(d, "weights_name.zip", lambda m: m.update(weights="model.pt"), member="model.pt")
    shutil.copy(tiny_posterior, d / "post.nc")

    def drop(name):
        def edit(g, meta):
            del g[name]
        return edit

    def as_int(name):
        def edit(g, meta):
            data, scales = g[name][...].astype(np.int64), [dim[0] for dim in g[name].dims]
            del g[name]
            new = g.create_dataset(name, data=data)
            for i, scale in enumerate(scales):
                new.dims[i].attach_scale(scale)
        return edit

    def put(name, value):
        def edit(g, meta):
            v = g[name][...]
            v.flat[3] = value
            g[name][...] = v
        return edit

    def meta_set(**kw):
        def edit(g, meta):
            meta.update(kw)
        return edit

    def meta_drop(key):
        def edit(g, meta):
            meta.pop(key)
        return edit

    for name, edit in {"post_no_w_a.nc": drop("w_a"), "post_int.nc": as_int("A_b"),
                       "post_nan.nc": put("w_b", np.nan), "post_huge.nc": put("A_a", 1e300),
                       "post_inf.nc": put("sigma", np.inf),
                       "post_engines.nc": meta_set(n_engines=2),
                       "post_measurements.nc": meta_set(n_measurements=5),
                       "post_marginal.nc": meta_set(marginal=True),
                       "post_best_fit.nc": meta_set(best_fit=[1.0, 2.0]),
                       "post_no_diag.nc": meta_drop("diagnostics"),
                       "post_priors.nc": meta_set(priors={"bounds": {}}),
                       "post_acq.nc": meta_set(acquisition={"ramps": "many"}),
                       "post_class.nc": meta_set(class_name="QUAD")}.items():
        _edit_posterior(d / "post.nc", d / name, edit)
    return d


AUG = ["augment", "--out", "{o}/a.npz", "--n-per-class", "5"]
TRAIN = ["--model", "nb", "--out", "{o}/m.zip"]

# (case id, argv, substrings of the one error line)
CASES = [
    # ---- posteriors ----
    ("post-missing-variable", [*AUG, "--posterior", "HELI={d}/post_no_w_a.nc"],
     ["post_no_w_a.nc: posterior variable 'w_a' is missing"]),
    ("post-int-dtype", [*AUG, "--posterior", "HELI={d}/post_int.nc"],
     ["post_int.nc: posterior variable 'A_b' has dtype int64"]),
    ("post-nan", [*AUG, "--fit", "HELI={d}/post_nan.nc"], ["post_nan.nc: posterior variable 'w_b' holds NaN"]),
    ("post-overflowing", [*AUG, "--posterior", "HELI={d}/post_huge.nc"],
     ["post_huge.nc: posterior variable 'A_a'", "outside its prior bounds"]),
    ("post-inf-nuisance", [*AUG, "--posterior", "HELI={d}/post_inf.nc"], ["post_inf.nc: posterior variable 'sigma'"]),
    ("post-meta-engines", [*AUG, "--posterior", "HELI={d}/post_engines.nc"],
     ["post_engines.nc", "'best_fit'", "n_engines = 2"]),
    ("post-meta-measurements", [*AUG, "--posterior", "HELI={d}/post_measurements.nc"],
     ["post_measurements.nc:", "5 measurements", "n_measurements"]),
    ("post-meta-marginal", [*AUG, "--posterior", "HELI={d}/post_marginal.nc"],
     ["post_marginal.nc: posterior variable 'carrier' is missing"]),
    ("post-meta-best-fit", [*AUG, "--fit", "HELI={d}/post_best_fit.nc"], ["post_best_fit.nc", "'best_fit' has shape (2,)"]),
    ("post-meta-no-diagnostics", [*AUG, "--posterior", "HELI={d}/post_no_diag.nc"],
     ["post_no_diag.nc", "lacks field(s) ['diagnostics']"]),
    ("post-meta-priors", [*AUG, "--posterior", "HELI={d}/post_priors.nc"], ["post_priors.nc", "field 'priors'"]),
    ("post-meta-acquisition", [*AUG, "--posterior", "HELI={d}/post_acq.nc"], ["post_acq.nc", "acquisition"]),
    ("post-meta-class", [*AUG, "--posterior", "HELI={d}/post_class.nc"],
     ["post_class.nc: posterior of class 'QUAD', expected 'HELI'"]),
    # ---- model files: meta.json against the weights ----
    ("model-kind-vs-weights", ["evaluate", "{d}/kind_mismatch.zip", "{d}/m.npz"],
     ["kind_mismatch.zip: meta.json field 'weights' = 'model.skops' disagrees with field 'kind' = 'xgb'"]),
    ("model-one-class", ["evaluate", "{d}/one_class.zip", "{d}/m.npz"], ["one_class.zip: meta.json field 'classes'"]),
    ("model-n-features", ["evaluate", "{d}/features.zip", "{d}/m.npz"],
     ["features.zip: the weights take 400-bin profiles but meta.json field 'n_features' says 300"]),
    ("model-class-count", ["evaluate", "{d}/three_classes.zip", "{d}/m.npz"],
     ["three_classes.zip: the weights score 2 classes but meta.json field 'classes' lists 3"]),
    ("model-normalisation", ["evaluate", "{d}/norm.zip", "{d}/m.npz"],
     ["norm.zip: meta.json field 'normalisation' = 'db' disagrees"]),
    ("model-weights-member", ["evaluate", "{d}/weights_name.zip", "{d}/m.npz"],
     ["weights_name.zip: meta.json field 'weights' = 'model.pt' disagrees with field 'kind' = 'nb'"]),
    # ---- profile files: dtype, shape and metadata ----
    ("profiles-complex", ["train", "{d}/complex.npz", *TRAIN], ["complex.npz: field 'profiles' is complex"]),
    ("labels-numbers", ["train", "{d}/num_labels.npz", *TRAIN],
     ["num_labels.npz: field 'labels' must hold text", "float64"]),
    ("labels-table", ["evaluate", "{d}/nb.zip", "{d}/table_labels.npz"],
     ["table_labels.npz: field 'labels' has shape (20, 2)"]),
    ("labels-not-utf8", ["train", "{d}/latin1_labels.npz", *TRAIN],
     ["latin1_labels.npz: field 'labels' holds bytes that are not UTF-8"]),
    ("settings-not-json", ["train", "{d}/settings_text.npz", *TRAIN],
     ["settings_text.npz: field 'settings' is not a JSON table"]),
    ("settings-not-table", ["evaluate", "{d}/nb.zip", "{d}/settings_list.npz"],
     ["settings_list.npz: field 'settings' is not a JSON table"]),
    ("settings-classes", ["train", "{d}/settings_classes.npz", *TRAIN],
     ["settings_classes.npz: field 'labels' holds class(es) ['QUAD'] that field 'settings' does not list"]),
    ("param-row-length", ["train", "{d}/param_row.npz", *TRAIN],
     ["param_row.npz: field 'param_row' has shape (7,); expected one entry per profile (20)"]),
    ("ramps-per-frame-text", ["calibrate", "{d}/ramps_text.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["ramps_text.npz: field 'ramps_per_frame' must be one integer"]),
    ("acquisition-vs-ramps", ["calibrate", "{d}/acq_disagrees.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["acq_disagrees.npz: field 'ramps_per_frame' = 4 disagrees with field 'acquisition'"]),
    ("csv-utf16", ["train", "{d}/utf16.csv", *TRAIN], ["utf16.csv: not UTF-8 text"]),
    ("csv-latin1", ["evaluate", "{d}/nb.zip", "{d}/latin1.csv"], ["latin1.csv: not UTF-8 text"]),
    ("toml-utf16", ["run", "--config", "{d}/utf16.toml", "--out", "{o}/study"], ["utf16.toml: not a text file"]),
    ("data-is-folder", ["train", "{d}/folder.npz", *TRAIN], ["folder.npz: is a folder, not a data file"]),
    ("model-is-folder", ["evaluate", "{d}/folder.zip", "{d}/m.npz"], ["folder.zip: is a folder, not a model file"]),
    ("posterior-is-folder", [*AUG, "--posterior", "HELI={d}/folder.nc"], ["folder.nc: is a folder"]),
    # ---- raw cubes ----
    ("raw-int64-codes", ["process", "{d}/raw_int64.npz", "--out", "{o}/p.npz"],
     ["raw_int64.npz: field 'cube' holds values that are not 16-bit ADC codes"]),
    ("raw-float32-overflow", ["process", "{d}/raw_overflow.npz", "--out", "{o}/p.npz"],
     ["raw_overflow.npz: field 'cube' holds values that exceed float32"]),
    ("raw-numeric-label", ["process", "{d}/raw_num_label.npz", "--out", "{o}/p.npz"],
     ["raw_num_label.npz: field 'label' must hold text"]),
]


def test_the_table_is_large_and_ids_unique():
    assert len(CASES) >= 30
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_almost_right_file(case, d, tmp_path, refused):
    _, argv, must = case
    out = tmp_path / "out"
    out.mkdir()
    refused([a.format(d=d, o=out) for a in argv], d, out, [m.format(d=d, o=out) for m in must])


def test_the_good_posterior_and_model_still_load(d):
    from mdaug.classify.persist import load_model
    from mdaug.inference.result.posterior import CalibrationResult

    assert CalibrationResult.load(d / "post.nc", class_name="HELI").n_draws > 0
    assert load_model(d / "nb.zip").classes_.tolist() == ["HELI", "QUAD"]


# ---- OS errors: one line naming the path, nothing left behind ----------------------------------
def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize("verb", ["process", "simulate", "augment", "train", "evaluate"])
def test_a_full_disk_names_the_output(verb, d, tmp_path, monkeypatch, refused):
    import builtins

    out = tmp_path / "out"
    out.mkdir()
    real_open = builtins.open

    def full_open(file, mode="r", *a, **k):  # an output's temporary file: every write fails, as on a full disk
        fh = real_open(file, mode, *a, **k)
        if "w" in mode and str(file).endswith(".part"):
            fh.write = _enospc
        return fh

    argv, target = {
        "process": (["process", f"{d}/raw_int64.npz"], None),
        "simulate": (["simulate", "--class", "HELI", "--acquisitions", "1", "--ramps", "1"], None),
        "augment": (["augment", "--classes", "HELI", "--n-per-class", "3", "--allow-one-class"], None),
        "train": (["train", f"{d}/m.npz", "--model", "nb"], None),
        "evaluate": (["evaluate", f"{d}/nb.zip", f"{d}/m.npz", "--n-boot", "0", "--json"], None),
    }[verb]
    if verb == "process":  # a readable raw file
        np.savez(tmp_path / "raw.npz", cube=np.random.default_rng(2).normal(size=(11, 8, 504)).astype(np.float32),
                 label="HELI")
        argv = ["process", str(tmp_path / "raw.npz")]
    name = {"train": "m.zip", "evaluate": "m.json"}.get(verb, "x.npz")
    monkeypatch.setattr(builtins, "open", full_open)
    if verb == "evaluate":
        argv = argv + [str(out / name)]
    else:
        argv = argv + ["--out", str(out / name)]
    refused(argv, d, out, [f"{out / name}: cannot write (No space left on device)"], seconds=60)


def test_an_os_error_with_a_file_name_is_one_line_naming_it():
    from mdaug.cli import _one_line

    assert _one_line(PermissionError(errno.EACCES, "Permission denied", "/data/x.npz")) == \
        "/data/x.npz: Permission denied"
    assert _one_line(OSError(errno.EXDEV, "Invalid cross-device link", "/a", None, "/b")) == \
        "/a -> /b: Invalid cross-device link"


def test_an_unreadable_input_names_its_path(d, tmp_path, monkeypatch, refused):
    def denied(path, *a, **k):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(np, "load", denied)
    out = tmp_path / "out"
    out.mkdir()
    refused(["train", f"{d}/m.npz", "--model", "nb", "--out", str(out / "m.zip")], d, out,
            [f"{d}/m.npz: cannot read (Permission denied)"])


# ---- messages that must be true ---------------------------------------------------------------
def _interrupt(*_a, **_k):
    raise KeyboardInterrupt


@pytest.mark.parametrize("existing, says, never", [
    ((), "no chain checkpoint was written yet", "is kept"),
    ((".fit.json",), "the global fit is kept in", "no chain checkpoint"),
    (("", ".fit.json"), "the chain checkpoint", "no chain checkpoint"),
])
def test_calibrate_interrupted_says_what_exists(existing, says, never, d, tmp_path, monkeypatch, capsys):
    from mdaug.cli import main

    import importlib

    monkeypatch.setattr(importlib.import_module("mdaug.inference.calibrate"), "calibrate", _interrupt)
    out = tmp_path / "p.nc"
    for suffix in existing:
        (tmp_path / f"p.nc.chain.h5{suffix}").write_bytes(b"x")
    assert main(["calibrate", f"{d}/m.npz", "--class", "HELI", "--out", str(out)]) == 130
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.startswith("mdaug calibrate: interrupted; ")
    assert says in line and never not in line, line


def test_undefined_precision_reads_as_a_dash():
    from mdaug.classify.metrics import evaluate, format_metrics

    text = format_metrics(evaluate(np.array(["HELI", "QUAD"] * 5), np.array(["QUAD"] * 10), n_boot=20))
    heli = next(ln for ln in text.splitlines() if ln.strip().startswith("HELI n="))
    assert heli.endswith("precision      –") and "0.0%" not in heli.split("precision")[1]
    assert "undefined" in text


def test_baseline_says_what_it_trained_on(d, tmp_path, capsys):
    from mdaug.cli import main

    assert main(["baseline", f"{d}/m.npz", "--n-per-class", "12", "--epochs", "1", "--out",
                 str(tmp_path / "b.zip"), "--allow-degenerate"]) == 0  # one epoch: a toy model
    out = capsys.readouterr().out
    assert "on 24 tsaug-augmented profiles (12 per class) made from the 20 measured profiles" in out
    assert "all 20 profiles" not in out


def test_sweep_says_its_pick_peeks_and_chooses_on_a_selection_set(d, tmp_path, capsys):
    from mdaug.cli import main

    assert main(["sweep", "--test", f"{d}/m.npz", "--sigma-p", "0,0.3", "--models", "nb", "--n-per-class", "10",
                 "--n-boot", "0", "--out", str(tmp_path / "sw")]) == 0
    out = capsys.readouterr().out
    assert "picked on each test set itself" in out and "peeks" in out and "selection set" in out
    assert "peeks" in (tmp_path / "sw" / "sweep.md").read_text()
    assert "chosen on the selection set" not in out
    assert main(["sweep", "--test", f"{d}/m.npz", "--select", f"{d}/param_row.npz", "--sigma-p", "0,0.3", "--models",
                 "nb", "--n-per-class", "10", "--n-boot", "0", "--out", str(tmp_path / "sw2")]) == 2  # a bad file
    capsys.readouterr()
    atomic_savez(tmp_path / "sel.npz", profiles=_profiles(), labels=LABELS)
    assert main(["sweep", "--test", f"{d}/m.npz", "--select", str(tmp_path / "sel.npz"), "--sigma-p", "0,0.3",
                 "--models", "nb", "--n-per-class", "10", "--n-boot", "0", "--out", str(tmp_path / "sw3")]) == 0
    out = capsys.readouterr().out
    table = out[out.index("chosen on the selection set"):]
    row = next(ln for ln in table.splitlines() if ln.startswith("| nb |"))
    import json as _json

    rows = [r for r in (tmp_path / "sw3" / "sweep.csv").read_text().splitlines()[1:]]
    assert "sel.npz" in table and len(rows) == 2 * 2  # two sigma_P x (the test set + the selection set)
    settings = _json.loads((tmp_path / "sw3" / "settings.json").read_text())
    assert settings["select_file"].endswith("sel.npz")
    assert row.count("|") == 5
    import csv as _csv

    sel = [r for r in _csv.DictReader((tmp_path / "sw3" / "sweep.csv").open()) if r["test_set"] == "select"]
    best = max(sel, key=lambda r: (float(r["balanced_accuracy"]), -float(r["sigma_p"])))
    assert row.split("|")[2].strip() == f"{float(best['sigma_p']):.2f}"  # the pick is the selection set's best


def test_calibrate_summary_has_units(tiny_posterior):
    from mdaug.inference.result.posterior import CalibrationResult

    report = CalibrationResult.load(tiny_posterior).report()
    rows = {ln.split()[0]: ln.split()[1] for ln in report.splitlines() if ln[:1].isalpha() and "[0]" in ln.split()[0]}
    assert rows["A_a[0]"] == "m" and rows["w_a[0]"] == "rad/s" and rows["C_p[0]"] == "ratio"
    assert any(ln.split()[:2] == ["offset@0", "bins"] for ln in report.splitlines())


def test_augment_through_the_chain_draws_a_bar_on_a_terminal(tmp_path, monkeypatch, capsys):
    import io
    import sys

    from mdaug.cli import main

    class TTY(io.StringIO):
        def isatty(self):
            return True

    import tqdm

    calls, update = [], tqdm.tqdm.update

    def counted(self, n=1):
        calls.append(n)
        return update(self, n)

    monkeypatch.setattr(tqdm.tqdm, "update", counted)
    tty = TTY()
    monkeypatch.setattr(sys, "stderr", tty)
    monkeypatch.delenv("MDAUG_QUIET", raising=False)
    assert main(["augment", "--classes", "HELI", "--n-per-class", "300", "--through-chain", "--acquisition",
                 "measured", "--ramps", "1", "--allow-one-class", "--out", str(tmp_path / "c.npz")]) == 0
    text = tty.getvalue()
    assert "HELI profiles" in text and "/300" in text
    assert sum(calls) == 300 and len([c for c in calls if c]) > 2, calls  # it moves block by block, not at the end
