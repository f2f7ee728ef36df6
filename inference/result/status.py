"""A calibration's status in one vocabulary: :func:`calibration_status` reads a
:class:`~.posterior.CalibrationResult` (or its diagnostics dict, or a study's record of
it) and returns :class:`CalibrationStatus`, the facts and the words that the terminal
report (:mod:`.report`), the corner plot's title (:mod:`.plots`), the study's
``results.json``, its HTML report and the README's block all print.

The facts and their words:

* **route**: ``amortized`` (the estimator's exact draws), ``smc`` (tempered SMC from
  the amortized posterior to the posterior of the estimator's learned likelihood: its
  summary likelihood or its likelihood ratio, ``diagnostics['smc']['likelihood']``;
  files of earlier releases may say ``emcee``, nlopt + emcee on the same) or
  ``likelihood`` (``--method likelihood``: the closed-form route, sampled by emcee, SMC
  or a Laplace approximation);
* **convergence**: ``converged`` or ``NOT converged`` for a chain (emcee, SMC, Laplace);
  ``exact draws`` for the amortized route, which has no chain;
* **honesty**, by the one gate, :func:`honest` (here; the route table of
  :mod:`mdaug.inference.diagnostics.yardsticks` uses it too)
  (outer-10% share <= 0.13 and every quantity's 90% coverage >= 0.85) on the SBC stored
  in the estimator file for the route used: ``honest``, ``overconfident`` or
  ``no SBC stored`` (the closed-form route stores none). The rank histograms' pooled
  chi-square p is said beside it in words, never as a second verdict;
* **out of range**: the measurements unlike the estimator's training set
  (``diagnostics['out_of_range']``, why in ``['out_of_range_why']``);
* **the posterior predictive check** (:mod:`mdaug.inference.diagnostics.predictive`,
  ``diagnostics['predictive']``): ``fits`` (the measurements are like those the
  posterior's drones make), ``misfit`` (some statistic of them lies beyond the check's
  limit: the posterior does not explain them, whatever its SBC says) or ``not checked``
  (the closed form's fitted-phase posteriors of the published chirp, files of earlier
  releases, ``--predictive 0``).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

OUTER_MAX = 0.13
"""Largest outer-10% share an honest posterior may show (0.10 expected)."""
COVERAGE_MIN = 0.85
"""Smallest 90% coverage of any quantity an honest posterior may show (0.90 expected)."""


def honest(summary: dict) -> bool:
    """The gate, the one rule for 'honest' (used here and by the route table of
    :mod:`mdaug.inference.diagnostics.yardsticks`): not overconfident, an outer-10% share
    of at most OUTER_MAX and every quantity's 90% coverage at least COVERAGE_MIN, on an
    SBC summary (:func:`mdaug.inference.diagnostics.routes.run`). A posterior wider than
    the data allow passes; the log score tells it apart."""
    return bool(summary["outer_share"] <= OUTER_MAX and summary["coverage90_range"][0] >= COVERAGE_MIN)


def exact_fail_chance(n_truths: int, n_quantities: int, n_draws: int = 199) -> float:
    """The chance that an exact posterior fails the gate's coverage rule (:func:`honest`)
    on ``n_truths`` drones with ``n_quantities`` quantities, its 90% intervals taken from
    ``n_draws`` draws a drone (the route table's 199). The truth and the draws are then
    exchangeable, so the truth falls inside the interval between the draws' 5% and 95%
    quantiles (numpy's linear interpolation, at order statistics 0.05 and 0.95 x (n - 1))
    with probability p = 0.9 (n - 1) / (n + 1), 0.891 at 199 draws, not 0.9; a quantity's
    coverage is a binomial(n_truths, p) share, and the rule fails when any of them falls
    under COVERAGE_MIN: 1 - P(share >= COVERAGE_MIN)^d, the quantities taken independent
    (correlated ones fail together, less often: an upper bound in practice). The outer-10%
    share pools every rank and almost never passes OUTER_MAX by chance, so it is left
    out. The rule's noise floor: an exact posterior fails it with chance 0.94 on 100 drones
    of QUAD's 35 quantities, 0.33 on 300; 0.21 on 200 drones of HELI's 8. A verdict read
    where this is large says little either way."""
    import math

    n = int(n_truths)
    return _lowest_at_most(n, n_quantities, math.ceil(COVERAGE_MIN * n - 1e-9) - 1, n_draws)  # a share < COVERAGE_MIN


def lowest_coverage_chance(n_truths: int, n_quantities: int, coverage: float, n_draws: int = 199) -> float:
    """The chance that an exact posterior's lowest 90% coverage of ``n_quantities`` on
    ``n_truths`` drones is ``coverage`` or lower (:func:`exact_fail_chance`'s model): how
    far below the noise a route's lowest coverage lies."""
    return _lowest_at_most(int(n_truths), n_quantities, int(round(coverage * int(n_truths))), n_draws)


def _lowest_at_most(n: int, d: int, count: int, n_draws: int) -> float:
    """1 - P(binomial(n, p) > count)^d, p = 0.9 (n_draws - 1) / (n_draws + 1): the chance that
    the lowest of d independent coverage counts of an exact posterior is count or fewer."""
    from scipy.stats import binom

    d, k = int(d), int(n_draws)
    if n < 1 or d < 1 or k < 2:
        raise ValueError(f"need >= 1 truth, >= 1 quantity and >= 2 draws, got {n}, {d} and {k}")
    below = binom.cdf(count, n, 0.9 * (k - 1) / (k + 1))
    return float(1.0 - (1.0 - below) ** d)


NOISY_GATE = 0.05
"""Chance of an exact posterior failing the gate (:func:`exact_fail_chance`) from which
a verdict is said to be noisy beside it."""


def noise_note(n_truths, n_quantities) -> str:
    """'' or, where an exact posterior would fail the gate on this many drones and
    quantities with a chance of NOISY_GATE or more, the clause that says so."""
    if not n_truths or not n_quantities:
        return ""
    chance = exact_fail_chance(n_truths, n_quantities)
    return "" if chance < NOISY_GATE else (f" (an exact posterior fails this rule on {n_truths} drones and "
                                           f"{n_quantities} quantities with chance {chance:.2f})")


def verdict(summary: dict) -> str:
    """One word for the gate: 'honest' or 'overconfident'."""
    return "honest" if honest(summary) else "overconfident"

RANK_P = 0.05
"""Pooled rank chi-square p below which the rank histograms are called not flat."""

EXACT, CONVERGED, NOT_CONVERGED = "exact draws", "converged", "NOT converged"
NO_SBC = "no SBC stored"
"""The honesty word where no SBC is stored (else the gate's own word, :func:`verdict`)."""
OUT_OF_RANGE = "out of range"
FITS, MISFIT, NOT_CHECKED = "fits", "misfit", "not checked"
"""The posterior predictive check's words (module doc)."""

_LIKELIHOODS = {"summary": "the estimator's summary likelihood", "ratio": "the estimator's learned likelihood ratio"}
_SAMPLERS = {"emcee": "emcee", "smc": "tempered SMC", "laplace": "a Laplace approximation"}


@dataclass(frozen=True)
class CalibrationStatus:
    """What a calibration is, in facts (``route``, ``converged``, ``sbc``, ...) and in the
    words every place prints (module doc)."""

    route: str
    """'amortized', 'smc', 'stacked' or 'likelihood' ('emcee' in files of releases before the smc route)."""
    route_words: str
    """How the posterior was drawn, e.g. "tempered SMC from the amortized posterior on the estimator's summary likelihood"."""
    converged: bool
    """True for exact draws and for a converged chain (the exit status follows it)."""
    convergence: str
    """'exact draws', 'converged' or 'NOT converged'."""
    convergence_detail: str
    """The sampler's own reason (without a status prefix)."""
    honesty: str
    """'honest', 'overconfident' or 'no SBC stored'."""
    passed: bool | None
    """The gate's verdict on the stored SBC (None: no SBC stored)."""
    sbc: dict | None
    """The stored SBC of the route used (outer_share, coverage90_range, n_replicates, pooled_p)."""
    rank_note: str
    """The rank test in words ('' when no p is stored)."""
    out_of_range: bool
    out_of_range_why: str
    check_route: str
    """The other route when it ran beside the amortized one ('smc'; 'emcee' in earlier
    files), for the best fit or as a check (``check_role``), else ''."""
    check_convergence: str
    """Its convergence word ('converged' or 'NOT converged'; '' when it did not run)."""
    check_detail: str
    """Its sampler's reason."""
    check_role: str = ""
    """Why it ran: 'run for the best fit', 'run as a check' or both (:func:`smc_role`)."""
    users: dict | None = None
    """The file's route table row of the route used on drones like a user's (``drones``,
    ``log_score``, ``lines``: :meth:`mdaug.inference.amortized.estimator.AmortizedEstimator.users_row`),
    or None where it stores none."""
    predictive: str = NOT_CHECKED
    """The posterior predictive check's word: 'fits', 'misfit' or 'not checked'."""
    predictive_facts: str = ""
    """What it compared and found, in one clause ('' when not checked)."""

    @property
    def check(self) -> str:
        """The route run beside the one used, in words ('' when none ran)."""
        if not self.check_route:
            return ""
        return f"{self.check_route} route, {self.check_role or 'run as a check'}: {self.check_convergence}"

    @property
    def headline(self) -> str:
        """One line: route, convergence, honesty and, when so, out of range and a misfit:
        e.g. ``smc route: NOT converged; SBC: overconfident; out of range; predictive check: misfit``."""
        text = f"{self.route} route: {self.convergence}; SBC: {self.honesty}"
        text += f"; {OUT_OF_RANGE}" if self.out_of_range else ""
        return text + ("; predictive check: misfit" if self.predictive == MISFIT else "")

    @property
    def trusted(self) -> bool:
        """Usable as it stands: converged (or exact), not overconfident, in range, and no
        misfit by the predictive check."""
        return self.converged and self.passed is not False and not self.out_of_range and self.predictive != MISFIT

    @property
    def sbc_facts(self) -> str:
        """The stored SBC against the gate's limits, and the rank note ('' without SBC)."""
        if not self.sbc:
            return ""
        s = self.sbc
        lo, hi = s.get("coverage90_range") or (float("nan"), float("nan"))
        n = s.get("n_replicates")
        text = (f"on {n if n is not None else '?'} simulated drones, outer-10% share {s['outer_share']:.3f} (at most "
                f"{OUTER_MAX:.2f}; 0.10 expected), 90% coverage {lo:.2f}-{hi:.2f} per quantity (at least "
                f"{COVERAGE_MIN:.2f})")
        text += noise_note(n, s.get("n_quantities"))
        return text + (f"; {self.rank_note}" if self.rank_note else "")

    @property
    def users_facts(self) -> str:
        """The route's stored row on drones like a user's in one clause ('' where none)."""
        u = self.users
        if not u:
            return ""
        lines = (f"; the brightest engine's lines 1-4 at {' / '.join(f'{v:.2f}' for v in u['lines'])} x the truth "
                 "(median 90% width)") if u.get("lines") else ""
        return (f"on {u['drones']} simulated drones like a user's (the specimen model), the file's route table: "
                f"log score {u['log_score']:.2f} nats{lines}")

    @property
    def sbc_words(self) -> str:
        """The honesty word and the facts behind it in one sentence."""
        return f"{self.honesty}: {self.sbc_facts}" if self.sbc else f"{NO_SBC} for the {self.route} route"

    def lines(self) -> list[str]:
        """The status as the terminal report prints it."""
        out = [f"status: {self.headline}", f"  route: {self.route_words}"]
        if self.convergence != EXACT:
            out.append(("  " if self.converged else "  WARNING: ") + self.convergence
                       + (f": {self.convergence_detail}" if self.convergence_detail else ""))
        out.append(f"  SBC: {self.sbc_words}")
        if self.users:
            out.append(f"  {self.users_facts}")
        if self.check:  # unconverged: a best fit from it is its particles' median at a temperature < 1
            out.append(("  WARNING: " if self.check_convergence == NOT_CONVERGED else "  ") + self.check
                       + (f" ({self.check_detail})" if self.check_detail else ""))
        if self.out_of_range:
            out.append(f"  WARNING: {OUT_OF_RANGE}: {self.out_of_range_why}")
        if self.predictive != NOT_CHECKED:
            out.append(("  WARNING: " if self.predictive == MISFIT else "  ") + self.predictive_words)
        return out

    @property
    def predictive_words(self) -> str:
        """The predictive check's word and facts in one sentence."""
        return f"posterior predictive check: {self.predictive}" + (f": {self.predictive_facts}"
                                                                   if self.predictive_facts else "")

    def to_dict(self) -> dict:
        """Plain data for ``results.json`` (the headline and SBC sentence included)."""
        return {**asdict(self), "headline": self.headline, "sbc_words": self.sbc_words, "sbc_facts": self.sbc_facts,
                "check": self.check, "predictive_words": self.predictive_words, "users_facts": self.users_facts,
                "trusted": self.trusted}


def run_facts(d: dict, num=None) -> str:
    """The sampled run behind a calibration's diagnostics ``d`` in a few words, as the
    README line and the report print it: the smc route's particles, stages and share of
    distinct particles (the route used or its check); the closed-form SMC's particles,
    stages and least ESS; an emcee chain's length over its autocorrelation time and
    least ESS; '' where nothing was sampled (the amortized route alone). ``num(key,
    value, decimals)`` writes each number (key: its place in ``d``, dotted; default:
    plain text, '–' when missing), so the report can key it to results.json."""
    num = num or (lambda key, value, decimals: "–" if value is None else f"{value:.{decimals}f}")
    m = d.get("smc")
    if isinstance(m, dict) and "particles" in m:
        parts = [("smc.particles", m["particles"], 0, "{} particles"), ("smc.stages", m["stages"], 0, "{} stages"),
                 ("smc.unique_share", m["unique_share"], 2, "distinct share {}")]
    elif d.get("sampler") == "smc" and "smc_n_particles" in d:
        parts = [("smc_n_particles", d["smc_n_particles"], 0, "{} particles"),
                 ("smc_stages", d.get("smc_stages"), 0, "{} stages"), ("ess_min", d.get("ess_min"), 0, "min ESS {}")]
    elif d.get("steps_over_tau") is not None:
        parts = [("steps_over_tau", d["steps_over_tau"], 1, "chain {} x max tau"),
                 ("ess_min", d.get("ess_min"), 0, "min ESS {}")]
    else:
        return ""
    return ", ".join(label.format(num(key, value, dec)) for key, value, dec, label in parts)


BEST_FIT_BESIDE = "the smc route's median"
"""Where the best fit comes from when the smc route ran beside the amortized one for it."""


def best_fit_beside(d: dict) -> bool:
    """Whether the best fit of diagnostics ``d`` came from a route other than the one
    used (the smc route's median beside the amortized posterior)."""
    return d.get("best_fit_from", d.get("route")) != d.get("route")


def smc_role(d: dict) -> str:
    """Why the smc route ran beside the amortized route of diagnostics ``d``: for the
    best fit (the summary likelihood's median, :mod:`mdaug.inference.amortized.calibrate`),
    as a check, or both."""
    why = ["for the best fit"] if d.get("best_fit_from") == "smc" else []
    why += ["as a check"] if d.get("check", True) else []  # without 'check' (earlier files): a check
    return "run " + " and ".join(why or ["as a check"])


def chain_words(converged: bool, reason: str) -> tuple[str, str]:
    """('converged' or 'NOT converged', the reason without a status prefix)."""
    return (CONVERGED if converged else NOT_CONVERGED), _strip(reason)


def rank_note(p, passed: bool) -> str:
    """The pooled rank chi-square p in words, beside the gate's verdict ``passed``."""
    if p is None or p != p:
        return ""
    if p >= RANK_P:
        return f"the rank histograms are flat (p = {_sig(p)})"
    if passed:
        return (f"the rank histograms are not flat (p = {_sig(p)}): the shape of the posterior differs from the "
                "simulator's, though its outer share and coverage pass")
    return f"the rank histograms are not flat either (p = {_sig(p)})"


def calibration_status(source) -> CalibrationStatus:
    """The status (module doc) of ``source``: a CalibrationResult, its diagnostics dict,
    or a study's calibration record (a dict holding ``diagnostics``)."""
    d = getattr(source, "diagnostics", source)
    if isinstance(d, dict) and isinstance(d.get("diagnostics"), dict):  # a study's record
        d = {"converged": d.get("converged"), **d["diagnostics"]}
    if not isinstance(d, dict) or "converged" not in d:
        raise ValueError("a calibration status needs its diagnostics (with 'converged' and 'reason')")
    amortized = "estimator" in d or d.get("sampler") == "amortized"  # an estimator's file drew it
    route = (d.get("route") or ("emcee" if d.get("sampler") == "emcee" else "amortized")) if amortized else "likelihood"
    check = ("", "", "")
    if not amortized:
        sampler = d.get("sampler", "emcee")
        words = f"the closed-form likelihood, sampled by {_SAMPLERS.get(sampler, sampler)}"
        convergence, detail = chain_words(bool(d["converged"]), d.get("reason", ""))
    elif route == "amortized":
        words = "the amortized posterior: the estimator's exact draws"
        convergence, detail = EXACT, ""
        other = next((r for r in ("smc", "emcee") if r in d), None)  # emcee: a file of an earlier release
        if other:
            check = (other, *chain_words(bool(d[other].get("converged")), d[other].get("reason", "")))
    else:
        m = d.get("smc" if route == "stacked" else route, {})
        how = "tempered SMC from the amortized posterior" if route in ("smc", "stacked") else "nlopt + emcee"
        words = f"{how} on {_LIKELIHOODS.get(m.get('likelihood', 'ratio'), 'the learned likelihood')}"
        if route == "stacked":  # the file's mixture of its two routes
            w = (d.get("stacked") or {}).get("weight", float("nan"))
            words = f"stacked: {w:.2f} x {words} + {1 - w:.2f} x the amortized posterior"
        convergence, detail = chain_words(bool(d["converged"]), d.get("reason", ""))
    sbc = ((d.get("estimator") or {}).get("sbc") or {}).get(route) if amortized else None
    if sbc and sbc.get("outer_share") is not None and sbc.get("coverage90_range"):
        passed, honesty = honest(sbc), verdict(sbc)
        note = rank_note(sbc.get("pooled_p"), passed)
        sbc = {k: sbc.get(k) for k in ("outer_share", "coverage90_range", "n_replicates", "pooled_p", "n_quantities")}
    else:
        passed, honesty, note, sbc = None, NO_SBC, "", None
    return CalibrationStatus(route=route, route_words=words, converged=bool(d["converged"]), convergence=convergence,
                             convergence_detail=detail, honesty=honesty, passed=passed, sbc=sbc, rank_note=note,
                             out_of_range=bool(d.get("out_of_range", False)),
                             out_of_range_why=str(d.get("out_of_range_why") or ""), check_route=check[0],
                             check_convergence=check[1], check_detail=check[2],
                             check_role=smc_role(d) if check[0] else "",
                             users=(d.get("estimator") or {}).get("users") if amortized else None,
                             **_predictive(predictive_record(d)))


def predictive_record(d: dict) -> dict | None:
    """The posterior predictive check's record in diagnostics ``d`` (its statistics, z, the
    limit, ``flagged`` and ``word``), or None where no check ran."""
    p = d.get("predictive") if isinstance(d, dict) else None
    return p if isinstance(p, dict) and p.get("word") in (FITS, MISFIT) else None


STATISTICS_UNITS = ("log10 of the peak-normalised profile, folded; spreads: the cube root of the variance over the "
                    "measurements")
"""What the predictive check's statistics are in, as its tables say it."""


def _predictive(p) -> dict:
    """The predictive check's word and facts from its record (None: not checked)."""
    if p is None:
        return {"predictive": NOT_CHECKED, "predictive_facts": ""}
    n, top = len(p["names"]), max(abs(z) for z in p["z"])
    facts = (f"{n} statistics of the measurements against {p['n_draws']} posterior draws measured "
             f"{p['n_measurements']} times each, largest |z| {top:.1f} (limit {p['z_limit']:.1f})")
    if p["word"] == MISFIT:
        facts += f"; beyond it: {p['why']}: the posterior's drones do not make profiles like these"
    return {"predictive": p["word"], "predictive_facts": facts}


def _strip(reason: str) -> str:
    for prefix in ("NOT CONVERGED: ", "NOT converged: ", "converged: ", "Converged: "):
        if reason.startswith(prefix):
            return reason[len(prefix):]
    return reason


def _sig(p: float) -> str:
    return f"{p:.1e}" if p < 1e-3 else f"{p:.2g}"
