"""The toolkit's one cache key: a short, stable hex digest of settings and arrays.

Keys stored in files depend on these exact bytes (the study's stage cache, the
sigma_P sweep's cache, a calibration's saved fit): a stored key must keep matching,
so nothing here may change what a given call returns.
"""
from __future__ import annotations

import hashlib
import json

import numpy as np


def cache_key(value=None, *, text: str | None = None, arrays=(), dtype=None, algorithm: str = "sha256",
              length: int | None = 16) -> str:
    """Hex digest (its first ``length`` characters; None: all of it) of ``value`` as JSON
    with sorted keys (anything else by ``str``), or of ``text`` as given (None and None:
    nothing), followed by the bytes of each of ``arrays`` in C order (cast to ``dtype``
    first when given). ``algorithm``: a :mod:`hashlib` name."""
    if value is not None and text is not None:
        raise ValueError("cache_key: give value or text, not both")
    blob = text if text is not None else ("" if value is None else json.dumps(value, sort_keys=True, default=str))
    h = hashlib.new(algorithm, blob.encode())
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=dtype).tobytes())
    digest = h.hexdigest()
    return digest if length is None else digest[:length]
