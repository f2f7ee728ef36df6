"""Speed and error of the calibration (run on demand: python tests/benchmarks/inference.py).

Prints, all with 1 thread:
1. likelihood throughput, float32 vs float64 f(x) (ratio against float64 in the same run);
2. fit: nlopt global algorithm x budget -> final misfit (nats above the truth's) and
   distance to the truth (shared parameters, in prior widths), medians over seeds;
3. MCMC: chain length -> error of posterior means and 90% interval ends against a
   long reference chain (in reference posterior sds), and seconds;
4. a full HELI calibration with the default settings (fit + MCMC to 50 tau or budget);
5. a QUAD run with a capped budget (time per step, tau so far);
6. simulation-based calibration: rank-uniformity statistics over many prior draws;
7. SBC of the default emcee sampler against the opt-in tempered SMC with and
   without mode jumps (``--sections sbc_compare``, ``--samplers``, ``--sbc-draws``):
   outer-10% share, chi-square and KS p, p of the truth's log-posterior rank,
   s/calibration;
8. a HELI calibration with ``sampler="smc"`` at default settings (time).

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


def section_mcmc(quick):
    print("\n== 3. MCMC: chain length vs error against a long reference chain")
    _, y = truth_and_profile()
    ref_steps = 4000 if quick else 24000
    lengths = (500, 1000) if quick else (1000, 2000, 4000, 8000)

    def run(steps, seed):
        s = CalibrationSettings(n_starts=2, fit_budget=3000, max_steps=steps, check_every=500,
                                min_tau_multiple=1e9)  # never stop early: fixed length
        t = time.perf_counter()
        r = calibrate(y, "HELI", settings=s, random_state=seed)
        return r, time.perf_counter() - t

    ref, t_ref = run(ref_steps, 100)
    rd = ref.draws()
    keep = [IDX[n] for n in ("A_a", "A_b", "A_p", "A_m", "w_a", "w_b", "C_p", "C_m")]
    mu, sd = rd[:, keep].mean(0), rd[:, keep].std(0)
    q = np.quantile(rd[:, keep], [0.05, 0.95], axis=0)
    print(f"  reference: {ref_steps} steps, {t_ref:.0f} s, max tau {ref.diagnostics['tau_max']:.0f}, "
          f"chain/tau {ref.diagnostics['steps_over_tau']:.1f}")
    print(f"  {'steps':>6s} {'s':>6s} {'|mean err|/sd (med, max)':>26s} {'|q05,q95 err|/sd (med, max)':>29s}")
    for n in lengths:
        r, t = run(n, 1)
        d = r.draws()[:, keep]
        em = np.abs(d.mean(0) - mu) / sd
        eq = np.abs(np.quantile(d, [0.05, 0.95], axis=0) - q) / sd
        print(f"  {n:6d} {t:6.1f} {np.median(em):12.2f} {em.max():12.2f} {np.median(eq):14.2f} {eq.max():13.2f}")


def section_full(quick):
    print("\n== 4. full HELI calibration, default settings (one profile, noise 1% of the peak)")
    _, y = truth_and_profile()
    s = CalibrationSettings.quick() if quick else CalibrationSettings()
    t = time.perf_counter()
    r = calibrate(y, "HELI", settings=s, random_state=0)
    took = time.perf_counter() - t
    d = r.diagnostics
    print(f"  {took:.1f} s total (fit {r.fit['seconds']:.1f} s, MCMC {d['seconds']:.1f} s); "
          f"{d['chain_steps']} steps x {d['n_walkers']} walkers; max tau {d['tau_max']:.0f}; "
          f"chain/tau {d['steps_over_tau']:.1f}; min ESS {d['ess_min']:.0f}; converged {r.converged}")
    print(f"  target: < 60 s to >= 50 tau and ESS >= 400 -> {'met' if r.converged and took < 60 else 'NOT met'}")
    ident = [k for k, v in d["identified"].items() if v]
    print(f"  identified: {', '.join(ident)}")
    print(f"  not identified: {', '.join(k for k, v in d['identified'].items() if not v)}")


def section_quad(quick):
    print("\n== 5. QUAD (4 engines) with a capped budget")
    quad = load_reference("QUAD")
    rng = np.random.default_rng(0)
    y = np.abs(profiles(quad.to_array())[0] + NOISE * rng.standard_normal(400))
    steps = 300 if quick else 3000
    s = CalibrationSettings(n_starts=1, fit_budget=2000 if quick else 8000, max_steps=steps, check_every=500)
    t = time.perf_counter()
    r = calibrate(y, "QUAD", settings=s, random_state=0)
    took = time.perf_counter() - t
    d = r.diagnostics
    per_step = d["seconds"] / d["chain_steps"]
    print(f"  {took:.0f} s total (fit {r.fit['seconds']:.0f} s); {d['n_walkers']} walkers, "
          f"{per_step * 1e3:.1f} ms/step; tau so far {d['tau_max']:.0f} steps "
          f"(a lower bound on a chain this short); 50 tau would need >= "
          f"{50 * d['tau_max'] * per_step / 60:.1f} min; chain/tau {d['steps_over_tau']:.1f}; "
          f"weak engines {d['weak_engines']}")


def section_sbc(quick):
    from mdaug.inference.sbc import run_sbc

    n = 4 if quick else 30
    print(f"\n== 6. simulation-based calibration ({n} prior draws, HELI, noise sigma in [0.005, 0.03])")
    t = time.perf_counter()
    out = run_sbc("HELI", n, settings=CalibrationSettings.quick(max_steps=600 if quick else 3000), seed=1,
                  n_rank=49, n_bins=5)
    print(f"  {time.perf_counter() - t:.0f} s; pooled chi-square p = {out['pooled_p']:.3g}; "
          f"min per-quantity p = {out['min_p']:.3g}; converged share {out['converged_share']:.2f}")
    worst = sorted(out["p_values"].items(), key=lambda kv: kv[1])[:6]
    print("  lowest p: " + ", ".join(f"{k} {v:.3g}" for k, v in worst))
    r = out["ranks"] / out["n_rank"]
    print(f"  share of truths in the outer 10% of their posterior (uniform: 0.10): "
          f"{np.mean((r < 0.05) | (r > 0.95)):.2f}")


OPTIONS = {"smc_particles": 0, "samplers": "emcee,smc,smc-nojump", "sbc_draws": 24, "sbc_c_bounds": None}


def section_sbc_compare(quick):
    """Same prior draws, same seeds: emcee (quick preset, 3000 steps) against tempered SMC."""
    from mdaug.inference.sbc import run_sbc

    n = 4 if quick else OPTIONS["sbc_draws"]
    print(f"\n== 7. SBC, emcee vs tempered SMC ({n} prior draws each, HELI, noise sigma in [0.005, 0.03], "
          f"C_p, C_m prior {OPTIONS['sbc_c_bounds'] or (0.5, 1.5)}, 1 thread, 49 posterior draws ranked, 5 rank bins)")
    smc = CalibrationSettings.quick(sampler="smc", n_particles=OPTIONS["smc_particles"], smc_polish=8)
    configs = {"emcee": CalibrationSettings.quick(max_steps=600 if quick else 3000), "smc": smc,
               "smc-nojump": smc.replace(smc_jump=0.0)}
    configs = {k: v for k, v in configs.items() if k in OPTIONS["samplers"].split(",")}
    print(f"  {'sampler':12s} {'outer 10%':>9s} {'pooled p':>10s} {'min p':>9s} {'KS p':>8s} {'lp p':>8s} "
          f"{'conv':>5s} {'s/calib':>8s}")
    from scipy import stats

    for name, s in configs.items():
        t = time.perf_counter()
        c = OPTIONS["sbc_c_bounds"]
        out = run_sbc("HELI", n, settings=s, seed=1, n_rank=49, n_bins=5,
                      prior_overrides={"C_p": c, "C_m": c} if c else None)
        took = (time.perf_counter() - t) / n
        r = out["ranks"] / out["n_rank"]
        outer = np.mean((r < 0.05) | (r > 0.95))
        # pooled Kolmogorov-Smirnov of the (jittered, continuous) normalised ranks against U(0, 1)
        u = (out["ranks"] + np.random.default_rng(0).uniform(size=out["ranks"].shape)) / (out["n_rank"] + 1)
        ks = stats.kstest(u.ravel(), "uniform").pvalue
        if name.startswith("smc") and s.n_particles:
            name = f"{name}@{s.n_particles}"
        print(f"  {name:12s} {outer:9.2f} {out['pooled_p']:10.3g} {out['min_p']:9.3g} {ks:8.3g} "
              f"{out['p_values']['log posterior']:8.3g} {out['converged_share']:5.2f} {took:8.1f}")
    print("  (uniform ranks: outer 10% share 0.10, p-values not small; KS over all quantities pooled, "
          "which ignores their dependence: read it as a descriptive statistic; lp p: chi-square p of the "
          "truth's log-posterior rank, small when the sampler misses modes)")


def section_full_smc(quick):
    print("\n== 8. full HELI calibration with sampler='smc', default settings otherwise")
    _, y = truth_and_profile()
    s = (CalibrationSettings.quick() if quick else CalibrationSettings()).replace(
        sampler="smc", n_particles=OPTIONS["smc_particles"])
    t = time.perf_counter()
    r = calibrate(y, "HELI", settings=s, random_state=0)
    took = time.perf_counter() - t
    d = r.diagnostics
    print(f"  {took:.1f} s total (fit {r.fit['seconds']:.1f} s, SMC {d['seconds']:.1f} s); "
          f"{d['smc_n_particles']} particles, {d['smc_stages']} stages, {d['smc_n_evals']} evaluations; "
          f"ESS {d['ess_min']:.0f}; distinct {d['smc_unique_share']:.0%}; converged {r.converged}")


SECTIONS = {"throughput": section_throughput, "fit": section_fit, "mcmc": section_mcmc, "full": section_full,
            "quad": section_quad, "sbc": section_sbc, "sbc_compare": section_sbc_compare,
            "full_smc": section_full_smc}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sections", default=",".join(SECTIONS), help=f"comma list of {list(SECTIONS)}")
    ap.add_argument("--smc-particles", type=int, default=0, help="SMC particles in sections 7, 8 (0 = auto)")
    ap.add_argument("--samplers", default=OPTIONS["samplers"], help="samplers compared in section 7")
    ap.add_argument("--sbc-draws", type=int, default=24, help="prior draws per sampler in section 7")
    ap.add_argument("--sbc-c-bounds", default=None, help="LO,HI prior bounds of C_p and C_m in section 7 "
                    "(default: the reference-derived 0.5,1.5)")
    args = ap.parse_args()
    OPTIONS.update(smc_particles=args.smc_particles, samplers=args.samplers, sbc_draws=args.sbc_draws,
                   sbc_c_bounds=tuple(map(float, args.sbc_c_bounds.split(","))) if args.sbc_c_bounds else None)
    unknown = [n for n in args.sections.split(",") if n not in SECTIONS]
    if unknown:
        ap.error(f"--sections: unknown {unknown}; choose from {list(SECTIONS)}")
    for name in args.sections.split(","):
        t = time.perf_counter()
        SECTIONS[name](args.quick)
        print(f"  [{name}: {time.perf_counter() - t:.0f} s]")


if __name__ == "__main__":
    main()
