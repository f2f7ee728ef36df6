"""``mdaug calibrate``: a class's posterior from measured profiles (nlopt fit + sampler).

Exit status: 0 when the sampler converged, 3 when it did not (the posterior is still
written, flagged not converged in the file and on stderr) unless
``--allow-unconverged`` is given, 2 on bad input, 130 when interrupted (the fit and
the chain checkpoint, where they exist yet, are kept: the same command resumes; the
message says which exist).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import (BYTES_SPECTRUM, EXIT_NOT_CONVERGED, SECONDS_LIKELIHOOD_RAMP, add_verb, check_size, count, count_2, ramps_factor,
                     info, positive_float,
                     positive_int, result, seed_int, warn)
from .options import acquisition_from_args, acquisition_given, add_acquisition_options



engines_arg = count(1, what="a positive integer or 'auto'", words=("auto",))


walkers_arg = count(2, what="an integer >= 2 (0 is not allowed here: leave the option out for auto)")
particles_arg = count(2, what="an integer >= 2 (leave the option out for auto)")


def route_knob_arg(text: str) -> tuple[str, object]:
    """``--route-knob NAME=VALUE``: one of the smc route's knobs (the names an estimator file's
    meta field ``route_settings`` uses), its value typed and checked."""
    from ..inference.samplers.smc import ROUTE_KNOBS, check_route_knobs

    name, sep, value = text.partition("=")
    name, value = name.strip(), value.strip()
    if not sep or name not in ROUTE_KNOBS:
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAME=VALUE with NAME one of {', '.join(ROUTE_KNOBS)}")
    try:
        typed = ({"true": True, "on": True, "false": False, "off": False}[value.lower()] if name == "route_moves"
                 else int(value) if name in ("route_max_sweeps", "n_particles") else float(value))
    except (KeyError, ValueError):
        typed = value  # left as text: check_route_knobs says what the knob takes
    try:
        check_route_knobs({name: typed}, where=repr(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name, typed


def _cap(value) -> str:
    return "no cap" if value is None else str(value)


def _backend(args) -> Path:
    return args.backend if args.backend is not None else Path(f"{args.out}.chain.h5")


ENGINE_CANDIDATES = (1, 2, 4)  # --engines auto: what mdaug.inference.compare.select_engines tries


def _checkpoint_files(args) -> list[Path]:
    """Every file the chain checkpoint may consist of: the backend, the fit saved beside
    it, and with ``--engines auto`` one of each per engine count."""
    backend = _backend(args)
    stems = [backend] + ([Path(f"{backend}.e{e}") for e in ENGINE_CANDIDATES] if args.engines == "auto" else [])
    return [p for s in stems for p in (s, Path(f"{s}.fit.json"))]


MAX_MEASUREMENTS = 64
"""Most measurements one calibration takes (the cost of every likelihood grows with them)."""


def check_calibrate_sizes(args, settings, n_measurements: int) -> None:
    """The fit's and the sampler's sizes against memory and time (before any work)."""
    from ..generator import load_reference

    engines = args.engines if isinstance(args.engines, int) else max(ENGINE_CANDIDATES) \
        if args.engines == "auto" else load_reference(args.class_name.upper()).n_engines
    dim = 13 * engines + 3 * n_measurements
    draws = ("--draws", settings.n_acquisitions, 16)
    ramps = ("--ramps-drawn", settings.ramps_drawn, 16)
    check_size(draws, ramps, bytes_each=engines * BYTES_SPECTRUM * 2, what="simulated ramps per evaluation")
    evaluation = n_measurements * engines * SECONDS_LIKELIHOOD_RAMP * settings.n_acquisitions * settings.ramps_drawn
    check_size(("--starts", settings.n_starts, 4), ("--fit-budget", settings.fit_budget, 1500),
               seconds_each=evaluation, what="likelihood evaluations of the fit")
    emcee, smc = settings.of("emcee"), settings.of("smc")
    walkers = ("--walkers", emcee.n_walkers or max(32, 2 * dim + 2), 2 * dim + 2)
    check_size(walkers, seconds_each=evaluation, what="likelihood evaluations of one sampler step")
    if emcee.max_steps is not None:  # the step cap also sets how sparsely the chain is stored
        check_size(("--max-steps", emcee.max_steps, 10000), walkers, seconds_each=evaluation,
                   what="likelihood evaluations of the sampler")
    if smc.n_particles:
        check_size(("--particles", smc.n_particles, 40 * dim), seconds_each=evaluation * 10,
                   bytes_each=dim * 8 * 8, what="particles over the first tempering stage")
    if settings.time_budget is not None:
        check_size(("--time-budget", settings.time_budget, 1200), seconds_each=1.0, what="seconds")


SHARED_OPTIONS = {"fit_budget": "fit_budget", "starts": "n_starts", "fit_algorithm": "fit_algorithm",
                  "normalisation": "normalisation", "sampler": "sampler", "time_budget": "time_budget",
                  "likelihood": "likelihood", "draws": "n_acquisitions", "ramps_drawn": "ramps_drawn"}
"""Options (their argparse dest) -> the shared calibration setting each sets."""

PLUGIN_OPTIONS = {"max_steps": (("emcee", "max_steps"),), "walkers": (("emcee", "n_walkers"),),
                  "particles": (("smc", "n_particles"), ("laplace", "n_particles"))}
"""Options -> the sampler plugins' knobs each sets (--particles sizes both SMC and Laplace)."""


def check_options_apply(args, settings, acquisition, k_name: str) -> None:
    """Options that do not apply to this calibration are refused by name (the pattern of
    :data:`.calibrate_amortized.CLOSED_FORM_ONLY`): a sampler plugin's option with
    another sampler, ``--ramps-drawn`` beyond the data's K (``k_name``: where K comes
    from), ``--likelihood fitted`` on data whose phases are random."""
    for dest, targets in PLUGIN_OPTIONS.items():
        plugins = sorted({plugin for plugin, _ in targets})
        if getattr(args, dest) is not None and settings.sampler not in plugins:
            raise ValueError(f"--{dest.replace('_', '-')} applies to --sampler {' or '.join(plugins)}; this "
                             f"calibration samples with {settings.sampler}")
    if args.ramps_drawn is not None and args.ramps_drawn > acquisition.ramps:
        raise ValueError(f"--ramps-drawn {args.ramps_drawn}: more ramps than the data's K = {acquisition.ramps} "
                         f"({k_name}); at most K")
    if args.likelihood == "fitted" and acquisition.phases == "uniform":
        raise ValueError(f"--likelihood fitted fits one set of phases per measurement, but the data's acquisition "
                         f"draws random phases per frame ({k_name}: K = {acquisition.ramps}, phases uniform); use "
                         "--likelihood marginal (the default for such data)")


def settings_from_args(args, base):
    """``base`` (a :class:`~mdaug.inference.settings.CalibrationSettings`) with the options
    the command line gave (None: not given) mapped onto the shared settings and the
    plugins' own."""
    settings = base.replace(**{key: getattr(args, dest) for dest, key in SHARED_OPTIONS.items()
                               if getattr(args, dest) is not None})
    for dest, targets in PLUGIN_OPTIONS.items():
        if getattr(args, dest) is not None:
            for plugin, knob in targets:
                settings = settings.with_plugin(plugin, **{knob: getattr(args, dest)})
    if getattr(args, "route_knob", None):  # the last of a knob given twice wins
        settings = settings.with_plugin("smc", **dict(args.route_knob))
    return settings


def run_calibrate(args) -> int:
    import numpy as np

    from ..inference.calibrate import calibrate
    from ..inference.settings import CalibrationSettings
    from ..radar import DataFileError, RadarConfig, load_profiles
    from ..radar.progress import progress_enabled
    from .guard import Output, check_paths

    backend = _backend(args)
    if args.population and (args.corner or args.trace or args.backend or args.specimen is not None):
        raise ValueError("--corner, --trace, --backend and --specimen apply to one drone's calibration, not to "
                         "--population (each drone's posterior is kept as OUT.drone-ID.nc)")
    check_paths(inputs=[("MEASURED", args.measured)],
                outputs=[Output("--out", args.out, "npz" if args.population else "posterior"),
                         Output("--corner", args.corner, "plot"),
                         Output("--trace", args.trace, "plot"),
                         Output("--backend", backend, "checkpoint", beside=_checkpoint_files(args)[1:])],
                overwrite=args.overwrite)
    radar = RadarConfig()
    data = load_profiles(args.measured)
    cls = args.class_name.upper() if args.class_name.upper() in data.classes else args.class_name
    profiles = data.select(cls)  # names the file when the class is absent
    data.check_no_zero_rows(cls)
    drones = data.specimens(cls)
    if args.specimen is not None:
        if args.specimen not in set(drones.tolist()):
            raise DataFileError(f"{args.measured}: field 'specimen' holds no drone {args.specimen!r} of class {cls} "
                                f"(drones present: {sorted(set(drones.tolist()))})")
        profiles, drones = profiles[drones == args.specimen], drones[drones == args.specimen]
    if profiles.shape[1] != radar.slice_length:
        raise DataFileError(f"{args.measured}: field 'profiles' has {profiles.shape[1]}-bin profiles; calibration "
                            f"takes {radar.slice_length}-bin peak-centred signatures (run 'mdaug process' on "
                            "whole MTI profiles first)")
    if np.any(profiles < 0):
        raise DataFileError(f"{args.measured}: field 'profiles' holds negative values; calibration takes linear "
                            "magnitudes (>= 0), not dB")
    base = CalibrationSettings.quick() if args.quick else CalibrationSettings()
    from ..generator.acquisition import Acquisition, acquisition_from_file, resolve_acquisition

    from_file = acquisition_from_file(data.extra, str(args.measured))
    resolve_acquisition(from_file, None if args.ramps is None else Acquisition.measured(args.ramps),
                        str(args.measured), "--ramps")  # the one file-against-setting rule (K must agree)
    acquisition, _ = acquisition_from_args(args, from_file)
    k_name = ("--ramps" if args.ramps is not None else f"{args.measured}: field 'ramps_per_frame'"
              if from_file is not None else "the published single chirp")
    ramps_factor(k_name, acquisition.ramps)  # the radar's bound, named, before any estimate
    source = ("from the options" if acquisition_given(args) else
              f"as {args.measured} states it" if from_file is not None else "the published single chirp (default)")
    settings = settings_from_args(args, base.replace(threads=args.threads, progress=progress_enabled(),
                                                     range_offset=not args.no_range_offset))
    if len(profiles) > MAX_MEASUREMENTS and not args.population:
        raise DataFileError(f"{args.measured}: field 'profiles' holds {len(profiles)} measurements of class {cls}; "
                            f"one calibration takes at most {MAX_MEASUREMENTS} of one drone (the supported case is "
                            "a handful; --specimen ID picks one drone, --population calibrates each)")
    from ..inference.sanity import check_calibration_profiles

    rows = np.flatnonzero(np.asarray(data.labels) == cls)
    check_calibration_profiles(profiles, str(args.measured), cls,  # constant, repeated or off-centre: refused
                               rows if args.specimen is None else rows[data.specimens(cls) == args.specimen])
    check_calibrate_sizes(args, settings, len(profiles))
    from .calibrate_amortized import (amortized_settings, calibration_method, predictive_draws, report_amortized,
                                      warn_several_drones)

    method = calibration_method(args, acquisition)
    check_options_apply(args, settings, acquisition, k_name)
    how = ("the class's trained estimator" if method == "amortized" else
           f"engines {args.engines or 'reference'}; chain checkpoint {backend}")
    info(f"calibrating {args.class_name.upper()} from {len(profiles)} profile(s) of {args.measured} "
         f"({how}; seed {args.seed})")
    result(f"acquisition ({source}): {acquisition.describe()}")
    if len(profiles) == 1:
        warn("calibrate", "one profile only: the posterior is weakly identified (the supported case is a handful "
                          "of measurements, typically 5)")
    if args.population:
        from .calibrate_population import run_population

        return run_population(args, profiles, drones, settings, acquisition, method)
    if method == "amortized":  # the class's trained estimator: the acquisition goes straight to it
        import warnings

        from ..inference.amortized.calibrate import calibrate_amortized

        warn_several_drones(args, drones, cls)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = calibrate_amortized(profiles, cls.upper(), acquisition=acquisition, estimator=args.estimator,
                                      settings=amortized_settings(args, settings), random_state=args.seed,
                                      route=args.route, check=args.check_route, source=str(args.measured),
                                      **predictive_draws(args))
        return report_amortized(args, res, drones, caught)
    if len(set(drones.tolist())) > 1:
        warn("calibrate", f"{args.measured} holds {len(set(drones.tolist()))} drones of {cls} (field 'specimen'); "
                          "they are calibrated as one drone: --population calibrates each and the class's "
                          "population, --specimen ID one of them")
    if args.engines == "auto":
        from ..inference.compare import select_engines

        res = select_engines(profiles, args.class_name.upper(), settings=settings, random_state=args.seed,
                             backend_path=backend, acquisition=acquisition, predictive=args.predictive)
    else:
        res = calibrate(profiles, args.class_name.upper(), engines=args.engines, settings=settings,
                        acquisition=acquisition, random_state=args.seed, backend_path=backend,
                        **predictive_draws(args))
    res.record_specimens(drones)
    if res.diagnostics.get("resumed_at") or res.diagnostics.get("fit_reused"):
        result(f"resumed from {backend}: fit reused, sampler continued at step {res.diagnostics.get('resumed_at', 0)}")
    res.save(args.out)
    result(res.report())
    result(f"wrote {args.out}")
    if args.corner is not None:
        res.plot_corner(args.corner)
        result(f"wrote {args.corner}")
    if args.trace is not None:
        res.plot_trace(args.trace)
        result(f"wrote {args.trace}")
    if args.backend is None:  # the default checkpoint is captured in the NetCDF now
        for p in _checkpoint_files(args):  # only the files calibrate itself wrote, never a glob
            p.unlink(missing_ok=True)
    if not res.converged:
        warn("calibrate", f"the chain did not converge ({res.diagnostics['reason']}); {args.out} is flagged "
                          "not converged")
        return 0 if args.allow_unconverged else EXIT_NOT_CONVERGED
    return 0


def _interrupted(args) -> str:
    """What an interrupt leaves, as it is: the checkpoint files that exist now."""
    if args.population:
        done = sorted(Path(args.out).parent.glob(f"{Path(args.out).name}.drone-*.nc"))
        return (f"{len(done)} drone posterior(s) {Path(args.out).name}.drone-*.nc and the running drone's chain "
                "checkpoint are kept; run the same command again to resume")
    kept = [p for p in _checkpoint_files(args) if p.exists()]
    if not kept:
        return ("no chain checkpoint was written yet (interrupted before the fit finished); nothing to resume: "
                "run the same command again to start over")
    if not any(p.suffix != ".json" for p in kept):
        return (f"the global fit is kept in {', '.join(map(str, kept))} (no sampler steps yet); run the same "
                "command again to reuse it")
    return f"the chain checkpoint {', '.join(map(str, kept))} is kept; run the same command again to resume"


def add_calibrate(sub, parents, help):
    from ..inference.settings import FIT_ALGORITHMS, SAMPLERS, CalibrationSettings
    from ..inference.amortized.estimator import ROUTES
    from ..inference.diagnostics.predictive import N_DRAWS as PREDICTIVE_DRAWS
    from .calibrate_amortized import ROUTE_BUDGET
    from ..radar.profiles import NORMALISATIONS

    d, q = CalibrationSettings(), CalibrationSettings.quick()
    d_emcee, q_emcee = d.of("emcee"), q.of("emcee")
    p = add_verb(sub, "calibrate", parents, help=help, interrupted=_interrupted,
                 description="Calibrate a class's vibration model from a few measurements of one drone. "
                             "Measured acquisitions (random phases): the class's trained estimator, by its "
                             "default route (the file's route table: the best log score among the routes that "
                             "pass SBC, measured on drones like a user's): tempered SMC from the amortized "
                             "posterior to the summary likelihood's posterior where the estimator's table names it; "
                             "else the amortized posterior's exact draws. The published single chirp: the closed-form "
                             "likelihood (nlopt, then emcee or --sampler smc/laplace). Exit status 3 when the "
                             "sampler did not converge (the posterior is still written, flagged).")
    p.add_argument("measured", type=Path, help="measured profiles (NPZ, CSV or .mat with profiles and labels)")
    p.add_argument("--class", dest="class_name", required=True, metavar="CLASS",
                   help="class label to calibrate (e.g. HELI); its reference gives the priors")
    p.add_argument("--out", type=Path, required=True, help="posterior NetCDF (arviz InferenceData)")
    p.add_argument("--engines", type=engines_arg, default=None, metavar="N|auto",
                   help="engines to fit: a count, or auto (chosen by LOO among 1, 2, 4) (default: the "
                        "reference's count)")
    p.add_argument("--seed", type=seed_int, default=0, help="random seed of fit and sampler (default: %(default)s)")
    p.add_argument("--specimen", default=None, metavar="ID",
                   help="calibrate only the profiles of this drone (the file's field 'specimen') (default: all)")
    p.add_argument("--population", action="store_true",
                   help="calibrate each drone of the class (field 'specimen') on its own, then the class's "
                        "population (spreads across drones); OUT is then a population NPZ, each drone's "
                        "posterior is kept beside it as OUT.drone-ID.nc")
    p.add_argument("--corner", type=Path, default=None, help="also write a corner plot PNG (default: none)")
    p.add_argument("--trace", type=Path, default=None, help="also write a trace plot PNG (default: none)")
    p.add_argument("--backend", type=Path, default=None,
                   help="HDF5 chain checkpoint; an interrupted run resumes from it (default: OUT.chain.h5, "
                        "removed after success)")
    p.add_argument("--allow-unconverged", action="store_true",
                   help="exit 0 even when the sampler did not converge")
    g = p.add_argument_group("method")
    g.add_argument("--method", choices=("auto", "amortized", "likelihood"), default="auto",
                   help="amortized: the class's trained estimator (simulation-based; the amortized posterior, "
                        "and tempered SMC to the likelihood learned from the same simulations); likelihood: "
                        "the closed-form likelihood with nlopt + a sampler (auto: amortized for measured "
                        "acquisitions, likelihood for the published single chirp) (default: %(default)s)")
    g.add_argument("--estimator", type=Path, default=None,
                   help="estimator ZIP of mdaug train-estimator (default: the shipped one for the class and K)")
    g.add_argument("--route", choices=ROUTES, default=None,
                   help="amortized: the estimator's posterior (exact draws, milliseconds); smc: tempered SMC "
                        "from the amortized posterior to the posterior of the estimator's likelihood (the summary "
                        "likelihood where it has one; weights between its modes); stacked: the two mixed at the "
                        "file's stacking weight (files that state one) (default: the estimator's default route)")
    g.add_argument("--route-knob", action="append", type=route_knob_arg, default=None, metavar="NAME=VALUE",
                   help="one of the smc route's knobs, over the estimator file's own (its meta field "
                        "route_settings) and the defaults: route_ess (ESS share kept a tempering stage), "
                        "route_p_move, route_max_sweeps, route_moves (true/false), n_particles; repeat for more "
                        "(default: the file's, else the defaults)")
    g.add_argument("--predictive", type=count(0, 5000, "0, or an integer from 20 to 5,000"), default=None,
                   metavar="N", help="posterior draws measured for the posterior predictive check (each as many "
                   "times as the data were; band means and spreads of the folded log-profile and the brightest "
                   "engine's lines against the measurements' own; 0: no check) "
                   f"(default: {PREDICTIVE_DRAWS})")
    g.add_argument("--check-route", action="store_true",
                   help="also run another route and keep its draws beside the posterior, as a check: smc "
                        "beside the amortized route, the amortized draws beside the smc route's (default: only "
                        "the route used runs)")
    g = p.add_argument_group("budget and sampler")
    g.add_argument("--quick", action="store_true",
                   help="short run of seconds, for a first look (usually not converged)")
    g.add_argument("--sampler", choices=SAMPLERS, default=None,
                   help="emcee: ensemble from the fit, run to 50 tau; smc: tempered SMC from the prior with "
                        "mode jumps, for multimodal posteriors, gives the evidence; laplace: importance sampling "
                        "from Gaussians at the fit's modes (seconds; flagged when its weights cannot be trusted) "
                        f"(default: {d.sampler})")
    g.add_argument("--time-budget", type=positive_float, default=None, metavar="SECONDS",
                   help="stop sampling after this many seconds when not converged before (the run is then "
                        f"flagged not converged; rerun to continue) (default: {d.time_budget:g}; the smc route "
                        f"of a trained estimator: {ROUTE_BUDGET:g})")
    g.add_argument("--max-steps", type=positive_int, default=None, metavar="N",
                   help=f"emcee step budget, steps per walker (default: {_cap(d_emcee.max_steps)}; --quick: "
                        f"{_cap(q_emcee.max_steps)})")
    g.add_argument("--walkers", type=walkers_arg, default=None, metavar="N",
                   help="emcee walkers (default: 2 x the number of sampled coordinates + 2, at least 32; "
                        f"--quick: {q_emcee.n_walkers})")
    g.add_argument("--particles", type=particles_arg, default=None, metavar="N",
                   help="SMC particles (default: max(500, 40 x the number of sampled coordinates))")
    g.add_argument("--starts", type=positive_int, default=None, metavar="N",
                   help=f"independent global fit starts (default: {d.n_starts}; --quick: {q.n_starts})")
    g.add_argument("--fit-budget", type=positive_int, default=None, metavar="EVALS",
                   help=f"objective evaluations per global fit start (default: {d.fit_budget}; --quick: "
                        f"{q.fit_budget})")
    g.add_argument("--fit-algorithm", choices=FIT_ALGORITHMS, default=None, metavar="NAME",
                   help=f"nlopt global algorithm, one of {', '.join(FIT_ALGORITHMS)} (default: {d.fit_algorithm})")
    g.add_argument("--likelihood", choices=("auto", "marginal", "synthetic", "fitted"), default=None,
                   help="auto: marginalise the phases in closed form when the acquisition randomises them or "
                        "averages ramps, fit them for the published single chirp; or force one (synthetic: the "
                        f"Monte-Carlo check of the closed form) (default: {d.likelihood})")
    g.add_argument("--draws", type=count_2, default=None, metavar="O",
                   help=f"synthetic likelihood: simulated acquisitions per evaluation (default: {d.n_acquisitions})")
    g.add_argument("--ramps-drawn", type=positive_int, default=None, metavar="I",
                   help=f"synthetic likelihood: ramps simulated per acquisition, at most K (default: {d.ramps_drawn})")
    add_acquisition_options(p, relative=False, profile_options=False)
    g = p.add_argument_group("model")
    g.add_argument("--normalisation", choices=NORMALISATIONS, default=None,
                   help=f"normalisation of measured and model profiles (default: {d.normalisation})")
    g.add_argument("--no-range-offset", action="store_true",
                   help="do not fit a per-measurement offset of the tone (fix it at 0 bins)")
    p.set_defaults(func=run_calibrate)
    return p


VERBS = {
    "calibrate": ("calibrate a class from measured profiles (fit + posterior)", add_calibrate),
}
