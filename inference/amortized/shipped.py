"""The estimators that ship with mdaug, and the settings they were trained with.

``data/<class>-k<K>.zip`` for the embedded radar, both classes, K = 1 (single
chirp), 4 (the quick study) and 32 (the default study), trained by
``tests/benchmarks/estimators.py`` (the README's calibration page gives the command
and the figures); QUAD at K = 32 then refined on 106,000 drones from those weights
(``train-estimator --start-from``; its meta's ``made_by`` says how). :func:`find` returns the one for a class and acquisition, or
refuses by name with the command that trains it.
"""
from __future__ import annotations

from pathlib import Path

from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from .estimator import AmortizedEstimator, EstimatorError, train_command
from .nets import NetConfig
from .simulate import SimulationSpec
from .train import TrainConfig

DATA = Path(__file__).with_name("data")


def default_nets(class_name: str) -> NetConfig:
    """Network sizes: QUAD (35 label-free quantities) gets a wider set embedding and flow
    (the per-profile CNN, which sets the training cost, is the same)."""
    if class_name.upper() == "QUAD":
        return NetConfig(set_out=96, flow_hidden=96, ratio_hidden=160)
    return NetConfig()


def default_training() -> TrainConfig:
    return TrainConfig(batch=128, lr=5e-4, patience=10, max_epochs=300)


def shipped_path(class_name: str, ramps: int) -> Path:
    return DATA / f"{class_name.lower()}-k{int(ramps)}.zip"


def available() -> list[str]:
    return sorted(p.stem for p in DATA.glob("*.zip"))


def find(class_name: str, acquisition: Acquisition, radar: RadarConfig = RadarConfig(), *, path=None,
         device: str = "cpu") -> AmortizedEstimator:
    """The estimator for this class and acquisition: ``path`` when given, else the
    shipped one; EstimatorError (naming the class, K and the command that trains
    one) when there is none or it does not match."""
    if path is None:
        path = shipped_path(class_name, acquisition.ramps)
        if not path.is_file():
            spec = SimulationSpec(class_name, acquisition, 10, radar)
            have = ", ".join(available()) or "none"
            raise EstimatorError(f"no shipped estimator for class {class_name} at K = {acquisition.ramps} "
                                 f"(ramps_per_frame; shipped: {have}); train one with: {train_command(spec)}")
    est = AmortizedEstimator.load(path, device=device)
    if est.class_name != class_name:
        raise EstimatorError(f"{path}: meta.json field 'spec.class_name' is {est.class_name!r}; the data are of "
                             f"class {class_name!r}")
    return est
