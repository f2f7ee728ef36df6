"""``mdaug calibrate`` by the trained estimator (the amortized calibration): which
method a command line asks for, and the run of one drone through
:func:`mdaug.inference.amortized.calibrate.calibrate_amortized`."""
from __future__ import annotations

from .common import EXIT_NOT_CONVERGED, result, warn

EMCEE_BUDGET = 120.0
"""Default seconds of the emcee route beside the amortized posterior (``--time-budget``)."""


CLOSED_FORM_ONLY = ("likelihood", "draws", "ramps_drawn", "fit_budget", "fit_algorithm", "starts", "normalisation",
                    "particles", "backend", "engines", "trace")
"""Options of the likelihood route only (the amortized route has no such knob)."""


def calibration_method(args, acquisition) -> str:
    """'amortized' (the trained estimator; default for measured acquisitions, whose
    phases are random) or 'likelihood' (the closed-form / fitted-phase likelihood; the
    default for the published single chirp at fixed phases).
    Refuses likelihood-only options with the amortized method, by name."""
    method = args.method
    if method == "auto":
        method = "amortized" if acquisition.phases == "uniform" else "likelihood"
    if method == "amortized":
        if acquisition.phases != "uniform":
            raise ValueError("--method amortized: the estimators are trained on measured acquisitions (random "
                             "phases per frame); the published single chirp at fixed phases needs --method "
                             "likelihood")
        given = [o for o in CLOSED_FORM_ONLY if getattr(args, o, None) not in (None, False)]
        if args.sampler not in (None, "emcee"):
            given.insert(0, "sampler")
        if args.no_range_offset:
            given.append("no_range_offset")
        if given:
            opt = "--" + given[0].replace("_", "-")
            raise ValueError(f"{opt} applies to --method likelihood (the closed-form route); the amortized "
                             "calibration (the default for measured acquisitions) has no such setting")
    elif args.estimator is not None or args.route is not None:
        raise ValueError(f"{'--estimator' if args.estimator is not None else '--route'} applies to --method "
                         "amortized")
    return method


def run_amortized(args, profiles, drones, settings, acquisition, cls) -> int:
    """One drone through the trained estimator: amortized draws, then nlopt + emcee on
    the learned likelihood (:mod:`mdaug.inference.amortized.calibrate`)."""
    import warnings

    from ..inference.amortized.calibrate import calibrate_amortized

    if len(set(drones.tolist())) > 1:
        warn("calibrate", f"{args.measured} holds {len(set(drones.tolist()))} drones of {cls} (field 'specimen'); "
                          "they are calibrated as one drone: --specimen ID calibrates one of them")
    if args.time_budget is None:  # the amortized posterior is the one used: the chain beside it gets minutes
        settings = settings.replace(time_budget=EMCEE_BUDGET)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = calibrate_amortized(profiles, cls.upper(), acquisition=acquisition, estimator=args.estimator,
                                  settings=settings, random_state=args.seed, route=args.route or "amortized",
                                  source=str(args.measured))
    res.record_specimens(drones)
    res.save(args.out)
    result(res.report())
    result(f"wrote {args.out}")
    for w in caught:
        if "unlike" in str(w.message):
            warn("calibrate", str(w.message))
    if args.corner is not None:
        res.plot_corner(args.corner)
        result(f"wrote {args.corner}")
    if not res.converged:
        warn("calibrate", f"the chain did not converge ({res.diagnostics['reason']}); {args.out} is flagged "
                          "not converged")
        return 0 if args.allow_unconverged else EXIT_NOT_CONVERGED
    emcee = res.diagnostics.get("emcee", {})
    if emcee and not emcee.get("converged"):
        warn("calibrate", f"the emcee route did not converge ({emcee.get('reason')}); the posterior used is the "
                          "amortized one")
    return 0
