"""Every door, second pass (issue 40), one kind per section: counts bounded by the
parser, sizes checked before work, estimator files as untrusted input, options that
do not apply, signals inside samplers, leftovers, the user's names in messages, data
sanity at the calibration boundary. Each refusal: exit status 2, ONE line naming the
option or the file and field, the inputs' bytes unchanged and nothing left behind
(the ``refused`` fixture of conftest.py)."""
import argparse

import numpy as np
import pytest

from mdaug.radar import atomic_savez

LABELS = np.array(["HELI"] * 10 + ["QUAD"] * 10)


def _profiles(n=20, seed=0):
    x = np.abs(np.random.default_rng(seed).normal(0.1, 0.05, (n, 400)))
    x[:, 200] = 1.0
    return x


@pytest.fixture
def io_dirs(tmp_path):
    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    out.mkdir()
    atomic_savez(d / "m.npz", profiles=_profiles(), labels=LABELS, ramps_per_frame=np.array(4))
    return d, out


# ---- 1. counts: bounded by the parser, one helper ------------------------------------------------
def _count_options():
    """(verb, option, action) of every option of every verb whose value is an integer."""
    from mdaug.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for verb, p in sub.choices.items():
        for action in p._actions:
            if not action.option_strings or action.type is None or not callable(action.type):
                continue
            try:
                value = action.type("7")
            except (argparse.ArgumentTypeError, ValueError, TypeError):
                continue
            if isinstance(value, int) and not isinstance(value, bool):
                found.append((verb, action.option_strings[-1], action))
    return found


def test_every_integer_option_is_a_count_of_the_one_helper():
    options = _count_options()
    assert len(options) > 30
    loose = [(v, o) for v, o, a in options if not a.type.__name__.startswith("count_")]
    assert not loose, f"integer options not parsed by cli.common.count: {loose}"


@pytest.mark.parametrize("verb,option", [(v, o) for v, o, _ in _count_options()])
def test_a_count_below_its_bound_is_refused_by_the_parser(verb, option, io_dirs, refused):
    d, out = io_dirs
    action = next(a for v, o, a in _count_options() if (v, o) == (verb, option))
    lo = int(action.type.__name__.split("_")[1])
    bad = str(lo - 1) if lo > 0 else "-1"
    line = refused([verb, option, bad], d, out, [f"argument {option}", f"got {bad}"], seconds=5)
    assert "expected" in line


@pytest.mark.parametrize("argv,must", [
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--sbc-truths", "-1"],
     ["argument --sbc-truths: expected an integer >= 0, got -1"]),
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--sbc-emcee-truths", "-3"],
     ["argument --sbc-emcee-truths", "got -3"]),
    (["sbc", "--class", "HELI", "--ramps", "4", "--emcee-truths", "-2"], ["argument --emcee-truths", "got -2"]),
    (["train-estimator", "--class", "HELI", "--ramps", "4", "--out", "{o}/e.zip", "--simulations", "2000001"],
     ["argument --simulations: expected an integer from 100 to 2,000,000"]),
    (["calibrate", "{d}/m.npz", "--class", "HELI", "--out", "{o}/p.nc", "--engines", "0"],
     ["argument --engines", "'auto'"]),
])
def test_the_issue_counts(argv, must, io_dirs, refused):
    d, out = io_dirs
    refused([a.format(d=d, o=out) for a in argv], d, out, must, seconds=5)
