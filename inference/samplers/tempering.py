"""Tempered sequential Monte Carlo (SMC) from the prior, the algorithm of the ``smc``
plugin (:mod:`.smc`: its knobs and its run), an opt-in sampler for multimodal
posteriors (``CalibrationSettings(sampler="smc")``).

Why SMC and not parallel tempering: the emcee ensemble starts at the fit's modes
and its walkers stay in them (tau capped by the chain length, SBC far from
uniform). Tempered SMC (Del Moral, Doucet & Jasra 2006; adaptive version of
Chopin & Papaspiliopoulos 2020, ch. 17) instead moves a population of N particles
from the prior (beta = 0) to the posterior (beta = 1) through the tempered targets
p_beta(theta) ~ prior(theta) x L(theta)^beta:

1. start: N independent prior draws (every mode is populated in proportion to
   its prior mass, whatever the fit found);
2. reweight: the next beta is chosen by bisection so that the effective sample size
   of the incremental weights L^(beta' - beta) is ``ess_target`` x N; the
   evidence estimate accumulates log mean(incremental weight);
3. resample (systematic) and rejuvenate: Metropolis sweeps that leave p_beta'
   invariant -- differential-evolution translations x + gamma (x_j - x_k) + e with
   x_j, x_k from the other half of the population (the two halves move in turn, so
   each half's proposal is a symmetric translation given the other; phases taken
   modulo 2 pi), gamma a mixture of 0.25, 1 x 2.38 / sqrt(2 dim) and 1 (mode hops),
   and, for a share of the proposals, one coordinate redrawn uniformly on its prior
   range (symmetric too): the HELI likelihood is a golf course in each frequency
   (a spectral line pays off only within ~1 bin of its place), and a redraw puts a
   particle's line at a distant place in one step.
   Sweeps run until each particle has moved with probability ``p_move`` under the
   observed acceptance (at least ``min_sweeps``, at most ``max_sweeps``);
4. mode jumps (calibration default, :mod:`.modes`): a share of the proposals are
   independence draws from a Student-t mixture over the optima found so far (the
   fit's starts, and particles polished at a few tempering levels). HELI modes
   differ in several coordinates at once (a line's frequency, amplitude and phase
   and the tone offset together), which neither DE nor single-coordinate moves
   cross; a mode no particle reached early stayed empty without them.

Mode weights come from the reweighting (which needs no mixing between modes), not
from walkers having to cross between modes, and the whole population is one
vectorised batch of the likelihood. Output: N equally weighted particles at beta =
1 and log Z (for model comparison). Not converged (flagged) when the stage budget
ends before beta = 1 or the last rejuvenation hardly moves the particles.

Resume: after every stage the population, beta, log Z, history and the random
generator's state are written atomically to an npz checkpoint; a rerun with the
same problem (fingerprint) continues from it to exactly the uninterrupted result.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...radar.seeds import rng as seeded_rng
from ...generator.model import wrap_phase
from .base import CalibrationInterrupted, stop_on_sigint
from .toolbox import systematic_resample

GAMMA_MIX = ((0.25, 0.5), (1.0, 0.4), (None, 0.1))  # (factor of 2.38/sqrt(2 dim) or None = 1.0, weight)
JITTER = 1e-6  # relative Gaussian jitter of DE proposals (in units of the population sd)


@dataclass
class SMCResult:
    """particles (N, dim) equally weighted at beta = 1; log_lik (N,); log_z (evidence,
    nats, including the prior's normalisation); betas (stages + 1,); ess (stages,)
    weight ESS at each reweighting; acceptance (stages,) and sweeps (stages,) of the
    rejuvenations; converged; reason; seconds; resumed_at (stage); n_evals (including
    the mode search's); n_modes: optima known to the mode jumps at the end."""

    particles: np.ndarray
    log_lik: np.ndarray
    log_z: float
    betas: np.ndarray
    ess: np.ndarray
    acceptance: np.ndarray
    sweeps: np.ndarray
    converged: bool
    reason: str
    seconds: float
    resumed_at: int = 0
    n_evals: int = 0
    log_prior: np.ndarray | None = None
    n_modes: int = 0


def next_beta(log_lik: np.ndarray, beta: float, target_ess: float) -> float:
    """The largest beta' in (beta, 1] whose incremental weights exp((beta' - beta) log L)
    keep an ESS >= target_ess (bisection on the monotone ESS curve)."""

    def ess(b):
        lw = (b - beta) * log_lik
        w = np.exp(lw - lw.max())
        return w.sum() ** 2 / np.sum(w * w)

    if ess(1.0) >= target_ess:
        return 1.0
    lo, hi = beta, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if ess(mid) >= target_ess:
            lo = mid
        else:
            hi = mid
    return max(lo, beta + 1e-12)


def de_sweep(theta, ll, lprior, beta, target, rng, phase_cols=(), bounds=None, p_redraw: float = 0.0,
             mixture=None, p_jump: float = 0.0, kernels=()):
    """One sweep: the two halves of the population move in turn by Metropolis steps
    under prior x L^beta. target: theta (n, dim) -> (log prior (n,), log lik (n,)).
    Proposals: DE translations; with probability ``p_redraw`` (needs ``bounds`` =
    (lo, hi) arrays (dim,)) instead one random coordinate redrawn uniformly on
    [lo, hi] (symmetric: the uniform density does not depend on the current value),
    which lets a particle jump straight to a distant narrow mode of that coordinate;
    a particle whose coordinate lies outside [lo, hi] keeps it (no redraw could
    return it there). With probability ``p_jump`` (needs ``mixture``, a
    :class:`.toolbox.StudentMixture`) instead an independence proposal from the
    mixture over known modes, accepted with the ratio that includes q(old) / q(new).
    kernels: further proposals, a sequence of (share, move), move (theta (k, dim),
    rng) -> (theta', log correction) with log correction = log q(theta | theta') -
    log q(theta' | theta), Jacobians included (-inf refuses), e.g. the line
    relabelling :meth:`..space.layout.Layout.random_relabel` (a random bijection whose
    inverse is as likely: the correction is its log |Jacobian|) or the smc route's
    redraws (:mod:`mdaug.inference.amortized.redraw`); each takes its share of the
    proposals after the mode jumps. Every particle picks its kernel independently of
    its state, so the sweep is a mixture of valid kernels.
    Returns (theta, ll, lprior, acceptance share); arrays are updated copies."""
    theta, ll, lprior = theta.copy(), ll.copy(), lprior.copy()
    n, dim = theta.shape
    cols = np.asarray(phase_cols, dtype=int)
    perm = rng.permutation(n)
    halves = (perm[: n // 2], perm[n // 2:])
    g0 = 2.38 / np.sqrt(2 * dim)
    accepted = 0
    for i in (0, 1):
        move, other = halves[i], halves[1 - i]
        m = len(move)
        pj = rng.integers(len(other), size=m)
        pk = rng.integers(len(other) - 1, size=m)
        j, k = other[pj], other[pk + (pk >= pj)]  # two distinct partners from the other half
        choice = rng.choice(len(GAMMA_MIX), size=m, p=[w for _, w in GAMMA_MIX])
        gamma = np.array([g0 * f if f else 1.0 for f, _ in GAMMA_MIX])[choice]
        diff = theta[j] - theta[k]
        if cols.size:
            diff[:, cols] = wrap_phase(diff[:, cols])
        scale = theta[other].std(axis=0) + 1e-300
        prop = theta[move] + gamma[:, None] * diff + JITTER * scale * rng.standard_normal((m, dim))
        log_jac = np.zeros(m)
        outside = np.zeros(m, bool)  # redraws of a coordinate that lies outside its box: refused
        if bounds is not None and p_redraw > 0:
            redraw = np.flatnonzero(rng.uniform(size=m) < p_redraw)
            c = rng.integers(dim, size=redraw.size)
            old = theta[move[redraw], c]
            prop[redraw] = theta[move[redraw]]
            prop[redraw, c] = rng.uniform(bounds[0][c], bounds[1][c])
            outside[redraw[(old < bounds[0][c]) | (old > bounds[1][c])]] = True
        kernel = rng.uniform(size=m)
        jump = (kernel < p_jump) if mixture is not None else np.zeros(m, bool)
        if jump.any():
            prop[jump] = mixture.sample(int(jump.sum()), rng)
        taken, start = jump.copy(), p_jump  # a jump or a kernel replaces the redraw drawn for its particle
        for share, fn in kernels:
            pick = (kernel >= start) & (kernel < start + share)
            start += share
            taken |= pick
            if pick.any():
                prop[pick], log_jac[pick] = fn(theta[move[pick]], rng)
        log_jac[outside & ~taken] = -np.inf
        if cols.size:
            prop[:, cols] = wrap_phase(prop[:, cols])
        lp_new, ll_new = target(prop)
        with np.errstate(invalid="ignore"):
            log_a = (lp_new + beta * np.where(np.isfinite(lp_new), ll_new, 0.0)) - (lprior[move] + beta * ll[move])
            if jump.any():
                log_a[jump] += mixture.logpdf(theta[move[jump]]) - mixture.logpdf(prop[jump])
            log_a += log_jac
        acc = np.log(rng.uniform(size=m)) < np.where(np.isfinite(log_a), log_a, -np.inf)
        idx = move[acc]
        theta[idx], ll[idx], lprior[idx] = prop[acc], ll_new[acc], lp_new[acc]
        accepted += int(acc.sum())
    return theta, ll, lprior, accepted / n


def _check_checkpoint(path: Path, fp: str):
    """Saved state dict of an SMC checkpoint, or None when there is none."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            state = {k: f[k] for k in f.files}
    except Exception as exc:  # a foreign or damaged file: name it
        raise ValueError(f"{path}: not a readable SMC checkpoint ({type(exc).__name__}: {exc}); "
                         "delete it or choose another backend path") from exc
    if "smc_fingerprint" not in state:
        raise ValueError(f"{path}: not an mdaug SMC checkpoint (no 'smc_fingerprint'); delete it or choose "
                         "another backend path")
    if str(state["smc_fingerprint"]) != fp:
        raise ValueError(f"{path}: holds an SMC run of a different problem (data, class, engines or settings "
                         "differ); delete it or choose another backend path")
    return state


def _save_checkpoint(path: Path, fp: str, rng, **arrays) -> None:
    from ...radar import atomic_savez

    atomic_savez(path, smc_fingerprint=np.array(fp), rng_state=np.array(json.dumps(rng.bit_generator.state)),
                 **{k: np.asarray(v) for k, v in arrays.items()})


def run_smc(target, sample_prior, n_particles: int, seed, *, ess_target: float = 0.5, p_move: float = 0.99,
            min_sweeps: int = 2, max_sweeps: int = 40, max_stages: int = 500, min_acceptance: float = 0.02,
            phase_cols=(), bounds=None, p_redraw: float = 0.0, modes=None, p_jump: float = 0.0,
            kernels=(), backend_path=None, fp: str = "",
            progress: bool | None = False, time_budget: float | None = None) -> SMCResult:
    """Adaptive tempered SMC from the prior to the posterior (see the module docstring).

    target: theta (n, dim) -> (log prior (n,), log likelihood (n,)), vectorised;
    log prior -inf outside the support (the likelihood is then ignored).
    sample_prior: (n, rng) -> (n, dim) prior draws. seed: int / SeedSequence for a
    numpy Generator. ess_target: ESS fraction kept at each reweighting; p_move:
    probability that a particle moves during a rejuvenation (sets the sweep count
    from the acceptance); min_acceptance: a final rejuvenation accepting less is
    flagged not converged. bounds, p_redraw: uniform single-coordinate redraws (see
    :func:`de_sweep`; the prior must be uniform on [lo, hi] in each coordinate for
    them to be efficient, they are valid for any prior). modes: a mode finder
    (:class:`.modes.ModeFinder` or any object with ``update(theta, beta, rng) ->
    evaluations``, ``mixture(beta, rng)``, ``state()`` and ``load(state)``) asked
    before every rejuvenation to look for new optima and for the mode mixture that
    ``p_jump`` of the proposals are drawn from (see :func:`de_sweep`). kernels:
    further proposals with their shares (see :func:`de_sweep`), e.g. an exact-symmetry move.
    backend_path: npz checkpoint (resumable, see above). progress: a bar of beta
    (0 -> 1) on a terminal. A Ctrl-C stops after the current stage (its checkpoint
    saved) with :class:`.CalibrationInterrupted`. time_budget: seconds; checked
    between the rejuvenation sweeps, the run ends within a sweep of it, flagged not converged.
    """
    t0 = time.perf_counter()
    deadline, timed_out = None if time_budget is None else t0 + time_budget, []

    def out_of_time() -> bool:  # True (and remembered) when the budget cuts the run short
        if deadline is not None and time.perf_counter() > deadline:
            timed_out.append(True)
        return bool(timed_out)

    path = None if backend_path is None else Path(backend_path)
    state = _check_checkpoint(path, fp) if path is not None else None
    rng = seeded_rng(seed)
    if state is not None:
        rng.bit_generator.state = json.loads(str(state["rng_state"]))
        theta, ll, lprior = state["theta"], state["ll"], state["lprior"]
        betas, log_z = list(state["betas"]), float(state["log_z"])
        ess_h, acc_h, sw_h = list(state["ess"]), list(state["acceptance"]), list(state["sweeps"])
        n_evals = int(state["n_evals"])
        resumed_at = len(betas) - 1
        if modes is not None:
            modes.load({k[6:]: v for k, v in state.items() if k.startswith("modes_")})
    else:
        theta = np.asarray(sample_prior(n_particles, rng), float)
        lprior, ll = target(theta)
        if not np.all(np.isfinite(lprior)) or not np.all(np.isfinite(ll)):
            raise ValueError("SMC: a prior draw has a non-finite log prior or log likelihood")
        betas, log_z, ess_h, acc_h, sw_h, n_evals, resumed_at = [0.0], 0.0, [], [], [], n_particles, 0
    n = theta.shape[0]
    from ...radar.progress import progress_bar

    bar = progress_bar(total=1000, initial=int(1000 * betas[-1]), desc="SMC (beta x 1000)", unit="",
                       progress=progress)
    try:
        with stop_on_sigint() as flag:
            while betas[-1] < 1.0 and len(betas) - 1 < max_stages and not out_of_time():
                beta = betas[-1]
                b = next_beta(ll, beta, ess_target * n)
                lw = (b - beta) * ll
                top = lw.max()
                w = np.exp(lw - top)
                log_z += top + np.log(w.mean())
                w /= w.sum()
                ess_h.append(1.0 / np.sum(w * w))
                idx = systematic_resample(w, rng)
                theta, ll, lprior = theta[idx], ll[idx], lprior[idx]
                mixture = None
                if modes is not None:
                    n_evals += modes.update(theta, b, rng)
                    mixture = modes.mixture(b, rng)
                acc_sum, sweeps, need = 0.0, 0, min_sweeps
                while sweeps < need and not (sweeps and out_of_time()):
                    theta, ll, lprior, a = de_sweep(theta, ll, lprior, b, target, rng, phase_cols, bounds, p_redraw,
                                                    mixture, p_jump, kernels)
                    n_evals += n
                    sweeps += 1
                    acc_sum += a
                    rate = min(max(acc_sum / sweeps, 1e-3), 0.999)
                    need = int(np.clip(np.ceil(np.log(1 - p_move) / np.log(1 - rate)), min_sweeps, max_sweeps))
                betas.append(b)
                acc_h.append(acc_sum / sweeps)
                sw_h.append(sweeps)
                if path is not None:
                    extra = {} if modes is None else {f"modes_{k}": v for k, v in modes.state().items()}
                    _save_checkpoint(path, fp, rng, theta=theta, ll=ll, lprior=lprior, betas=betas, log_z=log_z,
                                     ess=ess_h, acceptance=acc_h, sweeps=sw_h, n_evals=n_evals, **extra)
                bar.update(int(1000 * betas[-1]) - bar.n)
                bar.set_postfix_str(f"stage {len(betas) - 1}, acceptance {acc_h[-1]:.2f}")
                if flag["stop"]:
                    raise CalibrationInterrupted(f"stopped after stage {len(betas) - 1}")
    except KeyboardInterrupt as exc:
        where = f"; {len(betas) - 1} stage(s) are saved in {path}" if path is not None else ""
        raise CalibrationInterrupted(f"SMC interrupted{where}") from exc
    finally:
        bar.close()
    stages = len(betas) - 1
    if timed_out:
        converged, reason = False, (f"NOT CONVERGED: the time budget of {time_budget:g} s ended the run at beta "
                                    f"{betas[-1]:.3g} after {stages} stage(s); rerun to continue")
    elif betas[-1] < 1.0:
        converged, reason = False, (f"NOT CONVERGED: SMC stage budget of {max_stages} ended at beta "
                                    f"{betas[-1]:.3g} < 1 (particles are not posterior draws)")
    elif acc_h and acc_h[-1] < min_acceptance:
        converged, reason = False, (f"NOT CONVERGED: the last rejuvenation accepted {acc_h[-1]:.3f} < "
                                    f"{min_acceptance} of its moves (resampled duplicates barely moved)")
    else:
        converged = True
        reason = (f"SMC reached beta = 1 in {stages} stages, {n_evals} likelihood evaluations; last "
                  f"rejuvenation {sw_h[-1] if sw_h else 0} sweeps at acceptance {acc_h[-1] if acc_h else 1:.2f}")
    return SMCResult(particles=theta, log_lik=ll, log_z=float(log_z), betas=np.array(betas), ess=np.array(ess_h),
                     acceptance=np.array(acc_h), sweeps=np.array(sw_h, int), converged=converged, reason=reason,
                     seconds=time.perf_counter() - t0, resumed_at=resumed_at, n_evals=n_evals,
                     log_prior=lprior, n_modes=0 if modes is None else len(modes.state().get("means", ())))
