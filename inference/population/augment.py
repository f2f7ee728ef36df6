"""Population augmentation: new drones of the class, drawn from its calibrated population.

Each vector is a new drone (:meth:`.result.PopulationResult.draw_drones`:
spreads and the mean drone from the hyper-posterior, then the specimen model). The
strategy registry (:mod:`mdaug.strategies`, row ``population``) renders them under the
drones' acquisition (:meth:`PopulationResult.measured_acquisition`). No width to tune:
the spreads are the population's, measured from several drones or, from one, the
stated prior.
"""
from __future__ import annotations

import numpy as np

from ...generator.augment import VectorSource
from .result import PopulationResult


def load_population(population, label: str | None = None) -> PopulationResult:
    """A PopulationResult from a result or an NPZ path (checked against ``label``)."""
    if isinstance(population, PopulationResult):
        if label is not None and population.class_name != label.upper():
            raise ValueError(f"population of class {population.class_name!r}, expected {label.upper()!r}")
        return population
    return PopulationResult.load(population, class_name=label)


class PopulationSource(VectorSource):
    """New drones' class vectors from a population (module doc)."""

    def __init__(self, population, *, label: str | None = None):
        self.file = None if isinstance(population, PopulationResult) else str(population)
        self.population = load_population(population, label)
        self.label = self.population.class_name
        self.n_engines = self.population.n_engines

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.population.draw_drones(n, rng)

    def settings(self) -> dict:
        p = self.population
        return {"source": "population", "population_file": self.file, "class_name": p.class_name,
                "n_drones": p.n_drones, "specimens": p.meta["specimens"], "spreads_assumed": p.assumed,
                "hyper_converged": p.converged, "spreads": p.summary()}
