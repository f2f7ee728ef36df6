"""``mdaug calibrate`` by the trained estimator (the amortized calibration): which
method a command line asks for, the smc route's settings, and the report of one
drone's run (the run itself: :func:`mdaug.inference.amortized.calibrate.calibrate_amortized`,
called by the verb)."""
from __future__ import annotations

from .common import EXIT_NOT_CONVERGED, result, warn

ROUTE_BUDGET = 180.0
"""Default most seconds of the smc route (``--time-budget``): a HELI K = 32 run on the
summary likelihood takes 5-17 s on one core."""


CLOSED_FORM_ONLY = ("likelihood", "draws", "ramps_drawn", "fit_budget", "fit_algorithm", "starts", "normalisation",
                    "particles", "backend", "engines", "trace", "max_steps", "walkers")
"""Options of the likelihood route only (the amortized route has no such knob)."""


def calibration_method(args, acquisition) -> str:
    """'amortized' (the trained estimator; default for measured acquisitions, whose
    phases are random) or 'likelihood' (the closed-form / fitted-phase likelihood; the
    default for the published single chirp at fixed phases).
    Refuses likelihood-only options with the amortized method, by name."""
    from ..inference.diagnostics.predictive import MIN_DRAWS as PREDICTIVE_MIN

    predictive = getattr(args, "predictive", None)
    if predictive is not None and 0 < predictive < PREDICTIVE_MIN:
        raise ValueError(f"--predictive: expected 0 (no check) or at least {PREDICTIVE_MIN} draws, got {predictive}")
    method = args.method
    if method == "auto":
        method = "amortized" if acquisition.phases == "uniform" else "likelihood"
    if method == "amortized":
        if acquisition.phases != "uniform":
            raise ValueError("--method amortized: the estimators are trained on measured acquisitions (random "
                             "phases per frame); the published single chirp at fixed phases needs --method "
                             "likelihood")
        given = [o for o in CLOSED_FORM_ONLY if getattr(args, o, None) not in (None, False)]
        if args.sampler is not None:
            given.insert(0, "sampler")
        if args.no_range_offset:
            given.append("no_range_offset")
        if given:
            opt = "--" + given[0].replace("_", "-")
            raise ValueError(f"{opt} applies to --method likelihood (the closed-form route); the amortized "
                             "calibration (the default for measured acquisitions) has no such setting")
    else:
        given = [o for o, v in (("--estimator", args.estimator), ("--route", args.route),
                                ("--route-knob", getattr(args, "route_knob", None)),
                                ("--check-route", args.check_route or None)) if v is not None]
        if given:
            raise ValueError(f"{given[0]} applies to --method amortized")
    return method


def predictive_draws(args) -> dict:
    """A calibration's ``predictive`` (either method) from ``--predictive`` (absent: its default)."""
    return {} if getattr(args, "predictive", None) is None else {"predictive": int(args.predictive)}


def amortized_settings(args, settings):
    """The smc route's settings: ROUTE_BUDGET seconds unless ``--time-budget`` says otherwise."""
    return settings.replace(time_budget=ROUTE_BUDGET) if args.time_budget is None else settings


def warn_several_drones(args, drones, cls) -> None:
    """Before the run: several drones in the file are calibrated as one."""
    if len(set(drones.tolist())) > 1:
        warn("calibrate", f"{args.measured} holds {len(set(drones.tolist()))} drones of {cls} (field 'specimen'); "
                          "they are calibrated as one drone: --specimen ID calibrates one of them")


def report_amortized(args, res, drones, caught) -> int:
    """Write and report one drone's amortized calibration (``caught``: the warnings of
    the run); the exit status."""
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
    from ..inference.result.status import smc_role

    smc = res.diagnostics.get("smc", {})
    if smc and not smc.get("converged") and res.diagnostics.get("route") == "amortized":
        warn("calibrate", f"the smc route, {smc_role(res.diagnostics)}, did not converge ({smc.get('reason')}); the "
                          "posterior used is the amortized one")
    return 0
