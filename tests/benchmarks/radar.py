"""Chain, scene-simulator and chain-path speed, in one run (threads pinned to 1 unless --threads).

    python tests/benchmarks/radar.py [--n 200] [--repeats 5] [--threads 1] [--sections chain,campaign,chain_path]

Section ``chain``: on one acquisition of 11 frames x 8 antennas x 504 samples (int16
codes of a simulated QUAD, K = 1 ramp), prints acquisitions/s (medians over repeats) of:
(a) the floor: the FFTs alone on the same cube, in the literal order (range rfft of
    all 88 traces + the 64-point angle FFT of all 11 frames);
(b) the whole chain, literal order (MTI on the complex range-angle image);
(c) the whole chain, fast order (MTI first on the samples: linear steps commute);
(d) the simulator (rendering raw cubes only), for K = 1 and the default scene's K.
Ratios are against (a), measured in this run. Target: chain within 2x of its FFT floor.

Section ``campaign``: simulating + processing a 136-acquisition campaign (44 HELI +
92 QUAD, default scene). Target: under 30 s.

Section ``chain_path``: :func:`mdaug.generator.chain.render_through_chain`, class
vectors (the HELI and QUAD references) rendered as raw acquisitions and processed by the
chain, for K = 1, 4, 32 ramps: ms per profile (median of 3; wall clock and, in
brackets, CPU time of this process: the cores are shared) of the literal path (raw
cubes through the chain) and the reduced path, both on the default scene (noise 10 dB,
6 clutter scatterers, 12-bit ADC), their wall-clock ratio in this run, the reduced
path without noise; and the reduced path's largest error against the literal one on the same draws
(max over rows of max |difference| of peak-normalised profiles): noise and ADC off,
clutter on (acceptance: <= 1e-3), and with the ADC (its rounding floor, left out by the
reduced path). Then the literal chain on default draws (K = 4): the share of profiles
centred within 5 bins of the true range (on_target) and the share whose centre is not
the reduced path's within +-2 bins (the literal chain picked something other than the
drone's own lines). Target: <= 3 ms per profile at K = 32.
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


def section_chain(args) -> None:
    import numpy as np
    import scipy.fft

    from mdaug.generator import load_reference
    from mdaug.generator.chain import SceneConfig, draw_acquisitions, draw_specimens, render_cubes
    from mdaug.radar import RadarConfig
    from mdaug.radar.chain import ChainConfig, process_cube

    radar = RadarConfig()

    def make(scene, n_acq, seed=0):
        spec = draw_specimens(load_reference("QUAD").to_array(), 1, scene, np.random.default_rng(seed))
        d = draw_acquisitions(spec, n_acq, scene, radar, np.random.default_rng(seed + 1))
        rngs = [np.random.default_rng(seed + 2 + i) for i in range(n_acq)]
        return lambda: render_cubes(d, slice(0, n_acq), scene, radar, rngs)

    scene1 = SceneConfig().with_acquisition(ramps=1)
    cube = make(scene1, 1)()[0][:, 0]  # (11, 8, 504) int16
    print(f"\n== chain: cube {cube.shape} {cube.dtype}; threads={args.threads}")

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
    k_def = SceneConfig().acquisition.ramps
    for scene, what in ((scene1, "simulate raw cube, K=1"), (SceneConfig(), f"simulate raw cube, K={k_def} (default)")):
        render = make(scene, batch)
        rows.append((what, timed(render, max(1, args.n // 40), args.repeats) / batch))
    print(f"{'step':52s} {'ms/acq':>8s} {'acq/s':>9s} {'x floor':>8s}")
    for name, t in rows:
        print(f"{name:52s} {t * 1e3:8.3f} {1 / t:9.1f} {t / t_floor:8.2f}")


def section_campaign(args) -> None:
    import numpy as np

    from mdaug.generator.chain import SceneConfig, simulate_campaign

    k_def = SceneConfig().acquisition.ramps
    times = []
    for rep in range(max(1, min(args.repeats, 3))):
        t0 = time.perf_counter()
        h = simulate_campaign("HELI", 2, 44, seed=100 + rep)
        q = simulate_campaign("QUAD", 3, 92, seed=200 + rep)
        times.append(time.perf_counter() - t0)
    on = np.concatenate([h.on_target, q.on_target]).mean()
    print(f"\n== campaign: 136 acquisitions (44 HELI + 92 QUAD, default scene K={k_def}), simulate + process: "
          f"median {statistics.median(times):.2f} s over {len(times)} runs (target < 30 s); "
          f"{on:.0%} of signatures on the true target")


def _per_profile(render, n: int, repeats: int = 3) -> tuple[float, float]:
    """Median ms per profile of ``render()`` (which makes n profiles) over ``repeats`` runs:
    wall clock and CPU time of this process (the cores are shared: CPU time is what the
    path costs, wall time also holds waiting for other jobs)."""
    render()  # warm-up: caches (noise basis, interpolation matrices)
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        render()
        wall.append((time.perf_counter() - t0) / n)
        cpu.append((time.process_time() - c0) / n)
    return 1e3 * statistics.median(wall), 1e3 * statistics.median(cpu)


def _max_error(lit, red) -> float:
    peak = lambda p: p.profiles / p.profiles.max(axis=1, keepdims=True)  # noqa: E731
    return float((abs(peak(lit) - peak(red))).max())


def section_chain_path(args) -> None:
    import warnings

    import numpy as np

    from mdaug.generator import load_reference
    from mdaug.generator.chain import SceneConfig, render_through_chain

    print(f"\n== chain path: class vector -> raw acquisition -> chain, one profile each; threads={args.threads}; "
          "ms/profile median of 3")
    print(f"{'class':5s} {'K':>3s} {'literal':>15s} {'reduced':>15s} {'lit/red':>8s} {'red, no noise':>15s} "
          f"{'max err':>9s} {'err ADC':>9s}   (ms/profile: wall (CPU))")
    sizes = {1: (24, 256), 4: (12, 256), 32: (3, 64)}  # literal, reduced profiles per timing run
    for cls in ("HELI", "QUAD"):
        ref = load_reference(cls).to_array()
        for k, (n_lit, n_red) in sizes.items():
            scene = SceneConfig().with_acquisition(ramps=k)
            x_lit, x_red = np.repeat(ref[None], n_lit, axis=0), np.repeat(ref[None], n_red, axis=0)
            t_lit = _per_profile(lambda: render_through_chain(x_lit, scene, random_state=1, method="literal"), n_lit)
            t_red = _per_profile(lambda: render_through_chain(x_red, scene, random_state=1), n_red)
            quiet = scene.replace(snr_db=None)
            t_quiet = _per_profile(lambda: render_through_chain(x_red, quiet, random_state=1), n_red)
            errs = []
            for s in (quiet.replace(quantise=False), quiet):  # clutter on; ADC off, then on
                lit, red = (render_through_chain(x_lit, s, random_state=2, method=m) for m in ("literal", "reduced"))
                errs.append(_max_error(lit, red))
            fmt = lambda t: f"{t[0]:7.3f} ({t[1]:5.3f})"  # noqa: E731
            print(f"{cls:5s} {k:3d} {fmt(t_lit):>15s} {fmt(t_red):>15s} {t_lit[0] / t_red[0]:8.1f} {fmt(t_quiet):>15s} "
                  f"{errs[0]:9.1e} {errs[1]:9.1e}", flush=True)
    n = args.on_target
    for cls in ("HELI", "QUAD"):
        x = np.repeat(load_reference(cls).to_array()[None], n, axis=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lit, red = (render_through_chain(x, SceneConfig(), random_state=3, method=m)
                        for m in ("literal", "reduced"))
        other = np.abs(lit.peak_bin - red.peak_bin) > 2
        print(f"{cls}: literal chain on {n} default draws (K=4): on_target {lit.on_target.mean():.1%} "
              f"(reduced {red.on_target.mean():.1%}); centre not the drone's lines (off the reduced path's by "
              f"> 2 bins): {other.mean():.1%}")


SECTIONS = {"chain": section_chain, "campaign": section_campaign, "chain_path": section_chain_path}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="calls per timing batch (section chain)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--sections", default=",".join(SECTIONS), help=f"comma list of {list(SECTIONS)}")
    ap.add_argument("--on-target", type=int, default=400, help="default draws per class for on_target (chain_path)")
    args = ap.parse_args()
    unknown = [s for s in args.sections.split(",") if s not in SECTIONS]
    if unknown:
        ap.error(f"--sections: unknown {unknown}; choose from {list(SECTIONS)}")
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    for name in args.sections.split(","):
        SECTIONS[name](args)


if __name__ == "__main__":
    main()
