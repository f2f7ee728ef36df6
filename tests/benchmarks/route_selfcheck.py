"""The smc route's SBC on a right likelihood: is the sampler honest where the likelihood is?

python tests/benchmarks/route_selfcheck.py --class QUAD --ramps 32 [--from-file FILE] [--truths 60] \
    [--seed 502] [--particles 1000] [--covariance reference|plug-in] [--ess 0.7] [--p-move 0.9] \
    [--max-sweeps 20] [--moves] [--redraw R] [--quantity-redraw R] [--line-move R] \
    [--engine-swap R] [--thorough] [--workers 2]

The route table's SBC mixes two faults: the emulated likelihood's error and the sampler's. This
takes the first away. For each fresh prior drone (5 measurements, as the route table draws them)
the smc route starts from the amortized posterior of its profiles as always, but its likelihood's
data are a summary drawn from the file's summary likelihood itself at the truth: z* = mu(u_t) +
L e, the covariance L L' held at one point for every drone (``--covariance reference``: the class
reference drone's, so the likelihood is exactly the model z* came from; ``plug-in``: the route's
own plug-in point, which depends on the profiles and so is only nearly right). The likelihood is
then right by construction, and an exact sampler gives uniform ranks: outer-10% share about 0.10,
every quantity's 90% coverage near 0.90. What this prints is what the sampler and the prior
density add by themselves.

Prints the outer-10% share (199 draws a drone, ranks below 10 or above 189), the range of the
per-quantity 90% coverage, the median 90% width / truth of lines 1-4 (HELI's lines, QUAD's
brightest engine's), the share converged and the median seconds per drone.
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

_EST = {}


def _one(args):
    """One drone: (ranks (d,), 5% and 95% quantiles (d,), converged, seconds) (worker)."""
    import numpy as np
    import torch

    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.amortized.tempered import n_particles, prior_draws_u, sample_tempered
    from mdaug.inference.settings import CalibrationSettings

    path, truth_q, y, seed, a = args
    torch.set_num_threads(1)
    if path not in _EST:
        _EST[path] = AmortizedEstimator.load(path)
    est = _EST[path]
    lf = est.label_free
    st = CalibrationSettings(progress=False, time_budget=a["time_budget"], n_particles=a["particles"]).with_plugin(
        "smc", route_ess=a["ess"], route_p_move=a["p_move"], route_max_sweeps=a["max_sweeps"])
    t0 = time.perf_counter()
    start, _ = est.sample_u(y, n_particles(st, lf.dim), seed, strict=False)
    at = (lf.to_unbounded(lf.quantities(lf.reference[None]))[0] if a["covariance"] == "reference"
          else np.median(start, axis=0))
    post = est.target(y, plug_in=at)
    tu = lf.to_unbounded(truth_q[None])
    post.z = est.summary.mean(tu)[0] + post._chol @ np.random.default_rng(seed + 7).normal(size=len(post.z))
    run = sample_tempered(post, lambda v: est.log_prob_u(v, y), start, st, seed, redraw=a["redraw"],
                          quantity_redraw=a["quantity_redraw"],
                          line_move=a["line_move"], engine_swap=a["engine_swap"],
                          prior_u=prior_draws_u(est, len(start), seed) if a["quantity_redraw"] or a["line_move"] else None)
    dr = run.draws()
    q = lf.from_unbounded(dr[np.random.default_rng(seed).choice(len(dr), 199)])
    return (np.sum(q < truth_q, 0), np.quantile(q, 0.05, 0), np.quantile(q, 0.95, 0), bool(run.converged),
            time.perf_counter() - t0)


def main(argv=None) -> int:
    from concurrent.futures import ProcessPoolExecutor

    import numpy as np

    from mdaug.inference.amortized.estimator import AmortizedEstimator, EstimatorError
    from mdaug.inference.amortized.shipped import shipped_path
    from mdaug.inference.amortized.tempered import MOVES
    from mdaug.inference.samplers.smc import THOROUGH_ROUTE, SMCSettings
    from mdaug.inference.estimator_job import sbc_data

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", required=True)
    ap.add_argument("--ramps", type=int, required=True)
    ap.add_argument("--from-file", default=None, help="estimator file (default: the shipped one)")
    ap.add_argument("--truths", type=int, default=60)
    ap.add_argument("--seed", type=int, default=502)
    ap.add_argument("--particles", type=int, default=1000)
    ap.add_argument("--covariance", choices=("reference", "plug-in"), default="reference")
    ap.add_argument("--ess", type=float, default=None,
                    help="the tempering's ESS share per stage (default: the file's route, else 0.7)")
    ap.add_argument("--p-move", type=float, default=None, help="default: the file's route, else 0.9")
    ap.add_argument("--max-sweeps", type=int, default=None, help="default: the file's route, else 20")
    ap.add_argument("--moves", action="store_true",
                    help=f"the moves across the golf course at the shares measured ({MOVES}); "
                         "the four options below set them one by one")
    ap.add_argument("--redraw", type=float, default=None, help="share of u-coordinate redraws (the route's: 0)")
    ap.add_argument("--quantity-redraw", type=float, default=None, help="share of quantity redraws (the route's: 0)")
    ap.add_argument("--line-move", type=float, default=None, help="share of line moves (the route's: 0)")
    ap.add_argument("--engine-swap", type=float, default=None,
                    help="share of engine swaps, several engines only (the route's: 0)")
    ap.add_argument("--thorough", action="store_true",
                    help="the moves, --ess, --p-move, --max-sweeps and --particles of samplers.smc.THOROUGH_ROUTE "
                         "(those given explicitly win)")
    ap.add_argument("--time-budget", type=float, default=180.0)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    if a.thorough:  # its knobs where not given explicitly
        a.moves = True
        for opt, knob in (("ess", "route_ess"), ("p_move", "route_p_move"), ("max_sweeps", "route_max_sweeps")):
            if getattr(a, opt) is None:
                setattr(a, opt, THOROUGH_ROUTE[knob])
        if "--particles" not in " ".join(argv if argv is not None else sys.argv[1:]):
            a.particles = THOROUGH_ROUTE["n_particles"]
    t0 = time.perf_counter()
    path = str(a.from_file or shipped_path(a.cls, a.ramps))
    est = AmortizedEstimator.load(path)
    route = SMCSettings().route(est.meta.get("route_settings"))  # the file's route, else the defaults
    a.moves = a.moves or route["route_moves"]
    for opt in ("ess", "p_move", "max_sweeps"):
        if getattr(a, opt) is None:
            setattr(a, opt, route[f"route_{opt}"])
    for k, v in MOVES.items():
        if getattr(a, k) is None:
            setattr(a, k, v if a.moves else 0.0)
    try:
        est.summary_model(path)
    except EstimatorError as exc:
        ap.error(str(exc))
    vec, prof = sbc_data(est.spec, a.truths, a.seed, a.workers)
    tq = est.label_free.quantities(vec)
    knobs = {k: getattr(a, k) for k in ("particles", "covariance", "ess", "p_move", "max_sweeps", "time_budget", "redraw",
                                        "quantity_redraw", "line_move", "engine_swap")}
    jobs = [(path, tq[i], prof[i], a.seed * 1000 + i, knobs) for i in range(a.truths)]
    with ProcessPoolExecutor(a.workers) as pool:
        res = list(pool.map(_one, jobs, chunksize=2))
    ranks = np.array([r[0] for r in res])
    lo, hi = np.array([r[1] for r in res]), np.array([r[2] for r in res])
    cover = ((tq >= lo) & (tq <= hi)).mean(0)
    width = np.median((hi - lo) / np.abs(tq), 0)
    outer = float(((ranks < 10) | (ranks > 189)).mean())
    print(f"{os.path.basename(path)}: the smc route on summaries drawn from its own likelihood (covariance held at "
          f"the {a.covariance} point), {a.truths} prior drones, seed {a.seed}, {a.particles} particles, ess "
          f"{a.ess:g}, p_move {a.p_move:g}, at most {a.max_sweeps} sweeps a stage, redraws {a.redraw:g} (u) "
          f"{a.quantity_redraw:g} (quantity), line moves {a.line_move:g}, engine swaps {a.engine_swap:g}")
    print(f"outer-10% share {outer:.3f} (an exact sampler: about 0.10), 90% coverage {cover.min():.2f}-"
          f"{cover.max():.2f}, lines 1-4 90% width / truth {' '.join(f'{w:.2f}' for w in width[:4])}, converged "
          f"{np.mean([r[3] for r in res]):.2f}, {np.median([r[4] for r in res]):.1f} s / drone "
          f"({time.perf_counter() - t0:.0f} s)")
    low = np.argsort(cover)[:5]
    print("lowest 90% coverage: " + ", ".join(f"{est.label_free.names[c]} {cover[c]:.2f}" for c in low))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
