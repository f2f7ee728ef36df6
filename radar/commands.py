"""CLI verb of the radar layer: ``mdaug process`` (raw acquisitions -> measured profiles)."""
from __future__ import annotations

import argparse
from pathlib import Path


def add_chain_arguments(p: argparse.ArgumentParser) -> None:
    from .chain import EDGE_POLICIES, ORDERS, ChainConfig

    d = ChainConfig()
    g = p.add_argument_group("chain (SPEC section 4)")
    g.add_argument("--n-angle", type=int, default=d.n_angle, help=f"angle FFT points (default {d.n_angle})")
    g.add_argument("--rel-threshold-db", type=float, default=d.rel_threshold_db,
                   help=f"a peak counts if within this of the strongest (default {d.rel_threshold_db} dB)")
    g.add_argument("--floor-db", type=float, default=d.floor_db,
                   help=f"... and this far above the median noise floor (default {d.floor_db} dB)")
    g.add_argument("--max-targets", type=int, default=None, help="keep at most this many peaks per MTI frame")
    g.add_argument("--edge", choices=EDGE_POLICIES, default=d.edge,
                   help="signatures reaching past the profile's ends: keep (zero-filled) or drop")
    g.add_argument("--order", choices=ORDERS, default=d.order,
                   help="fast: MTI on the raw samples first (identical result, linear steps); image: literal")


def chain_from_args(args):
    from .chain import ChainConfig

    return ChainConfig(n_angle=args.n_angle, rel_threshold_db=args.rel_threshold_db, floor_db=args.floor_db,
                       max_targets=args.max_targets, edge=args.edge, order=args.order)


def run_process(args) -> int:
    import json
    import time

    import numpy as np

    from .chain import process_cube
    from .config import RadarConfig
    from .io import DataFileError, atomic_savez, check_writable
    from .raw import read_raw

    check_writable(args.out)
    radar, chain = RadarConfig(), chain_from_args(args)
    cols = {k: [] for k in ("profiles", "labels", "mti_profiles", "range_m", "direction_deg", "peak_db",
                            "n_missing", "frame", "acquisition", "source")}
    t0, n_acq = time.perf_counter(), 0
    for path in args.raw:
        raw = read_raw(path, radar)
        if args.label is None and raw.labels is None:
            raise DataFileError(f"{path}: no field 'label' or 'labels'; pass --label LABEL")
        for i, cube in enumerate(raw.cubes):
            res = process_cube(cube, radar, chain)
            label = args.label if args.label is not None else str(raw.labels[i])
            n = len(res)
            n_acq += 1
            for key, val in (("profiles", res.signatures), ("mti_profiles", res.profiles), ("range_m", res.range_m),
                             ("direction_deg", res.direction_deg), ("peak_db", res.peak_db),
                             ("n_missing", res.n_missing), ("frame", res.frame)):
                cols[key].append(val)
            cols["labels"].append(np.full(n, label))
            cols["acquisition"].append(np.full(n, i))
            cols["source"].append(np.full(n, str(path)))
    if not cols["profiles"] or sum(len(p) for p in cols["profiles"]) == 0:
        raise DataFileError(f"{args.raw[0]}: the chain found no signature in any file (try --edge keep)")
    out = {k: np.concatenate(v) for k, v in cols.items()}
    settings = {"kind": "mdaug processed raw acquisitions", "simulated": False, "files": [str(p) for p in args.raw],
                "radar": radar.to_dict(), "chain": chain.to_dict(),
                "profiles": "linear magnitude, one row per significant peak per MTI frame"}
    atomic_savez(args.out, settings=np.array(json.dumps(settings)), **out)
    took = time.perf_counter() - t0
    print(f"wrote {args.out}: {len(out['labels'])} signatures x {radar.slice_length} bins from {n_acq} "
          f"acquisition(s) in {len(args.raw)} file(s) ({n_acq / took:,.1f} acquisitions/s)")
    return 0


def register(sub) -> None:
    p = sub.add_parser("process", help="raw FMCW acquisitions -> measured profiles (the published chain)",
                       description="Range FFT, angle FFT, MTI, +-3.5 deg integration and signature "
                                   "extraction on raw cubes (NPZ/.mat field 'cube' (frames, [ramps,] "
                                   "antennas, samples) or 'cubes'); writes profiles + labels NPZ.")
    p.add_argument("raw", nargs="+", type=Path, metavar="RAW", help="raw acquisition file(s), .npz or .mat")
    p.add_argument("--out", type=Path, required=True, help="output NPZ (measured-profile format)")
    p.add_argument("--label", default=None, help="class label of every signature (default: the file's 'label')")
    add_chain_arguments(p)
    p.set_defaults(func=run_process)
