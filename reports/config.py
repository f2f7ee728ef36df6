"""Study configuration: defaults for the embedded simulated scene, or a TOML file
pointing the same study at measured files. Everything is checked before any work.

Example ``study.toml``::

    seed = 3
    classes = ["HELI", "QUAD"]
    ramps = 32                  # K; for measured files, only those that do not say ramps_per_frame

    [data]                      # omit for the embedded simulated scene
    calibration = { HELI = "old_heli.npz", QUAD = "old_quad.mat" }
    select = { HELI = "more_heli.npz", QUAD = "more_quad.npz" }   # optional: held-out, for choices
    test = { new = "new.npz" }

    [protocol]
    sigma_p = [0.0, 0.1, 0.2, 0.3]
    cnn_n_per_class = 16000
    cnn_seeds = 3

    [protocol.calibration]      # CalibrationSettings under their own names
    max_steps = 800

The simulated default is a 32-ramp campaign (``ramps = 4`` or ``mdaug run --ramps 4``
gives the 4-ramp one). Keys renamed since 0.1 (``[simulation] ramps``, ``[protocol]
acquisition_ramps``, ``[protocol] calibration_*``) are refused with their new names
(:data:`RENAMED`).
"""
from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..generator import load_reference
from ..radar import NORMALISATIONS
from ..radar.names import check_distinct, check_name
from ..strategies import STRATEGIES as REGISTRY
from .validation import ConfigTypeError, check_types, convert, field_types

STRATEGIES = tuple(REGISTRY)
"""The training-set strategies compared: the names of the registry,
:data:`mdaug.strategies.STRATEGIES` (what each does and assumes is stated there)."""


@dataclass
class DataConfig:
    """Measured files (none: the embedded simulated scene). ``select``: other
    measurements of the calibration drones, held out for the study's choices
    (optional: without it the choices use the calibration measurements themselves,
    and the report says so)."""

    calibration: dict[str, str] = field(default_factory=dict)
    select: dict[str, str] = field(default_factory=dict)
    test: dict[str, str] = field(default_factory=dict)


@dataclass
class SimulationConfig:
    """The embedded default scene (used when no measured files are given)."""

    calibration_drones: int = 1     # drones per class calibrated on: 1 = the reference drone itself (the
    #                                 population's spreads then assumed); more = drones of the specimen model,
    #                                 and one more drone, held out whole, that the choices are made on
    n_calibration: int = 5          # acquisitions of each calibration drone, calibrated on
    n_select: int = 24              # more acquisitions per drone held out for the choices (the held-out
    #                                 drone: n_calibration + n_select acquisitions)
    n_new: dict[str, int] = field(default_factory=lambda: {"HELI": 44, "QUAD": 92})
    new_specimens: int = 3          # new drone specimens per class in the test campaign
    large_factor: int = 4           # a second, larger new-drone campaign for tighter intervals
    ceiling_per_class: int = 3000   # simulator-trained classifiers (separability ceiling), the CNN included


SCENE_RAMPS = 32
"""K of the simulated scene when the study does not set ``ramps``."""


@dataclass
class CalibrationProtocol:
    """``[protocol.calibration]``: how the study calibrates each class.

    ``method``: ``amortized`` (the shipped estimator), ``likelihood`` (closed form), or
    ``auto``: amortized for measured acquisitions where an estimator ships for the class
    and K. Every other key is a :class:`~mdaug.inference.settings.CalibrationSettings`
    setting under its own name (``max_steps`` is the emcee plugin's knob), with the
    settings' own ranges. The defaults differ from a lone calibration's: a step cap
    per class, so the same command gives the same numbers however busy the machine
    (the run is flagged not converged when it ends before 50 tau), and an optional
    time budget on top."""

    method: str = "auto"
    max_steps: int = 400
    time_budget: float | None = None
    n_starts: int = 2
    fit_budget: int = 1500
    n_acquisitions: int = 16
    ramps_drawn: int = 16

    def settings(self, quick: bool = False):
        """The :class:`~mdaug.inference.settings.CalibrationSettings` of the study
        (``CalibrationSettings.quick()`` based when ``quick``) with these settings; the
        emcee plugin's blocks no longer than its step cap."""
        from ..inference.settings import CalibrationSettings

        base = CalibrationSettings.quick() if quick else CalibrationSettings()
        knobs = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "method"}
        return base.replace(**knobs).with_plugin("emcee", check_every=min(base.of("emcee").check_every,
                                                                          self.max_steps))


RENAMED = {("simulation", "ramps"): "ramps (top level)", ("protocol", "acquisition_ramps"): "ramps (top level)",
           ("protocol", "calibration_method"): "method in [protocol.calibration]",
           ("protocol", "calibration_max_steps"): "max_steps in [protocol.calibration]",
           ("protocol", "calibration_time_budget"): "time_budget in [protocol.calibration]",
           ("protocol", "calibration_starts"): "n_starts in [protocol.calibration]",
           ("protocol", "calibration_fit_budget"): "fit_budget in [protocol.calibration]",
           ("protocol", "calibration_draws"): "n_acquisitions in [protocol.calibration]",
           ("protocol", "calibration_ramps_drawn"): "ramps_drawn in [protocol.calibration]"}
"""Keys of 0.1 study configs -> where they live now (the value means the same): K is one
setting, and the calibration's settings go by their own names."""


@dataclass
class ProtocolConfig:
    sigma_p: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3, 0.4)  # the published grid: protocol.PUBLISHED_SIGMA_PS
    specimen_widths: tuple[float, ...] = (0.5, 1.0, 2.0)    # x the specimen model's default spreads
    models: tuple[str, ...] = ("svm", "nb", "xgb")          # the fast classifiers that rank the choices
    sweep_n_per_class: int = 1500
    # every CNN is trained cnn_seeds times (training runs: weights, split, shuffles) on its strategy's
    # one training set of cnn_n_per_class profiles per class (tsaug: tsaug_n_per_class); the report
    # gives the mean over the runs with an interval covering them. Smaller sets or fewer epochs cost
    # more error than the runs' spread (README: 'Training runs: where they are paid for'): the runs are
    # paid with a second worker instead. The published single run: cnn_seeds = 1, cnn_n_per_class = 16000
    cnn_seeds: int = 3
    cnn_n_per_class: int = 6000     # 12,000 profiles
    cnn_epochs: int = 40
    cnn_patience: int | None = 8    # early stopping on validation loss; None trains all epochs
    cnn_precision: str = "auto"     # auto: bfloat16 autocast on CPUs with native bfloat16 (1.5x, same accuracy), else float32
    tsaug_n_per_class: int = 3000
    tsaug_epochs: int = 60
    strategies: tuple[str, ...] = STRATEGIES
    through_chain: bool = False     # render model-based training sets through the scene + radar chain
    normalisation: str = "peak"
    n_boot: int = 1000
    calibration: CalibrationProtocol = field(default_factory=CalibrationProtocol)


@dataclass
class StudyConfig:
    seed: int = 0
    classes: tuple[str, ...] = ("HELI", "QUAD")
    # K, the ramps averaged per frame (ramps_per_frame): of the simulated scene (None: SCENE_RAMPS), or, with
    # measured files, of those that do not state it (None: 1); a file stating another K is refused
    ramps: int | None = None
    quick: bool = False
    workers: int = 2                # local worker processes (the classes' calibrations, the strategies' CNNs)
    scheduler: str | None = None
    device: str = "auto"            # where the CNNs train and predict: auto (a GPU when present), cpu, cuda
    data: DataConfig = field(default_factory=DataConfig)
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    source: str = "defaults"

    @property
    def simulated(self) -> bool:
        return not self.data.test

    @property
    def scene_ramps(self) -> int:
        """K of the simulated scene."""
        return self.ramps or SCENE_RAMPS

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def quick_version(self) -> "StudyConfig":
        """Small sizes for a run of about a minute (tests, first look)."""
        p = dataclasses.replace(
            self.protocol, sigma_p=(0.0, 0.2), specimen_widths=(1.0,), models=("nb", "xgb"), sweep_n_per_class=200,
            cnn_n_per_class=600, cnn_epochs=8, cnn_patience=4, tsaug_n_per_class=300, tsaug_epochs=8, n_boot=200,
            calibration=dataclasses.replace(self.protocol.calibration, max_steps=60, n_starts=1, fit_budget=200,
                                            n_acquisitions=6, ramps_drawn=2))
        s = dataclasses.replace(self.simulation, n_calibration=3, n_select=6, n_new={c: 24 for c in self.classes},
                                new_specimens=2, large_factor=1, ceiling_per_class=80)
        return dataclasses.replace(self, quick=True, protocol=p, simulation=s,
                                   ramps=4 if self.simulated else self.ramps)

    def validate(self, check_files: bool = True) -> "StudyConfig":
        """Fail before any work: wrong types, unknown classes or names, bad sizes,
        missing or unusable data files (``check_files`` reads each one)."""
        src = self.source
        try:
            check_types(self, "")
        except ConfigTypeError as exc:
            raise ConfigTypeError(f"{src}: {exc}") from None
        if self.seed < 0:
            raise ValueError(f"{src}: seed = {self.seed}: expected an integer >= 0")
        if self.workers < 1:
            raise ValueError(f"{src}: workers = {self.workers}: expected an integer >= 1")
        from ..classify.base import DEVICES

        if self.device not in DEVICES:
            raise ValueError(f"{src}: device = {self.device!r}: expected one of {list(DEVICES)}")
        if self.scheduler is not None and not self.scheduler.strip():
            raise ValueError(f"{src}: scheduler is empty: expected an address (host:port) or 'local'")
        if not self.classes or len(set(self.classes)) != len(self.classes):
            raise ValueError(f"{src}: classes = {list(self.classes)}: expected distinct class names")
        self._check_names(src)
        for c in self.classes:
            try:
                load_reference(c)
            except ValueError as exc:
                raise ValueError(f"{src}: classes: {exc}") from None
        for group in ("calibration", "select", "test"):
            for name, path in getattr(self.data, group).items():
                if group in ("calibration", "select") and name not in self.classes:
                    raise ValueError(f"{src}: data.{group} names unknown class {name!r} "
                                     f"(classes: {list(self.classes)})")
                if not Path(path).is_file():
                    raise ValueError(f"{src}: data.{group}.{name}: file not found: {path}")
        if self.data.test and set(self.data.calibration) != set(self.classes):
            raise ValueError(f"{src}: data.calibration must give a file for every class {list(self.classes)}")
        if self.data.select and set(self.data.select) != set(self.classes):
            raise ValueError(f"{src}: data.select must give a file for every class {list(self.classes)} (or none)")
        if self.data.select and not self.data.calibration:
            raise ValueError(f"{src}: data.select is given but data.calibration and data.test are not: the "
                             "simulated scene makes its own selection set; give all three, or leave select out")
        if self.data.calibration and not self.data.test:
            raise ValueError(f"{src}: data.calibration is given but data.test is not: give both, or neither "
                             "(the embedded simulated scene)")
        if self.ramps is not None and self.ramps < 1:
            raise ValueError(f"{src}: ramps = {self.ramps}: expected an integer >= 1 (leave it out for "
                             f"{SCENE_RAMPS} simulated, or the files' ramps_per_frame)")
        p = self.protocol
        bad = [w for w in p.specimen_widths if not w >= 0]
        if bad or not p.specimen_widths:
            raise ValueError(f"{src}: protocol.specimen_widths must be a non-empty list of numbers >= 0, "
                             f"got {p.specimen_widths}")
        try:  # the calibration's ranges are the settings' own
            p.calibration.settings()
        except ValueError as exc:
            named = [f.name for f in dataclasses.fields(p.calibration) if f.name in str(exc)]
            raise ValueError(f"{src}: protocol.calibration{'.' + named[0] if named else ''}: {exc}") from None
        bad = [s for s in p.sigma_p if not 0 <= s <= 1]
        if bad or not p.sigma_p:
            raise ValueError(f"{src}: protocol.sigma_p must be a non-empty list in [0, 1], got {p.sigma_p}")
        if p.cnn_seeds > 64:
            raise ValueError(f"{src}: protocol.cnn_seeds = {p.cnn_seeds}: at most 64 training runs per CNN")
        for name in ("cnn_seeds", "sweep_n_per_class", "cnn_n_per_class", "cnn_epochs", "tsaug_n_per_class",
                     "tsaug_epochs"):
            if getattr(p, name) < 1:
                raise ValueError(f"{src}: protocol.{name} must be >= 1")
        _check_names(src, "protocol.calibration.method", (p.calibration.method,), ("auto", "amortized", "likelihood"))
        _check_names(src, "protocol.models", p.models, ("svm", "nb", "xgb", "cnn"))
        _check_names(src, "protocol.normalisation", (p.normalisation,), NORMALISATIONS)
        from ..classify.base import PRECISIONS

        _check_names(src, "protocol.cnn_precision", (p.cnn_precision,), PRECISIONS)
        _check_names(src, "protocol.strategies", p.strategies, STRATEGIES)
        if p.cnn_patience is not None and p.cnn_patience < 1:
            raise ValueError(f"{src}: protocol.cnn_patience must be >= 1 (leave it out to train every epoch)")
        if p.n_boot < 0:
            raise ValueError(f"{src}: protocol.n_boot must be >= 0")
        sim = self.simulation
        for name in ("calibration_drones", "n_calibration", "n_select", "new_specimens", "large_factor",
                     "ceiling_per_class"):
            if getattr(sim, name) < 1:
                raise ValueError(f"{src}: simulation.{name} must be >= 1")
        for cls, n in sim.n_new.items():
            if cls not in self.classes and cls not in SimulationConfig().n_new:  # the defaults' own: harmless
                raise ValueError(f"{src}: simulation.n_new names unknown class {cls!r} (classes: "
                                 f"{list(self.classes)})")
            if n < 1:
                raise ValueError(f"{src}: simulation.n_new.{cls} must be >= 1")
        if check_files:
            self._check_files()
        return self

    def _check_names(self, src: str) -> None:
        """Names that become file names (classes, test sets) pass the one name rule
        (:mod:`mdaug.radar.names`) and are not the study's own sets: a study writes
        only inside its folder, and never one set over another."""
        for i, c in enumerate(self.classes):
            check_name(c, f"{src}: classes[{i}]")
        check_distinct(self.classes, f"{src}: classes")
        for group in ("calibration", "select"):
            for name in getattr(self.data, group):
                check_name(name, f"{src}: [data] {group} class name")
        own = ("select", "calibration", *(f"calibration_{c}" for c in self.classes))
        for name in self.data.test:
            check_name(name, f"{src}: [data] test set name", reserved=own, prefixes=("calibration_",))
        check_distinct(self.data.test, f"{src}: [data] test set names")

    def _check_files(self) -> None:
        """Every data file readable, 400-bin, no all-zero rows, the right classes, and
        the K it states (if any) the study's ``ramps`` (the one file-against-setting rule)."""
        from ..generator.acquisition import Acquisition, acquisition_from_file, resolve_acquisition
        from ..radar import RadarConfig, load_profiles

        length = RadarConfig().slice_length
        given = None if self.ramps is None else Acquisition.measured(self.ramps)
        first = None  # (path, acquisition) of the first file that states K: every other one must agree
        for group in ("calibration", "select", "test"):
            for name, path in getattr(self.data, group).items():
                ps = load_profiles(path)  # errors name the file and field
                stated = acquisition_from_file(ps.extra, path)
                resolve_acquisition(stated, given, str(path), f"{self.source}: ramps (or --ramps)")
                if stated is not None and first is not None:
                    resolve_acquisition(stated, first[1], str(path), str(first[0]))
                first = first or ((path, stated) if stated is not None else None)
                if ps.profiles.shape[1] != length:
                    raise ValueError(f"{self.source}: data.{group}.{name}: {path}: field 'profiles' has "
                                     f"{ps.profiles.shape[1]}-bin profiles; the study takes {length}-bin "
                                     "signatures (run 'mdaug process' first)")
                if group in ("calibration", "select"):
                    ps.select(name)
                    ps.check_no_zero_rows(name)
                if group == "calibration":  # constant, repeated or off-centre profiles: refused by name
                    from ..inference.sanity import check_calibration_profiles

                    check_calibration_profiles(ps.select(name), f"{self.source}: data.calibration.{name}: {path}",
                                               name, (ps.labels == name).nonzero()[0])
                else:
                    ps.check_no_zero_rows()
                    unknown = sorted(set(ps.classes) - set(self.classes))
                    if unknown:
                        raise ValueError(f"{self.source}: data.test.{name}: {path}: field 'labels' holds "
                                         f"class(es) {unknown} not in the study's classes {list(self.classes)}")


def _check_names(src: str, where: str, names, known) -> None:
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f"{src}: {where}: unknown {unknown or 'empty list'}; known {list(known)}")


SECTIONS = ("data", "protocol", "simulation")
"""The TOML tables of a study config (each a dataclass field of StudyConfig)."""


def _section(cls, table, path, section: str | None):
    """A config dataclass from one TOML table, every value type-checked against the
    dataclass's annotations (messages name the file, the section and the key); a table
    of a dataclass field (``[protocol.calibration]``) is read the same way; a key of an
    older config is refused with its new place (:data:`RENAMED`)."""
    where = f"{path} [{section}]" if section else str(path)
    if not isinstance(table, dict):
        raise ValueError(f"{path}: {section} = {table!r}: expected a table ([{section}] section)")
    prefix = f"{path}: [{section}] " if section else f"{path}: "
    for key in table:
        if (section, key) in RENAMED:
            raise ValueError(f"{prefix}{key}: renamed; write it as {RENAMED[section, key]} (same meaning; "
                             "docs/cli.md, study configs)")
    types = {k: v for k, v in field_types(cls).items() if k not in SECTIONS + ("source",)}
    unknown = sorted(set(table) - set(types))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; known: {sorted(types)}")

    def value(k, v):
        if dataclasses.is_dataclass(types[k]) and isinstance(v, dict):
            return _section(types[k], v, path, f"{section}.{k}" if section else k)
        return convert(v, types[k], f"{prefix}{k}")

    return cls(**{k: value(k, v) for k, v in table.items()})


def load_config(path) -> StudyConfig:
    """Read a study TOML; relative data paths are taken relative to the file.

    Everything is checked before any work (see :meth:`StudyConfig.validate`): unknown
    sections and keys, values of the wrong type, bad sizes, missing files."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: config file not found")
    try:
        raw = tomllib.loads(path.read_text())
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (expected a study TOML)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    tables = {k: v for k, v in raw.items() if isinstance(v, dict)}
    unknown = sorted(set(tables) - set(SECTIONS))
    if unknown:
        raise ValueError(f"{path}: unknown section {unknown[0]!r}; known: {', '.join(SECTIONS)}")
    top = {k: v for k, v in raw.items() if k not in tables}
    for name in SECTIONS:
        if name in top:
            raise ValueError(f"{path}: {name} = {top[name]!r}: expected a table ([{name}] section)")
    cfg = _section(StudyConfig, top, path, None)
    data = _section(DataConfig, raw.get("data", {}), path, "data")
    for group in ("calibration", "select", "test"):
        setattr(data, group, {k: str((path.parent / v).resolve()) for k, v in getattr(data, group).items()})
    cfg.data = data
    cfg.simulation = _section(SimulationConfig, raw.get("simulation", {}), path, "simulation")
    cfg.protocol = _section(ProtocolConfig, raw.get("protocol", {}), path, "protocol")
    cfg.source = str(path)
    return cfg.validate()
