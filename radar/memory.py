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
