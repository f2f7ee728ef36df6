"""Shared pieces of the command line, defined once.

* the parser class (errors become one ``mdaug VERB: error: ...`` line, exit 2);
* argument types that check their value and name the option when it is bad;
* the global options (``--threads``, ``--quiet``), accepted before and after the verb
  (the option groups shared by several verbs are in :mod:`.options`);
* checks run before any work: inputs readable and sensible, and the one bound of
  every size option (:func:`check_size`: memory and time, naming the option); the
  one output guard is :func:`.guard.check_paths`.

Nothing heavy is imported at module level: ``mdaug --help`` stays fast.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")
MODELS = ("svm", "nb", "xgb", "cnn")


# ---- parser and errors -------------------------------------------------------------
EXIT_NOT_CONVERGED = 3
"""Exit status of a calibration whose sampler did not converge (its file is written, flagged)."""


class UsageError(Exception):
    """A bad command line or option value: printed as one ``PROG: error: ...`` line, exit 2."""

    def __init__(self, message: str, prog: str | None = None):
        super().__init__(message)
        self.prog = prog


class Parser(argparse.ArgumentParser):
    """argparse, but an error raises :class:`UsageError` (one line, no usage dump),
    so that ``main`` returns 2 instead of exiting the interpreter."""

    def __init__(self, *args, **kw):
        kw.setdefault("allow_abbrev", False)  # --sigma must not silently mean --sigma-p
        super().__init__(*args, **kw)

    def error(self, message):
        raise UsageError(message, self.prog)


class HelpFormatter(argparse.HelpFormatter):
    """Wider option column; descriptions and epilogs keep their paragraphs."""

    def __init__(self, prog):
        super().__init__(prog, max_help_position=34)

    def _fill_text(self, text, width, indent):
        import textwrap

        paras = [textwrap.fill(" ".join(p.split()), width, initial_indent=indent, subsequent_indent=indent)
                 for p in text.split("\n\n")]
        return "\n\n".join(paras)


OVERWRITE_HELP = ("replace output files that exist already (default: refuse them, naming the file; nothing is "
                  "written)")


def add_verb(sub, name: str, parents, *, help: str, description: str, interrupted, epilog: str | None = None,
             overwrite: str = OVERWRITE_HELP):
    """One verb's parser with the global options, ``--overwrite`` (``overwrite``: its
    help; the rule is :func:`.guard.check_paths`'s, which every verb calls with
    ``overwrite=args.overwrite``), and what to say when it is interrupted
    (``interrupted(args) -> str``)."""
    p = sub.add_parser(name, help=help, description=description, epilog=epilog, parents=parents,
                       formatter_class=HelpFormatter)
    p.add_argument("--overwrite", action="store_true", help=overwrite)
    p.set_defaults(interrupted=interrupted)
    return p


def nothing_written(args) -> str:
    return "no partial file was left (outputs appear only when complete)"


# ---- argument types (each error names the option through argparse) ------------------
def _type(fn, name):
    fn.__name__ = name
    return fn


def integer(text: str, lo: int | None = None, what: str = "an integer") -> int:
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if lo is not None and value < lo:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def count(lo: int = 1, hi: int | None = None, what: str | None = None, words: tuple = ()):
    """The one argparse type of every count option: an integer in [lo, hi] (hi None: no
    upper bound here; the size bound :func:`check_size` weighs it against memory and
    time), or one of ``words`` (e.g. 'auto'). A value outside is refused by the parser,
    which names the option (``argument --sbc-truths: expected an integer >= 0, got -1``)."""
    if what is None:
        what = (f"an integer from {lo} to {hi:,}" if hi is not None else
                "a positive integer (>= 1)" if lo == 1 else f"an integer >= {lo}")

    def parse(text: str):
        if text in words:
            return text
        value = integer(text, lo, what)
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    return _type(parse, f"count_{lo}_{hi}")


positive_int = count(1)
nonneg_int = count(0)
seed_int = count(0, what="a seed: an integer >= 0")
count_2 = count(2)


def number(text: str, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           what: str = "a number") -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    bad = not math.isfinite(value)
    if lo is not None:
        bad |= value <= lo if lo_open else value < lo
    if hi is not None:
        bad |= value > hi
    if bad:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


finite_float = _type(lambda t: number(t, what="a finite number"), "finite_float")
nonneg_float = _type(lambda t: number(t, 0.0, what="a finite number >= 0"), "nonneg_float")
positive_float = _type(lambda t: number(t, 0.0, lo_open=True, what="a finite number > 0"), "positive_float")
db_at_most_0 = _type(lambda t: number(t, hi=0.0, what="a level in dB <= 0"), "db_at_most_0")
unit_fraction = _type(lambda t: number(t, 0.0, 1.0, what="a number in [0, 1]"), "unit_fraction")


def csv_list(text: str) -> list[str]:
    """'a, b,c' -> ['a', 'b', 'c'] (non-empty, no repeats)."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}")
    if len(set(items)) != len(items):
        raise argparse.ArgumentTypeError(f"names an item twice: {text!r}")
    return items


def path_list(text: str) -> list[Path]:
    """'a.npz,b.npz' -> [Path('a.npz'), Path('b.npz')]."""
    return [Path(t) for t in csv_list(text)]


def class_list(text: str) -> list[str]:
    return [c.upper() for c in csv_list(text)]


def model_list(text: str) -> list[str]:
    items = csv_list(text)
    bad = [m for m in items if m not in MODELS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown model(s) {bad}; known: {','.join(MODELS)}")
    return items


def sigma_list(text: str) -> list[float]:
    """Comma-separated sigma_P values in [0, 1]."""
    out = []
    for t in csv_list(text):
        out.append(number(t, 0.0, 1.0, what="comma-separated sigma_P values in [0, 1]"))
    return out


def nonneg_pair(text: str) -> tuple[float, float]:
    """'LO,HI' with 0 <= LO <= HI."""
    lo, hi = float_pair(text)
    if lo < 0:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH >= 0, got {text!r}")
    return lo, hi


def noise_pair(text: str):
    """'LO,HI' in dB, or 'none'."""
    if text.strip().lower() == "none":
        return "none"
    return float_pair(text)


def float_pair(text: str) -> tuple[float, float]:
    """'LO,HI' (or LO:HI) with LO <= HI."""
    parts = [t for t in text.replace(":", ",").split(",") if t.strip()]
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH, got {text!r}")
    lo, hi = (number(p, what="LOW,HIGH: two finite numbers") for p in parts)
    if lo > hi:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH with LOW <= HIGH, got {text!r}")
    return lo, hi


def default_threads() -> int:
    try:
        n = int(os.environ.get("MDAUG_THREADS", "1"))
    except ValueError:
        n = 1
    return max(n, 1)


def apply_threads(n: int) -> None:
    """Pin BLAS, OpenMP and torch to ``n`` threads (scipy.fft uses 1 worker unless asked).

    The default is 1: on these shared 2-core machines a 2-thread run collapses when
    the second core is busy; ask for 2 with ``--threads 2`` or MDAUG_THREADS=2.
    """
    for var in THREAD_VARS:
        os.environ[var] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)
    os.environ["MDAUG_THREADS"] = str(n)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)


def global_options(top: bool) -> Parser:
    """``--threads`` and ``--quiet``, accepted before the verb (``top``) and after it.

    After the verb they default to SUPPRESS, so a value given there wins and a value
    given before the verb is kept when none is given after it.
    """
    p = Parser(add_help=False)
    g = p.add_argument_group("global options (before or after the verb)")
    g.add_argument("--threads", type=positive_int, metavar="N",
                   default=default_threads() if top else argparse.SUPPRESS,
                   help="threads for BLAS, FFT and torch (default: $MDAUG_THREADS or 1; 1 is fastest on a "
                        "busy shared machine)")
    g.add_argument("-q", "--quiet", action="store_true", default=False if top else argparse.SUPPRESS,
                   help="no progress bars and no status lines; results, warnings and errors are still printed")
    return p


# ---- checks before any work ------------------------------------------------------------
def load_profile_file(path, *, length: int | None = None, why: str = "", allow_zero: bool = False):
    """Read a measured/synthetic profile file (NPZ, CSV, .mat) and refuse what no verb can
    use: all-zero rows (naming them), or profiles of the wrong length (``why`` says who
    needs ``length`` bins)."""
    from ..radar import DataFileError, load_profiles

    ps = load_profiles(path)
    if length is not None and ps.profiles.shape[1] != length:
        raise DataFileError(f"{path}: field 'profiles' has {ps.profiles.shape[1]}-bin profiles; {why} takes "
                            f"{length}-bin profiles")
    if not allow_zero:
        ps.check_no_zero_rows()
    return ps


# ---- size bounds ------------------------------------------------------------------------
# Per-unit costs for the size bounds (radar.memory.check_size): the rates measured on the
# project machine (1 thread) made about 3 times faster, so that a refused size is out of
# reach on a faster machine too; a size whose job would still take more than a day is
# refused in a few milliseconds, before any work.
SECONDS_FAST_RAMP = 1e-5        # fast path: one ramp of one engine of one profile (measured 30-80 us)
SECONDS_CHAIN_RAMP = 1.5e-5     # chain path: one ramp of one engine of one profile (measured 45-170 us)
SECONDS_SCENE_RAMP = 1e-4       # scene simulator + literal chain: one ramp of one frame (measured ~300 us)
SECONDS_CNN_PROFILE = 2e-5      # CNN: one profile through one epoch
SECONDS_TREE_BIN = 1e-9         # XGBoost: one tree over one profile bin
SECONDS_RESAMPLE = 5e-9         # bootstrap: one resampled prediction (measured ~15 ns)
SECONDS_TSAUG = 5e-6            # tsaug: one augmented profile
SECONDS_LIKELIHOOD_RAMP = 2e-6  # calibration: one simulated ramp of one engine in one likelihood evaluation
SECONDS_SIMULATED_RAMP = 5e-5   # estimator drones: one ramp of one measurement, scene + chain (measured 160-230 us)
BYTES_SPECTRUM = 4096 * 16      # one complex 4096-point range spectrum
CHAIN_ANTENNAS = 8
SAMPLES = 504


def check_size(*factors, bytes_each: float = 0.0, seconds_each: float = 0.0, what: str = "") -> None:
    """:func:`mdaug.radar.memory.check_size` (the one size bound) for options given as
    ``(option, value, typical)``; factors whose value is None are left out."""
    from ..radar.memory import check_size as bound

    bound([f for f in factors if f[1] is not None], bytes_each=bytes_each, seconds_each=seconds_each, what=what)


def ramps_factor(name: str, k: int, typical: int = 32) -> tuple[str, int, int]:
    """The size factor of K ramps per frame, ``(name, k, typical)`` for :func:`check_size`,
    after the radar's own bound (``max_ramps_per_frame``): a K the radar cannot run is
    refused by that bound, naming the option or the file and field (``name``), before
    any estimate of time or memory."""
    from ..radar import RadarConfig

    RadarConfig().check_ramps(int(k), name)
    return name, k, typical


def check_training_memory(n_profiles: int, option: str, n_per_class: int, n_classes: int,
                          bins: int = 400, itemsize: int = 8) -> None:
    """Refuse a training set that would not fit in memory (profiles, a few copies)."""
    from ..radar.memory import check_memory

    per = 3 * bins * itemsize * n_classes
    check_memory(per * n_per_class, f"{option} {n_per_class:,}: {n_profiles:,} training profiles x {bins} bins",
                 per, "per class")


def info(message: str = "") -> None:
    """A status line (silenced by --quiet)."""
    from ..radar.progress import echo

    echo(message)


def result(message: str = "") -> None:
    """A result line (always printed)."""
    from ..radar.progress import echo

    echo(message, force=True)


def warn(verb: str, message: str) -> None:
    from ..radar.progress import echo

    echo(f"mdaug {verb}: WARNING: {message}", err=True, force=True)


def format_table(headers, rows, align=None) -> str:
    """A plain-text table: header, rule, rows (strings); ``align`` per column '<' or '>'."""
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    align = align or ["<"] * len(headers)
    lines = []
    for k, r in enumerate(cells):
        lines.append("  ".join(f"{c:{a}{w}}" for c, a, w in zip(r, align, widths)).rstrip())
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)
