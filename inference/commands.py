"""CLI verbs of the inference layer: ``mdaug calibrate`` and ``augment --posterior``.

``calibrate`` exit status: 0 when the chain converged (>= 50 tau), 3 when it did
not (the posterior is still written, flagged not converged in the file and on
stderr) unless ``--allow-unconverged`` is given, 2 on bad input.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_NOT_CONVERGED = 3


def engines_arg(text: str):
    if text == "auto":
        return "auto"
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--engines must be a positive integer or 'auto', got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"--engines must be >= 1, got {value}")
    return value


def posterior_arg(text: str) -> tuple[str, Path]:
    name, sep, path = text.partition("=")
    if not sep or not name.strip() or not path.strip():
        raise argparse.ArgumentTypeError(f"--posterior expects CLASS=FILE (e.g. HELI=post_heli.nc), got {text!r}")
    return name.strip().upper(), Path(path.strip())


def run_calibrate(args) -> int:
    from ..radar import load_profiles
    from ..radar.io import check_outputs
    from .calibrate import calibrate
    from .settings import CalibrationSettings

    check_outputs(args.out, args.corner, args.trace)
    data = load_profiles(args.measured)
    profiles = data.select(args.class_name.upper() if args.class_name.upper() in data.classes else args.class_name)
    base = CalibrationSettings.quick() if args.quick else CalibrationSettings()
    overrides = {k: v for k, v in {"max_steps": args.max_steps, "fit_budget": args.fit_budget,
                                   "n_starts": args.starts, "n_walkers": args.walkers,
                                   "fit_algorithm": args.fit_algorithm, "normalisation": args.normalisation,
                                   "sampler": args.sampler, "n_particles": args.particles}.items()
                 if v is not None}
    settings = base.replace(threads=args.threads, progress=args.progress, range_offset=not args.no_range_offset,
                            **overrides)
    backend = args.backend if args.backend is not None else Path(f"{args.out}.chain.h5")
    print(f"calibrating {args.class_name.upper()} from {len(profiles)} profile(s) of {args.measured} "
          f"(engines {args.engines or 'reference'}, seed {args.seed}; chain checkpoint {backend})")
    res = calibrate(profiles, args.class_name.upper(), engines=args.engines, settings=settings,
                    random_state=args.seed, backend_path=backend)
    res.save(args.out)
    print(res.report())
    print(f"wrote {args.out}")
    if args.corner is not None:
        res.plot_corner(args.corner)
        print(f"wrote {args.corner}")
    if args.trace is not None:
        res.plot_trace(args.trace)
        print(f"wrote {args.trace}")
    if args.backend is None:  # the default checkpoint is captured in the NetCDF now
        for p in Path(backend).parent.glob(Path(backend).name + "*"):
            p.unlink()
    if not res.converged:
        print(f"mdaug calibrate: WARNING: the chain did not converge ({res.diagnostics['reason']}); "
              f"{args.out} is flagged not converged", file=sys.stderr)
        return 0 if args.allow_unconverged else EXIT_NOT_CONVERGED
    return 0


def run_augment_posterior(args) -> int:
    from ..generator import commands as gen

    if not args.posterior:
        return gen.run_augment(args)
    from .posterior_augment import PosteriorAugmenter

    names = [c for c, _ in args.posterior]
    if len(set(names)) != len(names):
        raise ValueError(f"--posterior names a class twice: {names}")
    augs = [PosteriorAugmenter(path, label=cls, nuisance=gen.nuisance_from_args(args),
                               normalisation=args.normalisation, dtype=args.dtype)
            for cls, path in args.posterior]
    for a in augs:
        if not a.posterior.converged:
            print(f"mdaug augment: WARNING: posterior of {a.label} ({a.source}) did not converge: "
                  f"{a.posterior.diagnostics['reason']}", file=sys.stderr)
    return gen.write_augmented(args, augs, extra_settings={
        "strategy": "posterior", "posteriors": {c: str(p) for c, p in args.posterior}})


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="calibrate a class from measured profiles (fit + MCMC posterior)",
                       description="Fit the class's parameter vector to measured profiles (nlopt, several starts) "
                                   "and sample its posterior (emcee until 50 autocorrelation times, or tempered SMC "
                                   "with --sampler smc). Exit status 3 when the sampler did not converge (output "
                                   "written, flagged).")
    p.add_argument("measured", type=Path, help="measured profiles (NPZ/CSV/.mat with profiles and labels)")
    p.add_argument("--class", dest="class_name", required=True, help="class label to calibrate (e.g. HELI)")
    p.add_argument("--engines", type=engines_arg, default=None, help="1, 4, ... or auto (default: the reference's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="posterior NetCDF (arviz InferenceData)")
    p.add_argument("--corner", type=Path, default=None, help="corner plot PNG")
    p.add_argument("--trace", type=Path, default=None, help="trace plot PNG")
    p.add_argument("--quick", action="store_true", help="short run (seconds; usually not converged)")
    p.add_argument("--backend", type=Path, default=None,
                   help="HDF5 chain checkpoint (default OUT.chain.h5, removed after success); rerun to resume")
    p.add_argument("--max-steps", type=int, default=None)
    p.add_argument("--fit-budget", type=int, default=None, help="objective evaluations per global start")
    p.add_argument("--starts", type=int, default=None, help="global fit starts")
    p.add_argument("--walkers", type=int, default=None)
    p.add_argument("--sampler", choices=("emcee", "smc"), default=None,
                   help="emcee (default: ensemble from the fit, 50 tau) or smc (tempered SMC from the prior with "
                        "mode jumps: for multimodal posteriors, gives the evidence)")
    p.add_argument("--particles", type=int, default=None, help="SMC particles (default max(500, 40 x dim))")
    p.add_argument("--fit-algorithm", default=None, help="nlopt global algorithm (default GN_CRS2_LM)")
    p.add_argument("--normalisation", default=None, choices=("peak", "db", "l2", "none"))
    p.add_argument("--no-range-offset", action="store_true", help="do not fit a sub-bin range offset")
    p.add_argument("--progress", action="store_true", help="progress bar")
    p.add_argument("--allow-unconverged", action="store_true", help="exit 0 even when the chain did not converge")
    p.set_defaults(func=run_calibrate)

    aug = sub.choices["augment"]
    aug.add_argument("--posterior", type=posterior_arg, action="append", default=None, metavar="CLASS=FILE",
                     help="draw from a calibrated posterior (repeat per class; replaces --classes/--sigma-p)")
    aug.set_defaults(func=run_augment_posterior)
