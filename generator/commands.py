"""CLI verb of the generator layer: ``mdaug augment`` (sigma_P strategy)."""
from __future__ import annotations

import argparse
from pathlib import Path

from .augment import PHASE_TREATMENTS, SIGN_POLICIES


def csv_list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def add_nuisance_arguments(p: argparse.ArgumentParser) -> None:
    from ..radar import NORMALISATIONS

    g = p.add_argument_group("nuisances and output (SPEC 3.1)")
    g.add_argument("--phases", choices=PHASE_TREATMENTS, default="relative",
                   help="vibration phases: relative (published), uniform on the circle, fixed")
    g.add_argument("--range-jitter", type=float, default=0.0, metavar="BINS",
                   help="uniform sub-bin jitter of the target range, width in FFT bins (default 0)")
    g.add_argument("--ramps", type=int, default=1, metavar="K",
                   help="ramps whose profiles are averaged incoherently (default 1)")
    g.add_argument("--normalisation", choices=NORMALISATIONS, default="peak")
    g.add_argument("--dtype", choices=("float32", "float64"), default="float32",
                   help="compute precision of f(x) (float32 is ~5x faster, error ~1e-7)")


def add_augment_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--classes", type=csv_list, default=["HELI", "QUAD"],
                   help="comma-separated class references (default HELI,QUAD)")
    p.add_argument("--n-per-class", type=int, default=16000)
    p.add_argument("--sigma-p", type=float, default=0.2, help="relative perturbation, 0..1 (default 0.2)")
    p.add_argument("--sign-policy", choices=SIGN_POLICIES, default="reflect",
                   help="what a draw that flips a non-negative parameter's sign becomes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="output NPZ")
    p.add_argument("--plot", type=Path, default=None, help="also write a PNG of the profiles")
    add_nuisance_arguments(p)


def nuisance_from_args(args):
    from .augment import Nuisance

    return Nuisance(phases=args.phases, range_jitter_bins=args.range_jitter, n_ramps=args.ramps)


def sigma_p_augmenters(args, radar=None) -> list:
    from ..radar import RadarConfig
    from .augment import SigmaPAugmenter

    return [SigmaPAugmenter(c, args.sigma_p, sign_policy=args.sign_policy, nuisance=nuisance_from_args(args),
                            normalisation=args.normalisation, dtype=args.dtype, radar=radar or RadarConfig())
            for c in args.classes]


def write_augmented(args, augmenters, extra_settings=None) -> int:
    """Make, save and (optionally) plot a dataset; print one summary line."""
    import time

    from ..radar.io import atomic_write, check_outputs
    from .dataset import make_dataset, save_dataset

    if args.n_per_class <= 0:
        raise ValueError(f"--n-per-class must be a positive integer, got {args.n_per_class}")
    check_outputs(args.out, args.plot)
    t0 = time.perf_counter()
    ds = make_dataset(augmenters, args.n_per_class, args.seed, extra_settings=extra_settings)
    save_dataset(args.out, ds)
    took = time.perf_counter() - t0
    print(f"wrote {args.out}: {len(ds)} profiles x {ds.profiles.shape[1]} bins "
          f"({', '.join(ds.settings['classes'])}; {len(ds) / took:,.0f} profiles/s)")
    if args.plot is not None:
        from ..radar.plots import plot_profiles

        title = f"{ds.settings.get('strategy', '')} sigma_P={ds.settings.get('sigma_p', '-')} seed={args.seed}"
        fig = plot_profiles(ds.profiles, ds.labels, title=title)
        atomic_write(args.plot, lambda fh: fig.savefig(fh, format="png", dpi=110))
        print(f"wrote {args.plot}")
    return 0


def run_augment(args) -> int:
    return write_augmented(args, sigma_p_augmenters(args))


def register(sub) -> None:
    p = sub.add_parser("augment", help="synthesise a training set from class references (sigma_P)",
                       description="Synthesise range profiles by perturbing class reference vectors "
                                   "with the published relative Gaussian (sigma_P).")
    add_augment_arguments(p)
    p.set_defaults(func=run_augment)
