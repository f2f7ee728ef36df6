"""How often does the posterior predictive check flag measurements, when the simulator made them and when it did not?

python tests/benchmarks/predictive_check.py --class HELI --ramps 32 [--drones 40] [--measurements 5]
    [--scenes matched,snr0,snr25,drift] [--seed 0] [--workers 1] [--method likelihood --time-budget 120]
    [--out FILE.json]

Drones are drawn as the default study draws new drones (the specimen model around the class
reference). Each is measured ``--measurements`` times under the shipped estimator's
acquisition, once per scene, with the same random numbers, and calibrated by the file's
default route with its predictive check (``mdaug calibrate``'s default,
:mod:`mdaug.inference.diagnostics.predictive`), or with ``--method likelihood`` by the
closed-form likelihood (nlopt from one start of 2,000 evaluations, then emcee for
``--time-budget`` seconds a drone: the default fit, 4 starts of 6,000, takes minutes a
drone). Scenes:

* ``matched``: the scene the estimators are trained on (the flag rate is the check's false
  alarms; at most its level, 0.01, is the design);
* ``snr0`` / ``snr25``: the target's signal-to-noise ratio 0 dB / 25 dB instead of 10 dB
  (a radar or range the training set did not see);
* ``drift``: the hovering drone drifting 10 mm a frame instead of 3 mm.

Prints, per scene, the share of drones flagged ``misfit`` with its 95% Wilson interval,
the median largest |z|, the statistic flagged most often, the share the calibration called
out of range, the median of the check's seconds and of the whole calibration's. 1 thread
a worker.
"""
from __future__ import annotations

import argparse
import json
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

SCENES = {"matched": {}, "snr0": {"snr_db": 0.0}, "snr25": {"snr_db": 25.0}, "drift": {"drift_step_m": 1e-2}}


def one_drone(job: dict) -> list[dict]:
    """Calibrate one drone under each scene; one record per scene."""
    import time
    import warnings

    import numpy as np

    from mdaug.generator import load_reference
    from mdaug.generator.acquisition import Acquisition
    from mdaug.generator.chain import SceneConfig
    from mdaug.generator.specimens import SpecimenSpread
    from mdaug.inference.amortized.calibrate import calibrate_amortized
    from mdaug.inference.amortized.estimator import EstimatorError
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.amortized.simulate import measure
    from mdaug.inference.calibrate import calibrate
    from mdaug.inference.settings import CalibrationSettings
    from mdaug.radar import RadarConfig
    from mdaug.radar.seeds import seed_sequence

    ref, acq, radar = load_reference(job["cls"]), Acquisition.measured(job["ramps"]), RadarConfig()
    est = find(job["cls"], acq, radar)
    ss = seed_sequence(job["seed"], "drone", job["i"])
    x = SpecimenSpread().apply(ref.to_array()[None], np.random.default_rng(ss.spawn(1)[0]))[0]
    out = []
    for name in job["scenes"]:
        scene = SceneConfig(**SCENES[name]) if SCENES[name] else None
        y = measure(x[None], job["m"], acq, radar, np.random.default_rng(seed_sequence(job["seed"], "data", job["i"])),
                    scene=scene)[0]
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                if job["method"] == "likelihood":
                    quick_fit = CalibrationSettings(time_budget=job["budget"], n_starts=1, fit_budget=2000)
                    res = calibrate(y, ref, acquisition=acq, settings=quick_fit,
                                    random_state=seed_sequence(job["seed"], "calibrate", job["i"]))
                else:
                    res = calibrate_amortized(y, ref, acquisition=acq, estimator=est, random_state=seed_sequence(
                        job["seed"], "calibrate", job["i"]), fit=False)
            except EstimatorError as exc:  # refused outright: as far out as data get
                out.append({"scene": name, "refused": str(exc)})
                continue
        d = res.diagnostics
        p = d["predictive"]
        out.append({"scene": name, "word": p["word"], "max_z": float(np.max(np.abs(p["z"]))),
                    "flagged": p["flagged"], "out_of_range": bool(d.get("out_of_range", False)),
                    "route": d.get("route", "likelihood"), "converged": bool(d["converged"]),
                    "check_seconds": p["seconds"], "seconds": time.perf_counter() - t0})
    return out


def wilson(k: int, n: int) -> tuple[float, float]:
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
    return float(ci.low), float(ci.high)


def table(records: list[dict], scenes) -> list[str]:
    import collections

    import numpy as np

    lines = [f"{'scene':9s} {'drones':>6s} {'misfit':>7s} {'95% interval':>14s} {'median max|z|':>14s} "
             f"{'out of range':>12s} {'converged':>9s} {'check s':>8s} {'calib s':>8s}  most flagged"]
    for name in scenes:
        rs = [r for r in records if r["scene"] == name and "word" in r]
        refused = sum(1 for r in records if r["scene"] == name and "refused" in r)
        k = sum(r["word"] == "misfit" for r in rs)
        lo, hi = wilson(k, len(rs)) if rs else (float("nan"), float("nan"))
        most = collections.Counter(s.split(":")[0] for r in rs for s in r["flagged"][:1]).most_common(1)
        lines.append(f"{name:9s} {len(rs):6d} {k / max(len(rs), 1):7.2f} {f'[{lo:.2f}, {hi:.2f}]':>14s} "
                     f"{np.median([r['max_z'] for r in rs]):14.1f} "
                     f"{np.mean([r['out_of_range'] for r in rs]):12.2f} "
                     f"{np.mean([r.get('converged', True) for r in rs]):9.2f} "
                     f"{np.median([r['check_seconds'] for r in rs]):8.1f} {np.median([r['seconds'] for r in rs]):8.1f}"
                     f"  {most[0][0] + f' ({most[0][1]})' if most else '-'}"
                     + (f"; {refused} refused by the estimator" if refused else ""))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--class", dest="cls", default="HELI", choices=("HELI", "QUAD"))
    ap.add_argument("--ramps", type=int, default=32)
    ap.add_argument("--drones", type=int, default=40)
    ap.add_argument("--measurements", type=int, default=5)
    ap.add_argument("--scenes", default="matched,snr0,snr25,drift")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--method", default="amortized", choices=("amortized", "likelihood"),
                    help="the shipped file's default route, or the closed-form likelihood")
    ap.add_argument("--time-budget", type=float, default=120.0, help="--method likelihood: seconds a drone")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    scenes = a.scenes.split(",")
    bad = [s for s in scenes if s not in SCENES]
    if bad:
        ap.error(f"--scenes: unknown {bad}; expected some of {', '.join(SCENES)}")
    jobs = [{"cls": a.cls, "ramps": a.ramps, "m": a.measurements, "seed": a.seed, "i": i, "scenes": scenes,
             "method": a.method, "budget": a.time_budget} for i in range(a.drones)]
    if a.workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(a.workers) as pool:
            records = [r for rs in pool.map(one_drone, jobs) for r in rs]
    else:
        records = [r for job in jobs for r in one_drone(job)]
    print(f"{a.cls} K = {a.ramps}: {a.drones} drones of the specimen model, {a.measurements} measurements each, "
          + (f"the closed-form likelihood ({a.time_budget:g} s a drone)" if a.method == "likelihood" else
             "the shipped file's default route") + f", seed {a.seed}")
    print("\n".join(table(records, scenes)))
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"args": vars(a), "records": records}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
