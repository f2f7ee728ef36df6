"""How much memory a job would take, against how much the machine has free.

Used before allocating large arrays, so that a request far beyond the machine (say
10^12 synthetic profiles) is refused with a clear message instead of numpy's
_ArrayMemoryError and a traceback.
"""
from __future__ import annotations

import os


def available_memory_bytes() -> int | None:
    """Memory available to a new allocation (psutil's ``available``, else the free
    physical pages), or None when the platform does not say."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # psutil missing or unsupported platform
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    """1536 -> '1.5 KB' (powers of 1024, up to EB)."""
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EB"


def check_memory(nbytes: float, what: str, unit_bytes: float | None = None, unit: str = "") -> None:
    """Raise ValueError when ``nbytes`` exceeds the available memory.

    what: the request, e.g. "--n-per-class 1000000000000: 2 x 10^12 profiles";
    unit_bytes / unit: the cost of one unit of the request (e.g. one profile per
    class), to say how many would fit.
    """
    avail = available_memory_bytes()
    if avail is None or nbytes <= avail:
        return
    fits = f"; at most about {int(avail // unit_bytes):,} {unit} fit" if unit_bytes else ""
    raise ValueError(f"{what} would take about {format_bytes(nbytes)} of memory, and {format_bytes(avail)} "
                     f"is available{fits}")


MAX_SECONDS = 86400.0
"""The longest job a size option may ask for: a request that would run longer than
this even at the fastest rate the toolkit reaches is refused (a mistyped size, not
a long study)."""


def format_seconds(s: float) -> str:
    """90 -> '1.5 min', 1e7 -> '116 days', 1e12 -> '31,710 years'."""
    for limit, div, unit in ((120, 1, "s"), (7200, 60, "min"), (2 * 86400, 3600, "h"), (730 * 86400, 86400, "days")):
        if s < limit:
            return f"{s / div:.3g} {unit}"
    return f"{s / (365.25 * 86400):,.0f} years"


def _big(v) -> float:
    return float(min(int(v), 10 ** 300)) if not isinstance(v, float) else v


def check_size(factors, *, bytes_each: float = 0.0, seconds_each: float = 0.0, what: str = "",
               limit_seconds: float = MAX_SECONDS) -> None:
    """The one bound of every size and count option: refuse (ValueError naming the
    option) a request whose memory exceeds what is available, or whose time exceeds
    ``limit_seconds`` even at the fastest rate.

    factors: [(option, value, typical)]: the options whose product counts the units of
    work (e.g. profiles x ramps), each with a typical value; the refusal names the
    option furthest above its typical value, with the others beside it. bytes_each,
    seconds_each: the optimistic memory and time of one unit (the product's 1); what:
    what a unit is, for the message (e.g. "rendered ramps").
    """
    units = 1.0
    for _, value, _ in factors:
        units *= _big(value)
    nbytes, seconds = units * bytes_each, units * seconds_each
    avail = available_memory_bytes() if bytes_each else None
    over_memory = avail is not None and nbytes > avail
    over_time = seconds > limit_seconds
    if not (over_memory or over_time):
        return
    name, value, _ = max(factors, key=lambda f: _big(f[1]) / max(_big(f[2]), 1.0))
    rest = 1.0
    for n, v, _ in factors:
        if n != name:
            rest *= _big(v)
    others = ", ".join(f"{n} {_big(v):,.0f}" for n, v, _ in factors if n != name)
    head = f"{name} {_big(value):,.0f}" + (f" (with {others})" if others else "")
    unit = f" ({units:,.0f} {what})" if what else ""
    if over_memory:
        fits = int(avail // max(bytes_each * rest, 1e-300))
        raise ValueError(f"{head}: would take about {format_bytes(nbytes)} of memory{unit}, and "
                         f"{format_bytes(avail)} is available; {name} at most about {fits:,} fits")
    fits = int(limit_seconds // max(seconds_each * rest, 1e-300))
    raise ValueError(f"{head}: would take at least {format_seconds(seconds)}{unit} even at the fastest rate, "
                     f"more than the {format_seconds(limit_seconds)} mdaug accepts; {name} at most about {fits:,} fits")
