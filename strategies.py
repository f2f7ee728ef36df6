"""The strategy registry: one table (:data:`STRATEGIES`) from a training-set strategy's
name to how it makes its training set, used by the study (:mod:`mdaug.reports.jobs`),
``mdaug augment`` and ``mdaug sweep``'s synthetic sets. One set of names:

* ``sigma_p_published``: the published method, sigma_P around the packaged class
  reference (its phases perturbed too: the published relative treatment), under the
  published single chirp unless an acquisition is given;
* ``sigma_p_fit``: sigma_P around the calibrated best fit (phases NOT perturbed: the
  acquisition randomises them), under the calibration's measured acquisition;
* ``posterior``: draws from the calibrated posterior, same acquisition;
* ``posterior_specimens``: posterior draws widened by the specimen model (its setting
  ``width``; width 0 = the posterior itself);
* ``population``: new drones from the class's calibrated population (a population
  file per class in ``spec.posteriors``; :mod:`mdaug.inference.population.model`);
* ``tsaug``: tsaug on the measured profiles (:mod:`mdaug.classify.tsaug_baseline`).

A strategy at one setting is a :class:`TrainingSpec` (frozen). A row of the table is
a :class:`Strategy`: a model-based one says how one class's vectors are drawn
(:meth:`Strategy.vectors`), handed to a :class:`~mdaug.generator.augment.Renderer`; a
strategy that needs a calibration file per class (``spec.posteriors``) reads it with
:meth:`Strategy.load`, and the file gives the default acquisition (its
``measured_acquisition()``). A new strategy (e.g. one that draws new drones from a
population file per class) is one more row: a small subclass whose ``vectors`` (and
``load``) say how.

Imports generator, inference and classify below it; reports and cli import it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

DRAWS_REVISION = 1
"""Raised whenever a strategy's source draws other vectors for the same settings; the
study's candidate and CNN stages are keyed on it, so a study folder made before the
change computes them again instead of resuming stale ones (its data and calibrations
are kept). 1: the posterior's draws resampled as they are (before: with a kernel jitter
of 0.1 x each parameter's posterior sd)."""

MIN_GROUPS = 5
"""A grouped 80/10/10 split needs a few source profiles per class; with fewer, the
tsaug set's groups are dropped (the validation split then holds copies of training
profiles; the report says so)."""


@dataclass(frozen=True)
class TrainingSpec:
    """One training-set strategy at one setting.

    ``sigma_p`` (sigma_P strategies), ``width`` (the specimen model: the setting of
    ``posterior_specimens``; for any other strategy, a given width widens its source),
    ``posteriors`` {class: calibration file}, ``acquisition`` (a dict; None = the
    strategy's default), ``perturb_phases`` (None = the strategy's rule),
    ``profiles``/``labels`` (tsaug's measured sources)."""

    strategy: str
    sigma_p: float | None = None
    width: float | None = None
    posteriors: dict | None = None
    normalisation: str = "peak"
    through_chain: bool | None = None
    acquisition: dict | None = None
    sign_policy: str = "reflect"
    perturb_phases: bool | None = None
    dtype: str = "float32"
    profiles: object = field(default=None, repr=False, compare=False)
    labels: object = field(default=None, repr=False, compare=False)

    TOOL_DEFAULTS = {"sign_policy": "reflect", "dtype": "float32"}

    def __post_init__(self):
        strategy(self.strategy)  # an unknown name fails here

    @property
    def setting(self):
        """The value of the strategy's setting (None: it has none)."""
        param = strategy(self.strategy).parameter
        return None if param is None else getattr(self, param)

    def to_dict(self) -> dict:
        """Plain data (the study's cache keys and results): the fields that are set,
        without the measured arrays and the tools' defaults."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if getattr(self, f.name) is not None and f.name not in ("profiles", "labels")
                and self.TOOL_DEFAULTS.get(f.name, object()) != getattr(self, f.name)}


@dataclass(frozen=True)
class Strategy:
    """One row of the registry: ``name``, ``text`` (what it assumes about new drones,
    for the report), ``parameter`` (the setting the study chooses; None: nothing to
    choose), ``calibrated`` (it needs a calibration file per class, ``spec.posteriors``,
    read by :meth:`load`; the file gives the default acquisition), ``study_chain``
    (False: the study renders it as the published single chirp, never through the
    chain), ``file_label`` (the ``strategy`` a dataset file states, as files always
    have). A model-based strategy says how one class's vectors are drawn
    (:meth:`vectors`); :meth:`augmenter` and :meth:`training_set` are shared."""

    name: str
    text: str
    parameter: str | None = None
    calibrated: bool = False
    study_chain: bool = True
    file_label: str | None = None

    @property
    def label(self) -> str:
        return self.file_label or self.name

    def vectors(self, spec: TrainingSpec, cls: str, calibration):
        """One class's source of class vectors (a :class:`~mdaug.generator.VectorSource`)."""
        raise ValueError(f"strategy {self.name!r} is not model-based: it has no augmenter per class")

    def load(self, path, cls: str):
        """A class's calibration file (a posterior NetCDF)."""
        from .inference.result.augment import load_posterior

        return load_posterior(path, cls)

    def augmenter(self, spec: TrainingSpec, cls: str, *, calibration=None, acquisition=None):
        """One class's augmenter: :meth:`vectors` (widened by the specimen model when
        ``spec.width`` asks: a strategy whose setting is the width, when it is not 0; any
        other, whenever it is given), rendered under ``acquisition`` (an Acquisition;
        None: ``spec.acquisition``, else the calibration's measured one, else the
        published chirp). ``calibration``: the class's file as :meth:`load` reads it
        (None: read from ``spec.posteriors`` when the strategy needs one)."""
        from .generator import Acquisition, ModelAugmenter, Renderer, SpecimenSource, SpecimenSpread

        if calibration is None and self.calibrated:
            calibration = self.load(spec.posteriors[cls], cls)
        src = self.vectors(spec, cls, calibration)
        if spec.width is not None and (spec.width or self.parameter != "width"):
            src = SpecimenSource(src, SpecimenSpread(width=float(spec.width)))
        if acquisition is None:
            acquisition = (Acquisition.from_dict(spec.acquisition) if spec.acquisition is not None
                           else calibration.measured_acquisition() if self.calibrated else Acquisition())
        return ModelAugmenter(src, Renderer(acquisition, spec.normalisation, spec.dtype,
                                            through_chain=bool(spec.through_chain)))

    def training_set(self, spec: TrainingSpec, classes, n_per_class: int, seed):
        """(X, y, None): :func:`mdaug.generator.make_dataset` over one augmenter per class."""
        from .generator import make_dataset

        ds = make_dataset([self.augmenter(spec, c) for c in classes], n_per_class, seed, progress=False)
        return ds.profiles, ds.labels, None


def _phases(spec: TrainingSpec, default: bool) -> bool:
    return default if spec.perturb_phases is None else bool(spec.perturb_phases)


class SigmaPAroundReference(Strategy):
    """sigma_P around the packaged class reference; its phases perturbed unless the
    spec says otherwise (the published relative treatment)."""

    def vectors(self, spec, cls, calibration):
        from .generator import SigmaPSource

        return SigmaPSource(cls, spec.sigma_p, sign_policy=spec.sign_policy, perturb_phases=_phases(spec, True))


class SigmaPAroundFit(Strategy):
    """sigma_P around the calibrated best fit; phases not perturbed unless the spec
    says so (the acquisition randomises them)."""

    def vectors(self, spec, cls, calibration):
        from .generator import SigmaPSource

        return SigmaPSource(calibration.best_fit, spec.sigma_p, sign_policy=spec.sign_policy,
                            perturb_phases=_phases(spec, False), label=cls)


class PosteriorDraws(Strategy):
    """Draws from the calibrated posterior (:class:`~mdaug.inference.PosteriorSource`)."""

    def vectors(self, spec, cls, calibration):
        from .inference.result.augment import PosteriorSource

        return PosteriorSource(calibration, label=cls)


class PopulationDraws(Strategy):
    """New drones drawn from the class's calibrated population (a population file per
    class, :class:`~mdaug.inference.population.augment.PopulationSource`)."""

    def vectors(self, spec, cls, calibration):
        from .inference.population.augment import PopulationSource

        return PopulationSource(calibration, label=cls)

    def load(self, path, cls: str):
        from .inference.population.augment import load_population

        return load_population(path, cls)


class TsaugCopies(Strategy):
    """tsaug on the measured profiles (``spec.profiles``, ``spec.labels``)."""

    def training_set(self, spec, classes, n_per_class, seed):
        """tsaug's set and its groups (each copy's source profile, so that the CNN's
        validation split never holds a copy of a profile it trains on; None below
        :data:`MIN_GROUPS` sources in a class)."""
        from .classify import tsaug_set

        X, y, sources = tsaug_set(np.asarray(spec.profiles), np.asarray(spec.labels), n_per_class, seed,
                                  normalisation=spec.normalisation)
        per_class = [np.unique(sources[y == c]).size for c in np.unique(y)]
        return X, y, (sources if min(per_class) >= MIN_GROUPS else None)


STRATEGIES = {s.name: s for s in (
    SigmaPAroundReference(
        "sigma_p_published", "the published method: sigma_P around the packaged class reference, one chirp at its "
        "phases; assumes new drones are the reference drone seen as the fit was, up to sigma_P",
        parameter="sigma_p", study_chain=False, file_label="sigma_p"),
    SigmaPAroundFit(
        "sigma_p_fit", "sigma_P around the calibrated best fit, through the measured acquisition; assumes new "
        "drones are the calibrated drone up to an unstructured relative spread sigma_P",
        parameter="sigma_p", calibrated=True),
    PosteriorDraws(
        "posterior", "draws from the calibrated posterior, through the measured acquisition; assumes new drones "
        "are the calibrated drone (only its measurement uncertainty)", calibrated=True),
    PosteriorDraws(
        "posterior_specimens", "posterior draws widened by the specimen model (common motor-speed factor, "
        "amplitude spread), through the measured acquisition; assumes new drones differ from the calibrated one "
        "as drones of one model do", parameter="width", calibrated=True),
    PopulationDraws(
        "population", "new drones drawn from the class's population (spreads across the calibrated drones; from "
        "one drone, the specimen model's stated prior), through the drones' acquisition; assumes new drones differ "
        "as the drones measured differ", calibrated=True),
    TsaugCopies(
        "tsaug", "tsaug (drift, pool, reverse) on the calibration measurements; assumes new drones look like "
        "distorted copies of the measured ones"),
)}
"""The registry: strategy name -> :class:`Strategy`, in the study's order."""


def strategy(name: str) -> Strategy:
    """The registry's row called ``name`` (ValueError naming the known ones)."""
    try:
        return STRATEGIES[name]
    except KeyError:
        raise ValueError(f"unknown training strategy {name!r}; known: {', '.join(STRATEGIES)}") from None


def augmenter(spec: TrainingSpec, cls: str, *, calibration=None, acquisition=None):
    """One class's augmenter for a model-based ``spec`` (:meth:`Strategy.augmenter`)."""
    return strategy(spec.strategy).augmenter(spec, cls, calibration=calibration, acquisition=acquisition)


def training_set(spec: TrainingSpec, classes, n_per_class: int, seed):
    """(X, y, groups) of ``spec``: the one way a strategy's set is built (model-based:
    :func:`mdaug.generator.make_dataset` over one augmenter per class; tsaug:
    :func:`mdaug.classify.tsaug_set`); groups: tsaug's source profiles, else None."""
    return strategy(spec.strategy).training_set(spec, classes, n_per_class, seed)
