"""``mdaug calibrate --population``: each drone of a file calibrated on its own (kept
beside the output, reused by a rerun on the same data with the same options), then
the class's population (:func:`mdaug.inference.population.result.calibrate_population`)."""
from __future__ import annotations

from pathlib import Path

from .common import EXIT_NOT_CONVERGED, info, result, warn


def drone_path(out: Path, drone: str) -> Path:
    """Where ``--population`` keeps a drone's posterior (a rerun reuses it)."""
    return Path(f"{out}.drone-{drone}.nc")


REUSE_FIELD = "population_reuse"
"""Where a drone's posterior of ``--population`` records the options it was made with."""


def reuse_key(engines, seed: int, settings, acquisition, method: str = "likelihood", estimator=None) -> dict:
    """Every option that changes a drone's posterior (not threads nor progress bars):
    a rerun reuses the posterior only when all of them, and the measurements, agree."""
    import json

    if method == "amortized":  # the estimator and the seed say it all
        return json.loads(json.dumps({"method": method, "estimator": str(estimator or "shipped"), "seed": int(seed),
                                      "acquisition": acquisition.to_dict()}))
    options = {k: v for k, v in settings.to_dict().items() if k not in ("threads", "progress")}
    return json.loads(json.dumps({"engines": engines, "seed": int(seed), "sampler": options.pop("sampler"),
                                  "settings": options, "acquisition": acquisition.to_dict()}))


def current_form(stored: dict) -> dict:
    """A drone's recorded :func:`reuse_key` with settings written before the sampler
    plugins had their own (every knob at the top level) read into today's form, so
    that such a posterior is still reused when nothing changed."""
    from ..inference.settings import CalibrationSettings

    flat = stored.get("settings")
    if not isinstance(flat, dict) or "plugins" in flat or "sampler" not in stored:
        return stored
    try:
        now = CalibrationSettings.from_dict({**flat, "sampler": stored["sampler"]}).to_dict()
    except ValueError:
        return stored  # settings no release wrote: compared as they are (and so not reused)
    return {**stored, "settings": {k: v for k, v in now.items() if k not in ("threads", "progress", "sampler")}}


def run_population(args, profiles, drones, settings, acquisition, method: str = "likelihood") -> int:
    """Each drone calibrated on its own (kept beside OUT, reused by a rerun on the same
    data with the same options: :func:`reuse_key`), then the class's population
    (:func:`mdaug.inference.population.result.calibrate_population`). ``method``
    "amortized": each drone's posterior is the trained estimator's (no smc route:
    the population uses the amortized draws), else the closed-form route."""
    import numpy as np

    from ..inference.calibrate import calibrate
    from ..inference.likelihood.base import prepare_measured
    from ..inference.population.result import calibrate_population
    from ..inference.result.posterior import CalibrationResult
    from ..radar import RadarConfig
    from ..radar.seeds import child_seed
    from .calibrate_amortized import predictive_draws

    if args.engines == "auto" and method != "amortized":
        raise ValueError("--population calibrates every drone with one engine count: give --engines N, not auto")
    ids = list(dict.fromkeys(drones.tolist()))
    cls = args.class_name.upper()
    if len(ids) < 2:
        warn("calibrate", f"one drone of {cls} only: the population's spreads are the stated prior (assumed, "
                          "not measured)")
    results = []
    for k, drone in enumerate(ids):
        path, rows = drone_path(args.out, drone), profiles[drones == drone]
        seed = child_seed(args.seed, "drone", drone)
        key = reuse_key(args.engines, seed, settings, acquisition, method, args.estimator)
        res = None
        if path.is_file():
            old = CalibrationResult.load(path, class_name=cls)
            data, _ = prepare_measured(rows, RadarConfig(), settings.normalisation)
            changed = [] if np.array_equal(np.asarray(old.idata.observed_data["y"]), data) else ["measurements"]
            stored = current_form(old.meta.get(REUSE_FIELD) or {})
            changed += ([name for name in key if stored.get(name) != key[name]] if stored
                        else ["options (none recorded)"])
            if not changed:
                res = old
                same = ["measurements", *key]  # what the reuse rests on, for either method
                result(f"drone {drone}: reused {path} (same {', '.join(same[:-1])} and {same[-1]})")
            else:
                info(f"drone {drone}: {path} was calibrated with other {', '.join(changed)}; calibrating again")
        if res is None:
            info(f"drone {drone} ({k + 1} of {len(ids)}): calibrating from {len(rows)} profile(s)")
            if method == "amortized":
                from ..inference.amortized.calibrate import calibrate_amortized
                res = calibrate_amortized(rows, cls, acquisition=acquisition, estimator=args.estimator,
                                          settings=settings, random_state=seed, route=args.route, fit=False,
                                          source=f"{args.measured} (drone {drone})",
                                          **predictive_draws(args)).record_specimens([drone])
            else:
                res = calibrate(rows, cls, engines=args.engines, settings=settings, acquisition=acquisition,
                                random_state=seed, backend_path=Path(f"{path}.chain.h5"),
                                **predictive_draws(args)).record_specimens([drone])
            res.record(**{REUSE_FIELD: key})  # what a rerun must match to reuse this posterior
            res.save(path)
            Path(f"{path}.chain.h5").unlink(missing_ok=True)
            Path(f"{path}.chain.h5.fit.json").unlink(missing_ok=True)
        result(f"drone {drone}: {'converged' if res.converged else 'NOT converged'} ({res.diagnostics['reason']})")
        results.append(res)
    pop = calibrate_population(results, ids, random_state=child_seed(args.seed, "population"))
    pop.save(args.out)
    result(pop.report())
    result(f"wrote {args.out} (and each drone's posterior beside it: {drone_path(args.out, '<id>')})")
    done = pop.converged and all(r.converged for r in results)
    if not done:
        warn("calibrate", f"not converged: {sum(not r.converged for r in results)} drone(s), hyper-posterior "
                          f"{'converged' if pop.converged else 'not converged'}; {args.out} is flagged")
        return 0 if args.allow_unconverged else EXIT_NOT_CONVERGED
    return 0
