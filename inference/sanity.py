"""Data that cannot be what they claim, refused at the calibration boundary.

One function per kind of input, called by every command that calibrates (``mdaug
calibrate``, the study's check of its calibration files) or reads what a calibration
made (a population file's drones). Each refusal is one :class:`mdaug.radar.DataFileError`
naming the file, the field, the class, how many profiles and which rows:

* constant profiles (no signal at all; all-zero rows are refused by the reader);
* identical profiles: one measurement repeated is not several independent ones (the
  posterior would be several times too sharp);
* off-centre profiles: calibration takes peak-centred signatures (``mdaug process``
  centres them), a peak more than :data:`CENTRE_TOLERANCE` bins from the centre bin
  is another kind of data;
* duplicate drone ids where each drone must appear once (a population's drones).
"""
from __future__ import annotations

import numpy as np

CENTRE_TOLERANCE = 4
"""Bins a profile's peak may lie from the centre bin (the widest tone-offset prior,
:data:`mdaug.inference.space.priors.OFFSET_BINS`); the chain's slices put it on the
centre bin exactly."""
SHOWN = 5  # rows named in a message


def _rows(idx) -> str:
    idx = [int(i) for i in idx]
    more = f", ... ({len(idx)} in all)" if len(idx) > SHOWN else ""
    return ", ".join(map(str, idx[:SHOWN])) + more


def check_calibration_profiles(profiles, source: str, class_name: str, rows=None) -> None:
    """Refuse (DataFileError naming ``source``, field 'profiles', the class, the count
    and the rows) calibration profiles (n, L) that are constant, repeated or off-centre.
    ``rows``: each profile's row in the file (default 0..n-1)."""
    from ..radar import DataFileError

    x = np.asarray(profiles, dtype=float)
    if x.ndim != 2 or not len(x):
        return
    rows = np.arange(len(x)) if rows is None else np.asarray(rows)
    finite = np.all(np.isfinite(x), axis=1)  # NaN and inf rows: the readers' own refusal names them
    x, rows = x[finite], rows[finite]
    if not len(x):
        return
    head = f"{source}: field 'profiles'"
    constant = np.flatnonzero(np.ptp(x, axis=1) <= 1e-12 * np.maximum(np.abs(x).max(axis=1), 1e-300))
    if constant.size:
        raise DataFileError(f"{head} holds {constant.size} constant profile(s) of class {class_name} (row(s) "
                            f"{_rows(rows[constant])}): no signal to calibrate on")
    _, first, inverse, counts = np.unique(x, axis=0, return_index=True, return_inverse=True, return_counts=True)
    inverse = np.asarray(inverse).reshape(-1)
    repeated = np.flatnonzero(counts[inverse] > 1)
    if repeated.size:
        copies = int(repeated.size - np.count_nonzero(counts > 1))
        raise DataFileError(f"{head} holds {repeated.size} identical profiles of class {class_name} (row(s) "
                            f"{_rows(rows[repeated])}): {copies} {'is a copy' if copies == 1 else 'are copies'}, not "
                            "independent measurements (the posterior would be too sharp); keep one of each")
    centre = x.shape[1] // 2
    peaks = np.argmax(x, axis=1)
    off = np.flatnonzero(np.abs(peaks - centre) > CENTRE_TOLERANCE)
    if off.size:
        raise DataFileError(f"{head} holds {off.size} of {len(x)} profile(s) of class {class_name} whose peak lies "
                            f"more than {CENTRE_TOLERANCE} bins from the centre bin {centre} (row(s) "
                            f"{_rows(rows[off])} at bin(s) {_rows(peaks[off])}): calibration takes peak-centred "
                            "signatures ('mdaug process' centres them)")


def check_unique_drones(ids, source: str, field: str) -> None:
    """Refuse (DataFileError naming the file, field, count and ids) drone ids that
    repeat where each drone must appear once."""
    from ..radar import DataFileError

    ids = [str(i) for i in ids]
    seen, twice = set(), []
    for i in ids:
        if i in seen and i not in twice:
            twice.append(i)
        seen.add(i)
    if twice:
        n = sum(ids.count(i) for i in twice)
        raise DataFileError(f"{source}: {field} names {n} drones with {len(twice)} repeated id(s) "
                            f"({', '.join(map(repr, twice[:SHOWN]))}): each drone appears once")


def shared_files(calibration: dict, test: dict, source: str) -> list[str]:
    """Warnings (one line each) for test sets that are a calibration file (the same
    file after resolving links): their scores are of data the calibration saw."""
    import os

    warnings = []
    for name, path in test.items():
        same = [cls for cls, cal in calibration.items() if os.path.realpath(cal) == os.path.realpath(path)]
        if same:
            warnings.append(f"{source}: data.test.{name} ({path}) is also the calibration file of "
                            f"{', '.join(same)}: its scores are of measurements the calibration saw, not of new data")
    return warnings
