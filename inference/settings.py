"""Settings of a calibration run (one frozen dataclass, presets as classmethods)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .samplers import SAMPLERS  # the registry holds the names

FIT_ALGORITHMS = ("GN_CRS2_LM", "GN_MLSL_LDS", "GN_DIRECT_L", "GN_ISRES", "GN_ESCH")
LOCAL_ALGORITHMS = ("LN_BOBYQA", "LN_NELDERMEAD", "LN_SBPLX")
LIKELIHOODS = ("auto", "marginal", "synthetic", "fitted")


@dataclass(frozen=True)
class CalibrationSettings:
    """How a calibration runs.

    Fit (nlopt): ``n_starts`` independent runs of ``fit_algorithm`` (a global
    algorithm, ``fit_budget`` objective evaluations each, seeded from the run's seed)
    followed by ``local_algorithm`` with ``polish_budget`` evaluations.

    MCMC (emcee): ``n_walkers`` walkers (0 = 2 x dimensions + 2, the least differential evolution
    needs, since every walker costs a likelihood evaluation per step; at least 32), run in
    blocks of ``check_every`` steps until the chain is ``min_tau_multiple`` integrated
    autocorrelation times long and tau changed by less than ``tau_rtol`` between
    checks: convergence sets the length. ``time_budget`` (seconds of sampling; None =
    none) and ``max_steps`` (None = no cap) end a run that has not converged by
    then (flagged not converged).
    Burn-in ``burn_tau`` x max tau, thinning ``thin_tau`` x min tau (at least 1).
    ``store_every``: keep every k-th step in memory and in the HDF5 checkpoint (0 =
    auto: the chain stays under ~160 MB; tau, burn-in and thinning count steps).
    Walkers start at the best fit + ``init_ball`` x the local curvature scale of
    every coordinate (see :func:`.sampler.curvature_scales`); with ``init_modes``
    they are split over every distinct fit start within 10 nats of the best (rival
    modes), so a multimodal posterior is started on all the modes the fit found.

    Both samplers: a share ``relabel`` of the moves give an engine's four lines to
    the roles (a, b, p, m) in a random other order (an exact symmetry of f(x), see
    :mod:`.space.priors`), so the posterior covers every labelling the prior allows; 0
    switches it off.

    Likelihood: ``likelihood`` ``auto`` (default) uses the acquisition: when its
    phases are random (``uniform``) or it averages several ramps, the phases are
    marginalised in closed form (:class:`.likelihood.closed_form.ClosedFormLikelihood`, sampled
    in line space, :class:`.space.line_layout.LineLayout`; compared every ``stride`` bins;
    lines below ``amp_tol`` x sum(Gamma) and sidelobes below ``reach_tol`` left out,
    pairs of lines below ``pair_tol`` of a bin's power summed at the mean Fejer
    weight; ``model_floor`` x the peak added to every bin's sd); the published single
    chirp at fixed phases fits them (:class:`.likelihood.fitted_phases.LogPosterior`, below).
    ``marginal`` / ``fitted`` force one; ``synthetic`` is the Monte-Carlo check of the
    closed form (:class:`.likelihood.synthetic.SyntheticLikelihood`, ``n_acquisitions`` O
    simulated acquisitions of ``ramps_drawn`` ramps each).

    Model (fitted phases): ``normalisation`` of measured and model profiles (SPEC section 2);
    ``alignment`` ``tone`` (default) compares the data with model windows centred on
    the carrier bin and fits a per-measurement offset of the tone (uniform on the
    priors' ``offset_bins``, +-4 bins by default), ``peak`` uses f(x)'s argmax
    centring (discontinuous in the parameters; offset then +-0.5 bins, sub-bin);
    see :meth:`.likelihood.fitted_phases.LogPosterior.model`. ``range_offset`` False fixes the
    offset at 0. Noise is Gaussian, iid over bins, with a per-measurement
    level sigma (log-uniform prior on [sigma_min, sigma_max], in normalised units).
    ``dtype``: precision of f(x) (float32 is ~2x faster, error ~1e-7 of the peak).
    ``threads``: BLAS/FFT threads (the calibrate verb pins them; 1 is the default).

    Sampler: ``sampler`` ``"emcee"`` (default, the ensemble above) or ``"smc"``
    (opt-in tempered sequential Monte Carlo from the prior, :mod:`.samplers.tempering`):
    ``n_particles`` (0 = auto: max(500, 40 x dim)), reweighting to an ESS of
    ``smc_ess`` x N per stage (0.9: slow tempering; at 0.5 the population collapsed
    onto a wrong mode on HELI), a share ``smc_redraw`` of the rejuvenation proposals
    redrawing one coordinate from its uniform prior range (jumps between distant
    narrow modes), rejuvenation sweeps until a particle has moved with
    probability ``smc_p_move`` (at most ``smc_max_sweeps`` per stage), at most
    ``smc_max_stages`` stages. The emcee settings above are then unused (the fit
    still runs, for the report and the best-fit vector).
    """

    fit_algorithm: str = "GN_CRS2_LM"
    local_algorithm: str = "LN_BOBYQA"
    n_starts: int = 4
    fit_budget: int = 6000
    polish_budget: int = 2000
    n_walkers: int = 0
    max_steps: int | None = None
    time_budget: float | None = 1200.0
    check_every: int = 500
    store_every: int = 0
    min_tau_multiple: float = 50.0
    tau_rtol: float = 0.05
    burn_tau: float = 3.0
    thin_tau: float = 0.5
    init_ball: float = 0.5
    init_modes: bool = True
    normalisation: str = "peak"
    range_offset: bool = True
    alignment: str = "tone"
    sigma_min: float = 1e-4
    sigma_max: float = 1.0
    dtype: str = "float32"
    threads: int = 1
    progress: bool = False
    sampler: str = "emcee"
    n_particles: int = 0
    smc_ess: float = 0.9
    smc_redraw: float = 0.3
    smc_p_move: float = 0.99
    smc_max_sweeps: int = 40
    smc_max_stages: int = 500
    smc_jump: float = 0.1
    smc_polish: int = 8
    relabel: float = 0.1
    likelihood: str = "auto"
    n_acquisitions: int = 16
    ramps_drawn: int = 16
    stride: int = 8
    amp_tol: float = 1e-3
    pair_tol: float = 0.05
    reach_tol: float = 3e-4
    model_floor: float = 0.0

    def __post_init__(self) -> None:
        if self.fit_algorithm not in FIT_ALGORITHMS:
            raise ValueError(f"fit_algorithm must be one of {FIT_ALGORITHMS}, got {self.fit_algorithm!r}")
        if self.local_algorithm not in LOCAL_ALGORITHMS + ("none",):
            raise ValueError(f"local_algorithm must be one of {LOCAL_ALGORITHMS} or 'none', "
                             f"got {self.local_algorithm!r}")
        positive = {"n_starts": self.n_starts, "fit_budget": self.fit_budget,
                    "check_every": self.check_every, "min_tau_multiple": self.min_tau_multiple,
                    "threads": self.threads, "init_ball": self.init_ball, "ramps_drawn": self.ramps_drawn,
                    "stride": self.stride}
        if self.max_steps is not None:
            positive["max_steps"] = self.max_steps
        if self.time_budget is not None:
            positive["time_budget"] = self.time_budget
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"CalibrationSettings.{name} must be > 0, got {value!r}")
        if self.n_walkers < 0 or self.polish_budget < 0 or self.store_every < 0:
            raise ValueError("CalibrationSettings.n_walkers, polish_budget and store_every must be >= 0")
        if not 0 < self.sigma_min < self.sigma_max:
            raise ValueError(f"need 0 < sigma_min < sigma_max, got {self.sigma_min}, {self.sigma_max}")
        if self.alignment not in ("tone", "peak"):
            raise ValueError(f"alignment must be 'tone' or 'peak', got {self.alignment!r}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {SAMPLERS}, got {self.sampler!r}")
        if not 0 <= self.relabel < 1 or self.smc_jump + self.relabel >= 1:
            raise ValueError(f"relabel must be in [0, 1) with smc_jump + relabel < 1, got {self.relabel}")
        if not (0 <= self.smc_jump < 1 and self.smc_redraw + self.smc_jump < 1 and self.smc_polish >= 0):
            raise ValueError(f"smc_jump must be in [0, 1) with smc_redraw + smc_jump < 1 and smc_polish >= 0, "
                             f"got {self.smc_jump}, {self.smc_redraw}, {self.smc_polish}")
        if not (0 < self.smc_ess < 1 and 0 < self.smc_p_move < 1 and 0 <= self.smc_redraw < 1):
            raise ValueError(f"smc_ess and smc_p_move must be in (0, 1) and smc_redraw in [0, 1), got "
                             f"{self.smc_ess}, {self.smc_p_move}, {self.smc_redraw}")
        if self.n_particles < 0 or self.n_particles == 1 or self.smc_max_sweeps < 2 or self.smc_max_stages < 1:
            raise ValueError("CalibrationSettings: n_particles must be 0 (auto) or >= 2, smc_max_sweeps >= 2 "
                             "and smc_max_stages >= 1")
        if self.likelihood not in LIKELIHOODS:
            raise ValueError(f"likelihood must be one of {LIKELIHOODS}, got {self.likelihood!r}")
        if self.n_acquisitions < 2:
            raise ValueError(f"n_acquisitions must be >= 2 (simulated acquisitions per likelihood), got "
                             f"{self.n_acquisitions}")
        if not (0 < self.amp_tol < 1 and 0 < self.pair_tol <= 1 and 0 < self.reach_tol < 1 and self.model_floor >= 0):
            raise ValueError(f"CalibrationSettings: amp_tol, pair_tol and reach_tol must be in (0, 1) and model_floor "
                             f">= 0, got {self.amp_tol}, {self.pair_tol}, {self.reach_tol}, {self.model_floor}")
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype must be float32 or float64, got {self.dtype!r}")

    @classmethod
    def quick(cls, **kw) -> "CalibrationSettings":
        """A few-second HELI run for tests and ``--quick``: small fit budget, short
        chain, 3 particles polished per mode search. It will usually end before
        50 tau and say so (converged=False)."""
        base = dict(n_starts=2, fit_budget=1000, polish_budget=2000, max_steps=1000, check_every=250,
                    n_walkers=32, smc_polish=3, n_acquisitions=8, ramps_drawn=4)
        base.update(kw)
        return cls(**base)

    def replace(self, **kw) -> "CalibrationSettings":
        return dataclasses.replace(self, **kw)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)
