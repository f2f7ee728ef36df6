"""Chain and scene-simulator speed, in one run (threads pinned to 1 unless --threads).

    python tests/benchmarks/radar.py [--n 200] [--repeats 5] [--threads 1]

On one acquisition of 11 frames x 8 antennas x 504 samples (int16 codes of a
simulated QUAD, K = 1 ramp), prints acquisitions/s (medians over repeats) of:
(a) the floor: the FFTs alone on the same cube, in the literal order (range rfft of
    all 88 traces + the 64-point angle FFT of all 11 frames);
(b) the whole chain, literal order (MTI on the complex range-angle image);
(c) the whole chain, fast order (MTI first on the samples: linear steps commute);
(d) the simulator (rendering raw cubes only), for K = 1 and the default scene's K;
then simulating + processing a 136-acquisition campaign (44 HELI + 92 QUAD, default
scene). Ratios are against (a), measured in this run.
Targets: chain within 2x of its FFT floor; the campaign under 30 s.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time


def timed(fn, n: int, repeats: int) -> float:
    """Median seconds per call of ``fn`` over ``repeats`` batches of ``n`` calls."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        times.append((time.perf_counter() - t0) / n)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="calls per timing batch")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)

    import numpy as np
    import scipy.fft

    from mdaug.generator import load_reference
    from mdaug.generator.scene import (SceneConfig, draw_acquisitions, draw_specimens, render_cubes,
                                       simulate_campaign)
    from mdaug.radar import RadarConfig
    from mdaug.radar.chain import ChainConfig, process_cube

    radar = RadarConfig()

    def make(scene, n_acq, seed=0):
        spec = draw_specimens(load_reference("QUAD").to_array(), 1, scene, np.random.default_rng(seed))
        d = draw_acquisitions(spec, n_acq, scene, radar, np.random.default_rng(seed + 1))
        rngs = [np.random.default_rng(seed + 2 + i) for i in range(n_acq)]
        return lambda: render_cubes(d, slice(0, n_acq), scene, radar, rngs)

    scene1 = SceneConfig(n_ramps=1)
    cube = make(scene1, 1)()[0][:, 0]  # (11, 8, 504) int16
    print(f"cube {cube.shape} {cube.dtype}; threads={args.threads}")

    def floor():
        x = cube.astype(np.float32)
        spec = scipy.fft.rfft(x, n=radar.fft_points, axis=-1)[..., : radar.n_bins]
        scipy.fft.fft(np.moveaxis(spec, -2, -1), n=64, axis=-1)

    t_floor = timed(floor, args.n, args.repeats)
    t_image = timed(lambda: process_cube(cube, radar, ChainConfig(order="image")), args.n, args.repeats)
    t_fast = timed(lambda: process_cube(cube, radar, ChainConfig(order="fast")), args.n, args.repeats)
    rows = [("FFT floor (range + angle FFTs, all frames)", t_floor),
            ("chain, literal order (MTI on range-angle image)", t_image),
            ("chain, fast order (MTI first, default)", t_fast)]
    batch = 16
    k_def = SceneConfig().n_ramps
    for scene, what in ((scene1, "simulate raw cube, K=1"), (SceneConfig(), f"simulate raw cube, K={k_def} (default)")):
        render = make(scene, batch)
        rows.append((what, timed(render, max(1, args.n // 40), args.repeats) / batch))
    print(f"{'step':52s} {'ms/acq':>8s} {'acq/s':>9s} {'x floor':>8s}")
    for name, t in rows:
        print(f"{name:52s} {t * 1e3:8.3f} {1 / t:9.1f} {t / t_floor:8.2f}")

    times = []
    for rep in range(max(1, min(args.repeats, 3))):
        t0 = time.perf_counter()
        h = simulate_campaign("HELI", 2, 44, seed=100 + rep)
        q = simulate_campaign("QUAD", 3, 92, seed=200 + rep)
        times.append(time.perf_counter() - t0)
    on = np.concatenate([h.on_target, q.on_target]).mean()
    print(f"136-acquisition campaign (44 HELI + 92 QUAD, default scene K={k_def}), simulate + process: "
          f"median {statistics.median(times):.2f} s over {len(times)} runs (target < 30 s); "
          f"{on:.0%} of signatures on the true target")


if __name__ == "__main__":
    main()
