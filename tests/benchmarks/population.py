"""Population calibration: SBC of the population and the cost of each stage
(run on demand: python tests/benchmarks/population.py).

Prints, with 1 thread:
1. cost of the stages of one population (HELI, ``--drones`` drones x
   ``--acquisitions`` acquisitions at K = ``--ramps``): each drone's calibration
   (fit + ``--sampler``, the closed form), the hyper-posterior, 10,000 new drones;
2. simulation-based calibration of the population (``--replicates`` populations:
   spreads from the hyperprior, drones drawn by the scene simulator's specimen
   model, acquisitions through the scene simulator and the chain, each drone
   calibrated by ``--method``: the shipped amortized estimator or the closed form, a
   drone held out):
   outer-10% share (honest: 0.10; pass 0.04-0.16) and pooled chi-square p for the
   spreads and for the unseen drone's lines, seconds per population. Resumable
   (``--checkpoint``) and spread over ``--workers`` processes.
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"
warnings.simplefilter("ignore")

import numpy as np  # noqa: E402

from mdaug.inference import CalibrationSettings  # noqa: E402


def settings_from(args) -> CalibrationSettings:
    return CalibrationSettings(sampler=args.sampler, n_starts=args.starts, fit_budget=args.fit_budget,
                               polish_budget=args.fit_budget, max_steps=args.max_steps, progress=False)


def section_cost(args):
    from mdaug.generator.chain import SceneConfig, simulate_campaign
    from mdaug.inference.calibrate import calibrate
    from mdaug.inference.population.result import calibrate_population

    print(f"\n== 1. cost of one {args.cls} population: {args.drones} drones x {args.acquisitions} acquisitions, "
          f"K = {args.ramps}, sampler {args.sampler}")
    camp = simulate_campaign(args.cls, args.drones, args.drones * args.acquisitions, 11,
                             scene=SceneConfig().with_acquisition(ramps=args.ramps))
    results = []
    for d in range(args.drones):
        t = time.perf_counter()
        res = calibrate(camp.profiles[camp.specimen == d], args.cls, acquisition=camp.acquisition,
                        settings=settings_from(args), random_state=d)
        dg = res.diagnostics
        print(f"drone {d}: {time.perf_counter() - t:6.1f} s (fit {dg['fit_seconds']:.1f} s, sampler "
              f"{dg['seconds']:.1f} s) {dg['reason']}")
        results.append(res)
    t = time.perf_counter()
    pop = calibrate_population(results, random_state=1)
    print(f"hyper-posterior: {time.perf_counter() - t:.1f} s")
    t = time.perf_counter()
    pop.draw_drones(10_000, np.random.default_rng(0))
    print(f"10,000 new drones: {time.perf_counter() - t:.2f} s")
    print(pop.report())


def section_sbc(args):
    from mdaug.inference.diagnostics.population_sbc import run_population_sbc

    print(f"\n== 2. population SBC ({args.cls}): {args.replicates} populations of {args.drones} drones x "
          f"{args.acquisitions} acquisitions, K = {args.ramps}, drones by {args.method}; {args.workers} worker(s); "
          f"resumable from {args.checkpoint}")
    out = run_population_sbc(args.cls, args.replicates, n_drones=args.drones, n_acquisitions=args.acquisitions,
                             ramps=args.ramps, settings=settings_from(args), seed=args.seed, n_rank=49,
                             checkpoint=args.checkpoint, workers=args.workers, method=args.method)
    for part in ("spreads", "new_drone", "all"):
        s = out[part]
        verdict = "pass" if 0.04 <= s["outer_share"] <= 0.16 and s["pooled_p"] > 0.01 else "FAIL"
        print(f"{part:<10} outer-10% share {s['outer_share']:.3f} (0.04-0.16), pooled p {s['pooled_p']:.3f}, "
              f"min p {s['min_p']:.3f}  [{verdict}] over {s['n_replicates']} populations")
        worst = sorted(s["outer_share_by_quantity"].items(), key=lambda kv: -abs(kv[1] - 0.1))[:4]
        print("           furthest from 0.10: " + ", ".join(f"{k} {v:.2f}" for k, v in worst))
    a, r = out["all"], out["refused"]
    if r["count"]:
        print(f"refused: {r['count']} of {r['of']} populations had a drone the calibration refused, left out of "
              f"the ranks above (first: {r['first']})")
    print(f"converged share {a['converged_share']:.2f}; seconds per population: median "
          f"{np.median(a['seconds']):.0f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", default="cost,sbc", help="comma-separated: cost, sbc")
    ap.add_argument("--cls", default="HELI")
    ap.add_argument("--replicates", type=int, default=50)
    ap.add_argument("--drones", type=int, default=3)
    ap.add_argument("--acquisitions", type=int, default=5)
    ap.add_argument("--ramps", type=int, default=32)
    ap.add_argument("--method", default="amortized", choices=("amortized", "likelihood"),
                    help="each drone's calibration: the shipped estimator (default) or the closed form (--sampler)")
    ap.add_argument("--sampler", default="laplace")
    ap.add_argument("--starts", type=int, default=2)
    ap.add_argument("--fit-budget", type=int, default=1500)
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--checkpoint", default=None, help="JSON-lines file the SBC resumes from")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    for name in args.sections.split(","):
        {"cost": section_cost, "sbc": section_sbc}[name.strip()](args)


if __name__ == "__main__":
    main()
