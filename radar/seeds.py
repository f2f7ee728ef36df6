"""The toolkit's one seed helper: every random stream derives from the user's one seed.

A seed may be an int, None (fresh entropy), a ``numpy.random.SeedSequence`` or a
``numpy.random.Generator``. Child streams are keyed: ``child_seed(seed, "cnn",
"HELI")`` always gives the same number for the same seed and keys, whatever else
runs, so stages, jobs and classes are reproducible independently of each other and
of the order or the process they run in. String keys are hashed stably (not with
Python's per-process ``hash``).
"""
from __future__ import annotations

import hashlib

import numpy as np


def _key(k) -> int:
    if isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 0:
        return int(k)
    digest = hashlib.sha256(repr(k).encode()).digest()
    return int.from_bytes(digest[:4], "little")


def seed_sequence(random_state=None, *keys) -> np.random.SeedSequence:
    """A SeedSequence for ``random_state`` and the child keys (none: the seed itself).

    A Generator contributes one draw from itself (so it advances); a SeedSequence
    is extended by the keys."""
    if isinstance(random_state, np.random.Generator):
        random_state = int(random_state.integers(2**63 - 1))
    if isinstance(random_state, np.random.SeedSequence):
        base = random_state
    elif random_state is None or isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool):
        base = np.random.SeedSequence(None if random_state is None else int(random_state))
    else:
        raise ValueError(f"random_state (the seed) must be an integer, None, a SeedSequence or a numpy Generator, "
                         f"got {random_state!r}")
    if not keys:
        return base
    return np.random.SeedSequence(base.entropy, spawn_key=tuple(base.spawn_key) + tuple(_key(k) for k in keys),
                                  pool_size=base.pool_size)


def child_seed(random_state, *keys) -> int:
    """A 31-bit integer seed derived from ``random_state`` and the keys."""
    return int(seed_sequence(random_state, *keys).generate_state(1)[0] >> 1)


def rng(random_state=None, *keys) -> np.random.Generator:
    """A Generator: ``random_state`` itself when it is one and no keys are given, else
    a fresh one from :func:`seed_sequence`."""
    if isinstance(random_state, np.random.Generator) and not keys:
        return random_state
    return np.random.default_rng(seed_sequence(random_state, *keys))


def torch_generator(random_state, *keys):
    """A torch.Generator seeded with :func:`child_seed` of ``random_state`` and the keys
    (torch is imported only here)."""
    import torch

    return torch.Generator().manual_seed(child_seed(random_state, *keys))
