"""Numbers as the report and the README print them: rounded to their interval's
precision (the Particle Data Group's rule, :func:`decimals`), signed differences, an
undefined value as "–", lists of names in words, config values without repr."""
from __future__ import annotations

import html
import json
import math
from importlib import resources

import numpy as np


def published_results() -> dict:
    """The published study's figures (packaged copy of reference/published_results.json)."""
    return json.loads(resources.files("mdaug.reports").joinpath("data/published_results.json").read_text())


def get(results: dict, key: str):
    """The value at a dot-separated path of results.json ('strategies.tsaug.tests.new.n')."""
    v = results
    for part in key.split("."):
        v = v[part] if isinstance(v, dict) else v[int(part)]
    return v


def decimals(interval, default: int = 2, lo: int = 1, hi: int = 4) -> int:
    """Decimals that round a number to its interval's precision, by the Particle Data
    Group's rule on the half-width h: its three leading digits 100-354 keep two
    significant digits, 355-949 one, 950-999 round up to 1000 and keep two
    (h = 0.08 -> 2 decimals, 0.12 -> 2, 0.04 -> 2, 0.03 -> 3, 0.4 -> 1); within [lo, hi];
    ``default`` when there is no interval or it has no width."""
    if not interval or interval[0] is None or interval[1] is None:
        return default
    h = (float(interval[1]) - float(interval[0])) / 2.0
    if not np.isfinite(h) or h <= 0:
        return default
    e = math.floor(math.log10(h))
    lead = int(round(h / 10.0 ** (e - 2)))
    if lead >= 1000:  # h = 9.995... rounded up a decade
        e, lead = e + 1, 100
    sig = 2 if lead <= 354 else 1 if lead <= 949 else 2
    if lead >= 950:
        e += 1
    return int(min(max(sig - 1 - e, lo), hi))


def column_decimals(intervals, default: int = 2, lo: int = 1, hi: int = 4) -> int:
    """One precision per table column: the decimals of its sharpest interval
    (:func:`decimals`), so every cell of the column shows as many (a column never holds
    '0.9 [0.0, 1.0]' beside '0.334 [0.311, 0.364]'); intervals without width (a class
    always or never recognised) do not count; ``default`` when none has a width."""
    ds = [decimals(ci, default, lo, hi) for ci in intervals
          if ci and ci[0] is not None and ci[1] is not None and np.isfinite(ci[0]) and np.isfinite(ci[1])
          and ci[1] > ci[0]]
    return max(ds) if ds else default


def fmt(v, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return f"{v:.{max(digits, 0)}f}"
    return html.escape(str(v))


def fmt_sig(v, sig: int = 2) -> str:
    """A number to ``sig`` significant digits (scientific below 1e-3)."""
    if v is None or not np.isfinite(v):
        return "–"
    if v == 0:
        return "0"
    if abs(v) < 1e-3:
        return f"{v:.{sig - 1}e}"
    d = max(sig - 1 - math.floor(math.log10(abs(v))), 0)
    return f"{v:.{d}f}"


def signed(d: float, ci) -> str:
    """A difference and its interval, signed, at the interval's precision: '+0.06 [-0.03, +0.15]'."""
    dd = decimals(ci)
    f = lambda v: f"{round(v, dd) + 0.0:+.{dd}f}"  # noqa: E731  (+ 0.0: no '-0.00')
    return f"{f(d)} [{f(ci[0])}, {f(ci[1])}]" if ci else f(d)


def spread(s: dict | None, digits: int) -> str:
    """A result's seed spread: 'runs 0.68-0.72' (the lowest and highest run's balanced
    accuracy), '' for a single run."""
    if not s or not s.get("balanced_accuracy"):
        return ""
    lo, hi = s["balanced_accuracy"]
    return f"{fmt(lo, digits)}–{fmt(hi, digits)}"


def join(names) -> str:
    """'a', 'a and b', 'a, b and c'."""
    names = list(names)
    if not names:
        return ""
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def plain(v) -> str:
    """A config value as text (lists joined, mappings as 'key value', no repr)."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, dict):
        return ", ".join(f"{k} {plain(x)}" for k, x in v.items()) or "–"
    if isinstance(v, (list, tuple)):
        return ", ".join(plain(x) for x in v) or "–"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)
