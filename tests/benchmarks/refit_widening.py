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

For many quantities (QUAD: 35), where BOBYQA from a few starts stops short of the maximum:
--maximum smc finds each drone's maximum from the smc route's own particles (--particles,
no widening, the covariance held at the route's plug-in point as the route holds it), polished
by BOBYQA; --against plug-in fits w against that plug-in point (where the route evaluates it:
a function of the data alone) rather than the truth; --reference own compares each gap with
what a right likelihood's gap would be at that drone (``reference_gaps``: summaries drawn from
the likelihood itself), not with chi-square(d), which overstates it where the data identify few
of the d quantities. --gaps-out keeps the gaps (and references) in an .npz that --gaps-in fits
again without simulating.
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


def _gap_smc(args):
    """Twice the likelihood gap of one drone, the maximum found from the smc route's own
    particles (the route run with the covariance held at its plug-in point and no
    widening), polished by BOBYQA from the three of highest likelihood; returns (gap,
    the plug-in point u (d,), converged)."""
    import numpy as np

    from mdaug.inference.amortized.tempered import smc_route
    from mdaug.inference.emulator.train import likelihood_gaps

    y, ut, seed = args
    est, model = _EST, _EST.summary
    post, run = smc_route(est, y, _SETTINGS, seed, seed)
    parts = run.draws()
    top = parts[np.argsort(post.log_likelihood(parts))[::-1][:3]]
    gap = likelihood_gaps(model, ut[None], post.z[None], len(y), max_eval=500, starts=top[None],
                          plug_in=post.plug_in[None])[0]
    return float(gap), post.plug_in, bool(run.converged)


def _reference(args):
    """The gap a right likelihood would show at one drone (worker; :func:`reference_gaps`)."""
    from mdaug.inference.emulator.train import reference_gaps

    ut, plug_in, seed = args
    return float(reference_gaps(_EST.summary, ut[None], plug_in[None], 5, draws=2, seed=seed)[0])


_SETTINGS = None


def _init(path, particles=0, budget=None):
    global _EST, _SETTINGS
    import torch

    from mdaug.inference.amortized.estimator import AmortizedEstimator
    from mdaug.inference.settings import CalibrationSettings

    torch.set_num_threads(1)
    _EST = AmortizedEstimator.load(path)
    _EST.summary.widening = None  # the gaps are the unwidened likelihood's
    _SETTINGS = CalibrationSettings(progress=False, time_budget=budget, n_particles=int(particles))


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
    ap.add_argument("--maximum", choices=("bobyqa", "smc"), default="bobyqa",
                    help="how each drone's global maximum is found: BOBYQA from the amortized draws (default), "
                         "or from the smc route's particles (where BOBYQA alone stops short: QUAD's 35 dimensions)")
    ap.add_argument("--particles", type=int, default=1000, help="--maximum smc: the route's particle count")
    ap.add_argument("--time-budget", type=float, default=120.0, help="--maximum smc: seconds per drone")
    ap.add_argument("--against", choices=("truth", "plug-in"), default="truth",
                    help="fit w against the truth's u (default) or, with --maximum smc, against the smc route's "
                         "plug-in point (the amortized draws' median, where the route evaluates w: a function of "
                         "the data alone)")
    ap.add_argument("--linear", action="store_true", help="log w linear in u (no quadratic terms)")
    ap.add_argument("--reference", choices=("chi2", "own"), default="chi2",
                    help="what a right likelihood's gap is: chi-square(d) (default), or each drone's own "
                         "(summaries drawn from the likelihood itself, refit; needs plug-in points: --maximum smc)")
    ap.add_argument("--gaps-out", default=None, help="keep the gaps and their points in this .npz")
    ap.add_argument("--gaps-in", default=None, help="fit to the gaps of an earlier --gaps-out (nothing simulated)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if (a.against == "plug-in" or a.reference == "own") and a.maximum != "smc" and not a.gaps_in:
        ap.error("--against plug-in and --reference own need --maximum smc (the plug-in point is the smc route's)")
    t0 = time.perf_counter()
    path = a.from_file or shipped_path(a.cls, a.ramps)
    est = AmortizedEstimator.load(path)
    try:
        lf, model = est.label_free, est.summary_model(str(path))
    except EstimatorError as exc:
        ap.error(str(exc))
    groups = {}
    if a.gaps_in:
        a.prior = a.near = a.specimens = 0
    for name, n, width, seed in (("prior", a.prior, 0.0, a.seed), ("near x4", a.near, 4.0, a.seed - 1),
                                 ("specimens", a.specimens, 1.0, a.seed - 2)):
        if n:
            spec = est.spec if not width else replace(est.spec, near_width=width)
            vec, prof = sbc_data(spec, n, seed, workers=a.workers)
            groups[name] = (lf.to_unbounded(lf.quantities(vec)), prof, seed)
    old = model.widening
    if not groups and not a.gaps_in:  # no drones: the file's own fit, its stated power and scale divided out, raised anew
        if not old:
            ap.error(f"{path}: its summary likelihood has no widening to raise; give drones (--prior N) to fit one")
        was = est.meta["summary"].get("training", {}).get("widening_refit", {})
        p, s = float(was.get("power", 1.0)), float(was.get("scale", 1.0))
        new = raise_widening(raise_widening(old, 1.0 / p, s ** (-1.0 / p)), a.power, a.scale)  # (w^p s)^(1/p) s^(-1/p)
        kept = {k: v for k, v in was.items() if k not in ("command", "made_by", "scale_chosen_by", "chosen_by")}
        return _write(est, model, new, {**kept, "fit_command": was.get("fit_command", was.get("command")),
                                        "fit_made_by": was.get("fit_made_by", was.get("made_by")),
                                        "power": a.power, "scale": a.scale, "raised_from": Path(path).name}, a, t0)
    gaps, points, conv, ref = {}, {}, {}, {}
    init = (str(path), a.particles, a.time_budget)
    if a.gaps_in:
        with np.load(a.gaps_in, allow_pickle=False) as f:
            need = ["groups"] + [f"{g}/{k}" for g in (f["groups"] if "groups" in f else [])
                                 for k in ("gaps", "converged", "truth", "plug_in")]
            missing = [k for k in need if k not in f]
            if missing:
                ap.error(f"{a.gaps_in}: field '{missing[0]}' missing (expected an .npz written by --gaps-out)")
            for name in [str(k) for k in f["groups"]]:
                if a.against == "plug-in" and not np.all(np.isfinite(f[f"{name}/plug_in"])):
                    ap.error(f"{a.gaps_in}: field '{name}/plug_in' is not finite (gaps found with --maximum bobyqa "
                             "have no plug-in point); fit --against truth")
                gaps[name], conv[name] = f[f"{name}/gaps"], f[f"{name}/converged"]
                points[name] = {"truth": f[f"{name}/truth"], "plug-in": f[f"{name}/plug_in"]}
                if f"{name}/reference" in f:
                    ref[name] = f[f"{name}/reference"]
    else:
        with ProcessPoolExecutor(a.workers, initializer=_init, initargs=init) as pool:
            for name, (tu, prof, seed) in groups.items():
                jobs = [(prof[i], tu[i], seed + 1000 + i) for i in range(len(tu))]
                if a.maximum == "smc":
                    res = list(pool.map(_gap_smc, jobs))
                    gaps[name] = np.array([r[0] for r in res])
                    points[name] = {"truth": tu, "plug-in": np.array([r[1] for r in res])}
                    conv[name] = np.array([r[2] for r in res])
                    print(f"{name}: {len(res)} drones, smc converged on {conv[name].mean():.2f}", flush=True)
                else:
                    gaps[name] = np.array(list(pool.map(_gap, jobs, chunksize=4)))
                    points[name] = {"truth": tu, "plug-in": np.full_like(tu, np.nan)}
                    conv[name] = np.ones(len(tu), bool)
    if a.reference == "own" and set(ref) != set(gaps):
        with ProcessPoolExecutor(a.workers, initializer=_init, initargs=init) as pool:
            for name in gaps:
                jobs = [(points[name]["truth"][i], points[name]["plug-in"][i], a.seed + 5000 + i)
                        for i in range(len(gaps[name]))]
                ref[name] = np.array(list(pool.map(_reference, jobs, chunksize=2)))
                print(f"{name}: a right likelihood's gap median {np.median(ref[name]):.1f}", flush=True)
    if a.gaps_out:
        tmp = a.gaps_out + ".part.npz"
        np.savez(tmp, groups=np.array(list(gaps)), **{f"{k}/gaps": v for k, v in gaps.items()},
                 **{f"{k}/converged": v for k, v in conv.items()},
                 **{f"{k}/truth": v["truth"] for k, v in points.items()},
                 **{f"{k}/plug_in": v["plug-in"] for k, v in points.items()},
                 **{f"{k}/reference": v for k, v in ref.items()})
        os.replace(tmp, a.gaps_out)
    at = {k: v[a.against] for k, v in points.items()}
    d = lf.dim
    dof = {k: (np.maximum(ref[k], 1.0) if a.reference == "own" else np.full(len(gaps[k]), float(d))) for k in gaps}
    new = raise_widening(fit_widening(np.concatenate(list(at.values())), np.concatenate(list(gaps.values())),
                                      np.concatenate(list(dof.values())), quadratic=not a.linear), a.power, a.scale)
    print(f"reference: {'each drone its own (a right likelihood gap)' if a.reference == 'own' else f'chi-square({d})'}")
    for label, wd in (("before", old), ("after", new)):
        model.widening = wd
        for name in gaps:
            w = model.widen(at[name])
            r = gaps[name] / w / dof[name]
            print(f"{label:6s} {name:9s} {len(w):4d} drones: w median {np.median(w):.2f} ({np.quantile(w, 0.1):.2f}-"
                  f"{np.quantile(w, 0.9):.2f}); gap / w / reference median {np.median(r):.2f}, q90 "
                  f"{np.quantile(r, 0.9):.2f}; beyond the reference chi-square's q90 "
                  f"{np.mean(gaps[name] / w > chi2.ppf(0.9, dof[name])):.3f}")
    g = np.concatenate(list(gaps.values()))
    refit = {"drones": {k: int(len(v)) for k, v in gaps.items()}, "seed": a.seed, "power": a.power,
             "scale": a.scale, "gap_median": float(np.median(g)), "gap_q90": float(np.quantile(g, 0.9)),
             "maximum": a.maximum, "against": a.against, "quadratic": not a.linear, "reference": a.reference}
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
