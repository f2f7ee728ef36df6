"""The installed package's version, for the settings every output records.

Read from the package metadata (importlib.metadata), so library modules need not
reach up to ``mdaug.__version__``; ``mdaug.__version__`` is this same value.
"""
from __future__ import annotations

from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version

UNKNOWN = "0.0.0+unknown"


@lru_cache(maxsize=1)
def package_version() -> str:
    """mdaug's version string ("0.0.0+unknown" when running from an uninstalled tree)."""
    try:
        return version("mdaug")
    except PackageNotFoundError:
        return UNKNOWN
