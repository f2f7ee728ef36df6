"""``mdaug augment``: synthesise a training set, sigma_P or from calibrated posteriors.

Options of the augmenters belong here; the nuisance/acquisition options shared with
``mdaug sweep`` are in :func:`.common.add_nuisance_options`.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import (SIGN_POLICIES, add_nuisance_options, add_verb, class_list, info, nuisance_from_args,
                     positive_int, result, seed_int, unit_fraction, warn)

DEFAULT_CLASSES = ("HELI", "QUAD")
DEFAULT_SIGMA_P = 0.2


def posterior_arg(text: str) -> tuple[str, Path]:
    name, sep, path = text.partition("=")
    if not sep or not name.strip() or not path.strip():
        raise argparse.ArgumentTypeError(f"expected CLASS=FILE (e.g. HELI=post_heli.nc), got {text!r}")
    return name.strip().upper(), Path(path.strip())


def augmenters_from_args(args) -> tuple[list, dict | None]:
    """The augmenters the options ask for, and the settings they add to the file."""
    from ..radar import RadarConfig

    nuisance = nuisance_from_args(args)
    if args.posterior:
        from ..inference import PosteriorAugmenter

        if args.classes is not None or args.sigma_p is not None:
            given = [o for o, v in (("--classes", args.classes), ("--sigma-p", args.sigma_p)) if v is not None]
            raise ValueError(f"--posterior draws from the posteriors' classes; drop {' and '.join(given)}")
        names = [c for c, _ in args.posterior]
        if len(set(names)) != len(names):
            raise ValueError(f"--posterior names a class twice: {names}")
        augs = [PosteriorAugmenter(path, label=cls, nuisance=nuisance, normalisation=args.normalisation,
                                   dtype=args.dtype) for cls, path in args.posterior]
        for a in augs:
            if not a.posterior.converged:
                warn("augment", f"posterior of {a.label} ({a.source}) did not converge: "
                                f"{a.posterior.diagnostics['reason']}")
        return augs, {"strategy": "posterior", "posteriors": {c: str(p) for c, p in args.posterior}}
    from ..generator import SigmaPAugmenter

    sigma_p = DEFAULT_SIGMA_P if args.sigma_p is None else args.sigma_p
    classes = list(DEFAULT_CLASSES) if args.classes is None else args.classes
    return [SigmaPAugmenter(c, sigma_p, sign_policy=args.sign_policy, nuisance=nuisance,
                            normalisation=args.normalisation, dtype=args.dtype, radar=RadarConfig())
            for c in classes], None


def run_augment(args) -> int:
    import time

    from ..generator.dataset import check_dataset_memory, make_dataset, save_dataset
    from ..radar import atomic_write, check_outputs
    from ..radar.progress import progress_enabled

    check_outputs(args.out, args.plot)
    augmenters, extra = augmenters_from_args(args)
    check_dataset_memory(augmenters, args.n_per_class, what="--n-per-class")
    info(f"synthesising {args.n_per_class:,} profiles per class of {', '.join(a.label for a in augmenters)}")
    t0 = time.perf_counter()
    ds = make_dataset(augmenters, args.n_per_class, args.seed, extra_settings=extra,
                      progress=None if progress_enabled() else False)  # None: a bar for large sets
    save_dataset(args.out, ds)
    took = time.perf_counter() - t0
    result(f"wrote {args.out}: {len(ds)} profiles x {ds.profiles.shape[1]} bins "
           f"({', '.join(ds.settings['classes'])}; {len(ds) / took:,.0f} profiles/s)")
    if args.plot is not None:
        import matplotlib.pyplot as plt

        from ..radar.plots import plot_profiles

        title = f"{ds.settings.get('strategy', '')} sigma_P={ds.settings.get('sigma_p', '-')} seed={args.seed}"
        fig = plot_profiles(ds.profiles, ds.labels, title=title)
        try:
            atomic_write(args.plot, lambda fh: fig.savefig(fh, format="png", dpi=110))
        finally:
            plt.close(fig)
        result(f"wrote {args.plot}")
    return 0


def _interrupted(args) -> str:
    return "nothing was written; augment does not resume, run it again to start over"


def add_augment(sub, parents, help):
    p = add_verb(sub, "augment", parents, help=help, interrupted=_interrupted,
                 description="Synthesise range profiles: by perturbing the class reference vectors with the "
                             "published relative Gaussian (sigma_P), or by drawing from calibrated posteriors "
                             "(--posterior). Writes one NPZ (profiles, labels, the parameter vectors, settings); "
                             "it appears only when complete.")
    g = p.add_argument_group("strategy")
    g.add_argument("--classes", type=class_list, default=None, metavar="LIST",
                   help="sigma_P: comma-separated class references (default: HELI,QUAD)")
    g.add_argument("--sigma-p", type=unit_fraction, default=None, metavar="S",
                   help=f"sigma_P: relative perturbation x_i + N(0, S |x_i|), 0..1 (default: {DEFAULT_SIGMA_P})")
    g.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect",
                   help="sigma_P: a draw that flips a non-negative parameter's sign is reflected to |x|, "
                        "redrawn (truncate) or kept (default: %(default)s)")
    g.add_argument("--posterior", type=posterior_arg, action="append", default=None, metavar="CLASS=FILE",
                   help="draw from a calibrated posterior NetCDF instead of sigma_P; repeat per class "
                        "(default: none, i.e. sigma_P)")
    g = p.add_argument_group("size and output")
    g.add_argument("--n-per-class", type=positive_int, default=16000, metavar="N",
                   help="profiles per class (16000 x 2 classes is the published 32,000; about 1.6 KB of "
                        "memory each) (default: %(default)s)")
    g.add_argument("--seed", type=seed_int, default=0,
                   help="random seed; the same seed gives the same file bytes (default: %(default)s)")
    g.add_argument("--out", type=Path, required=True, help="output NPZ")
    g.add_argument("--plot", type=Path, default=None, help="also write a PNG of the profiles (default: none)")
    add_nuisance_options(p)
    p.set_defaults(func=run_augment)
    return p


VERBS = {
    "augment": ("synthesise a training set (sigma_P, or from calibrated posteriors)", add_augment),
}
