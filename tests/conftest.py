import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


class FakeTTY:
    """A stderr that says it is a terminal and keeps what is written (``text``)."""

    def __init__(self):
        self.parts = []

    def isatty(self):
        return True

    def write(self, s):
        self.parts.append(s)

    def flush(self):
        pass

    @property
    def text(self):
        return "".join(self.parts)


@pytest.fixture
def terminal():
    """A factory of :class:`FakeTTY` (a stderr that draws bars)."""
    return FakeTTY


def _tree(folder):
    """{relative path: sha256} of every file under ``folder`` (links by their target's bytes)."""
    import hashlib
    from pathlib import Path

    out = {}
    for p in sorted(Path(folder).rglob("*")):
        if p.is_file():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[str(p.relative_to(folder))] = "dir"
    return out


@pytest.fixture
def refused(capsys):
    """``refused(argv, inputs, out, must)``: run ``mdaug argv`` in-process and check the
    refusal: exit status 2, ONE stderr line ``mdaug VERB: error: ...`` holding every
    substring of ``must``, no traceback, no input file changed (bytes hashed before and
    after, nothing added or removed under ``inputs``) and nothing written in ``out``."""
    import time

    from mdaug.cli import main

    def run(argv, inputs, out, must, seconds: float = 20.0):
        before, out_before = _tree(inputs), _tree(out)
        t0 = time.perf_counter()
        status = main(list(argv))
        took = time.perf_counter() - t0
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert status == 2, err
        assert len(lines) == 1, err
        verb = next(a for a in argv if not a.startswith("-"))
        assert lines[0].startswith(f"mdaug {verb}: error: "), err
        assert "Traceback" not in err
        for text in must:
            assert text in lines[0], lines[0]
        assert _tree(inputs) == before, "an input changed"
        assert _tree(out) == out_before, "an output was left behind"
        assert took < seconds, f"the refusal took {took:.1f} s"
        return lines[0]

    return run


@pytest.fixture(scope="session")
def tiny_posterior(tmp_path_factory):
    """A small real HELI posterior NetCDF (published single chirp, phases fitted, two
    measurements, a few seconds of fit and sampling): for readers and the CLI."""
    import warnings

    from mdaug.generator import load_reference, profiles
    from mdaug.inference.calibrate import calibrate
    from mdaug.inference.settings import CalibrationSettings

    x = load_reference("HELI").to_array()
    y = np.repeat(profiles(x[None]), 2, axis=0) + np.abs(np.random.default_rng(0).normal(0, 0.01, (2, 400)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(y, "HELI", settings=CalibrationSettings.quick(max_steps=20, fit_budget=50, n_starts=1,
                                                                      polish_budget=50, check_every=10),
                        random_state=0)
    path = tmp_path_factory.mktemp("posterior") / "heli.nc"
    res.save(path)
    return path
