"""augment's doors for issue 39, item 3: a one-class set is refused unless asked for
(``--allow-one-class``), and a calibrated class mixes with the other class's reference
(``--posterior HELI=post.nc --classes QUAD``), both rendered under the calibration's
acquisition."""
import json
import shutil

import numpy as np
import pytest

from mdaug.cli import main


@pytest.fixture(scope="module")
def d(tmp_path_factory, tiny_posterior):
    d = tmp_path_factory.mktemp("mix_inputs")
    shutil.copy(tiny_posterior, d / "post.nc")
    return d


# (case id, argv, substrings of the one error line)
REFUSED = [
    ("posterior-alone", ["--posterior", "HELI={d}/post.nc"],
     ["--posterior HELI={d}/post.nc: the set would hold one class only (HELI)", "--classes QUAD",
      "--allow-one-class"]),
    ("fit-alone", ["--fit", "HELI={d}/post.nc"], ["--fit HELI={d}/post.nc: the set would hold one class only"]),
    ("one-reference", ["--classes", "QUAD"],
     ["--classes QUAD: the set would hold one class only (QUAD)", "--posterior HELI=FILE", "--allow-one-class"]),
    ("class-given-twice", ["--posterior", "HELI={d}/post.nc", "--classes", "HELI,QUAD"],
     ["--classes HELI,QUAD names HELI, which --fit/--posterior/--population already give: one source per class"]),
]


@pytest.mark.parametrize("case", REFUSED, ids=[c[0] for c in REFUSED])
def test_a_one_class_set_is_refused(case, d, tmp_path, refused):
    _, args, must = case
    out = tmp_path / "out"
    out.mkdir()
    refused(["augment", "--n-per-class", "5", "--out", str(out / "a.npz"), *[a.format(d=d) for a in args]],
            d, out, [m.format(d=d) for m in must], seconds=20)


def test_allow_one_class_writes_it(d, tmp_path, capsys):
    out = tmp_path / "a.npz"
    assert main(["augment", "--posterior", f"HELI={d}/post.nc", "--n-per-class", "5", "--allow-one-class",
                 "--out", str(out)]) == 0
    with np.load(out) as z:
        assert set(z["labels"].tolist()) == {"HELI"}


def test_a_calibrated_class_mixes_with_the_other_reference(d, tmp_path, capsys):
    out = tmp_path / "mix.npz"
    assert main(["augment", "--posterior", f"HELI={d}/post.nc", "--classes", "QUAD", "--sigma-p", "0.1",
                 "--n-per-class", "6", "--seed", "3", "--out", str(out)]) == 0
    assert "HELI, QUAD" in capsys.readouterr().out
    with np.load(out) as z:
        labels = z["labels"].astype(str)
        settings = json.loads(str(z["settings"]))
        profiles = z["profiles"]
    assert (labels == "HELI").sum() == 6 and (labels == "QUAD").sum() == 6
    assert np.all(np.isfinite(profiles)) and np.all(profiles.max(axis=1) > 0)
    assert settings["posteriors"] == {"HELI": f"{d}/post.nc"} and settings["references"] == ["QUAD"]
    assert settings["strategy"] == "posterior+sigma_p"
    # one acquisition for the whole set: the calibration's (a classifier cannot tell the classes by it)
    per_class = settings["per_class"]
    assert per_class["QUAD"]["source"] == "sigma_p" and per_class["HELI"]["source"] == "posterior"
    assert per_class["QUAD"]["acquisition"] == per_class["HELI"]["acquisition"]
    assert settings["acquisition_from"] == "calibration"
