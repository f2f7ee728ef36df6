"""The emcee driver :func:`run_ensemble` (the ``emcee`` sampler's and the amortized
route's learned likelihood's runs): one convergence rule, resumable through emcee's
HDF5 backend.

* Moves: differential evolution (``DEMove``, three step scales) taken modulo 2 pi
  on the phases, so phases live on the circle without boundaries, and (a share
  ``settings.relabel``) the line relabelling of :meth:`..space.layout.Layout.random_relabel`,
  an exact symmetry no translation crosses (:func:`make_moves`).
* The chain runs in blocks of ``check_every`` steps (aligned to absolute step
  numbers, so a resumed run checks at the same steps as an uninterrupted one);
  after each block the integrated autocorrelation time tau of every coordinate is
  estimated (emcee.autocorr) and the run stops when the chain is at least
  ``min_tau_multiple`` x max tau long and tau moved by less than ``tau_rtol``.
  Otherwise it stops when the time budget (``settings.time_budget`` seconds) or
  the optional step cap ``max_steps`` ends, and is flagged not converged.
* Progress: one bar for the run (steps against the 50 tau target, which is
  re-estimated at every check, so its ETA sharpens as tau settles).
* Resume: every step is written to the HDF5 file together with emcee's random
  state (a legacy ``RandomState``); on restart emcee reads both back, so an
  interrupted run continues to exactly the chain an uninterrupted one would give.
  The file also records a fingerprint of the problem; resuming a different
  problem is refused.
* Memory: every ``store_every``-th step is kept (auto: the chain stays under
  ~160 MB; HELI keeps every step, QUAD about every 14th); tau, burn-in and
  thinning are still counted in steps.
* Walkers are not independent chains: ESS per coordinate is
  n_walkers x (steps after burn-in) / tau, not arviz's R-hat/ESS over walkers.
"""
from __future__ import annotations

import contextlib
import io
import signal
import time
from pathlib import Path

import numpy as np

from ...generator.model import wrap_phase
from .base import CalibrationInterrupted, SamplerRun, stop_on_signal, stop_on_sigint
from .toolbox import estimate_tau

GROUP = "mcmc"
DE_MIX = ((0.25, 0.5), (1.0, 0.4), (None, 0.1))  # (factor of the standard gamma or None = 1.0, weight)

MAX_STORED_FLOATS = 2e7  # chain kept in memory / on disk: ~160 MB of float64


AUTO_MAX_STEPS = 100_000  # steps the automatic storage interval plans for when no step cap is set


def store_interval(own, n_walkers: int, dim: int) -> int:
    """Steps per stored step: ``own.store_every`` (an :class:`.ensemble.EmceeSettings`) or,
    when 0, the smallest k that keeps (max_steps or AUTO_MAX_STEPS) / k x walkers x dim
    under MAX_STORED_FLOATS."""
    if own.store_every:
        return int(own.store_every)
    steps = own.max_steps or AUTO_MAX_STEPS
    return max(1, int(np.ceil(steps * n_walkers * dim / MAX_STORED_FLOATS)))


def make_moves(phase_cols, dim: int, relabel=None, p_relabel: float = 0.0):
    """Differential-evolution moves whose proposals are wrapped on the phase columns.

    A DE proposal is a translation x + gamma (x_j - x_k) + noise whose law is symmetric
    under sign change, so taking it modulo 2 pi on the circle keeps it a symmetric
    proposal on the torus (detailed balance holds). The snooker move is not a
    translation and is not used.

    Mixture (``DE_MIX``): scale 0.25 x the standard 2.38 / sqrt(2 dim) (half the
    steps: the posterior's ridges are narrow, the standard scale alone accepts ~2%),
    the standard scale, and gamma = 1 (10%: swaps a walker between the regions
    occupied by two others, the mode-hopping move of ter Braak 2006).
    ``relabel`` (coords, random) -> (coords', log |Jacobian|): a random bijection
    whose inverse is as likely (:meth:`..space.layout.Layout.random_relabel`), used as an
    emcee ``MHMove`` for a share ``p_relabel`` of the steps (the DE weights shrink).
    """
    import emcee

    cols = np.asarray(phase_cols, dtype=int)

    class WrappedDEMove(emcee.moves.DEMove):
        def get_proposal(self, s, c, random):
            q, f = super().get_proposal(s, c, random)
            if cols.size:
                q[:, cols] = wrap_phase(q[:, cols])
            return q, f

    g_default = 2.38 / np.sqrt(2 * dim)
    share = 1.0 - (p_relabel if relabel is not None else 0.0)
    moves = [(WrappedDEMove(gamma0=f * g_default if f else 1.0), w * share) for f, w in DE_MIX]
    if relabel is not None and p_relabel > 0:
        moves.append((emcee.moves.MHMove(relabel), p_relabel))
    return moves


def _check_backend(path: Path, fp: str, shape) -> int:
    """Iterations already in the backend at ``path`` (0 when new); refuses a foreign file."""
    import h5py

    if not path.exists():
        return 0
    try:
        with h5py.File(path, "r") as f:
            if GROUP not in f:
                raise ValueError(f"{path}: not an mdaug MCMC backend (no group {GROUP!r}); "
                                 "delete it or choose another backend path")
            g = f[GROUP]
            old = g.attrs.get("mdaug_fingerprint")
            it = int(g.attrs.get("iteration", 0))
            if old is not None and str(old) != fp:
                raise ValueError(f"{path}: holds a chain of a different problem (data, class, engines or "
                                 "settings differ); delete it or choose another backend path")
            if it and (int(g.attrs["nwalkers"]), int(g.attrs["ndim"])) != tuple(shape):
                raise ValueError(f"{path}: chain shape ({g.attrs['nwalkers']}, {g.attrs['ndim']}) walkers x dim, "
                                 f"expected {tuple(shape)}")
            return it
    except OSError as exc:
        raise ValueError(f"{path}: not a readable HDF5 file ({exc})") from exc


def _interrupted(terminated: bool, message: str):
    """The interrupt to raise outside emcee: a SIGTERM's carries a Terminated as its cause."""
    from ...radar.workers import Terminated

    exc = CalibrationInterrupted(message)
    if terminated:
        exc.__cause__ = Terminated()
    return exc


def _tau(chain, phase_cols, k: int) -> np.ndarray:
    """tau in steps, at least one stored step (``k``): a chain too short to estimate it
    gives ~1e-16 from emcee's estimator, and chain / tau ratios of 1e16."""
    return np.maximum(estimate_tau(chain, phase_cols) * k, float(k))


def _block_end(it: int, check: int, max_steps: int | None) -> int:
    end = (it // check + 1) * check
    return end if max_steps is None else min(end, max_steps)


def run_ensemble(log_post, p0: np.ndarray, settings, seed: int, backend_path=None, fp: str = "",
                 phase_cols=(), relabel=None) -> SamplerRun:
    """Run (or resume) the ensemble; see the module docstring.

    log_post: vectorised callable theta (W, dim) -> (W,); p0: (W, dim) start (ignored
    when the backend already holds steps); settings: the shared
    :class:`~mdaug.inference.settings.CalibrationSettings` (``time_budget``,
    ``relabel``, ``progress``; the emcee knobs at ``settings.of("emcee")``, an
    :class:`.ensemble.EmceeSettings`); seed: int for emcee's RandomState;
    phase_cols: columns that live on the circle (wrapped by the moves); relabel: the
    exact-symmetry move (``settings.relabel`` of the steps), see :func:`make_moves`.
    Stops at the first check at or after ``min_tau_multiple`` x max tau with tau
    stable, when ``time_budget`` seconds have passed (checked at every step), or at
    ``max_steps`` (None: no step cap). A Ctrl-C stops at the next step with the
    checkpoint saved and raises :class:`CalibrationInterrupted`.
    """
    import emcee

    from ...radar.progress import progress_bar

    t0 = time.perf_counter()
    own = settings.of("emcee")
    n_walkers, dim = p0.shape
    moves = make_moves(phase_cols, dim, relabel, settings.relabel)
    backend, resumed_at = None, 0
    if backend_path is not None:
        path = Path(backend_path)
        resumed_at = _check_backend(path, fp, (n_walkers, dim))
        backend = emcee.backends.HDFBackend(str(path), name=GROUP)
        if resumed_at == 0:
            backend.reset(n_walkers, dim)
        import h5py

        with h5py.File(path, "a") as f:
            g = f[GROUP]
            g.attrs["mdaug_fingerprint"] = fp
            if resumed_at:  # keep the stored interval of the file
                stored_k = int(g.attrs.get("mdaug_store_every", 1))
            else:
                g.attrs["mdaug_store_every"] = stored_k = store_interval(own, n_walkers, dim)
    sampler = emcee.EnsembleSampler(n_walkers, dim, log_post, vectorize=True, moves=moves, backend=backend)
    if resumed_at:
        state = None  # emcee restores the last walkers, log-probs and random state
    else:
        state = emcee.State(p0, random_state=np.random.RandomState(seed).get_state())
    k = stored_k if backend_path is not None else store_interval(own, n_walkers, dim)
    check = -(-own.check_every // k) * k  # block length, a multiple of k steps
    max_steps = None if own.max_steps is None else max(k, own.max_steps // k * k)
    it = resumed_at * k  # steps done (the backend counts stored steps)
    tau, converged, reason, out_of_time = np.full(dim, np.inf), False, "", False
    budget = settings.time_budget
    target = own.min_tau_multiple * 20.0  # steps: a first guess, replaced at every check

    def bar_total(goal: float) -> int:  # the 50 tau goal, never past the step cap
        return int(goal if max_steps is None else min(goal, max_steps))

    bar = progress_bar(total=bar_total(max(target, check)), initial=min(it, bar_total(max(target, check))),
                       desc="calibration", unit="step", progress=settings.progress)
    try:
        with stop_on_sigint() as flag, stop_on_signal(signal.SIGTERM, only_if_handled=True) as term, \
                contextlib.redirect_stdout(io.StringIO()):
            while True:
                if it > 0 and it % check == 0 or (max_steps is not None and it >= max_steps) or out_of_time:
                    chain = sampler.get_chain()
                    tau = _tau(chain, phase_cols, k)
                    long_enough = it >= own.min_tau_multiple * tau.max()
                    target = own.min_tau_multiple * tau.max()
                    bar.total = max(bar_total(target), it)
                    bar.set_postfix_str(f"tau {tau.max():.0f}, {it / tau.max():.1f} tau of "
                                        f"{own.min_tau_multiple:g}", refresh=True)
                    if long_enough and it > check:
                        # tau one block earlier, recomputed (not remembered) so that a resumed
                        # run takes exactly the decisions of an uninterrupted one
                        tau_prev = _tau(chain[: (it - check) // k], phase_cols, k)
                        if np.all(np.abs(tau - tau_prev) <= own.tau_rtol * tau):
                            converged = True
                            reason = f"chain {it} steps >= {own.min_tau_multiple:g} x max tau {tau.max():.0f}"
                            break
                if (max_steps is not None and it >= max_steps) or out_of_time:
                    ratio = it / tau.max()
                    what = (f"time budget of {budget:g} s" if out_of_time else f"budget of {max_steps} steps")
                    reason = (f"NOT CONVERGED: {what} ended at {ratio:.1f} x max tau ({tau.max():.0f} steps; "
                              f"need {own.min_tau_multiple:g})")
                    if tau.max() <= k:  # no estimate: never an impossible ratio (4 steps were '1.8e16 x max tau')
                        reason = (f"NOT CONVERGED: {what} ended after {it} steps, too few to estimate the "
                                  f"autocorrelation time tau (need {own.min_tau_multiple:g} x tau)")
                    elif ratio >= own.min_tau_multiple:
                        reason += f"; tau still changing by more than {own.tau_rtol:.0%} per block"
                    elif ratio < 20:
                        reason += "; tau is a lower bound (its estimate is capped by the chain length)"
                    break
                n = _block_end(it, check, max_steps) - it
                if state is None:  # resumed: emcee's backend holds the last walkers and random state
                    state = sampler.get_last_sample()
                for state in sampler.sample(state, iterations=n // k, thin_by=k, skip_initial_state_check=True):
                    it += k
                    bar.update(k)
                    if flag["stop"] or term["stop"]:
                        raise _interrupted(term["stop"], f"stopped at step {it}")
                    if budget is not None and time.perf_counter() - t0 > budget:
                        out_of_time = True
                        break
    except KeyboardInterrupt as exc:
        where = f"; its {sampler.iteration * k} steps are saved in {backend_path}" if backend_path else ""
        raise CalibrationInterrupted(f"calibration interrupted{where}") from exc
    finally:
        bar.close()
    chain = sampler.get_chain()
    burn = min(int(np.ceil(own.burn_tau * tau.max())), it // 2)
    thin = max(k, int(own.thin_tau * tau.min()) // k * k)
    return SamplerRun(chain=chain, log_prob=sampler.get_log_prob(), tau=tau, burn=burn, thin=thin,
                      acceptance=np.asarray(sampler.acceptance_fraction, float), converged=converged,
                      reason=reason, seconds=time.perf_counter() - t0, resumed_at=resumed_at * k,
                      store_every=k, sampler="emcee")
