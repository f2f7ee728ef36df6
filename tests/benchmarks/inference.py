"""Speed and error of the calibration (run on demand: python tests/benchmarks/inference.py).

Prints, all with 1 thread:
1. fitted-phase likelihood throughput, float32 vs float64 f(x) (ratio in the same run);
2. fit: nlopt global algorithm x budget on one single-chirp profile (fitted phases);
3. likelihood: the marginal (synthetic) likelihood's cost per evaluation and its
   Monte Carlo error against the number of simulated acquisitions O and ramps I
   (speed against error; error = rms over bins of the model mean's spread across
   common-random-number seeds, peak = 1);
3b. the closed-form likelihood's cost per walker-evaluation against the synthetic one in
   the same run, and its tolerances' speed against error;
4. HELI from 5 scene-simulated acquisitions at K = 32 (and ``--ramps`` K): time to
   50 tau with min ESS >= 400 (target < 90 s), and the label-free lines' 90%
   intervals against the truth (recovery);
5. QUAD from 5 acquisitions at K = 32 with the default time budget (target < 8 min);
6. simulation-based calibration of the supported case (``--sbc-draws`` truths from
   the prior, 5 scene-simulated acquisitions each, K = ``--sbc-ramps``): outer-10%
   share (honest: 0.10), pooled chi-square p, seconds per calibration.

``--quick`` shrinks every section (for a smoke run).
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

from mdaug.generator import IDX, load_reference, profiles  # noqa: E402
from mdaug.inference import CalibrationSettings, Layout, LogPosterior, Priors, calibrate, prepare_measured  # noqa: E402
from mdaug.inference.fit import global_fit  # noqa: E402
from mdaug.radar import RadarConfig  # noqa: E402

RADAR = RadarConfig()
HELI = load_reference("HELI")
NOISE = 0.01


def truth_and_profile(seed=0, noise=NOISE):
    x = HELI.to_array().copy()
    x[[IDX["A_a"], IDX["w_a"], IDX["w_b"], IDX["C_p"]]] *= [1.08, 0.95, 1.05, 0.97]
    rng = np.random.default_rng(seed)
    return x, np.abs(profiles(x)[0] + noise * rng.standard_normal(400))


def make_post(y, dtype="float32"):
    data, _ = prepare_measured(y, RADAR, "peak")
    return LogPosterior(data, Layout(1, 1, Priors.from_reference(HELI)), RADAR, dtype=dtype)


def section_throughput(quick):
    print("\n== 1. likelihood throughput (walker batch 48, 1 thread)")
    _, y = truth_and_profile()
    res = {}
    for dt in ("float64", "float32"):
        post = make_post(y, dt)
        th = post.layout.sample_prior(48, np.random.default_rng(0), (1e-3, 0.1))
        times = []
        for _ in range(5 if quick else 15):
            t = time.perf_counter()
            post(th)
            times.append(time.perf_counter() - t)
        res[dt] = 48 / np.median(times)
        print(f"  {dt}: {res[dt]:,.0f} profiles/s (median of {len(times)})")
    print(f"  float32 / float64 speed ratio: {res['float32'] / res['float64']:.2f}")


def section_fit(quick):
    print("\n== 2. fit: algorithm x budget (1 start + BOBYQA polish 1000; medians over seeds)")
    x, y = truth_and_profile()
    post = make_post(y)
    lay = post.layout
    zt = lay.z_from_physics(x)
    lo, hi = lay.z_bounds()
    width = (hi - lo)[: lay.n_shared]
    grid = np.repeat(zt[None], 161, axis=0)
    grid[:, -1] = np.linspace(-4, 4, 161)  # the truth at its best window offset
    truth_misfit = post.misfit(grid).min()
    algs = ("GN_CRS2_LM", "GN_ISRES", "GN_MLSL_LDS", "GN_DIRECT_L")
    budgets = (500, 2000) if quick else (1000, 4000, 16000)
    seeds = (0,) if quick else (0, 1, 2)
    print(f"  {'algorithm':13s} {'budget':>7s} {'misfit-truth':>13s} {'max dist':>9s} {'med dist':>9s} {'s':>6s}")
    for alg in algs:
        for b in budgets:
            rows = []
            for sd in seeds:
                s = CalibrationSettings(fit_algorithm=alg, n_starts=1, fit_budget=b, polish_budget=1000)
                t = time.perf_counter()
                # no reference start: the global algorithm alone has to find the basin
                fit = global_fit(post, s, np.random.SeedSequence(sd), start=None)
                d = np.abs(fit.best_z[: lay.n_shared] - zt[: lay.n_shared]) / width
                rows.append((fit.misfit - truth_misfit, d.max(), np.median(d), time.perf_counter() - t))
            m = np.median(np.array(rows), axis=0)
            print(f"  {alg:13s} {b:7d} {m[0]:13.1f} {m[1]:9.3f} {m[2]:9.3f} {m[3]:6.1f}")
    print("  (negative misfit-truth: the fit beats the truth's misfit -- noise fitted; "
          "distances in prior widths)")


OPTIONS = {"ramps": 32, "sbc_draws": 20, "sbc_ramps": 32, "time_budget": 3600.0, "sbc_steps": 3000,
           "sbc_workers": 1, "sbc_checkpoint": None, "sbc_class": "HELI"}


def scene_profiles(cls, ramps, n=5, seed=11):
    from mdaug.generator.chain import SceneConfig, simulate_campaign

    return simulate_campaign(cls, 1, n, seed, scene=SceneConfig().with_acquisition(ramps=ramps).with_specimens(width=0.0)).profiles


def section_likelihood(quick):
    from mdaug.generator.acquisition import Acquisition
    from mdaug.generator.synthetic import SyntheticDraws

    k = OPTIONS["ramps"]
    print(f"\n== 3. marginal likelihood: cost and Monte Carlo error against draws (HELI, K = {k}, 5 measurements, "
          "16 walkers a batch, median of 3)")
    acq = Acquisition.measured(k)
    heli = HELI.to_array()
    carrier, noise, offset = np.full((16, 5), 0.1), np.full((16, 5), -45.0), np.zeros((16, 5))
    x = np.repeat(heli[None], 16, 0)
    ref = SyntheticDraws(acq, 1, n_acquisitions=16 if quick else 128, ramps_drawn=min(k, 32), seed=999)
    mu_ref = ref.profiles(x[:1], carrier[:1], noise[:1], offset[:1], stride=8)[0].mean(axis=1)
    grid = ((4, 4), (8, 8)) if quick else ((4, 4), (8, 8), (16, 8), (16, 16), (32, 16))
    print(f"  {'O':>3s} {'I':>3s} {'ms/evaluation':>14s} {'MC error':>9s}")
    for o, i in grid:
        mus, secs = [], []
        for seed in range(3 if quick else 6):
            sd = SyntheticDraws(acq, 1, n_acquisitions=o, ramps_drawn=i, seed=seed)
            t = time.perf_counter()
            p = sd.profiles(x, carrier, noise, offset, stride=8)
            secs.append((time.perf_counter() - t) / 16)
            mus.append(p[0].mean(axis=1))
        err = np.sqrt(np.mean((np.array(mus) - mu_ref) ** 2))
        print(f"  {o:3d} {i:3d} {1e3 * np.median(secs):14.2f} {err:9.4f}")


def section_closed_form(quick):
    """Cost per walker-evaluation of the closed-form likelihood (5 measurements, 32 walkers a
    batch, CPU time, min of repeats) against the synthetic likelihood at O = 16, I = 16 in the
    same run, and its tolerances' speed against error (log-likelihood change from the
    tightest setting, and the model mean's largest change, peak = 1)."""
    from mdaug.generator.acquisition import Acquisition, render
    from mdaug.inference.calibrate import make_likelihood
    from mdaug.inference.likelihood.closed_form import ClosedFormLikelihood

    k = OPTIONS["ramps"]
    reps = 2 if quick else 5
    print(f"\n== 3b. closed-form likelihood: CPU ms per walker-evaluation (5 measurements, K = {k}, 32 walkers "
          f"a batch, min of {reps}), against the synthetic likelihood (O = 16, I = 16) in the same run")
    acq = Acquisition.measured(k)
    for cls in ("HELI", "QUAD"):
        ref = load_reference(cls)
        y, _ = prepare_measured(render(np.repeat(ref.to_array()[None], 5, 0), acq, rng=1, radar=RADAR), RADAR, "peak")
        ss = np.random.SeedSequence(0)
        cf = make_likelihood(y, ref, ref.n_engines, acq, CalibrationSettings(), ss)
        syn = make_likelihood(y, ref, ref.n_engines, acq, CalibrationSettings(likelihood="synthetic"), ss)
        th_cf = cf.layout.sample_prior(32, np.random.default_rng(2))
        th_syn = syn.layout.sample_prior(32, np.random.default_rng(2))

        def cost(post, th):
            post(th[:2])
            best = np.inf
            for _ in range(reps):
                t = time.process_time()
                post(th)
                best = min(best, time.process_time() - t)
            return 1e3 * best / len(th)

        c_cf, c_syn = cost(cf, th_cf), cost(syn, th_syn)
        print(f"  {cls}: closed form {c_cf:.2f} ms, synthetic {c_syn:.2f} ms (ratio {c_syn / c_cf:.1f}x)")
        tight = ClosedFormLikelihood(y, cf.layout, acq, RADAR, amp_tol=1e-5, pair_tol=1e-3, reach_tol=1e-5)
        th = th_cf[:8]
        ll0, m0 = tight.log_likelihood(th), tight.mean_profiles(th[:2])
        print(f"    {'amp_tol':>8s} {'pair_tol':>8s} {'reach_tol':>9s} {'ms':>7s} {'|dll| median':>12s} {'mean change':>11s}")
        for at, pt, rt in ((1e-4, 1e-2, 1e-4), (1e-3, 5e-2, 3e-4), (3e-3, 0.1, 1e-3)):
            lik = ClosedFormLikelihood(y, cf.layout, acq, RADAR, amp_tol=at, pair_tol=pt, reach_tol=rt)
            d_ll = np.median(np.abs(lik.log_likelihood(th) - ll0))
            d_mu = np.max(np.abs(lik.mean_profiles(th[:2]) - m0))
            print(f"    {at:8.0e} {pt:8.0e} {rt:9.0e} {cost(lik, th_cf):7.2f} {d_ll:12.2f} {d_mu:11.4f}")


def _recovery(res, cls):
    from mdaug.inference.space.priors import engine_lines

    w_true = np.sort(engine_lines(load_reference(cls).to_array().reshape(-1, 13))[0], axis=-1)
    lo, hi = np.quantile(res.lines()[..., 0], [0.05, 0.95], axis=0)
    inside = (lo <= w_true) & (w_true <= hi)
    return f"{int(inside.sum())} of {inside.size} lines inside their 90% interval"


def _calibration(cls, ramps, quick, budget):
    from mdaug.generator.acquisition import Acquisition

    y = scene_profiles(cls, ramps)
    s = (CalibrationSettings.quick() if quick else CalibrationSettings()).replace(time_budget=budget)
    t = time.perf_counter()
    r = calibrate(y, cls, acquisition=Acquisition.measured(ramps), settings=s, random_state=0)
    took = time.perf_counter() - t
    d = r.diagnostics
    print(f"  {took:.1f} s total (fit {r.fit['seconds']:.1f} s, MCMC {d['seconds']:.1f} s); {d['chain_steps']} steps "
          f"x {d['n_walkers']} walkers ({1e3 * d['seconds'] / max(d['chain_steps'], 1):.0f} ms/step); max tau "
          f"{d['tau_max']:.0f}; chain/tau {d['steps_over_tau']:.1f}; min ESS {d['ess_min']:.0f}; "
          f"converged {r.converged}; {_recovery(r, cls)}")
    return r, took


def section_heli(quick):
    k = OPTIONS["ramps"]
    print(f"\n== 4. HELI from 5 scene-simulated acquisitions, K = {k}, default settings (budget "
          f"{OPTIONS['time_budget']:g} s)")
    r, took = _calibration("HELI", k, quick, 60.0 if quick else OPTIONS["time_budget"])
    print(f"  target: converged (>= 50 tau, min ESS >= 400) in < 90 s -> "
          f"{'met' if r.converged and took < 90 else 'NOT met'}")


def section_quad(quick):
    k = OPTIONS["ramps"]
    print(f"\n== 5. QUAD from 5 scene-simulated acquisitions, K = {k}, default settings (budget "
          f"{OPTIONS['time_budget']:g} s)")
    r, took = _calibration("QUAD", k, quick, 60.0 if quick else OPTIONS["time_budget"])
    print(f"  target: converged in < 8 min -> {'met' if r.converged and took < 480 else 'NOT met'}")


def section_sbc(quick):
    from mdaug.inference.diagnostics.sbc import run_sbc

    n, k = (2 if quick else OPTIONS["sbc_draws"]), OPTIONS["sbc_ramps"]
    steps = 200 if quick else OPTIONS["sbc_steps"]
    print(f"\n== 6. SBC of the supported case: {n} truths from the prior, 5 acquisitions each through the scene "
          f"simulator and the chain, K = {k}; at most {steps} steps per calibration; {OPTIONS['sbc_workers']} "
          f"worker(s); resumable from {OPTIONS['sbc_checkpoint']}")
    t = time.perf_counter()
    out = run_sbc(OPTIONS["sbc_class"], n, ramps=k, settings=CalibrationSettings(max_steps=steps, time_budget=None),
                  seed=1, n_rank=49, n_bins=5, checkpoint=OPTIONS["sbc_checkpoint"],
                  workers=OPTIONS["sbc_workers"])
    print(f"  {time.perf_counter() - t:.0f} s ({np.median(out['seconds']):.0f} s per calibration); outer-10% share "
          f"{out['outer_share']:.2f} (honest: 0.10); pooled chi-square p {out['pooled_p']:.3g}; min p "
          f"{out['min_p']:.3g}; converged share {out['converged_share']:.2f}")
    worst = sorted(out["outer_share_by_quantity"].items(), key=lambda kv: -kv[1])[:4]
    print("  largest outer shares: " + ", ".join(f"{q} {v:.2f}" for q, v in worst))


SECTIONS = {"throughput": section_throughput, "fit": section_fit, "likelihood": section_likelihood,
            "closed_form": section_closed_form,
            "heli": section_heli, "quad": section_quad, "sbc": section_sbc}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sections", default=",".join(SECTIONS), help=f"comma list of {list(SECTIONS)}")
    ap.add_argument("--ramps", type=int, default=32, help="K of sections 3-5 (default 32)")
    ap.add_argument("--time-budget", type=float, default=3600.0, help="calibration budget, s (sections 4-5)")
    ap.add_argument("--sbc-draws", type=int, default=20, help="truths from the prior in section 6")
    ap.add_argument("--sbc-ramps", type=int, default=32, help="K of the SBC's acquisitions (section 6)")
    ap.add_argument("--sbc-class", default="HELI", help="class of the SBC's truths (section 6)")
    ap.add_argument("--sbc-steps", type=int, default=3000, help="step cap of each SBC calibration (section 6)")
    ap.add_argument("--sbc-workers", type=int, default=1, help="SBC replicates run in this many processes")
    ap.add_argument("--sbc-checkpoint", default=None,
                    help="JSON-lines file of finished SBC replicates: a rerun resumes from it")
    args = ap.parse_args()
    OPTIONS.update(ramps=args.ramps, time_budget=args.time_budget, sbc_draws=args.sbc_draws,
                   sbc_ramps=args.sbc_ramps, sbc_steps=args.sbc_steps, sbc_workers=args.sbc_workers,
                   sbc_checkpoint=args.sbc_checkpoint, sbc_class=args.sbc_class)
    unknown = [n for n in args.sections.split(",") if n not in SECTIONS]
    if unknown:
        ap.error(f"--sections: unknown {unknown}; choose from {list(SECTIONS)}")
    for name in args.sections.split(","):
        t = time.perf_counter()
        SECTIONS[name](args.quick)
        print(f"  [{name}: {time.perf_counter() - t:.0f} s]")


if __name__ == "__main__":
    main()
