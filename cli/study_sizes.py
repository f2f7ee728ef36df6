"""The sizes of a study, from its config and its files, under the one size bound.

``mdaug run`` checks every size a study config sets (drones, acquisitions, ramps,
training sets, epochs, ceiling, bootstrap) and the sizes its measured files state
(ramps per frame, measurements per class) with :func:`.common.check_size`, the bound
of every size option, before the output folder exists. A refusal names the config
key (``study.toml: [simulation] ceiling_per_class``) or the file and field, as the
options' refusals name the option.
"""
from __future__ import annotations

from .common import (SECONDS_CHAIN_RAMP, SECONDS_CNN_PROFILE, SECONDS_FAST_RAMP, SECONDS_LIKELIHOOD_RAMP,
                     SECONDS_RESAMPLE, SECONDS_SCENE_RAMP, check_size, ramps_factor)

FRAMES = 11        # the scene's frames per acquisition (MTI over 10, and the current one)
BINS = 400
MAX_ENGINES = 4    # QUAD


def _ramps(cfg) -> tuple[str, int]:
    """(name, K) of the study's ramps per frame: the simulation's, or what its files state."""
    if cfg.simulated:
        return "ramps", cfg.scene_ramps
    from ..generator.acquisition import acquisition_from_file
    from ..radar import load_profiles

    for group in ("calibration", "select", "test"):
        for path in getattr(cfg.data, group).values():
            acq = acquisition_from_file(load_profiles(path).extra, str(path))  # inf, nan: refused by name
            if acq is not None:
                return f"{path}: field 'ramps_per_frame'", acq.ramps
    return "ramps", cfg.ramps or 1


def _measurements(cfg) -> list[tuple[str, int]]:
    """(name, count) of the measurements each class is calibrated on."""
    s = cfg.simulation
    if cfg.simulated:
        return [("[simulation] n_calibration", s.n_calibration * s.calibration_drones)]
    from ..radar import load_profiles

    return [(f"{path}: field 'profiles' (class {cls})", len(load_profiles(path).select(cls)))
            for cls, path in cfg.data.calibration.items()]


def check_study_sizes(cfg) -> None:
    """Every size of the study ``cfg`` (checked, with its files) against memory and a day
    of work at the fastest rates (:mod:`.common`); raises ValueError naming the config
    and the key (or the file and field)."""
    try:
        _check(cfg)
    except ValueError as exc:
        raise ValueError(f"{cfg.source}: {exc}") from None


def _check(cfg) -> None:
    s, p = cfg.simulation, cfg.protocol
    key = lambda section, name: f"[{section}] {name}"  # noqa: E731
    n_cls = len(cfg.classes)
    k_name, k = _ramps(cfg)
    ramps = ramps_factor(k_name, k)  # the radar's bound first, then time and memory
    strategies = max(len(p.strategies), 1)
    if cfg.simulated:
        drones = s.calibration_drones + (s.calibration_drones > 1)
        check_size((key("simulation", "calibration_drones"), drones, 2),
                   (key("simulation", "n_calibration + n_select"), s.n_calibration + s.n_select, 29), ramps,
                   seconds_each=n_cls * FRAMES * SECONDS_SCENE_RAMP, what="simulated ramps of the calibration drones")
        for cls, n in s.n_new.items():
            check_size((key("simulation", f"n_new.{cls}"), n, 92), (key("simulation", "large_factor"),
                                                                     1 + s.large_factor, 5), ramps,
                       seconds_each=FRAMES * SECONDS_SCENE_RAMP, what="simulated ramps of the new drones")
        check_size((key("simulation", "new_specimens"), s.new_specimens, 3), bytes_each=2 * 13 * MAX_ENGINES * 8,
                   what="new drone specimens' vectors")
        ceiling = (key("simulation", "ceiling_per_class"), s.ceiling_per_class, 3000)
        check_size(ceiling, ramps, seconds_each=n_cls * FRAMES * MAX_ENGINES * SECONDS_CHAIN_RAMP,
                   what="ceiling ramps through the chain")
        check_size(ceiling, bytes_each=n_cls * BINS * 8 * 3, what="ceiling profiles")
        check_size(ceiling, (key("protocol", "cnn_epochs"), p.cnn_epochs, 40), (key("protocol", "cnn_seeds"),
                                                                                   p.cnn_seeds, 3),
                   seconds_each=n_cls * SECONDS_CNN_PROFILE, what="ceiling CNN profile passes")
    settings = (key("protocol", "sigma_p + specimen_widths"), len(p.sigma_p) + len(p.specimen_widths), 8)
    for name, typical in (("cnn_n_per_class", 6000), ("sweep_n_per_class", 1500), ("tsaug_n_per_class", 3000)):
        size = (key("protocol", name), getattr(p, name), typical)
        check_size(size, ramps, *([settings] if name == "sweep_n_per_class" else []),
                   seconds_each=n_cls * strategies * MAX_ENGINES * SECONDS_FAST_RAMP, what="rendered ramps")
        check_size(size, bytes_each=n_cls * BINS * 8 * 3, what="training profiles")
    for n_name, epochs_name in (("cnn_n_per_class", "cnn_epochs"), ("tsaug_n_per_class", "tsaug_epochs")):
        check_size((key("protocol", n_name), getattr(p, n_name), 6000),
                   (key("protocol", epochs_name), getattr(p, epochs_name), 40),
                   (key("protocol", "cnn_seeds"), p.cnn_seeds, 3),
                   seconds_each=n_cls * strategies * SECONDS_CNN_PROFILE, what="CNN profile passes")
    c = p.calibration
    evaluation = MAX_ENGINES * SECONDS_LIKELIHOOD_RAMP * c.n_acquisitions * c.ramps_drawn
    for m_name, m in _measurements(cfg):
        measurements = (m_name, m, 5)
        walkers = 2 * (13 * MAX_ENGINES + 3 * m) + 2
        check_size(measurements, (key("protocol.calibration", "max_steps"), c.max_steps, 400),
                   seconds_each=n_cls * walkers * evaluation, what="likelihood evaluations of the calibration")
        check_size(measurements, (key("protocol.calibration", "n_starts"), c.n_starts, 2),
                   (key("protocol.calibration", "fit_budget"), c.fit_budget, 1500),
                   seconds_each=n_cls * evaluation, what="likelihood evaluations of the fit")
    n_test = sum(s.n_new.values()) * (1 + s.large_factor) if cfg.simulated else 10 ** 4
    check_size((key("protocol", "n_boot"), p.n_boot, 1000), seconds_each=n_test * strategies * p.cnn_seeds
               * SECONDS_RESAMPLE, bytes_each=200, what="bootstrap resamples")
