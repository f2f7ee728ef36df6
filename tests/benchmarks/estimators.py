"""Train the shipped amortized estimators (or any set of them) side by side.

python tests/benchmarks/estimators.py --cost
python tests/benchmarks/estimators.py --out DIR [--work WORK] [--jobs CLASS:K:N:WORKERS,...]
    [--device auto] [--sim-budget S] [--posterior-budget S] [--ratio-budget S] [--sbc-truths 300]

Each job CLASS:K:SIMULATIONS:WORKERS runs in its own process (simulation on WORKERS
processes, then training on the device, then its SBC), writing DIR/<class>-k<K>.zip
(first without, then with its SBC figures), its work folder (resumable) and log under
WORK (default DIR/work). This is
how the estimators in mdaug/inference/amortized/data were made (the README's
calibration page gives the command line and the figures each job printed).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import warnings

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")

DEFAULT_JOBS = "QUAD:32:24000:6,HELI:32:24000:4,QUAD:4:40000:2,HELI:4:40000:2,QUAD:1:40000:1,HELI:1:40000:1"


def one(cls: str, ramps: int, n: int, workers: int, out: str, work: str, device: str, sim_budget: float,
        post_budget: float, ratio_budget: float, sbc_truths: int, seed: int, threads: int, shard_size: int) -> None:
    import torch

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.estimator_job import train_estimator
    from mdaug.inference.amortized.shipped import default_nets, default_training
    from mdaug.inference.amortized.simulate import SimulationSpec

    torch.set_num_threads(threads)
    name = f"{cls.lower()}-k{ramps}"
    os.makedirs(work, exist_ok=True)
    log_path = os.path.join(work, f"{name}.log")

    def log(msg):
        line = f"[{time.strftime('%H:%M:%S')}] {msg}"
        print(line, flush=True)
        with open(log_path, "a") as fh:
            fh.write(line + "\n")

    spec = SimulationSpec(cls, Acquisition.measured(ramps), 10)
    cfg = default_training()
    est = train_estimator(spec, n, os.path.join(work, name), os.path.join(out, f"{name}.zip"), seed=seed,
                          workers=workers, device=device, net_cfg=default_nets(cls),
                          train_cfg=cfg, sim_budget=sim_budget, post_budget=post_budget, ratio_budget=ratio_budget,
                          sbc_truths=sbc_truths, shard_size=shard_size, progress=False, log=log,
                          command=f"python tests/benchmarks/estimators.py --jobs {cls}:{ramps}:{n}:{workers} "
                                  f"--device {device} --sim-budget {sim_budget} --posterior-budget {post_budget} "
                                  f"--ratio-budget {ratio_budget} --sbc-truths {sbc_truths} --seed {seed} "
                                  f"--shard-size {shard_size}")
    log(f"done: {est.meta['job_seconds']:.0f} s")


def cost(n_drones: int = 200, n_train: int = 2000, ramps: int = 32) -> None:
    """Print, on 1 thread: simulation ms per training example (one drone, 5 and 10
    measurements through the scene simulator and the chain, batched n_drones per call)
    and training seconds per epoch of each network on n_train examples (CPU)."""
    import numpy as np
    import torch
    from threadpoolctl import threadpool_limits

    from mdaug.generator.acquisition import Acquisition
    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.shipped import default_nets, default_training
    from mdaug.inference.amortized.simulate import SimulationSpec, simulate
    from mdaug.inference.amortized.train import fit, posterior_loss, ratio_loss

    from dataclasses import replace

    torch.set_num_threads(1)
    with threadpool_limits(1):
        for cls in ("HELI", "QUAD"):
            for m in (5, 10):
                spec = SimulationSpec(cls, Acquisition.measured(ramps), m)
                simulate(spec, 4, 0)
                t0 = time.process_time()
                x, y = simulate(spec, n_drones, 1)
                ms = (time.process_time() - t0) / n_drones * 1e3
                print(f"simulation {cls} K={ramps}, {m} measurements: {ms:.1f} ms per example (CPU time, 1 thread)",
                      flush=True)
            spec = SimulationSpec(cls, Acquisition.measured(ramps), 10)
            x, y = simulate(spec, 64, 2)
            reps = -(-n_train // 64)
            from mdaug.inference.amortized.target import LabelFree

            ref = spec.reference
            label_free = LabelFree(ref.n_engines, spec.priors(), ref.to_array())
            u = torch.as_tensor(np.tile(label_free.to_unbounded(label_free.quantities(x)), (reps, 1))[:n_train],
                                dtype=torch.float32)
            xt = torch.as_tensor(np.tile(y, (reps, 1, 1))[:n_train])
            est = AmortizedEstimator.build(spec, default_nets(cls), u, xt)
            cfg = replace(default_training(), max_epochs=2, patience=10)
            for name, net, loss in (("posterior", est.posterior, posterior_loss), ("ratio", est.ratio, ratio_loss)):
                log = fit(net, loss, u, xt, cfg, 0, progress=False)
                print(f"training {cls} {name}: {log.seconds / log.epochs:.1f} s per epoch of {n_train} examples "
                      f"({log.seconds / log.epochs / n_train * 1e3:.2f} ms per example-epoch, 1 thread)", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None)
    p.add_argument("--jobs", default=DEFAULT_JOBS)
    p.add_argument("--device", default="auto")
    p.add_argument("--work", default=None)
    p.add_argument("--sim-budget", type=float, default=None)
    p.add_argument("--posterior-budget", type=float, default=150.0)
    p.add_argument("--ratio-budget", type=float, default=90.0)
    p.add_argument("--sbc-truths", type=int, default=300)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--shard-size", type=int, default=200)
    p.add_argument("--cost", action="store_true", help="print simulation and training costs on 1 thread")
    p.add_argument("--one", nargs=4, metavar=("CLASS", "K", "N", "WORKERS"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.cost:
        cost()
        return 0
    if a.out is None:
        p.error("--out is required")
    os.makedirs(a.out, exist_ok=True)
    work = a.work or os.path.join(a.out, "work")
    if a.one:
        cls, k, n, w = a.one
        one(cls, int(k), int(n), int(w), a.out, work, a.device, a.sim_budget, a.posterior_budget, a.ratio_budget,
            a.sbc_truths, a.seed, a.threads, a.shard_size)
        return 0
    procs = []
    for job in a.jobs.split(","):
        cls, k, n, w = job.split(":")
        cmd = [sys.executable, __file__, "--out", a.out, "--work", work, "--device", a.device,
               *(["--sim-budget", str(a.sim_budget)] if a.sim_budget is not None else []), "--posterior-budget",
               str(a.posterior_budget), "--ratio-budget", str(a.ratio_budget), "--sbc-truths", str(a.sbc_truths),
               "--seed", str(a.seed), "--threads", str(a.threads), "--shard-size", str(a.shard_size),
               "--one", cls, k, n, w]
        procs.append((job, subprocess.Popen(cmd)))
    status = 0
    for job, proc in procs:
        rc = proc.wait()
        print(f"{job}: exit {rc}", flush=True)
        status |= rc
    return status


if __name__ == "__main__":
    raise SystemExit(main())
