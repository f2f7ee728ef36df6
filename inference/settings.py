"""Settings of a calibration run: what every run needs in :class:`CalibrationSettings`,
each sampler plugin's own knobs in its own frozen dataclass beside the plugin
(:func:`.samplers.settings_class`), carried here one per registered plugin."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .samplers import SAMPLERS, settings_class  # the registry holds the names and the plugins' settings

FIT_ALGORITHMS = ("GN_CRS2_LM", "GN_MLSL_LDS", "GN_DIRECT_L", "GN_ISRES", "GN_ESCH")
LOCAL_ALGORITHMS = ("LN_BOBYQA", "LN_NELDERMEAD", "LN_SBPLX")
LIKELIHOODS = ("auto", "marginal", "synthetic", "fitted")


def _flat_names(name: str) -> dict:
    """Plugin ``name``'s knobs by their flat name (the vocabulary of keyword calls and of
    settings written before the plugins had their own): flat name -> field name."""
    cls = settings_class(name)
    own = {f.name: f.name for f in dataclasses.fields(cls)}
    return {**own, **cls.LEGACY}


@dataclass(frozen=True, init=False)
class CalibrationSettings:
    """How a calibration runs.

    Fit (nlopt): ``n_starts`` independent runs of ``fit_algorithm`` (a global
    algorithm, ``fit_budget`` objective evaluations each, seeded from the run's seed)
    followed by ``local_algorithm`` with ``polish_budget`` evaluations.

    Sampler: ``sampler`` names the plugin that samples the posterior (:data:`SAMPLERS`:
    ``emcee`` default, ``smc``, ``laplace``); ``plugins`` holds every registered
    plugin's own settings, name -> its frozen dataclass (defaults in the plugin's
    module; :meth:`of` reads one, :meth:`with_plugin` changes one). Shared by the
    samplers: ``time_budget`` (seconds of sampling; None = none) ends a run that has
    not converged by then (flagged not converged); a share ``relabel`` of the moves
    give an engine's four lines to the roles (a, b, p, m) in a random other order (an
    exact symmetry of f(x), see :mod:`.space.priors`), so the posterior covers every
    labelling the prior allows; 0 switches it off. ``progress``: a progress bar.

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

    Keywords: the fields above, ``plugins`` (a mapping name -> settings; plugins left
    out get their defaults), and a plugin knob by its flat name (``max_steps=``,
    ``smc_ess=``: the plugin's field or its ``LEGACY`` name; a name two plugins share,
    ``n_particles``, sets both); reading ``settings.n_walkers`` gives the knob of the
    chosen plugin, else of the one plugin that has it.
    """

    fit_algorithm: str = "GN_CRS2_LM"
    local_algorithm: str = "LN_BOBYQA"
    n_starts: int = 4
    fit_budget: int = 6000
    polish_budget: int = 2000
    time_budget: float | None = 1200.0
    relabel: float = 0.1
    normalisation: str = "peak"
    range_offset: bool = True
    alignment: str = "tone"
    sigma_min: float = 1e-4
    sigma_max: float = 1.0
    dtype: str = "float32"
    threads: int = 1
    progress: bool = False
    likelihood: str = "auto"
    n_acquisitions: int = 16
    ramps_drawn: int = 16
    stride: int = 8
    amp_tol: float = 1e-3
    pair_tol: float = 0.05
    reach_tol: float = 3e-4
    model_floor: float = 0.0
    sampler: str = "emcee"
    plugins: tuple = ()  # ((name, settings), ...) in registry order, one per plugin: see of()

    def __init__(self, *, plugins=None, **knobs) -> None:
        for f in dataclasses.fields(self):
            if f.name != "plugins":
                object.__setattr__(self, f.name, knobs.pop(f.name, f.default))
        given = dict(plugins or {})
        unknown = sorted(set(given) - set(SAMPLERS))
        if unknown:
            raise ValueError(f"CalibrationSettings: no sampler plugin {unknown[0]!r}; expected one of {SAMPLERS}")
        own = {name: given.get(name) or settings_class(name)() for name in SAMPLERS}
        for flat, value in knobs.items():
            targets = [(name, names[flat]) for name in SAMPLERS if flat in (names := _flat_names(name))]
            if not targets:
                raise TypeError(f"CalibrationSettings: unknown setting {flat!r} (neither a shared setting nor a "
                                f"knob of the sampler plugins {', '.join(SAMPLERS)})")
            for name, field_name in targets:
                own[name] = dataclasses.replace(own[name], **{field_name: value})
        object.__setattr__(self, "plugins", tuple(own.items()))
        self._check()

    def _check(self) -> None:
        if self.fit_algorithm not in FIT_ALGORITHMS:
            raise ValueError(f"fit_algorithm must be one of {FIT_ALGORITHMS}, got {self.fit_algorithm!r}")
        if self.local_algorithm not in LOCAL_ALGORITHMS + ("none",):
            raise ValueError(f"local_algorithm must be one of {LOCAL_ALGORITHMS} or 'none', "
                             f"got {self.local_algorithm!r}")
        positive = {"n_starts": self.n_starts, "fit_budget": self.fit_budget, "threads": self.threads,
                    "ramps_drawn": self.ramps_drawn, "stride": self.stride}
        if self.time_budget is not None:
            positive["time_budget"] = self.time_budget
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"CalibrationSettings.{name} must be > 0, got {value!r}")
        if self.polish_budget < 0:
            raise ValueError("CalibrationSettings.polish_budget must be >= 0")
        if not 0 < self.sigma_min < self.sigma_max:
            raise ValueError(f"need 0 < sigma_min < sigma_max, got {self.sigma_min}, {self.sigma_max}")
        if self.alignment not in ("tone", "peak"):
            raise ValueError(f"alignment must be 'tone' or 'peak', got {self.alignment!r}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {SAMPLERS}, got {self.sampler!r}")
        if not 0 <= self.relabel < 1 or self.of("smc").jump + self.relabel >= 1:  # the SMC's shares of moves
            raise ValueError(f"relabel must be in [0, 1) with smc_jump + relabel < 1, got {self.relabel}")
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

    def of(self, name: str):
        """Plugin ``name``'s own settings (its frozen dataclass)."""
        for key, value in self.plugins:
            if key == name:
                return value
        raise ValueError(f"unknown sampler {name!r}; expected one of {SAMPLERS}")

    def __getattr__(self, flat: str):
        """A plugin knob by its flat name: the chosen plugin's, else the first plugin's
        that has it (called only for names that are not fields)."""
        if flat.startswith("_") or flat == "plugins":
            raise AttributeError(flat)
        order = [self.sampler] + [n for n in SAMPLERS if n != self.sampler]
        for name in order:
            names = _flat_names(name)
            if flat in names:
                return getattr(self.of(name), names[flat])
        raise AttributeError(f"CalibrationSettings has no setting {flat!r}")

    @classmethod
    def quick(cls, **kw) -> "CalibrationSettings":
        """A few-second HELI run for tests and ``--quick``: small fit budget and every
        plugin's ``quick()`` preset (a short chain, 3 particles polished per mode
        search). It will usually end before 50 tau and say so (converged=False)."""
        base = dict(n_starts=2, fit_budget=1000, polish_budget=2000, n_acquisitions=8, ramps_drawn=4,
                    plugins={name: settings_class(name).quick() for name in SAMPLERS})
        base.update(kw)
        return cls(**base)

    def replace(self, **kw) -> "CalibrationSettings":
        """A copy with fields, ``plugins`` or flat plugin knobs changed (see the class doc)."""
        now = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "plugins"}
        plugins = dict(kw.pop("plugins", self.plugins))
        return CalibrationSettings(**{**now, **kw, "plugins": plugins})

    def with_plugin(self, name: str, **knobs) -> "CalibrationSettings":
        """A copy with plugin ``name``'s knobs (its field names) changed."""
        return self.replace(plugins={**dict(self.plugins), name: self.of(name).replace(**knobs)})

    def to_dict(self) -> dict:
        """Plain data: the shared fields and ``plugins``: {name: {knob: value}}."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "plugins"}
        out["plugins"] = {name: dataclasses.asdict(s) for name, s in self.plugins}
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "CalibrationSettings":
        """The inverse of :meth:`to_dict`; also reads the flat dicts written before the
        plugins had their own settings (every knob at the top level). An unknown key or
        plugin is refused by name."""
        d = dict(d)
        nested = d.pop("plugins", None) or {}
        unknown = sorted(set(nested) - set(SAMPLERS))
        if unknown:
            raise ValueError(f"calibration settings name no sampler plugin {unknown[0]!r}; expected one of "
                             f"{SAMPLERS}")
        plugins = {}
        for name, knobs in nested.items():
            try:
                plugins[name] = settings_class(name)(**knobs)
            except TypeError as exc:
                raise ValueError(f"calibration settings of sampler {name!r}: {exc}") from None
        try:
            return cls(plugins=plugins, **d)
        except TypeError as exc:
            raise ValueError(str(exc)) from None

    def resume_key(self) -> dict:
        """The settings a checkpoint must share to be resumed: all but the budgets (the
        shared time budget, each plugin's ``BUDGETS``), ``progress`` and ``threads``."""
        out = self.to_dict()
        for key in ("time_budget", "progress", "threads"):
            out.pop(key)
        for name, knobs in out["plugins"].items():
            for key in settings_class(name).BUDGETS:
                knobs.pop(key)
        return out
