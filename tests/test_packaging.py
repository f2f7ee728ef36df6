"""The wheel is the tool: built from the tracked files, installed into a fresh
environment, ``mdaug`` runs from a folder outside the repository.

The environment is a venv with ``--system-site-packages`` (the dependencies come from
the machine: no network) and the wheel installed into it; the check asserts that
``mdaug`` is imported from the venv, not from an editable install of a checkout.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tracked_copy(dest: Path) -> Path:
    """The repository's tracked files (and setup/pyproject as they are now) under ``dest``:
    the build writes build/ and *.egg-info next to its sources, never in the checkout."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    names = [n for n in listed.decode().split("\0") if n] + ["setup.py", "pyproject.toml"]
    for name in names:
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env.update(OMP_NUM_THREADS="1", MPLBACKEND="Agg", PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
    return env


@pytest.mark.slow
def test_wheel_installs_and_runs_outside_the_repository(tmp_path):
    src = _tracked_copy(tmp_path / "src")
    wheels = tmp_path / "wheels"
    env = _env()
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(wheels), str(src)], check=True, env=env, cwd=tmp_path)
    (wheel,) = wheels.glob("mdaug-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "mdaug/generator/chain/__init__.py" in names
    assert "mdaug/generator/data/classes.json" in names
    assert not any(n.startswith(("tests/", "mdaug/tests/")) for n in names)
    # the root folder is the package: the build's own files must not be installed inside it
    assert not {"mdaug/setup.py", "mdaug/pyproject.toml", "mdaug/README.md"} & set(names)
    assert not any(n.startswith("mdaug/docs/") for n in names)

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True, env=env)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--ignore-installed", str(wheel)],
                   check=True, env=env, cwd=tmp_path)

    work = tmp_path / "elsewhere"
    work.mkdir()
    where = subprocess.run([str(py), "-c", "import mdaug; print(mdaug.__file__)"], capture_output=True,
                           text=True, env=env, cwd=work, check=True).stdout.strip()
    assert Path(where).resolve().is_relative_to(venv.resolve()), where

    mdaug = str(venv / "bin" / "mdaug")
    top = subprocess.run([mdaug, "--help"], capture_output=True, text=True, env=env, cwd=work)
    assert top.returncode == 0, top.stderr
    assert "simulate" in top.stdout
    sim_help = subprocess.run([mdaug, "simulate", "--help"], capture_output=True, text=True, env=env, cwd=work)
    assert sim_help.returncode == 0, sim_help.stderr

    sim = subprocess.run([mdaug, "simulate", "--class", "HELI", "--reference-specimens", "--acquisitions", "2",
                          "--ramps", "2", "--seed", "1", "--out", "m.npz"],
                         capture_output=True, text=True, env=env, cwd=work)
    assert sim.returncode == 0, sim.stderr
    with np.load(work / "m.npz") as data:
        assert data["profiles"].shape[0] >= 2
        assert set(data["labels"].tolist()) == {"HELI"}


@pytest.mark.slow
def test_the_dependencies_pull_no_cuda_runtime(tmp_path):
    """``pip install .`` resolves no ``nvidia-*`` package (xgboost-cpu, not xgboost, which
    pulls nvidia-nccl-cu12; torch from the CPU wheel): a dry run of the wheel's
    dependencies with the machine's indexes, nothing installed."""
    import json

    src = _tracked_copy(tmp_path / "src")
    env = {k: v for k, v in _env().items() if k != "PIP_NO_INDEX"}
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(tmp_path / "wheels"), str(src)], check=True, env=env, cwd=tmp_path)
    (wheel,) = (tmp_path / "wheels").glob("mdaug-*.whl")
    report = tmp_path / "report.json"
    subprocess.run([sys.executable, "-m", "pip", "install", "--dry-run", "--ignore-installed", "-q", "--report",
                    str(report), str(wheel)], check=True, env=env, cwd=tmp_path, capture_output=True)
    names = {i["metadata"]["name"].lower() for i in json.loads(report.read_text())["install"]}
    assert "xgboost-cpu" in names and "xgboost" not in names
    assert not [n for n in names if n.startswith("nvidia")], sorted(names)


def test_every_source_folder_is_a_package_the_wheel_ships():
    """setup.py ships the folders that hold an __init__.py; a folder of modules without
    one would be left out of a non-editable install (an editable one still finds it)."""
    listed = subprocess.run(["git", "ls-files", "-z", "*.py"], cwd=ROOT, capture_output=True, check=True).stdout
    folders = {Path(n).parent for n in listed.decode().split("\0") if n}
    missing = sorted(str(f) for f in folders
                     if f != Path(".") and f.parts[0] != "tests" and not (ROOT / f / "__init__.py").is_file())
    assert not missing, f"folders of modules without __init__.py: {missing}"
