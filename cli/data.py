"""Measured-data verbs: ``mdaug simulate`` (scene simulator) and ``mdaug process``
(raw FMCW acquisitions through the published chain)."""
from __future__ import annotations

from pathlib import Path

from .common import (BYTES_SPECTRUM, CHAIN_ANTENNAS, SAMPLES, SECONDS_SCENE_RAMP, add_verb, check_size, class_list,
                     finite_float, float_pair, info, nonneg_float, nonneg_int, nothing_written, positive_int, ramps_factor,
                     result, seed_int)
from .options import DTYPES, add_chain_options, chain_from_args

SCENE_PHASES = ("fixed", "uniform")  # checked against mdaug.generator.chain.SCENE_PHASES in tests


def _pair(v) -> str:
    return f"{v[0]:g},{v[1]:g}"


# ---- simulate ------------------------------------------------------------------------------
def scene_from_args(args):
    from ..generator.chain import SceneConfig

    d = SceneConfig()
    return SceneConfig(
        acquisition=d.acquisition.replace(ramps=args.ramps, phases=args.phases, yaw_deg=args.yaw_deg),
        specimens=d.specimens.replace(width=0.0 if args.reference_specimens else args.specimen_spread),
        n_frames=args.frames, snr_db=None if args.no_noise else args.snr_db,
        range_m=args.range_m, azimuth_deg=args.azimuth_deg,
        drift_step_m=args.drift_mm * 1e-3, n_clutter=args.clutter, clutter_db=args.clutter_db,
        quantise=not args.no_adc, dtype=args.dtype,
    )


def check_simulate_sizes(args, frames: int) -> None:
    """Every size option of simulate against memory and time (before any work)."""
    if args.specimens > args.acquisitions:
        raise ValueError(f"--specimens {args.specimens:,} exceeds --acquisitions {args.acquisitions:,}: every "
                         "specimen needs at least one acquisition")
    n_classes = len(args.class_name)
    acq = ("--acquisitions", args.acquisitions, 100)
    ramps, frm = ramps_factor("--ramps", args.ramps), ("--frames", frames, 11)
    chunk = min(args.acquisitions, 8)  # acquisitions rendered together (generator.chain.CHUNK_ACQ)
    check_size(ramps, frm, bytes_each=chunk * CHAIN_ANTENNAS * SAMPLES * 8 * 2, what="ramp frames in memory at once")
    check_size(("--n-angle", args.n_angle, 64), frm, bytes_each=chunk * BYTES_SPECTRUM, what="angle-range images")
    if args.keep_cubes:
        check_size(acq, ramps, frm, bytes_each=n_classes * CHAIN_ANTENNAS * SAMPLES * 4, what="stored ramp frames")
    check_size(acq, ramps, frm, seconds_each=n_classes * SECONDS_SCENE_RAMP, what="simulated ramp frames")
    clutter = ("--clutter", args.clutter, 10)
    check_size(clutter, bytes_each=chunk * SAMPLES * 16 * 3 + args.acquisitions * 32, what="clutter scatterers")
    check_size(acq, clutter, seconds_each=n_classes * CHAIN_ANTENNAS * SAMPLES * 1e-9, what="clutter returns")


def run_simulate(args) -> int:
    import time

    from ..generator import load_reference
    from ..generator.chain import save_campaigns, simulate_campaign
    from ..radar import RadarConfig
    from ..radar.seeds import child_seed
    from .guard import Output, check_paths

    check_paths(outputs=[Output("--out", args.out, "npz")], overwrite=args.overwrite)
    radar = RadarConfig()
    for cls in args.class_name:
        load_reference(cls)  # unknown class: fail before any work
    lo, hi = args.range_m
    if lo <= 0 or hi > radar.max_range_m:
        raise ValueError(f"--range-m {lo:g},{hi:g}: the target range must lie in (0, {radar.max_range_m:.2f}] m "
                         "(the chain's unambiguous range)")
    frames = radar.mti_depth + 1
    if args.frames is not None and args.frames < frames:
        raise ValueError(f"--frames {args.frames}: the MTI needs at least mti_depth + 1 = {frames} frames")
    check_simulate_sizes(args, args.frames or frames)
    scene, chain = scene_from_args(args), chain_from_args(args)
    classes = args.class_name
    t0, camps = time.perf_counter(), []
    for cls in classes:  # one class: the seed itself; several: a child seed per class
        seed = args.seed if len(classes) == 1 else child_seed(args.seed, "simulate", cls)
        info(f"simulating {args.acquisitions} {cls} acquisition(s) of {args.specimens} specimen(s) (seed {seed})")
        camps.append(simulate_campaign(cls, args.specimens, args.acquisitions, seed, scene=scene, radar=radar,
                                       keep_cubes=args.keep_cubes, chain=chain))
    save_campaigns(args.out, camps)
    took = time.perf_counter() - t0
    n = sum(len(c) for c in camps)
    on_target = sum(c.on_target.sum() for c in camps) / n
    what = (f"{n} simulated {camps[0].labels[0]} acquisitions of {args.specimens} specimen(s)" if len(camps) == 1 else
            f"{n} simulated acquisitions ({', '.join(f'{len(c)} {c.labels[0]}' for c in camps)}) of "
            f"{args.specimens} specimen(s) per class")
    result(f"wrote {args.out}: {what}, {camps[0].profiles.shape[1]}-bin profiles"
           f"{' + raw cubes' if args.keep_cubes else ''} ({n / took:,.1f} acquisitions/s; {on_target:.0%} on target)")
    return 0


def add_simulate(sub, parents, help):
    from ..generator.chain import SceneConfig

    d = SceneConfig()
    p = add_verb(sub, "simulate", parents, help=help, interrupted=nothing_written,
                 description="Scene simulator: drone specimens of a class around its reference, acquisitions "
                             "with random phases, yaw, range, azimuth, hover drift, body, clutter, noise and "
                             "12-bit ADC, processed by the published chain. Writes profiles + labels + the true "
                             "parameters + settings (NPZ).")
    p.add_argument("--class", dest="class_name", type=class_list, required=True, metavar="CLASS[,CLASS]",
                   help="class reference(s) to simulate: HELI, QUAD, or HELI,QUAD for one file of both classes "
                        "(each its own campaign from a child of the seed)")
    p.add_argument("--acquisitions", type=positive_int, required=True, metavar="N",
                   help="acquisitions per class, spread evenly over the specimens")
    p.add_argument("--specimens", type=positive_int, default=1, metavar="N",
                   help="drones per class, each drawn around the reference, at most --acquisitions "
                        "(default: %(default)s)")
    p.add_argument("--seed", type=seed_int, default=0, help="random seed of the whole campaign (default: %(default)s)")
    p.add_argument("--out", type=Path, required=True, help="output NPZ (profiles, labels, truth, settings)")
    p.add_argument("--keep-cubes", action="store_true", help="also store the raw cubes (field 'cubes')")
    g = p.add_argument_group("scene")
    g.add_argument("--snr-db", type=finite_float, default=d.snr_db, metavar="DB",
                   help="target to receiver-noise power per IF sample, dB (default: %(default)s dB)")
    g.add_argument("--no-noise", action="store_true", help="no receiver noise (overrides --snr-db)")
    g.add_argument("--ramps", type=positive_int, default=d.acquisition.ramps, metavar="K",
                   help="ramps per frame, averaged incoherently by the chain (default: %(default)s)")
    g.add_argument("--frames", type=positive_int, default=None, metavar="N",
                   help="frames per acquisition, at least mti_depth + 1 (default: mti_depth + 1 = 11, one "
                        "MTI frame)")
    g.add_argument("--phases", choices=SCENE_PHASES, default=d.acquisition.phases,
                   help="vibration phases per frame: uniform (random) or fixed (default: %(default)s)")
    g.add_argument("--range-m", type=float_pair, default=d.range_m, metavar="LO,HI",
                   help=f"target range, uniform in LO..HI, m (default: {_pair(d.range_m)} m)")
    g.add_argument("--azimuth-deg", type=float_pair, default=d.azimuth_deg, metavar="LO,HI",
                   help="target azimuth, uniform in LO..HI, degrees; write --azimuth-deg=-30,30 (a leading "
                        f"minus needs the =) (default: {_pair(d.azimuth_deg)} deg)")
    g.add_argument("--yaw-deg", type=nonneg_float, default=d.acquisition.yaw_deg, metavar="DEG",
                   help="drone yaw, uniform in +- this, degrees (default: %(default)s deg)")
    g.add_argument("--drift-mm", type=nonneg_float, default=d.drift_step_m * 1e3, metavar="MM",
                   help="hover drift step per frame, mm (default: %(default)s mm)")
    g.add_argument("--clutter", type=nonneg_int, default=d.n_clutter, metavar="N",
                   help="static clutter scatterers (default: %(default)s)")
    g.add_argument("--clutter-db", type=float_pair, default=d.clutter_db, metavar="LO,HI",
                   help="clutter amplitude relative to the target, uniform in LO..HI, dB; write "
                        f"--clutter-db=-10,10 (default: {_pair(d.clutter_db)} dB)")
    g.add_argument("--no-adc", action="store_true", help="keep float samples (no gain control, no 12-bit codes)")
    g.add_argument("--specimen-spread", type=nonneg_float, default=d.specimens.width, metavar="X",
                   help="multiplier of every specimen-to-specimen spread (default: %(default)s)")
    g.add_argument("--reference-specimens", action="store_true",
                   help="every specimen is the class reference itself (spread 0)")
    g.add_argument("--dtype", choices=DTYPES, default=d.dtype,
                   help="precision of the simulated IF samples (default: %(default)s)")
    add_chain_options(p)
    p.set_defaults(func=run_simulate)
    return p


# ---- process -------------------------------------------------------------------------------
def run_process(args) -> int:
    import json
    import time

    import numpy as np

    from ..radar import DataFileError, RadarConfig, atomic_savez
    from ..radar.chain import process_cube
    from ..radar.progress import progress_bar
    from ..radar.raw import read_raw
    from .guard import Output, check_paths

    check_paths(inputs=[("RAW", p) for p in args.raw], outputs=[Output("--out", args.out, "npz")],
                overwrite=args.overwrite)
    radar, chain = RadarConfig(), chain_from_args(args)
    raws = []
    for path in args.raw:  # read and check every file before processing any
        raw = read_raw(path, radar)
        if args.label is None and raw.labels is None:
            raise DataFileError(f"{path}: no field 'label' or 'labels'; pass --label LABEL")
        zero = [i for i, cube in enumerate(raw.cubes) if not np.any(cube)]
        if zero:
            field = "cube" if len(raw) == 1 else f"cubes{zero[:5]}"
            raise DataFileError(f"{path}: field {field!r} is all zeros (no signal was recorded); nothing to "
                                "process")
        raws.append(raw)
    frames = max(r.cubes.shape[1] for r in raws)
    check_size(("--n-angle", args.n_angle, 64), bytes_each=frames * BYTES_SPECTRUM * 2, what="angle-range images")
    cols = {k: [] for k in ("profiles", "labels", "mti_profiles", "range_m", "direction_deg", "peak_db",
                            "n_missing", "frame", "acquisition", "source")}
    t0, n_acq = time.perf_counter(), 0
    with progress_bar(total=sum(len(r) for r in raws), desc="acquisitions", unit="acq") as bar:
        for path, raw in zip(args.raw, raws):
            for i, cube in enumerate(raw.cubes):
                res = process_cube(cube, radar, chain)
                label = args.label if args.label is not None else str(raw.labels[i])
                n = len(res)
                n_acq += 1
                for key, val in (("profiles", res.signatures), ("mti_profiles", res.profiles),
                                 ("range_m", res.range_m), ("direction_deg", res.direction_deg),
                                 ("peak_db", res.peak_db), ("n_missing", res.n_missing), ("frame", res.frame)):
                    cols[key].append(val)
                cols["labels"].append(np.full(n, label))
                cols["acquisition"].append(np.full(n, i))
                cols["source"].append(np.full(n, str(path)))
                bar.update(1)
    if sum(len(p) for p in cols["profiles"]) == 0:
        files = ", ".join(map(str, args.raw))
        if chain.edge == "drop":
            why = "every signature reached past the profile's ends and --edge drop discarded it (try --edge keep)"
        else:
            why = ("no peak passed the detection thresholds (lower --floor-db or --rel-threshold-db, or check "
                   "that the cubes hold moving targets: the MTI removes static ones)")
        raise DataFileError(f"{files}: field 'cube': the chain found no signature: {why}")
    out = {k: np.concatenate(v) for k, v in cols.items()}
    settings = {"kind": "mdaug processed raw acquisitions", "simulated": False, "files": [str(p) for p in args.raw],
                "radar": radar.to_dict(), "chain": chain.to_dict(),
                "profiles": "linear magnitude, one row per significant peak per MTI frame"}
    atomic_savez(args.out, settings=np.array(json.dumps(settings)), **out)
    took = time.perf_counter() - t0
    result(f"wrote {args.out}: {len(out['labels'])} signatures x {radar.slice_length} bins from {n_acq} "
           f"acquisition(s) in {len(args.raw)} file(s) ({n_acq / took:,.1f} acquisitions/s)")
    return 0


def add_process(sub, parents, help):
    p = add_verb(sub, "process", parents, help=help, interrupted=nothing_written,
                 description="Range FFT, angle FFT, MTI, +-3.5 deg integration and signature extraction on raw "
                             "cubes (NPZ/.mat field 'cube' (frames, [ramps,] antennas, samples) or 'cubes'); "
                             "writes profiles + labels NPZ (the measured-profile format).")
    p.add_argument("raw", nargs="+", type=Path, metavar="RAW", help="raw acquisition file(s), .npz or .mat")
    p.add_argument("--out", type=Path, required=True, help="output NPZ (measured-profile format)")
    p.add_argument("--label", default=None,
                   help="class label of every signature (default: the file's field 'label' or 'labels')")
    add_chain_options(p)
    p.set_defaults(func=run_process)
    return p


VERBS = {
    "simulate": ("simulate a measurement campaign (raw FMCW acquisitions -> profiles)", add_simulate),
    "process": ("raw FMCW acquisitions -> measured profiles (the published chain)", add_process),
}
