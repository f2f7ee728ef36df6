"""Refit the widening of a file's summary likelihood on held-out simulated drones.

python tests/benchmarks/refit_widening.py --class HELI --ramps 32 [--from-file FILE0] [--prior 300] \
    [--near 100] [--specimens 60] [--seed 999] [--power P] [--scale C] [--workers 2] --out FILE

1. Fresh drones (5 measurements each), none of them an SBC or route-table drone (their
   seeds differ): --prior drones of the prior, --near drones of the specimen model at
   4 x its spreads, --specimens drones of the specimen model itself.
2. For each, twice the gap between the summary likelihood's global maximum and its
   value at the truth (:func:`mdaug.inference.emulator.train.likelihood_gaps`, BOBYQA
   from the truth and from the amortized posterior's four draws of highest importance
   weight and two of highest likelihood), the widening left out.
3. The widening w(u) fitted to them (:func:`~mdaug.inference.emulator.train.fit_widening`,
   log w linear and quadratic in u), raised to --power P and times --scale C
   (:func:`~mdaug.inference.emulator.train.raise_widening`: extra numbers chosen by the
   route's own SBC on other held-out drones, stated in the file), written into a copy
   of the shipped file (or of --from-file) with its stale route table removed.
Prints the gaps against chi-square(d) before and after, per group of drones.

With --prior 0 --near 0 --specimens 0 no drone is simulated: the file's own fit (its
stated scale and power divided out) is raised to the new --power and --scale.
"""
from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
warnings.simplefilter("ignore")

_EST = None


def _gap(args):
    """Twice the likelihood gap of one drone (worker)."""
    import numpy as np

    from mdaug.inference.emulator.train import likelihood_gaps

    y, ut, seed = args
    est, lf = _EST, _EST.label_free
    model = est.summary
    z = model.summarise(y)
    u, _ = est.sample_u(y, 2000, seed, strict=False)
    lp = lf.log_prior_u(u)
    u, lp = u[np.isfinite(lp)], lp[np.isfinite(lp)]
    ll = model.log_likelihood(u, z, len(y), widen=False)
    iw = ll + lp - est.log_prob_u(u, y)
    starts = np.concatenate([u[np.argsort(iw)[::-1][:4]], u[np.argsort(ll)[::-1][:2]]])
    return float(likelihood_gaps(model, ut[None], z[None], len(y), max_eval=500, starts=starts[None])[0])


def _init(path):
    global _EST
    import torch

    from mdaug.inference.amortized.estimator import AmortizedEstimator

    torch.set_num_threads(1)
    _EST = AmortizedEstimator.load(path)


def main(argv=None) -> int:
    from concurrent.futures import ProcessPoolExecutor
    from dataclasses import replace

    import numpy as np
    from scipy.stats import chi2

    from mdaug.inference.amortized.shipped import shipped_path
    from mdaug.inference.amortized.estimator import AmortizedEstimator, EstimatorError
    from mdaug.inference.emulator.train import fit_widening, raise_widening
    from mdaug.inference.estimator_job import sbc_data

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--class", dest="cls", required=True)
    ap.add_argument("--ramps", type=int, required=True)
    ap.add_argument("--from-file", default=None, help="estimator file (default: the shipped one)")
    ap.add_argument("--prior", type=int, default=300)
    ap.add_argument("--near", type=int, default=100)
    ap.add_argument("--specimens", type=int, default=60)
    ap.add_argument("--seed", type=int, default=999)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--power", type=float, default=1.0)
    ap.add_argument("--chosen-by", default=None, help="how --power and --scale were chosen (kept in the file)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    path = a.from_file or shipped_path(a.cls, a.ramps)
    est = AmortizedEstimator.load(path)
    try:
        lf, model = est.label_free, est.summary_model(str(path))
    except EstimatorError as exc:
        ap.error(str(exc))
    groups = {}
    for name, n, width, seed in (("prior", a.prior, 0.0, a.seed), ("near x4", a.near, 4.0, a.seed - 1),
                                 ("specimens", a.specimens, 1.0, a.seed - 2)):
        if n:
            spec = est.spec if not width else replace(est.spec, near_width=width)
            vec, prof = sbc_data(spec, n, seed, workers=a.workers)
            groups[name] = (lf.to_unbounded(lf.quantities(vec)), prof, seed)
    old = model.widening
    if not groups:  # no drones: the file's own fit, its stated power and scale divided out, raised anew
        if not old:
            ap.error(f"{path}: its summary likelihood has no widening to raise; give drones (--prior N) to fit one")
        was = est.meta["summary"].get("training", {}).get("widening_refit", {})
        p, s = float(was.get("power", 1.0)), float(was.get("scale", 1.0))
        new = raise_widening(raise_widening(old, 1.0 / p, s ** (-1.0 / p)), a.power, a.scale)  # (w^p s)^(1/p) s^(-1/p)
        kept = {k: v for k, v in was.items() if k not in ("command", "made_by", "scale_chosen_by", "chosen_by")}
        return _write(est, model, new, {**kept, "fit_command": was.get("fit_command", was.get("command")),
                                        "fit_made_by": was.get("fit_made_by", was.get("made_by")),
                                        "power": a.power, "scale": a.scale, "raised_from": Path(path).name}, a, t0)
    gaps = {}
    with ProcessPoolExecutor(a.workers, initializer=_init, initargs=(str(path),)) as pool:
        for name, (tu, prof, seed) in groups.items():
            jobs = [(prof[i], tu[i], seed + 1000 + i) for i in range(len(tu))]
            gaps[name] = np.array(list(pool.map(_gap, jobs, chunksize=4)))
    u = np.concatenate([g[0] for g in groups.values()])
    g = np.concatenate(list(gaps.values()))
    d = lf.dim
    new = raise_widening(fit_widening(u, g, d), a.power, a.scale)
    print(f"chi-square({d}): median {chi2.median(d):.2f}, q90 {chi2.ppf(0.9, d):.2f}")
    for label, wd in (("before", old), ("after", new)):
        model.widening = wd
        for name, (tu, _, _) in groups.items():
            w = model.widen(tu)
            r = gaps[name] / w
            print(f"{label:6s} {name:9s} {len(tu):4d} drones: w median {np.median(w):.2f} ({np.quantile(w, 0.1):.2f}-"
                  f"{np.quantile(w, 0.9):.2f}); gap / w median {np.median(r):.2f}, q90 {np.quantile(r, 0.9):.2f}, "
                  f"beyond chi-square's q90 {np.mean(r > chi2.ppf(0.9, d)):.3f}")
    refit = {"drones": {k: int(len(v[0])) for k, v in groups.items()}, "seed": a.seed, "power": a.power,
             "scale": a.scale, "gap_median": float(np.median(g)), "gap_q90": float(np.quantile(g, 0.9))}
    return _write(est, model, new, refit, a, t0)


def _write(est, model, widening: dict, refit: dict, a, t0: float) -> int:
    """The file with this widening and its record (the command that made it), its stale
    route table removed."""
    import sys

    model.widening = widening
    report = dict(est.meta["summary"]["training"])
    if a.chosen_by:
        refit["chosen_by"] = a.chosen_by
    report["widening_refit"] = {**refit, "command": "python tests/benchmarks/refit_widening.py " + " ".join(
        sys.argv[1:])}
    est.with_summary(model, report)
    est.meta["sbc"] = {k: v for k, v in est.meta.get("sbc", {}).items() if k in ("amortized", "n_measurements")}
    est.meta["default_route"] = "amortized"  # until a route table on the refitted file says otherwise
    est.save(a.out)
    print(f"wrote {a.out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
