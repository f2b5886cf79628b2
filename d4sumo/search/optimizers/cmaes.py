"""CMA-ES with restarts (IPOP), on pycma."""

from __future__ import annotations

import warnings

import numpy as np

from .base import Optimizer


class CMAES(Optimizer):
    """CMA-ES (pycma) in the unit box, restarted with a doubled population when it converges or stalls
    (IPOP-CMA-ES, as in falsification competitions). It draws its normals from the campaign's Generator,
    never from numpy's global state. ``popsize`` 0 is pycma's default, 4 + 3 ln(dimension)."""

    name = "cmaes"
    OPTIONS = {"popsize": (0, 0, 10_000), "sigma0": (0.3, 1e-3, 1.0), "restart_factor": (2.0, 1.0, 10.0)}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._popsize = self.options["popsize"] or 4 + int(3 * np.log(self.dimension))
        self._pending: list[np.ndarray] = []
        self._population: list[np.ndarray] = []
        self._scores: list[float] = []
        self.restarts = 0
        self._es = self._start(np.full(self.dimension, 0.5))

    def _start(self, x0: np.ndarray):
        import cma

        options = {"bounds": [0.0, 1.0], "popsize": self._popsize, "seed": np.nan, "verbose": -9,
                   "randn": _Normals(self.rng)}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return cma.CMAEvolutionStrategy(list(x0), self.options["sigma0"], options)

    def ready(self) -> int:  # the rest of the current population
        population = len(self._population) if self._population else self._popsize
        return population - len(self._scores) - self.outstanding

    def _ask(self) -> np.ndarray:
        self._modelled()  # pycma samples through an eigendecomposition (LAPACK), its first population too
        if not self._pending:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._population = [np.clip(np.asarray(z, float), 0.0, 1.0) for z in self._es.ask()]
            self._pending = list(self._population)
            self._scores = []
        return self._unit_to_box(self._pending.pop(0))

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        self._scores.append(self.y[-1])
        i = len(self._scores) - 1  # told in the order asked: a point told other than asked (a stored one) stands
        if not np.array_equal(self.X[-1], self._unit_to_box(self._population[i])):
            self._population[i] = np.clip(self._box_to_unit(self.X[-1]), 0.0, 1.0)
        if len(self._scores) < len(self._population):
            return
        with warnings.catch_warnings():  # flat fitness is reported as a warning; CMA widens by itself
            warnings.simplefilter("ignore")
            self._es.tell(self._population, [-v for v in self._scores])  # pycma minimises
        if self._es.stop():
            self.restarts += 1
            self._popsize = int(round(self._popsize * self.options["restart_factor"]))
            self._es = self._start(self.rng.random(self.dimension))
        self._pending, self._population, self._scores = [], [], []

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        _rekey(self._es)


def _rekey(es) -> None:
    """pycma finds the points it handed out by ``hash(x.tobytes())``, and Python salts that hash anew in
    every process: an optimiser carried to another process mid-generation (a sweep's next chunk on
    another worker) found none of them, and its next generation changed. Each of its solution archives
    is keyed again here, from the points they keep."""
    from cma.utilities.utils import SolutionDict

    archives = [v for v in vars(es).values() if isinstance(v, SolutionDict)]
    archives += [v for owner in vars(es).values() if hasattr(owner, "__dict__") and not isinstance(owner, SolutionDict)
                 for v in vars(owner).values() if isinstance(v, SolutionDict)]
    for archive in archives:
        new_key = {old: archive.key(x) for old, x in archive._unhashed_keys.items()}
        archive.data = {new_key.get(k, k): v for k, v in archive.data.items()}
        archive.data_with_same_key = {new_key.get(k, k): v for k, v in archive.data_with_same_key.items()}
        archive._unhashed_keys = {new_key[k]: x for k, x in archive._unhashed_keys.items()}


class _Normals:
    """pycma's source of normal draws: the campaign's Generator (a class, not a lambda, so that the
    optimiser's state pickles: a sweep sends it between processes)."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def __call__(self, lam: int, n: int) -> np.ndarray:
        return self.rng.standard_normal((lam, n))
