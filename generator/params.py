"""Parameter vectors of the vibration model and the packaged class references.

An engine has 13 parameters, in the order of :data:`PARAM_NAMES` (SPEC section 1);
a class vector is its engines concatenated (13 * n_engines numbers). Batches of
vectors are plain arrays of shape (N, 13 * n_engines) in the hot paths.

Units: Gamma dimensionless, A in m, w in rad/s, phi in rad, C dimensionless.
"""
from __future__ import annotations

import json
from dataclasses import astuple, dataclass
from importlib import resources

import numpy as np

PARAM_NAMES = ("Gamma", "A_a", "w_a", "phi_a", "A_b", "w_b", "phi_b",
               "A_p", "C_p", "phi_p", "A_m", "C_m", "phi_m")
N_PARAMS = len(PARAM_NAMES)
IDX = {name: i for i, name in enumerate(PARAM_NAMES)}

AMPLITUDES = (IDX["A_a"], IDX["A_b"], IDX["A_p"], IDX["A_m"])
PHASES = (IDX["phi_a"], IDX["phi_b"], IDX["phi_p"], IDX["phi_m"])
FREE_FREQS = (IDX["w_a"], IDX["w_b"])
SKEWS = (IDX["C_p"], IDX["C_m"])
NONNEGATIVE = (IDX["Gamma"],) + AMPLITUDES + FREE_FREQS + SKEWS
"""Columns that are physically non-negative (phases are free, on the circle)."""

UNITS = {"Gamma": "", "A": "m", "w": "rad/s", "phi": "rad", "C": ""}


def unit_of(name: str) -> str:
    return UNITS[name.split("_")[0]]


def param_labels(n_engines: int) -> list[str]:
    """Names of the flat vector's entries: ``Gamma[0], A_a[0], ...``."""
    return [f"{p}[{k}]" for k in range(n_engines) for p in PARAM_NAMES]


@dataclass(frozen=True)
class Engine:
    """One engine's 13 parameters (SPEC section 1 order)."""

    Gamma: float
    A_a: float
    w_a: float
    phi_a: float
    A_b: float
    w_b: float
    phi_b: float
    A_p: float
    C_p: float
    phi_p: float
    A_m: float
    C_m: float
    phi_m: float

    @property
    def w_p(self) -> float:
        return self.C_p * abs(self.w_a + self.w_b)

    @property
    def w_m(self) -> float:
        return self.C_m * abs(self.w_a - self.w_b)


def validate_vectors(x, n_engines: int | None = None, what: str = "parameter vector",
                     physical: bool = True) -> np.ndarray:
    """Check a vector (13n,) or batch (N, 13n); return it as float64 (N, 13n).

    Raises ValueError naming ``what``, the offending entry and what was expected.
    ``physical`` also requires the non-negative columns to be >= 0.
    """
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2:
        raise ValueError(f"{what}: expected shape (13*n_engines,) or (N, 13*n_engines), got {arr.shape}")
    width = arr.shape[1]
    if width == 0 or width % N_PARAMS:
        raise ValueError(f"{what}: length {width} is not a multiple of {N_PARAMS} "
                         f"(13 parameters per engine: {', '.join(PARAM_NAMES)})")
    if n_engines is not None and width != N_PARAMS * n_engines:
        raise ValueError(f"{what}: length {width} does not match {n_engines} engine(s) "
                         f"(expected {N_PARAMS * n_engines})")
    labels = param_labels(width // N_PARAMS)
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(f"{what}: {labels[col]} is {arr[row, col]} in row {row}; expected a finite number")
    if physical:
        cols = np.array([k * N_PARAMS + c for k in range(width // N_PARAMS) for c in NONNEGATIVE])
        neg = arr[:, cols] < 0
        if neg.any():
            row, j = np.argwhere(neg)[0]
            raise ValueError(f"{what}: {labels[cols[j]]} = {arr[row, cols[j]]} in row {row}; "
                             "expected >= 0 (amplitudes, frequencies, Gamma and C are non-negative)")
    return arr


@dataclass(frozen=True)
class ClassParams:
    """A drone class's parameter vector: a name and its engines (only those present)."""

    name: str
    engines: tuple[Engine, ...]
    description: str = ""
    note: str = ""

    def __post_init__(self) -> None:
        if not self.engines:
            raise ValueError(f"class {self.name!r}: needs at least one engine")
        validate_vectors(self.to_array(), what=f"class {self.name!r}")

    @property
    def n_engines(self) -> int:
        return len(self.engines)

    @property
    def size(self) -> int:
        return N_PARAMS * self.n_engines

    def to_array(self) -> np.ndarray:
        """Flat float64 vector (13 * n_engines,)."""
        return np.array([v for e in self.engines for v in astuple(e)], dtype=np.float64)

    @classmethod
    def from_array(cls, x, name: str = "custom", **kw) -> "ClassParams":
        arr = validate_vectors(x, what=f"class {name!r}")
        if arr.shape[0] != 1:
            raise ValueError(f"class {name!r}: from_array takes one vector, got {arr.shape[0]}")
        rows = arr[0].reshape(-1, N_PARAMS)
        return cls(name=name, engines=tuple(Engine(*map(float, r)) for r in rows), **kw)

    def labels(self) -> list[str]:
        return param_labels(self.n_engines)


def _reference_table() -> dict:
    text = resources.files("mdaug.generator").joinpath("data/classes.json").read_text()
    return json.loads(text)


def reference_classes() -> tuple[str, ...]:
    """Names of the packaged class references."""
    return tuple(_reference_table()["classes"])


def load_reference(name: str) -> ClassParams:
    """The packaged reference vector of class ``name`` (``HELI`` or ``QUAD``).

    Values from the published model tables; QUAD engine 3 is a best reading of a
    garbled source row (see :attr:`ClassParams.note`).
    """
    table = _reference_table()
    classes = table["classes"]
    key = name.upper()
    if key not in classes:
        raise ValueError(f"unknown class {name!r}; packaged references: {sorted(classes)}")
    entry = classes[key]
    assert tuple(table["order"]) == PARAM_NAMES, "classes.json parameter order changed"
    engines = tuple(Engine(*map(float, row)) for row in entry["engines"])
    note = ""
    if "uncertain" in entry:
        u = entry["uncertain"]
        note = f"engine {u['engine']} uncertain: {u['why']}"
    return ClassParams(name=key, engines=engines, description=entry.get("description", ""), note=note)
