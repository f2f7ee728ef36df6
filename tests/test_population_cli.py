"""The population from the command line: drones in a file, calibrate --population,
augment --population, and the errors that name file and field."""
import json

import numpy as np
import pytest

from mdaug.cli import main
from mdaug.inference.population.result import PopulationResult

FAST = ["--method", "likelihood", "--sampler", "laplace", "--starts", "1", "--fit-budget", "60", "--particles", "200", "--allow-unconverged"]


@pytest.fixture(scope="module")
def drones(tmp_path_factory):
    d = tmp_path_factory.mktemp("drones")
    assert main(["simulate", "--class", "HELI", "--specimens", "2", "--acquisitions", "4", "--ramps", "4",
                 "--seed", "2", "--out", str(d / "d.npz")]) == 0
    return d


@pytest.mark.slow
def test_calibrate_population_keeps_each_drone_and_reuses_it(drones, capsys):
    out = drones / "pop.npz"
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--population", *FAST,
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "population of HELI: 2 drone(s) (0, 1)" in text
    pop = PopulationResult.load(out, class_name="HELI")
    assert pop.n_drones == 2 and not pop.assumed
    from mdaug.inference.result.posterior import CalibrationResult
    assert CalibrationResult.load(drones / "pop.npz.drone-1.nc").specimens == ["1"]
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--population", *FAST,
                 "--out", str(out), "--overwrite"]) == 0  # the population file is replaced; the drones reused
    again = capsys.readouterr().out
    assert "drone 0: reused" in again and "drone 1: reused" in again and "calibrating from" not in again

    aug = drones / "set.npz"
    assert main(["augment", "--population", f"HELI={out}", "--n-per-class", "50", "--allow-one-class",
                 "--out", str(aug)]) == 0
    with np.load(aug, allow_pickle=False) as z:
        assert z["profiles"].shape == (50, 400)
        settings = json.loads(str(z["settings"]))
    assert settings["strategy"] == "population" and settings["posteriors"] == {"HELI": str(out)}


def test_population_from_the_trained_estimator_by_default(drones, capsys):
    """--population on measured (K = 4) acquisitions: each drone's posterior is the shipped
    estimator's, by the route its file names (HELI K = 4: the smc route on its summary
    likelihood, seconds, no chain), the population is built on them, a rerun reuses them."""
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import shipped_path

    route = AmortizedEstimator.load(shipped_path("HELI", 4)).default_route
    out = drones / "pop_amortized.npz"
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--population", "--seed", "4",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "population of HELI: 2 drone(s) (0, 1)" in text
    from mdaug.inference.result.posterior import CalibrationResult
    drone = CalibrationResult.load(drones / "pop_amortized.npz.drone-0.nc")
    assert route == "smc" and drone.amortized and drone.specimens == ["0"] and drone.diagnostics["sampler"] == route
    pop = PopulationResult.load(out, class_name="HELI")
    assert pop.n_drones == 2 and pop.spreads().shape[1] == 5 and np.all(pop.spreads() > 0)
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--population", "--seed", "4",
                 "--out", str(out)]) == 2  # no silent overwrite of the population file
    assert "--out: the file exists" in capsys.readouterr().err
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--population", "--seed", "4",
                 "--out", str(out), "--overwrite"]) == 0  # the population file is replaced; the drones reused
    again = capsys.readouterr().out
    assert "drone 0: reused" in again and "drone 1: reused" in again


@pytest.mark.slow
def test_one_drone_is_calibrated_alone_with_specimen(drones, capsys):
    out = drones / "one.nc"
    assert main(["calibrate", str(drones / "d.npz"), "--class", "HELI", "--specimen", "1", *FAST,
                 "--out", str(out)]) == 0
    assert "calibrating HELI from 2 profile(s)" in capsys.readouterr().out
    from mdaug.inference.result.posterior import CalibrationResult
    assert CalibrationResult.load(out).specimens == ["1"]


@pytest.mark.parametrize("argv, says", [
    (["calibrate", "{d}/d.npz", "--class", "HELI", "--specimen", "7", "--out", "{d}/x.nc"],
     "d.npz: field 'specimen' holds no drone '7' of class HELI (drones present: ['0', '1'])"),
    (["calibrate", "{d}/d.npz", "--class", "HELI", "--population", "--out", "{d}/x.nc"],
     "--out"),
    (["calibrate", "{d}/d.npz", "--class", "HELI", "--population", "--corner", "{d}/c.png", "--out", "{d}/p.npz"],
     "--corner, --trace, --backend and --specimen apply to one drone's calibration, not to --population"),
    (["augment", "--population", "HELI={d}/d.npz", "--out", "{d}/y.npz"],
     "d.npz: not a population file, missing field(s)"),
])
def test_bad_population_inputs_name_the_file_and_field(drones, argv, says, capsys):
    assert main([a.format(d=drones) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err
