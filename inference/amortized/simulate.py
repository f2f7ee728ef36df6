"""Training examples: drones from the calibration prior, measured by the scene simulator.

An example is one drone (a truth drawn from the prior of :class:`.target.DroneSpace`)
and ``n_measurements`` acquisitions of it, each drawing every nuisance as a measured
acquisition draws it (phases, K-ramp averaging, yaw, body return, range, azimuth,
hover drift, clutter, noise, ADC, MTI): the scene simulator and the radar chain of
:class:`mdaug.generator.augment.Renderer`, then :func:`prepare_measured` (peak
normalisation, re-centring), exactly what a measured file goes through.

Simulations are written in shards (``shard-00000.npz``: ``vectors`` (n, 13E) float64
truths, ``profiles`` (n, M, L) float32, ``key`` JSON), each appearing only when
complete; a rerun with the same :class:`SimulationSpec` and seed keeps the shards it
finds (resume), and refuses a folder of another spec by name.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...generator import load_reference
from ...generator.acquisition import Acquisition
from ...radar import RadarConfig
from ...radar.io import atomic_savez
from ...radar.seeds import rng as seeded_rng
from ...radar.seeds import seed_sequence
from ...radar.version import package_version
from ..likelihood.base import prepare_measured
from ..space.priors import Priors
from .target import DroneSpace

SIMULATOR = "scene+chain-1"
"""Version of the simulator the examples come from (stored in every estimator)."""


@dataclass(frozen=True)
class SimulationSpec:
    """What one training set simulates: class, acquisition (K = ``acquisition.ramps``),
    measurements per drone, radar; the prior is the class reference's default."""

    class_name: str
    acquisition: Acquisition
    n_measurements: int = 10
    radar: RadarConfig = field(default_factory=RadarConfig)
    near_width: float = 0.0
    """0: drones from the calibration prior; > 0: drones of the specimen model around the
    class reference, its default spreads times ``near_width`` (where users' drones are;
    the summary likelihood trains on both)."""

    def __post_init__(self) -> None:
        if isinstance(self.n_measurements, bool) or not 1 <= int(self.n_measurements) <= 64:
            raise ValueError(f"n_measurements must be an integer in 1..64, got {self.n_measurements!r}")
        if not (isinstance(self.near_width, (int, float)) and np.isfinite(self.near_width) and self.near_width >= 0):
            raise ValueError(f"near_width must be a finite number >= 0, got {self.near_width!r}")

    @property
    def reference(self):
        return load_reference(self.class_name)

    def priors(self) -> Priors:
        return Priors.from_reference(self.reference, self.radar)

    def space(self) -> DroneSpace:
        return DroneSpace(self.reference.n_engines, self.priors())

    def to_dict(self) -> dict:
        d = {"class_name": self.class_name, "acquisition": self.acquisition.to_dict(),
             "n_measurements": int(self.n_measurements), "radar": self.radar.to_dict(), "simulator": SIMULATOR}
        if self.near_width:  # prior drones keep the key they always had
            d["near_width"] = float(self.near_width)
        return d

    def sample_vectors(self, n: int, rng) -> np.ndarray:
        """n drones' class vectors (n, 13E): from the prior, or near the reference (``near_width``)."""
        if self.near_width:
            from ...generator.specimens import SpecimenSpread

            ref = self.reference.to_array()
            return SpecimenSpread(width=float(self.near_width)).apply(np.repeat(ref[None], n, axis=0), rng)
        space = self.space()
        return space.vectors(space.sample_prior(n, rng))


def simulate(spec: SimulationSpec, n: int, seed, scene=None) -> tuple[np.ndarray, np.ndarray]:
    """n drones (:meth:`SimulationSpec.sample_vectors`) and their measurements: (vectors
    (n, 13E), profiles (n, M, L) float32 peak-normalised). Depends only on ``seed``."""
    truth_ss, data_ss = seed_sequence(seed).spawn(2)
    x = spec.sample_vectors(n, seeded_rng(truth_ss))
    return x, measure(x, spec.n_measurements, spec.acquisition, spec.radar, seeded_rng(data_ss), scene=scene)


def measure(x: np.ndarray, n_measurements: int, acquisition: Acquisition, radar: RadarConfig, rng,
            scene=None) -> np.ndarray:
    """Profiles (n, M, L) float32 of ``n_measurements`` acquisitions of each drone x (n, 13E):
    the scene simulator and the radar chain, then :func:`prepare_measured` (peak
    normalisation, re-centring), as a measured file goes through. rng: a Generator."""
    from ...generator.augment import Renderer

    x = np.atleast_2d(np.asarray(x, float))
    renderer = Renderer(acquisition, normalisation="none", radar=radar, through_chain=True, scene=scene)
    raw = renderer.render(np.repeat(x, n_measurements, axis=0), rng)
    y, _ = prepare_measured(raw, radar, "peak", what="simulated profiles")
    return y.astype(np.float32).reshape(len(x), n_measurements, -1)


def _shard_job(args) -> str:
    spec, n, ss, path, key = args
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        x, y = simulate(spec, n, ss)
    atomic_savez(path, vectors=x, profiles=y, key=np.array(key))
    return str(path)


def shard_key(spec: SimulationSpec, seed, shard_size: int) -> str:
    return json.dumps({"spec": spec.to_dict(), "seed": str(seed), "shard_size": int(shard_size)}, sort_keys=True)


def same_key(stored: str, key: str) -> bool:
    """Whether a stored shard key names the simulations of ``key``: compared as read
    today, so keys written under older field names (a radar's ``ramps_per_frame``, now
    ``max_ramps_per_frame``) still match."""
    if stored == key:
        return True
    try:
        d = json.loads(stored)
        return shard_key(spec_from_dict(d["spec"]), d["seed"], d["shard_size"]) == key
    except (ValueError, KeyError, TypeError):
        return False


def simulate_shards(folder, spec: SimulationSpec, n: int, *, seed=0, shard_size: int = 500, workers: int = 1,
                    time_budget: float | None = None, progress=None, log=None) -> list[Path]:
    """Simulate n drones into ``folder`` in shards of ``shard_size`` (module doc); the
    shards that exist with the same key are kept. workers: processes. time_budget:
    seconds after which no new shard starts (the shards done so far are returned; a
    rerun adds the rest). Returns the paths of the complete shards, in order."""
    import time
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    from ...radar.progress import progress_bar

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = shard_key(spec, seed, shard_size)
    stamp = folder / "simulation.json"
    if stamp.is_file():
        stored = json.loads(stamp.read_text())
        if not same_key(str(stored.get("key")), key):
            raise ValueError(f"{folder}: holds simulations of another spec or seed ({stamp.name} field 'key'); "
                             "use another folder")
    else:
        stamp.write_text(json.dumps({"key": key, "version": package_version()}))
    n_shards = -(-int(n) // int(shard_size))
    seeds = seed_sequence(seed).spawn(n_shards)
    paths = [folder / f"shard-{i:05d}.npz" for i in range(n_shards)]
    todo = []
    for i, p in enumerate(paths):
        size = min(shard_size, n - i * shard_size)
        if p.is_file():
            try:
                with np.load(p, allow_pickle=False) as f:
                    if same_key(str(f["key"]), key) and f["vectors"].shape[0] == size:
                        continue
            except (OSError, ValueError, KeyError, EOFError):
                pass
        todo.append((spec, size, seeds[i], p, key))
    if log and len(todo) < n_shards:
        log(f"simulations: {n_shards - len(todo)} of {n_shards} shards found in {folder}, reused")
    bar = progress_bar(total=n_shards, initial=n_shards - len(todo), desc=f"simulate {spec.class_name}",
                       unit="shard", progress=progress)
    t0 = time.perf_counter()
    over = lambda: time_budget is not None and time.perf_counter() - t0 > time_budget  # noqa: E731
    try:
        if workers > 1 and len(todo) > 1:
            with ProcessPoolExecutor(workers) as pool:
                queue, running = list(todo), set()
                while queue or running:
                    while queue and len(running) < workers and not over():
                        running.add(pool.submit(_shard_job, queue.pop(0)))
                    if not running:
                        break
                    done, running = wait(running, return_when=FIRST_COMPLETED)
                    for f in done:
                        f.result()
                        bar.update(1)
        else:
            for job in todo:
                if over():
                    break
                _shard_job(job)
                bar.update(1)
    finally:
        bar.close()
    complete = [p for p in paths if p.is_file()]
    if log and len(complete) < n_shards:
        log(f"simulations: time budget of {time_budget:g} s reached with {len(complete)} of {n_shards} shards")
    return complete


def load_shards(paths) -> tuple[np.ndarray, np.ndarray]:
    """(vectors (N, 13E), profiles (N, M, L) float32) of shard files, in order."""
    xs, ys = [], []
    for p in paths:
        with np.load(p, allow_pickle=False) as f:
            xs.append(f["vectors"])
            ys.append(f["profiles"])
    return np.concatenate(xs), np.concatenate(ys)


def spec_from_dict(d: dict) -> SimulationSpec:
    return SimulationSpec(d["class_name"], Acquisition.from_dict(d["acquisition"]), int(d["n_measurements"]),
                          RadarConfig.from_dict(d["radar"]), float(d.get("near_width", 0.0)))
