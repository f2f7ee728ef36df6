"""Choose an estimator file's amortized temperature on fresh drones, then rerun its SBC on others.

python tests/benchmarks/fit_temperature.py --class QUAD --ramps 32 [--from-file FILE] \
    [--truths 300] [--sbc-truths 300] [--workers 2] [--seed 8080] --out FILE2

1. --truths fresh prior drones (seed --seed, 5 measurements each): SBC of the amortized
   route at each temperature of ``mdaug.inference.temperature.GRID``; the choice is the
   best exact log score among the temperatures that pass the gate (the nearest to passing
   when none does). Prints one row per temperature.
2. The file's own SBC of the amortized route, rerun at the chosen temperature on
   --sbc-truths other fresh drones (seed --seed + 1): the figures the status reads.
3. Writes FILE2 with ``temperature`` and ``temperature_fit`` in its meta. The rest of the
   file's SBC record is kept; a route table measured at another temperature says so in
   ``sbc.route_table.measured_with`` (rerun it with summary_likelihood.py --from-file).
FILE defaults to the shipped estimator of --class and --ramps. 1 thread per process.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")


def main(argv=None) -> int:
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.shipped import find
    from mdaug.inference.diagnostics.routes import headline
    from mdaug.inference.estimator_job import choose_temperature, estimator_sbc

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--class", dest="cls", required=True)
    p.add_argument("--ramps", type=int, required=True)
    p.add_argument("--from-file", default=None)
    p.add_argument("--truths", type=int, default=300)
    p.add_argument("--sbc-truths", type=int, default=300)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--seed", type=int, default=8080)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    est = find(a.cls, Acquisition.measured(a.ramps), path=a.from_file)
    before = est.temperature
    fit = choose_temperature(est, a.truths, seed=a.seed, workers=a.workers, log=print)
    fit["command"] = "python tests/benchmarks/fit_temperature.py " + " ".join(argv or sys.argv[1:])
    sbc = estimator_sbc(est, a.sbc_truths, seed=a.seed + 1, workers=a.workers, log=print)
    old = dict(est.meta.get("sbc", {}))
    old.update(sbc)
    if "route_table" in old and est.temperature != before:
        old["route_table"]["measured_with"] = (f"the amortized flow at temperature {before:g} (the route table was "
                                               f"not rerun at {est.temperature:g})")
    est.meta["sbc"] = old
    est.save(a.out)
    print(f"{a.cls} K={a.ramps}: temperature {est.temperature:g}; its SBC on {a.sbc_truths} other drones: "
          f"{headline(sbc['amortized'])}")
    print("90% width / truth, lines of the brightest engine: "
          + " ".join(f"{sbc['amortized']['width_over_truth'][n]:.2f}" for n in est.label_free.names[:4]))
    print(f"wrote {a.out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
