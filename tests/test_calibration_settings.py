"""CalibrationSettings: what every run needs, each sampler plugin's knobs in the plugin's
own frozen dataclass, the command line's options mapped onto them, and settings
written before the split (every knob flat) still read."""
import json
from types import SimpleNamespace

import pytest

from mdaug.inference.samplers import SAMPLERS, settings_class
from mdaug.inference.samplers.ensemble import EmceeSettings
from mdaug.inference.samplers.laplace import LaplaceSettings
from mdaug.inference.samplers.smc import SMCSettings
from mdaug.inference.settings import CalibrationSettings

OLD_QUICK = json.loads(
    '{"fit_algorithm": "GN_CRS2_LM", "local_algorithm": "LN_BOBYQA", "n_starts": 2, "fit_budget": 1000, '
    '"polish_budget": 2000, "n_walkers": 32, "max_steps": 1000, "time_budget": 1200.0, "check_every": 250, '
    '"store_every": 0, "min_tau_multiple": 50.0, "tau_rtol": 0.05, "burn_tau": 3.0, "thin_tau": 0.5, '
    '"init_ball": 0.5, "init_modes": true, "normalisation": "peak", "range_offset": true, "alignment": "tone", '
    '"sigma_min": 0.0001, "sigma_max": 1.0, "dtype": "float32", "threads": 1, "progress": false, '
    '"sampler": "emcee", "n_particles": 0, "smc_ess": 0.9, "smc_redraw": 0.3, "smc_p_move": 0.99, '
    '"smc_max_sweeps": 40, "smc_max_stages": 500, "smc_jump": 0.1, "smc_polish": 3, "relabel": 0.1, '
    '"likelihood": "auto", "n_acquisitions": 8, "ramps_drawn": 4, "stride": 8, "amp_tol": 0.001, '
    '"pair_tol": 0.05, "reach_tol": 0.0003, "model_floor": 0.0}')
"""CalibrationSettings.quick().to_dict() as mdaug wrote it before the plugins had their own settings."""


def test_each_plugin_owns_its_knobs_and_defaults():
    s = CalibrationSettings()
    assert [name for name, _ in s.plugins] == list(SAMPLERS)
    assert s.of("emcee") == EmceeSettings() and s.of("smc") == SMCSettings() and s.of("laplace") == LaplaceSettings()
    assert settings_class("smc") is SMCSettings
    shared = {f for f in s.to_dict() if f != "plugins"}
    for name in SAMPLERS:  # no knob is both shared and a plugin's
        assert not shared & set(s.to_dict()["plugins"][name]), name
    assert EmceeSettings().min_tau_multiple == 50.0 and SMCSettings().ess == 0.9
    with pytest.raises(ValueError, match="unknown sampler"):
        s.of("pt")


def test_keywords_by_their_flat_names_reach_the_plugins():
    s = CalibrationSettings.quick(sampler="smc", n_particles=120, smc_ess=0.5, max_steps=7)
    assert s.of("smc") == SMCSettings(n_particles=120, ess=0.5, polish=3)  # quick: 3 polished
    assert s.of("laplace").n_particles == 120  # a flat name two plugins share sets both
    assert s.of("emcee") == EmceeSettings(n_walkers=32, max_steps=7, check_every=250)
    assert s.n_particles == 120 and s.smc_ess == 0.5 and s.n_walkers == 32  # flat reads
    assert s.replace(n_starts=3).of("smc") == s.of("smc") and s.replace(n_starts=3).n_starts == 3
    assert s.with_plugin("emcee", n_walkers=40).of("emcee").n_walkers == 40
    with pytest.raises(TypeError, match="unknown setting 'walkers'"):
        CalibrationSettings(walkers=3)
    with pytest.raises(ValueError, match="smc_ess"):
        CalibrationSettings(smc_ess=1.5)
    with pytest.raises(AttributeError, match="no setting 'nope'"):
        _ = s.nope


def test_settings_round_trip_and_old_flat_files_still_load():
    s = CalibrationSettings.quick(sampler="laplace", n_particles=300)
    assert CalibrationSettings.from_dict(json.loads(json.dumps(s.to_dict()))) == s
    assert CalibrationSettings.from_dict(OLD_QUICK) == CalibrationSettings.quick()
    with pytest.raises(ValueError, match="unknown setting 'n_chains'"):
        CalibrationSettings.from_dict({**OLD_QUICK, "n_chains": 4})
    with pytest.raises(ValueError, match="no sampler plugin 'pt'"):
        CalibrationSettings.from_dict({"plugins": {"pt": {}}})


def test_a_resumed_run_may_change_only_the_budgets():
    s = CalibrationSettings.quick()
    key = s.resume_key()
    assert key == s.replace(time_budget=5.0, max_steps=50, threads=3, progress=True).resume_key()
    assert key != s.replace(n_walkers=40).resume_key() and key != s.replace(smc_jump=0.2).resume_key()


def test_the_command_line_maps_its_options_onto_the_plugins():
    from mdaug.cli.calibrate import PLUGIN_OPTIONS, SHARED_OPTIONS, settings_from_args

    args = SimpleNamespace(**{dest: None for dest in (*SHARED_OPTIONS, *PLUGIN_OPTIONS)})
    base = CalibrationSettings.quick()
    assert settings_from_args(args, base) == base
    args.particles, args.walkers, args.max_steps, args.draws, args.sampler = 200, 40, 90, 3, "smc"
    s = settings_from_args(args, base)
    assert s.of("smc").n_particles == s.of("laplace").n_particles == 200
    assert (s.of("emcee").n_walkers, s.of("emcee").max_steps, s.n_acquisitions, s.sampler) == (40, 90, 3, "smc")


def test_a_drone_reuse_key_of_flat_settings_reads_as_today():
    from mdaug.cli.calibrate_population import current_form, reuse_key
    from mdaug.generator.acquisition import Acquisition

    acq = Acquisition.measured(4)
    key = reuse_key(None, 7, CalibrationSettings.quick(), acq)
    old = {**key, "settings": {k: v for k, v in OLD_QUICK.items() if k not in ("threads", "progress", "sampler")}}
    assert current_form(old) == key
    assert current_form(key) == key
    odd = {**old, "settings": {**old["settings"], "n_chains": 4}}
    assert current_form(odd) == odd  # unreadable: compared as recorded, so not reused
