"""Samplers whose points depend on no score: uniform random search and a scrambled Halton sequence."""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from .base import INDEPENDENT_BATCH, Optimizer


class RandomSearch(Optimizer):
    name = "random"

    def ready(self) -> int:  # no point depends on a score
        return min(self.budget - self.asked, INDEPENDENT_BATCH)

    def _ask(self) -> np.ndarray:
        return self._unit_to_box(self.rng.random(self.dimension))


class Halton(Optimizer):
    name = "halton"

    def ready(self) -> int:  # no point depends on a score
        return min(self.budget - self.asked, INDEPENDENT_BATCH)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._sequence = qmc.Halton(d=self.dimension, scramble=True, seed=self.rng)

    def _ask(self) -> np.ndarray:
        return self._unit_to_box(self._sequence.random(1)[0])
