"""Global fit with nlopt: several global starts, each polished locally
(the first start also polishes the class reference itself, after a vectorised
random scan of every measurement's phases when they are fitted).

Both likelihoods expose one fit space (``fit_bounds``, ``fit_objective``,
``canonical_fit``, ``theta_from_fit``): for :class:`.likelihood.fitted_phases.LogPosterior` it is
z with the noise level profiled out (misfit = negative profile log-likelihood),
for :class:`.likelihood.synthetic.SyntheticLikelihood` the whole theta (negative
log-likelihood); the global stage of the latter runs on its ``coarse()`` copy
(fewer simulated acquisitions: a global search needs the landscape, not its last
decimal) and the local polish on the likelihood itself. The objective is
minimised on the unit cube mapped onto the fit space's prior box.
Each start is one run of a global algorithm (``GN_CRS2_LM`` by default) with its
own nlopt seed and budget, then a local polish (``LN_BOBYQA``). The first start
begins at the class reference. Results are reduced by the model's symmetries
(:meth:`Layout.canonical`) before they are compared.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..radar.progress import progress_bar
from ..radar.seeds import rng as seeded_rng

from .likelihood.fitted_phases import LogPosterior

AGREE_MISFIT = 2.0  # nats: starts within this of the best fit "reach the same height"
RIVAL_MISFIT = 10.0  # nats: a distant start within this of the best is a rival mode (multimodal)
AGREE_DISTANCE = 0.05  # max |difference| of shared parameters, in units of their prior width


@dataclass
class FitResult:
    """Outcome of the multi-start fit.

    best_z: canonical best point of the fit space (z, or theta for the marginal
    likelihood); misfit: its objective (nats, up to a constant); sigma: (M,) the
    noise of each measurement there (fitted phases: the maximum-likelihood level;
    marginal: the noise floor in dB); starts_z (S, d), starts_misfit (S,), evals (S,);
    n_agree: starts whose misfit is within ``AGREE_MISFIT`` of the best and whose
    shared parameters are within ``AGREE_DISTANCE`` prior widths of it;
    multimodal: some start ends within ``RIVAL_MISFIT`` nats of the best at a distant
    point (a rival mode; the sampler's walkers start on every rival mode too).
    """

    best_z: np.ndarray
    misfit: float
    sigma: np.ndarray
    starts_z: np.ndarray
    starts_misfit: np.ndarray
    evals: np.ndarray
    n_agree: int
    multimodal: bool
    algorithm: str
    seconds: float
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"best_z": self.best_z.tolist(), "misfit": float(self.misfit), "sigma": self.sigma.tolist(),
                "starts_z": self.starts_z.tolist(), "starts_misfit": self.starts_misfit.tolist(),
                "evals": self.evals.tolist(), "n_agree": int(self.n_agree), "multimodal": bool(self.multimodal),
                "algorithm": self.algorithm, "seconds": float(self.seconds), "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: dict) -> "FitResult":
        arr = {k: np.asarray(d[k], float) for k in ("best_z", "sigma", "starts_z", "starts_misfit", "evals")}
        return cls(misfit=float(d["misfit"]), n_agree=int(d["n_agree"]), multimodal=bool(d["multimodal"]),
                   algorithm=d["algorithm"], seconds=float(d["seconds"]), notes=list(d.get("notes", [])), **arr)


def run_one(nlopt, algorithm: str, post, lo, hi, u0, budget: int, seed: int, bar=None):
    """One nlopt run on the unit cube; returns (best u, best value, evaluations). ``bar``:
    a progress bar told of every evaluation."""
    d = len(lo)
    best = {"f": np.inf, "u": np.array(u0, float), "n": 0}

    def objective(u, grad):
        best["n"] += 1
        if bar is not None:
            bar.update(1)
        f = float(post.fit_objective((lo + (hi - lo) * np.asarray(u))[None])[0])
        if not np.isfinite(f):
            f = 1e300
        if f < best["f"]:
            best["f"], best["u"] = f, np.array(u, float)
        return f

    opt = nlopt.opt(getattr(nlopt, algorithm), d)
    if algorithm.startswith("GN_MLSL"):
        local = nlopt.opt(nlopt.LN_BOBYQA, d)
        local.set_xtol_rel(1e-4)
        local.set_maxeval(max(50, budget // 20))
        opt.set_local_optimizer(local)
    if algorithm.startswith("GN_ISRES") or algorithm.startswith("GN_ESCH") or algorithm.startswith("GN_CRS"):
        opt.set_population(max(10 * (d + 1), 64) if algorithm.startswith("GN_CRS") else 0)
    opt.set_lower_bounds(np.zeros(d))
    opt.set_upper_bounds(np.ones(d))
    opt.set_min_objective(objective)
    opt.set_maxeval(int(budget))
    if algorithm.startswith("LN_"):
        opt.set_initial_step(0.02)
        opt.set_xtol_rel(1e-6)
    nlopt.srand(int(seed))
    try:
        opt.optimize(np.clip(u0, 0.0, 1.0))
    except (nlopt.RoundoffLimited, RuntimeError, ValueError):
        pass  # keep the best point seen; nlopt stops on round-off or a flat objective
    return best["u"], best["f"], best["n"]


def polish_subset(post, v: np.ndarray, cols: np.ndarray, budget: int, seed: int) -> np.ndarray:
    """v (d,) with only its coordinates ``cols`` polished by BOBYQA (the rest held):
    the measurements' nuisances first, before the physics moves."""
    import nlopt

    lo, hi = post.fit_bounds()
    v = np.array(v, float)
    sub_lo, sub_hi = lo[cols], hi[cols]

    class _Sub:
        def fit_objective(self, u):
            full = np.repeat(v[None], len(u), axis=0)
            full[:, cols] = u
            return post.fit_objective(full)

    u, _, _ = run_one(nlopt, "LN_BOBYQA", _Sub(), sub_lo, sub_hi, (v[cols] - sub_lo) / (sub_hi - sub_lo), budget, seed)
    v[cols] = sub_lo + (sub_hi - sub_lo) * u
    return v


def scan_phases(post: LogPosterior, z: np.ndarray, rng: np.random.Generator, n: int = 2048) -> np.ndarray:
    """z with every measurement's phases (and offset) replaced by the best of ``n``
    uniform random draws, the shared parameters held: a measurement's rotor phases
    are arbitrary, so a reference start says nothing about them. Vectorised: one
    batch of n candidates per measurement."""
    lay = post.layout
    lo, hi = lay.z_bounds()
    z = np.array(z, float)
    for m in range(lay.M):
        cols = np.arange(lay.n_shared + m * lay.n_meas_z, lay.n_shared + (m + 1) * lay.n_meas_z)
        cand = np.repeat(z[None], n, axis=0)
        cand[:, cols] = rng.uniform(lo[cols], hi[cols], size=(n, len(cols)))
        cand[0] = z
        z = cand[int(np.argmin(post.misfit(cand)))]
    return z


def global_fit(post, settings, seed_seq: np.random.SeedSequence, start=None) -> FitResult:
    """Multi-start global fit + local polish; see the module docstring.

    start: optional fit-space point used as the first start's initial point
    (default: the class reference, or a prior draw when shapes differ).
    """
    import nlopt

    t0 = time.perf_counter()
    layout = post.layout
    lo, hi = post.fit_bounds()
    width = hi - lo
    coarse = post.coarse()
    rng = seeded_rng(seed_seq)
    zs, fs, ns = [], [], []
    polish = settings.polish_budget if settings.local_algorithm != "none" else 0
    bar = progress_bar(total=settings.n_starts * (settings.fit_budget + polish) + polish, desc="fit",
                       unit="eval", progress=settings.progress)  # an upper bound: nlopt may stop early
    for s in range(settings.n_starts):
        if s == 0 and start is not None:
            v0 = np.clip(start, lo, hi)
            if layout.phase_cols.size:
                v0 = scan_phases(post, v0, rng)
            elif post.nuisance_cols().size:  # marginal: each measurement's own terms first
                v0 = polish_subset(post, v0, post.nuisance_cols(), max(50, settings.polish_budget // 2),
                                   int(rng.integers(2**31 - 1)))
            u0 = (np.clip(v0, lo, hi) - lo) / width
        else:
            u0 = rng.uniform(size=len(lo))
        seed = int(rng.integers(2**31 - 1))
        u, f, n = run_one(nlopt, settings.fit_algorithm, coarse, lo, hi, u0, settings.fit_budget, seed, bar)
        if coarse is not post:
            f = float(post.fit_objective((lo + width * u)[None])[0])
        if settings.local_algorithm != "none" and settings.polish_budget > 0:
            # polish the global result; the first start also polishes its initial point
            # (the reference) directly, which a population method may have left behind
            for u_from in ([u, u0] if s == 0 and start is not None else [u]):
                u2, f2, n2 = run_one(nlopt, settings.local_algorithm, post, lo, hi, u_from,
                                      settings.polish_budget, seed, bar)
                n += n2
                if f2 < f:
                    u, f = u2, f2
        zs.append(post.canonical_fit((lo + width * u)[None])[0])
        fs.append(f)
        ns.append(n)
        bar.set_postfix_str(f"start {s + 1} of {settings.n_starts}, best misfit {min(fs):.1f}", refresh=True)
    bar.close()
    zs, fs = np.array(zs), np.array(fs)
    best = int(np.argmin(fs))
    shared = slice(0, layout.n_shared)
    dist = np.max(np.abs(zs[:, shared] - zs[best, shared]) / width[shared], axis=1)
    close = fs - fs[best] <= AGREE_MISFIT
    n_agree = int(np.sum(close & (dist <= AGREE_DISTANCE)))
    rivals = (fs - fs[best] <= RIVAL_MISFIT) & (dist > AGREE_DISTANCE)
    multimodal = bool(np.any(rivals))
    sigma = post.fit_noise(zs[best][None])[0]
    notes = []
    if multimodal:
        notes.append(f"multimodal: {int(np.sum(rivals))} start(s) fit within {RIVAL_MISFIT} nats of the best "
                     "at a distant point; the MCMC walkers start on every such mode")
    if n_agree < settings.n_starts:
        notes.append(f"{settings.n_starts - n_agree} of {settings.n_starts} start(s) ended elsewhere "
                     f"(misfits {np.round(fs - fs[best], 1).tolist()} above the best)")
    return FitResult(best_z=zs[best], misfit=float(fs[best]), sigma=sigma, starts_z=zs, starts_misfit=fs,
                     evals=np.array(ns, float), n_agree=n_agree, multimodal=multimodal,
                     algorithm=f"{settings.fit_algorithm}+{settings.local_algorithm}",
                     seconds=time.perf_counter() - t0, notes=notes)
