"""No silent overwrite (issue 39, item 4): every verb refuses an output file that exists
already, before any work, unless it is given ``--overwrite`` (the one rule of
:func:`mdaug.cli.guard.check_paths`; the option added once, by
:func:`mdaug.cli.common.add_verb`). A refusal is exit status 2 and one line naming the
file and the option; the existing file keeps its bytes and nothing else is written."""
import shutil

import numpy as np
import pytest

from mdaug.cli import main, verbs
from mdaug.radar import atomic_savez

LABELS = np.array(["HELI", "QUAD"] * 10)
OLD = b"an older result the user wants to keep"


@pytest.fixture(scope="module")
def d(tmp_path_factory, tiny_posterior):
    d = tmp_path_factory.mktemp("overwrite_inputs")
    rng = np.random.default_rng(0)
    x = np.abs(rng.normal(0.1, 0.05, (20, 400)))
    x[:, 200] = 1.0
    x[LABELS == "QUAD", 210] = 1.0
    atomic_savez(d / "m.npz", profiles=x, labels=LABELS)
    from mdaug.classify import make_classifier, save_model

    save_model(make_classifier("nb").fit(x, LABELS), d / "nb.zip")
    np.savez(d / "raw.npz", cube=rng.normal(size=(11, 8, 504)).astype(np.float32), label="HELI")
    shutil.copy(tiny_posterior, d / "post.nc")
    return d


# (case id, argv, the existing file in the output folder {o}, the option the line names)
EXISTING = [
    ("simulate", ["simulate", "--class", "HELI", "--acquisitions", "2", "--out", "{o}/s.npz"], "s.npz", "--out"),
    ("process", ["process", "{d}/raw.npz", "--out", "{o}/p.npz"], "p.npz", "--out"),
    ("calibrate-out", ["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p.nc"], "p.nc", "--out"),
    ("calibrate-corner", ["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p2.nc", "--corner",
                          "{o}/c.png"], "c.png", "--corner"),
    ("train-estimator", ["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip"], "e.zip",
     "--out"),
    ("sbc-json", ["sbc", "--class", "HELI", "--ramps", "4", "--json", "{o}/s.json"], "s.json", "--json"),
    ("augment-out", ["augment", "--classes", "HELI", "--n-per-class", "3", "--out", "{o}/a.npz"], "a.npz", "--out"),
    ("augment-plot", ["augment", "--classes", "HELI", "--n-per-class", "3", "--out", "{o}/a2.npz", "--plot",
                      "{o}/a.png"], "a.png", "--plot"),
    ("augment-posterior", ["augment", "--posterior", "HELI={d}/post.nc", "--classes", "QUAD", "--n-per-class", "3",
                           "--out", "{o}/post.npz"], "post.npz", "--out"),
    ("train", ["train", "{d}/m.npz", "--model", "nb", "--out", "{o}/m.zip"], "m.zip", "--out"),
    ("evaluate-json", ["evaluate", "{d}/nb.zip", "{d}/m.npz", "--json", "{o}/r.json"], "r.json", "--json"),
    ("evaluate-plot", ["evaluate", "{d}/nb.zip", "{d}/m.npz", "--plot", "{o}/r.png"], "r.png", "--plot"),
    ("baseline-out-set", ["baseline", "{d}/m.npz", "--out-set", "{o}/b.npz", "--n-per-class", "4"], "b.npz",
     "--out-set"),
    ("sweep-table", ["sweep", "--test", "{d}/m.npz", "--out", "{o}", "--n-per-class", "5", "--sigma-p", "0"],
     "sweep.csv", "--out"),
]


def test_every_verb_has_overwrite_and_every_writing_verb_is_in_the_table():
    from mdaug.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "verb")
    for name in verbs():
        assert "--overwrite" in sub.choices[name].format_help(), name
    # every verb that writes a file (run: its folder resumes, its own rule) has a case
    assert {c[1][0] for c in EXISTING} == set(verbs()) - {"run"}


@pytest.mark.parametrize("case", EXISTING, ids=[c[0] for c in EXISTING])
def test_an_existing_output_is_refused_and_kept(case, d, tmp_path, refused):
    _, argv, name, option = case
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(OLD)
    line = refused([a.format(d=d, o=out) for a in argv], d, out,
                   [f"{out / name}: {option}: the file exists", "--overwrite"], seconds=10)
    assert "give --overwrite to replace it" in line
    assert (out / name).read_bytes() == OLD


def test_overwrite_replaces_it(d, tmp_path, capsys):
    out = tmp_path / "m.zip"
    out.write_bytes(OLD)
    argv = ["train", str(d / "m.npz"), "--model", "nb", "--out", str(out)]
    assert main(argv) == 2 and out.read_bytes() == OLD
    assert main(argv + ["--overwrite"]) == 0
    assert out.read_bytes() != OLD
    from mdaug.classify import load_model

    assert load_model(out).name == "nb"


def test_a_resumed_checkpoint_and_the_study_folder_are_not_refused(tmp_path):
    """Outputs a command resumes from are not 'existing outputs': the chain checkpoint,
    the study's folder (its own rule: the same study resumes, another is refused)."""
    from mdaug.cli.guard import Output, check_paths
    from mdaug.reports.identity import STUDY_FILES

    (tmp_path / "p.nc.chain.h5").write_bytes(OLD)
    (tmp_path / "study").mkdir()
    (tmp_path / "study" / "report.html").write_bytes(OLD)
    check_paths(outputs=[Output("--backend", tmp_path / "p.nc.chain.h5", "checkpoint"),
                         Output("--out", tmp_path / "study", "folder", inside=STUDY_FILES, resumes=True)])
    with pytest.raises(Exception, match="report.html: --out: the file exists"):
        check_paths(outputs=[Output("--out", tmp_path / "study", "folder", inside=STUDY_FILES)])
