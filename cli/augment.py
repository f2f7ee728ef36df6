"""``mdaug augment``: synthesise a training set from class vectors rendered through an acquisition.

Sources of class vectors: sigma_P around the packaged references (``--classes``),
sigma_P around a calibration's best fit (``--fit CLASS=post.nc``), posterior draws
(``--posterior CLASS=post.nc``), new drones from a population (``--population
CLASS=pop.npz``); any of them widened by the specimen model
(``--specimen-width``). One source per class; sources mix (``--posterior
HELI=post.nc --classes QUAD``: the classes of ``--classes`` then render under the
calibration's acquisition). A set of one class is refused unless
``--allow-one-class``. They are rendered under the acquisition (the calibration's
by default, with the carrier and noise it measured; options in
:func:`.common.add_acquisition_options`), by the fast path or through the scene
simulator and the radar chain (``--through-chain``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import (SAMPLES, SECONDS_CHAIN_RAMP, SECONDS_FAST_RAMP, add_verb, check_size, class_list, info,
                     nonneg_float, positive_int, ramps_factor, result, seed_int, unit_fraction, warn)
from .options import SIGN_POLICIES, acquisition_from_args, acquisition_given, add_acquisition_options

DEFAULT_CLASSES = ("HELI", "QUAD")
DEFAULT_SIGMA_P = 0.2


def posterior_arg(text: str) -> tuple[str, Path]:
    name, sep, path = text.partition("=")
    if not sep or not name.strip() or not path.strip():
        raise argparse.ArgumentTypeError(f"expected CLASS=FILE (e.g. HELI=post_heli.nc), got {text!r}")
    return name.strip().upper(), Path(path.strip())


def augmenters_from_args(args) -> tuple[list, dict | None, list[str]]:
    """The augmenters the options ask for (through the strategy registry,
    :mod:`mdaug.strategies`: ``--classes`` is sigma_p_published, ``--fit`` sigma_p_fit,
    ``--posterior`` posterior), the settings they add to the file, and the warnings to
    print once every check has passed."""
    from ..inference.result.augment import load_posterior
    from ..strategies import STRATEGIES, TrainingSpec, augmenter

    fits, posts, pops = args.fit or [], args.posterior or [], args.population or []
    names = [c for c, _ in fits + posts + pops]
    if len(set(names)) != len(names):
        raise ValueError(f"--fit/--posterior/--population name a class twice: {names}")
    refs = [] if args.classes is None else args.classes  # sigma_P around the references, beside the files
    both = sorted(set(names) & set(refs))
    if both:
        raise ValueError(f"--classes {','.join(refs)} names {', '.join(both)}, which --fit/--posterior/--population "
                         "already give: one source per class")
    if pops and args.specimen_width is not None:
        raise ValueError("--specimen-width applies to --fit, --posterior and --classes, not to --population (a "
                         "population's new drones already spread as its measured drones do; the two spreads would "
                         "stack)")
    if pops and args.sigma_p is not None and not (fits or refs):
        raise ValueError("--sigma-p applies to sigma_P sources (--classes or --fit), not to --population")
    if posts and args.sigma_p is not None and not (fits or refs):
        raise ValueError("--sigma-p applies to sigma_P sources (--classes or --fit), not to --posterior")
    sigma_p = DEFAULT_SIGMA_P if args.sigma_p is None else args.sigma_p

    def spec(name, perturb):
        return TrainingSpec(name, sigma_p=sigma_p if STRATEGIES[name].parameter == "sigma_p" else None,
                            width=args.specimen_width, normalisation=args.normalisation,
                            through_chain=args.through_chain, sign_policy=args.sign_policy, perturb_phases=perturb,
                            dtype=args.dtype)

    augs, warnings = [], []
    if names:
        for cls, path in fits + posts:
            post = load_posterior(path, cls)
            if not post.converged:
                warnings.append(f"posterior of {cls} ({path}) did not converge: {post.diagnostics['reason']}")
            acq, _ = acquisition_from_args(args, post.measured_acquisition())
            # sigma_p_fit perturbs the phases only when asked (--phases relative), as in the study
            s = spec("sigma_p_fit", args.phases == "relative") if (cls, path) in fits else spec("posterior", None)
            augs.append(augmenter(s, cls, calibration=post, acquisition=acq))
        for cls, path in pops:
            pop = STRATEGIES["population"].load(path, cls)
            from ..inference.sanity import check_unique_drones

            check_unique_drones(pop.meta["specimens"], str(path), "field 'meta' key 'specimens'")
            if not pop.converged or not all(pop.meta["drones_converged"]):
                warnings.append(f"population of {cls} ({path}) was built from unconverged calibrations "
                                "(see mdaug calibrate's report); its spreads may be too wide")
            if pop.assumed:
                warnings.append(f"population of {cls} ({path}) is of one drone: its spreads are assumed (the stated "
                                "prior), not measured")
            acq, _ = acquisition_from_args(args, pop.measured_acquisition())
            augs.append(augmenter(spec("population", None), cls, calibration=pop, acquisition=acq))
        kinds = ["sigma_p_fit" if f in fits else "posterior" for f in fits + posts] + ["population"] * len(pops)
        if refs:  # the other classes around their references, under the first calibration's acquisition
            acq, perturb = acquisition_from_args(args, augs[0].renderer.acquisition)
            augs += [augmenter(spec("sigma_p_published", perturb), c, acquisition=acq) for c in refs]
            kinds += ["sigma_p_published"]
        extra = {"strategy": "+".join(sorted({STRATEGIES[k].label for k in kinds})),
                 "posteriors": {c: str(p) for c, p in fits + posts + pops}}
        if refs:
            extra["references"] = list(refs)
    else:
        acq, perturb = acquisition_from_args(args)
        classes = list(DEFAULT_CLASSES) if args.classes is None else args.classes
        augs = [augmenter(spec("sigma_p_published", perturb), c, acquisition=acq) for c in classes]
        extra = {"strategy": STRATEGIES["sigma_p_published"].label}
    if args.specimen_width is not None:
        extra["specimens"] = augs[0].source.spread.to_dict()
    extra["acquisition_from"] = "options" if acquisition_given(args) else ("calibration" if names else "default")
    return augs, extra, warnings


def check_augment_sizes(args, augmenters) -> None:
    """The ramps (the chain's included) and the counts against memory and time."""
    n = ("--n-per-class", args.n_per_class, 16000)
    files = [path for _, path in (args.fit or []) + (args.posterior or []) + (args.population or [])]
    for k, aug in enumerate(augmenters):  # in the order augmenters_from_args made them: fits, posteriors, populations
        acq, e = aug.renderer.acquisition, aug.n_engines
        ramps = ramps_factor("--ramps" if args.ramps is not None or k >= len(files) else
                             f"{files[k]}: acquisition field 'ramps'", acq.ramps)
        if args.through_chain:
            frames = ("--mti-depth (+ 1 frames)", acq.mti_depth + 1, 11)
            check_size(ramps, frames, bytes_each=e * SAMPLES * 8 * 4, what="ramp frames of one profile")
            check_size(n, ramps, frames, seconds_each=e * SECONDS_CHAIN_RAMP / 11, what=f"{aug.label} ramp frames")
        else:
            check_size(n, ramps, seconds_each=e * SECONDS_FAST_RAMP, what=f"{aug.label} rendered ramps")


def check_two_classes(args, augmenters) -> None:
    """A training set of one class teaches a classifier nothing: refused before any work
    unless ``--allow-one-class`` (e.g. one class now, the other in a later file)."""
    if len(augmenters) >= 2 or args.allow_one_class:
        return
    (aug,) = augmenters
    source = next((f"--{opt} {cls}={path}" for opt in ("fit", "posterior", "population")
                   for cls, path in (getattr(args, opt) or []) if cls == aug.label), f"--classes {aug.label}")
    other = next((c for c in DEFAULT_CLASSES if c != aug.label), "OTHER")
    raise ValueError(f"{source}: the set would hold one class only ({aug.label}); give the other class a source "
                     f"(--posterior {other}=FILE, --fit {other}=FILE, --population {other}=FILE, or --classes "
                     f"{other}: sigma_P around its reference), or --allow-one-class to write it anyway")


def run_augment(args) -> int:
    import time

    from ..generator.dataset import check_dataset_memory, make_dataset, save_dataset
    from ..radar.progress import progress_enabled
    from .guard import Output, check_paths

    check_paths(inputs=[(f"--{opt} {cls}=", path) for opt in ("fit", "posterior", "population")
                        for cls, path in (getattr(args, opt) or [])],
                outputs=[Output("--out", args.out, "npz"), Output("--plot", args.plot, "plot")],
                overwrite=args.overwrite)
    augmenters, extra, warnings = augmenters_from_args(args)
    check_dataset_memory(augmenters, args.n_per_class, what="--n-per-class")
    check_augment_sizes(args, augmenters)
    check_two_classes(args, augmenters)
    for text in warnings:
        warn("augment", text)
    info(f"synthesising {args.n_per_class:,} profiles per class of {', '.join(a.label for a in augmenters)}")
    t0 = time.perf_counter()
    ds = make_dataset(augmenters, args.n_per_class, args.seed, extra_settings=extra,
                      progress=None if progress_enabled() else False)  # None: a bar for large sets
    save_dataset(args.out, ds)
    took = time.perf_counter() - t0
    result(f"wrote {args.out}: {len(ds)} profiles x {ds.profiles.shape[1]} bins "
           f"({', '.join(ds.settings['classes'])}; {len(ds) / took:,.0f} profiles/s)")
    if args.plot is not None:
        from ..radar.plots import plot_profiles, save_figure

        title = f"{ds.settings.get('strategy', '')} sigma_P={ds.settings.get('sigma_p', '-')} seed={args.seed}"
        fig = plot_profiles(ds.profiles, ds.labels, title=title)
        save_figure(fig, args.plot)
        result(f"wrote {args.plot}")
    return 0


def _interrupted(args) -> str:
    return "nothing was written; augment does not resume, run it again to start over"


def add_augment(sub, parents, help):
    p = add_verb(sub, "augment", parents, help=help, interrupted=_interrupted,
                 description="Synthesise range profiles: class vectors (sigma_P around the references or a "
                             "calibrated best fit, or posterior draws, optionally widened for other specimens) "
                             "rendered through the acquisition (the calibration's by default). Writes one NPZ "
                             "(profiles, labels, the parameter vectors, settings, the acquisition); it appears only "
                             "when complete.")
    g = p.add_argument_group("class vectors")
    g.add_argument("--classes", type=class_list, default=None, metavar="LIST",
                   help="sigma_P around these packaged class references, comma-separated; beside --fit/"
                        "--posterior/--population, the classes they do not give (rendered under the "
                        "calibration's acquisition) (default: HELI,QUAD when no --fit/--posterior/--population)")
    g.add_argument("--fit", type=posterior_arg, action="append", default=None, metavar="CLASS=FILE",
                   help="sigma_P around the calibrated best fit of a posterior NetCDF (the published method on "
                        "your measurements); repeat per class (default: none)")
    g.add_argument("--sigma-p", type=unit_fraction, default=None, metavar="S",
                   help=f"sigma_P: relative perturbation x_i + N(0, S |x_i|), 0..1 (default: {DEFAULT_SIGMA_P})")
    g.add_argument("--specimen-width", type=nonneg_float, default=None, metavar="W",
                   help="widen every source by the specimen model (common motor-speed factor 5%%, amplitudes "
                        "15%%, ... times W) for drones other than the one calibrated (default: none)")
    g.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect",
                   help="sigma_P: a draw that flips a non-negative parameter's sign is reflected to |x|, "
                        "redrawn (truncate) or kept (default: %(default)s)")
    g.add_argument("--posterior", type=posterior_arg, action="append", default=None, metavar="CLASS=FILE",
                   help="draw from a calibrated posterior NetCDF; repeat per class (default: none)")
    g.add_argument("--population", type=posterior_arg, action="append", default=None, metavar="CLASS=FILE",
                   help="new drones from a class's population NPZ (mdaug calibrate --population); repeat per "
                        "class (default: none)")
    g.add_argument("--through-chain", action="store_true",
                   help="render each vector as a raw acquisition of the scene simulator processed by the radar "
                        "chain (MTI, angle integration, extraction), about 2 ms per profile at K = 32 (default: "
                        "the fast path, f(x) under the acquisition)")
    g = p.add_argument_group("size and output")
    g.add_argument("--n-per-class", type=positive_int, default=16000, metavar="N",
                   help="profiles per class (16000 x 2 classes is the published 32,000; about 1.6 KB of "
                        "memory each) (default: %(default)s)")
    g.add_argument("--seed", type=seed_int, default=0,
                   help="random seed; the same seed gives the same file bytes (default: %(default)s)")
    g.add_argument("--out", type=Path, required=True, help="output NPZ")
    g.add_argument("--plot", type=Path, default=None, help="also write a PNG of the profiles (default: none)")
    g.add_argument("--allow-one-class", action="store_true",
                   help="write a set of one class (default: refuse it; a classifier needs two)")
    add_acquisition_options(p)
    p.set_defaults(func=run_augment)
    return p


VERBS = {
    "augment": ("synthesise a training set (sigma_P, a calibrated fit or posterior, through the acquisition)",
                add_augment),
}
