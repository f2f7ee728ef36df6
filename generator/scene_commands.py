"""CLI verb of the scene simulator: ``mdaug simulate``."""
from __future__ import annotations

import argparse
from pathlib import Path


def float_pair(text: str) -> tuple[float, float]:
    parts = [t for t in text.replace(":", ",").split(",") if t.strip()]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH, got {text!r}")
    return float(parts[0]), float(parts[1])


def scene_from_args(args):
    from .scene import SceneConfig

    d = SceneConfig()
    return SceneConfig(
        n_frames=args.frames, n_ramps=args.ramps, snr_db=None if args.no_noise else args.snr_db,
        phases=args.phases, range_m=args.range_m, azimuth_deg=args.azimuth_deg, yaw_deg=args.yaw_deg,
        drift_step_m=args.drift_mm * 1e-3, n_clutter=args.clutter, clutter_db=args.clutter_db,
        quantise=not args.no_adc, specimen_spread=0.0 if args.reference_specimens else args.specimen_spread,
        dtype=args.dtype, body_ratio=d.body_ratio,
    )


def run_simulate(args) -> int:
    import time

    from ..radar import RadarConfig, check_writable
    from ..radar.commands import chain_from_args
    from .scene import simulate_campaign

    check_writable(args.out)
    scene = scene_from_args(args)
    t0 = time.perf_counter()
    camp = simulate_campaign(args.class_name, args.specimens, args.acquisitions, args.seed, scene=scene,
                             radar=RadarConfig(), keep_cubes=args.keep_cubes, chain=chain_from_args(args))
    camp.save(args.out)
    took = time.perf_counter() - t0
    print(f"wrote {args.out}: {len(camp)} simulated {camp.labels[0]} acquisitions of {args.specimens} "
          f"specimen(s), {camp.profiles.shape[1]}-bin profiles{' + raw cubes' if args.keep_cubes else ''} "
          f"({len(camp) / took:,.1f} acquisitions/s; {camp.on_target.mean():.0%} on target)")
    return 0


def register(sub) -> None:
    from ..radar.commands import add_chain_arguments
    from .scene import SCENE_PHASES, SceneConfig

    d = SceneConfig()
    p = sub.add_parser("simulate", help="simulate a measurement campaign (raw FMCW acquisitions -> profiles)",
                       description="Scene simulator: drone specimens of a class around its reference, "
                                   "acquisitions with random phases, yaw, range, azimuth, hover drift, body, "
                                   "clutter, noise and 12-bit ADC, processed by the published chain.")
    p.add_argument("--class", dest="class_name", required=True, help="class reference (HELI or QUAD)")
    p.add_argument("--specimens", type=int, default=1, help="drones of the class (default 1)")
    p.add_argument("--acquisitions", type=int, required=True, help="acquisitions in total (over all specimens)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="output NPZ (profiles + labels + truth + settings)")
    p.add_argument("--keep-cubes", action="store_true", help="also store the raw cubes (field 'cubes')")
    g = p.add_argument_group("scene (defaults: the default SceneConfig)")
    g.add_argument("--snr-db", type=float, default=d.snr_db,
                   help=f"target/noise power per IF sample, dB (default {d.snr_db})")
    g.add_argument("--no-noise", action="store_true", help="no receiver noise")
    g.add_argument("--ramps", type=int, default=d.n_ramps, metavar="K", help=f"ramps per frame (default {d.n_ramps})")
    g.add_argument("--frames", type=int, default=None, help="frames per acquisition (default mti_depth + 1)")
    g.add_argument("--phases", choices=SCENE_PHASES, default=d.phases, help="vibration phases per frame")
    g.add_argument("--range-m", type=float_pair, default=d.range_m, metavar="LO,HI", help="target range, m")
    g.add_argument("--azimuth-deg", type=float_pair, default=d.azimuth_deg, metavar="LO,HI",
                   help="azimuth range, deg (write --azimuth-deg=-30,30: a leading minus needs the =)")
    g.add_argument("--yaw-deg", type=float, default=d.yaw_deg, help="yaw uniform in +- this (deg)")
    g.add_argument("--drift-mm", type=float, default=d.drift_step_m * 1e3, help="hover drift step per frame, mm")
    g.add_argument("--clutter", type=int, default=d.n_clutter, help="static clutter scatterers")
    g.add_argument("--clutter-db", type=float_pair, default=d.clutter_db, metavar="LO,HI",
                   help="clutter amplitude relative to the target, dB (--clutter-db=-10,10)")
    g.add_argument("--no-adc", action="store_true", help="keep float samples (no gain control / 12-bit codes)")
    g.add_argument("--specimen-spread", type=float, default=d.specimen_spread,
                   help="multiplier of all specimen spreads (default 1)")
    g.add_argument("--reference-specimens", action="store_true", help="every specimen is the class reference")
    g.add_argument("--dtype", choices=("float32", "float64"), default=d.dtype)
    add_chain_arguments(p)
    p.set_defaults(func=run_simulate)
