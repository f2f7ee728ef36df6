"""The newer doors checked like the old ones (issue 31), one table: names in a study
config are labels, not paths; population files read through the checked NPZ reader;
sizes read from files and configs bounded like the options' sizes. Every case ends
with exit status 2 and ONE line naming the file or field, no traceback, no input
changed (hashed), nothing written anywhere under the test's folder: not in the output
folder, not beside it (a name like ``../../m`` must not reach the inputs).

Then the name rule itself (the study's folder and the population reuse key:
test_study_folder.py)."""
import json

import numpy as np
import pytest

from mdaug.radar import atomic_savez

LABELS = np.array(["HELI"] * 10 + ["QUAD"] * 10)


def _profiles(n=20):
    x = np.abs(np.random.default_rng(0).normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    return x


def _population():
    """A population file's arrays and meta of the right layout (values need not mean
    anything: only the reader is tested)."""
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
            "acquisition": Acquisition.measured(4).to_dict(), "drones_converged": [True, True],
            "identified": [[True] * model.p] * 2,
            "diagnostics": {"tau": [1.0], "steps": 10, "converged": True, "acceptance": 0.3}}
    arrays = {"spreads": np.abs(rng.normal(0.05, 0.01, (40, len(SPREADS)))),
              "mu": np.tile(model.transform(x0[None]), (40, 1)), "measured": np.ones(model.p, bool),
              "pool": np.tile(x0, (6, 1)), "pool_drone": np.repeat([0, 1], 3),
              "drone_means": np.tile(model.transform(x0[None]), (2, 1)), "reference": x0}
    return arrays, meta


def _save_population(path, edit=None, edit_meta=None):
    arrays, meta = _population()
    if edit_meta:
        edit_meta(meta)
    if edit:
        edit(arrays)
    atomic_savez(path, meta=np.array(json.dumps(meta)), **arrays)


def _drop(d, key):
    d.pop(key)


def _config(d, name, test=None, extra=""):
    """A study config on d/m.npz with test sets ``test`` ({name: file})."""
    test = test or {"new": "m.npz"}
    sets = ", ".join(f'"{k}" = "{v}"' for k, v in test.items())
    (d / name).write_text(f'[data]\ncalibration = {{ HELI = "m.npz", QUAD = "m.npz" }}\ntest = {{ {sets} }}\n'
                          + extra)


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """root/in: the inputs (profiles, configs, population files); each case writes in root/out_<case>."""
    root = tmp_path_factory.mktemp("doors")
    d = root / "in"
    d.mkdir()
    x = _profiles()
    atomic_savez(d / "m.npz", profiles=x, labels=LABELS)
    # ---- names in a config: traversal, absolute paths, the study's own sets ----
    for name, test in {"dotdot": "../../in/m", "slash": "a/b", "abs": "/tmp/x", "dot": ".hidden",
                       "dots": "a..b", "space": "a b", "empty": "", "device": "NUL", "long": "x" * 65,
                       "select": "select", "calibration": "calibration", "calib_cls": "calibration_HELI",
                       "calib_case": "Calibration_QUAD", "select_case": "SELECT", "backslash": "a\\\\b",
                       "colon": "c:x", "tilde": "~root", "newline": "a\\nb"}.items():
        _config(d, f"name_{name}.toml", {test: "m.npz"})
    _config(d, "name_twice.toml", {"new": "m.npz", "NEW": "m.npz"})
    (d / "class_path.toml").write_text('classes = ["../HELI"]\n')
    (d / "calib_key.toml").write_text('[data]\ncalibration = { "../HELI" = "m.npz", QUAD = "m.npz" }\n'
                                      'test = { new = "m.npz" }\n')
    (d / "select_key.toml").write_text('[data]\ncalibration = { HELI = "m.npz", QUAD = "m.npz" }\n'
                                       'select = { "/HELI" = "m.npz", QUAD = "m.npz" }\ntest = { new = "m.npz" }\n')
    _config(d, "name_trailing_dot.toml", {"new.": "m.npz"})
    # ---- drone ids (field 'specimen') become file names of the drones' posteriors ----
    atomic_savez(d / "spec_path.npz", profiles=x, labels=LABELS, specimen=np.array(["../../in/m"] * 20))
    atomic_savez(d / "spec_dot.npz", profiles=x, labels=LABELS, specimen=np.array([".x"] * 20))
    atomic_savez(d / "spec_case.npz", profiles=x, labels=LABELS, specimen=np.array(["a", "A"] * 10))
    # ---- sizes read from files and configs ----
    atomic_savez(d / "k_inf.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(np.inf))
    atomic_savez(d / "k_nan.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(np.nan))
    atomic_savez(d / "k_text.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(["4"]))
    atomic_savez(d / "k_big.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(10 ** 9))
    atomic_savez(d / "k_acq_inf.npz", profiles=x, labels=LABELS, acquisition=np.array('{"ramps": Infinity}'))
    atomic_savez(d / "k_acq_null.npz", profiles=x, labels=LABELS, acquisition=np.array('{"ramps": null}'))
    _config(d, "k_big.toml", {"new": "k_big.npz"})
    atomic_savez(d / "k4.npz", profiles=x, labels=LABELS, ramps_per_frame=np.array(4))
    _config(d, "k4.toml", {"new": "k4.npz"})
    (d / "k8.toml").write_text("ramps = 8\n" + (d / "k4.toml").read_text())
    _config(d, "k_inf.toml", {"new": "k_inf.npz"})
    big = 10 ** 12
    for name, text in {"ceiling": f"[simulation]\nceiling_per_class = {big}\n",
                       "drones": f"[simulation]\ncalibration_drones = {big}\n",
                       "n_new": f"[simulation]\nn_new = {{ HELI = {big}, QUAD = 5 }}\n",
                       "sim_ramps": f"ramps = {big}\n",
                       "specimens": f"[simulation]\nnew_specimens = {big}\n",
                       "cnn_n": f"[protocol]\ncnn_n_per_class = {big}\n",
                       "epochs": f"[protocol]\ncnn_epochs = {big}\n",
                       "n_boot": f"[protocol]\nn_boot = {big}\n",
                       "steps": f"[protocol.calibration]\nmax_steps = {big}\n",
                       "sweep": f"[protocol]\nsweep_n_per_class = {big}\n"}.items():
        (d / f"size_{name}.toml").write_text(text)
    _config(d, "size_measured_steps.toml", extra=f"[protocol.calibration]\nmax_steps = {big}\n")
    # ---- population files ----
    _save_population(d / "pop.npz")
    _save_population(d / "pop_no_mu.npz", edit=lambda a: _drop(a, "mu"))
    _save_population(d / "pop_no_diag.npz", edit_meta=lambda m: _drop(m, "diagnostics"))
    _save_population(d / "pop_no_tau.npz", edit_meta=lambda m: _drop(m["diagnostics"], "tau"))
    _save_population(d / "pop_no_hyper.npz", edit_meta=lambda m: _drop(m["hyperprior"], "gamma"))
    _save_population(d / "pop_engines.npz", edit_meta=lambda m: m.update(n_engines=10 ** 9))
    _save_population(d / "pop_engines_float.npz", edit_meta=lambda m: m.update(n_engines=1.5))
    _save_population(d / "pop_priors.npz", edit_meta=lambda m: m.update(priors={"bounds": 3}))
    _save_population(d / "pop_acq.npz", edit_meta=lambda m: m["acquisition"].update(ramps=float("inf")))
    _save_population(d / "pop_mu_shape.npz", edit=lambda a: a.update(mu=a["mu"][:, :-1]))
    _save_population(d / "pop_mu_draws.npz", edit=lambda a: a.update(mu=a["mu"][:-1]))
    _save_population(d / "pop_spreads_text.npz", edit=lambda a: a.update(spreads=np.array(["x"] * 5)))
    _save_population(d / "pop_spreads_nan.npz", edit=lambda a: a["spreads"].__setitem__((0, 0), np.nan))
    _save_population(d / "pop_spreads_empty.npz", edit=lambda a: a.update(spreads=a["spreads"][:0],
                                                                          mu=a["mu"][:0]))
    _save_population(d / "pop_drone_index.npz", edit=lambda a: a.update(pool_drone=np.array([0, 1, 2, 3, 4, 5])))
    _save_population(d / "pop_meta_array.npz", edit_meta=None,
                     edit=lambda a: a.update(reference=a["reference"][None]))
    raw = (d / "pop.npz").read_bytes()
    (d / "pop_cut.npz").write_bytes(raw[: len(raw) // 2])
    (d / "pop_cut_end.npz").write_bytes(raw[:-30])
    np.savez(d / "pop_pickled.npz", meta=np.array([{"a": 1}], dtype=object))
    return root


AUG = ["augment", "--n-per-class", "5", "--out", "{o}/x.npz", "--population"]


def _run(name):
    return ["run", "--config", "{d}/" + name, "--out", "{o}/study"]


RULE = "expected a name of 1 to 64 letters, digits"
# (case id, argv, substrings the one line must contain)
CASES = [
    # ---- names in a study config are labels, not paths ----
    ("name-dotdot", _run("name_dotdot.toml"), ["name_dotdot.toml: [data] test set name = '../../in/m'",
                                                "path separator", RULE]),
    ("name-slash", _run("name_slash.toml"), ["[data] test set name = 'a/b'", "path separator"]),
    ("name-absolute", _run("name_abs.toml"), ["[data] test set name = '/tmp/x'", "path separator"]),
    ("name-backslash", _run("name_backslash.toml"), ["[data] test set name", "path separator"]),
    ("name-leading-dot", _run("name_dot.toml"), ["[data] test set name = '.hidden'", "starts with a dot"]),
    ("name-dotdot-inside", _run("name_dots.toml"), ["[data] test set name = 'a..b'", "'..'"]),
    ("name-space", _run("name_space.toml"), ["[data] test set name = 'a b'", "holds ' '"]),
    ("name-colon", _run("name_colon.toml"), ["[data] test set name = 'c:x'", "holds ':'"]),
    ("name-tilde", _run("name_tilde.toml"), ["[data] test set name = '~root'"]),
    ("name-newline", _run("name_newline.toml"), ["[data] test set name = 'a\\nb'"]),
    ("name-empty", _run("name_empty.toml"), ["[data] test set name = ''", "empty"]),
    ("name-device", _run("name_device.toml"), ["[data] test set name = 'NUL'", "device name"]),
    ("name-long", _run("name_long.toml"), ["[data] test set name", "65 characters"]),
    ("name-is-select", _run("name_select.toml"), ["[data] test set name = 'select'", "reserved"]),
    ("name-is-select-case", _run("name_select_case.toml"), ["[data] test set name = 'SELECT'", "'select'"]),
    ("name-is-calibration", _run("name_calibration.toml"), ["[data] test set name = 'calibration'", "reserved"]),
    ("name-is-calibration-file", _run("name_calib_cls.toml"), ["test set name = 'calibration_HELI'", "reserved"]),
    ("name-calibration-prefix", _run("name_calib_case.toml"), ["test set name = 'Calibration_QUAD'"]),
    ("name-twice-by-case", _run("name_twice.toml"), ["[data] test set names", "'new' and 'NEW' differ only in case"]),
    ("name-class-path", _run("class_path.toml"), ["class_path.toml: classes[0] = '../HELI'", "path separator"]),
    ("name-calibration-key", _run("calib_key.toml"), ["calib_key.toml: [data] calibration class name = '../HELI'"]),
    ("name-select-key", _run("select_key.toml"), ["select_key.toml: [data] select class name = '/HELI'"]),
    ("name-trailing-dot", _run("name_trailing_dot.toml"), ["[data] test set name = 'new.'", "ends with a dot"]),
    ("drone-id-path", ["calibrate", "{d}/spec_path.npz", "--class", "HELI", "--population", "--engines", "1",
                       "--out", "{o}/p.npz"], ["spec_path.npz: field 'specimen' drone id = '../../in/m'"]),
    ("drone-id-dot", ["calibrate", "{d}/spec_dot.npz", "--class", "HELI", "--population", "--engines", "1",
                      "--out", "{o}/p.npz"], ["spec_dot.npz: field 'specimen' drone id = '.x'", "dot"]),
    ("drone-id-case", ["calibrate", "{d}/spec_case.npz", "--class", "HELI", "--population", "--engines", "1",
                       "--out", "{o}/p.npz"], ["spec_case.npz: field 'specimen'", "differ only in case"]),
    # ---- sizes in files and configs: refused by name before any work, like the options' sizes ----
    ("k-inf", ["calibrate", "{d}/k_inf.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k_inf.npz: field 'ramps_per_frame' must be one integer >= 1", "got inf"]),
    ("k-nan", ["calibrate", "{d}/k_nan.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k_nan.npz: field 'ramps_per_frame'", "got nan"]),
    ("k-text", ["calibrate", "{d}/k_text.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k_text.npz: field 'ramps_per_frame'"]),
    ("k-acquisition-inf", ["calibrate", "{d}/k_acq_inf.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k_acq_inf.npz: field 'acquisition'"]),
    ("k-acquisition-null", ["calibrate", "{d}/k_acq_null.npz", "--class", "HELI", "--out", "{o}/p.nc"],
     ["k_acq_null.npz: field 'acquisition'"]),
    ("k-inf-study", _run("k_inf.toml"), ["k_inf.npz: field 'ramps_per_frame'"]),
    ("k-file-against-config", _run("k8.toml"), ["k4.npz says 4 ramp(s) per frame but", "k8.toml: ramps (or --ramps) "
                                                "says 8"]),
    ("k-file-against-option", [*_run("k4.toml"), "--ramps", "8"], ["k4.npz says 4 ramp(s) per frame but",
                                                                   "k4.toml: ramps (or --ramps) says 8"]),
    ("k-huge-study", _run("k_big.toml"), ["k_big.npz: field 'ramps_per_frame' = 1000000000", "max_ramps_per_frame"]),
    ("size-ceiling", _run("size_ceiling.toml"), ["size_ceiling.toml: [simulation] ceiling_per_class "
                                                 "1,000,000,000,000"]),
    ("size-drones", _run("size_drones.toml"), ["size_drones.toml: [simulation] calibration_drones"]),
    ("size-n-new", _run("size_n_new.toml"), ["size_n_new.toml: [simulation] n_new.HELI 1,000,000,000,000"]),
    ("size-ramps", _run("size_sim_ramps.toml"), ["size_sim_ramps.toml: ramps = 1000000000000", "max_ramps_per_frame"]),
    ("size-specimens", _run("size_specimens.toml"), ["size_specimens.toml: [simulation] new_specimens"]),
    ("size-cnn-n", _run("size_cnn_n.toml"), ["size_cnn_n.toml: [protocol] cnn_n_per_class 1,000,000,000,000"]),
    ("size-epochs", _run("size_epochs.toml"), ["size_epochs.toml: [protocol] cnn_epochs 1,000,000,000,000"]),
    ("size-n-boot", _run("size_n_boot.toml"), ["size_n_boot.toml: [protocol] n_boot 1,000,000,000,000"]),
    ("size-steps", _run("size_steps.toml"), ["size_steps.toml: [protocol.calibration] max_steps"]),
    ("size-sweep", _run("size_sweep.toml"), ["size_sweep.toml: [protocol] sweep_n_per_class"]),
    ("size-steps-measured", _run("size_measured_steps.toml"), ["size_measured_steps.toml: "
                                                               "[protocol.calibration] max_steps"]),
    # ---- population files: the checked NPZ reader ----
    ("pop-missing-field", [*AUG, "HELI={d}/pop_no_mu.npz"], ["pop_no_mu.npz: not a population file", "'mu'"]),
    ("pop-no-diagnostics", [*AUG, "HELI={d}/pop_no_diag.npz"], ["pop_no_diag.npz: field 'meta' lacks",
                                                                "'diagnostics'"]),
    ("pop-no-tau", [*AUG, "HELI={d}/pop_no_tau.npz"], ["pop_no_tau.npz: field 'meta' key 'diagnostics'"]),
    ("pop-no-hyperprior", [*AUG, "HELI={d}/pop_no_hyper.npz"], ["pop_no_hyper.npz: field 'meta' key 'hyperprior'"]),
    ("pop-engines-huge", [*AUG, "HELI={d}/pop_engines.npz"], ["pop_engines.npz: field 'meta' key 'n_engines'"]),
    ("pop-engines-float", [*AUG, "HELI={d}/pop_engines_float.npz"], ["pop_engines_float.npz: field 'meta' key "
                                                                      "'n_engines'"]),
    ("pop-priors", [*AUG, "HELI={d}/pop_priors.npz"], ["pop_priors.npz: field 'meta' key 'priors'"]),
    ("pop-acquisition-inf", [*AUG, "HELI={d}/pop_acq.npz"], ["pop_acq.npz: field 'meta' key 'acquisition'"]),
    ("pop-mu-shape", [*AUG, "HELI={d}/pop_mu_shape.npz"], ["pop_mu_shape.npz: field 'mu' has shape"]),
    ("pop-mu-draws", [*AUG, "HELI={d}/pop_mu_draws.npz"], ["pop_mu_draws.npz: field 'mu' has shape (39,",
                                                           "as its 'draws'"]),
    ("pop-spreads-text", [*AUG, "HELI={d}/pop_spreads_text.npz"], ["pop_spreads_text.npz: field 'spreads' has dtype"]),
    ("pop-spreads-nan", [*AUG, "HELI={d}/pop_spreads_nan.npz"], ["pop_spreads_nan.npz: field 'spreads' holds NaN"]),
    ("pop-spreads-empty", [*AUG, "HELI={d}/pop_spreads_empty.npz"], ["pop_spreads_empty.npz: field 'spreads' "
                                                                      "holds no draws"]),
    ("pop-drone-index", [*AUG, "HELI={d}/pop_drone_index.npz"], ["pop_drone_index.npz: field 'pool_drone'"]),
    ("pop-reference-rank", [*AUG, "HELI={d}/pop_meta_array.npz"], ["pop_meta_array.npz: field 'reference' has "
                                                                   "shape (1, 13)"]),
    ("pop-cut-short", [*AUG, "HELI={d}/pop_cut.npz"], ["pop_cut.npz: not a readable NPZ file"]),
    ("pop-cut-end", [*AUG, "HELI={d}/pop_cut_end.npz"], ["pop_cut_end.npz"]),
    ("pop-pickled", [*AUG, "HELI={d}/pop_pickled.npz"], ["pop_pickled.npz: field 'meta' holds Python objects"]),
    ("pop-not-found", [*AUG, "HELI={d}/nowhere.npz"], ["nowhere.npz: population file not found"]),
    ("pop-is-profiles", [*AUG, "HELI={d}/m.npz"], ["m.npz: not a population file, missing field(s)"]),
]


def test_the_table_is_large_and_ids_unique():
    assert len(CASES) >= 60
    assert len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_refused(case, root, refused):
    name, argv, must = case
    d, out = root / "in", root / f"out_{name}"
    out.mkdir()
    # the whole root is the "input": nothing may be written anywhere under it, not even beside out/
    refused([a.format(d=d, o=out) for a in argv], root, out, [m.format(d=d, o=out) for m in must], seconds=10)


def test_the_good_population_still_loads(root):
    from mdaug.inference.population.result import PopulationResult

    pop = PopulationResult.load(root / "in" / "pop.npz", class_name="HELI")
    assert pop.n_drones == 2 and pop.draw_drones(3, 0).shape == (3, 13)


def test_the_name_rule():
    from mdaug.radar.names import check_name, name_problem

    for good in ("new", "new_large", "HELI", "drone-3", "0", "a.b", "_x"):
        assert name_problem(good) is None, good
    for bad in ("..", "../x", "a/b", "/abs", ".x", "x.", "a..b", "", "x" * 65, "con", "Con.npz", "é", "a\x00b"):
        assert name_problem(bad) is not None, bad
    assert "reserved" in name_problem("Select", reserved=("select",))
    assert "prefix" in name_problem("calibration_x", prefixes=("calibration_",))
    with pytest.raises(ValueError, match=r"f.toml: \[data\] test set name = '\.\./x'"):
        check_name("../x", "f.toml: [data] test set name")
