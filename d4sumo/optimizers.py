"""Optimisers with one ask/tell interface. They maximise a score over a box and know nothing else.

    opt = make_optimizer("bo", lower, upper, budget=100, rng=np.random.default_rng(seed))
    x = opt.ask(); opt.tell(x, score)

- ``random``: uniform samples in the box.
- ``halton``: a scrambled Halton sequence (low discrepancy), scaled to the box.
- ``ce``: cross-entropy: sample a batch from independent truncated normals, keep the elite quantile
  (ties included), refit mean and standard deviation with smoothing; a batch that is all one plateau
  leaves the distribution as it was.
- ``ce-bucket``: VerifAI's cross-entropy over buckets, the sampler the paper ran, for comparison.
- ``cmaes``: CMA-ES (pycma) with restarts and a growing population (IPOP).
- ``bo``: Bayesian optimisation: scikit-optimize's Gaussian process (Matern 5/2 with a length scale
  per dimension, learned noise) and expected improvement, maximised over random candidates and
  perturbations of the incumbent. Kernel hyperparameters are re-learned every ``refit_every`` samples
  and kept in between (the GP is still conditioned on every sample): this keeps BO's own time per
  sample below an episode's, where scikit-optimize's Optimizer spends ~2 s per tell. It proposes
  ``batch_size`` points at once (5; 1 is the paper's one point per score): the constant liar, each
  point proposed but not yet scored counts as the worst score seen, so their episodes can be played
  side by side (and the batch spreads out: it found more distinct attacks than one at a time).

``ready()`` says how many points an optimiser can propose before it is told a score, with exactly the
points it would propose one at a time: a cross-entropy generation, a CMA-ES population, any number of
random or Halton points, BO's initial design. The campaign plays them as one batch (`batch`).

Every optimiser draws from the Generator it is given: one seed reproduces a campaign exactly. Options
(``OPTIONS`` of each class) come from a config's ``[search.<optimizer>]`` table, validated by
`resolve_options`. A score that is NaN or infinite counts as the worst score told so far: one failed
sample never breaks later proposals. No optimiser proposes past its budget.
"""

from __future__ import annotations

import warnings
from typing import Callable

import numpy as np
from scipy.stats import qmc, truncnorm

from .errors import ConfigError, check_int, check_number

OPTIMIZERS = ("bo", "ce", "ce-bucket", "cmaes", "random", "halton")


class Optimizer:
    """Ask for a point in [lower, upper], tell its score (higher is better)."""

    name = ""
    #: option -> (default, low, high); an int default means a whole number
    OPTIONS: dict[str, tuple[float, float, float]] = {}

    def __init__(self, lower: np.ndarray, upper: np.ndarray, budget: int, rng: np.random.Generator, **options):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.dimension = self.lower.size
        self.budget = budget
        self.rng = rng
        self.options = resolve_options(self.name, options)
        self.asked = 0
        self.X: list[np.ndarray] = []
        self.y: list[float] = []

    @property
    def outstanding(self) -> int:
        """Points asked for whose scores have not been told yet."""
        return self.asked - len(self.y)

    def ready(self) -> int:
        """How many points may be asked for now, before any outstanding score is told, such that every
        one of them is what the optimiser would ask with all earlier scores told: a batch whose episodes
        can be played side by side without changing the campaign. At least 1 when nothing is
        outstanding; by default the optimiser is sequential."""
        return 0 if self.outstanding else 1

    def ask(self) -> np.ndarray:
        if self.asked >= self.budget:
            raise ValueError(f"{self.name}: the budget of {self.budget} samples is spent")
        self.asked += 1
        return self._ask()

    def _ask(self) -> np.ndarray:
        raise NotImplementedError

    def tell(self, x: np.ndarray, score: float) -> None:
        score = float(score)
        if not np.isfinite(score):
            finite = [v for v in self.y if np.isfinite(v)]
            score = min(finite) if finite else 0.0
        self.X.append(np.asarray(x, dtype=float))
        self.y.append(score)

    def _unit_to_box(self, z: np.ndarray) -> np.ndarray:
        return self.lower + z * (self.upper - self.lower)

    def _box_to_unit(self, x: np.ndarray) -> np.ndarray:
        span = np.where(self.upper > self.lower, self.upper - self.lower, 1.0)
        return (np.asarray(x) - self.lower) / span


#: points a sampler whose points depend on no score proposes at a time (a batch's worth: proposing the
#: whole budget at once would only carry it around)
INDEPENDENT_BATCH = 64


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


class CrossEntropy(Optimizer):
    """Cross-entropy method with independent truncated normals over the box.

    Each batch of ``batch_size`` samples is drawn from the current distribution; the best
    ``elite_fraction`` of the batch refit the mean and standard deviation, blended with the old
    ones by ``smoothing`` (1: take the elite's fit entirely).
    """

    name = "ce"
    OPTIONS = {"batch_size": (10, 2, 10_000), "elite_fraction": (0.2, 0.01, 1.0), "smoothing": (0.7, 0.01, 1.0),
               "min_std_fraction": (0.02, 0.0, 1.0)}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        self.batch_size = o["batch_size"]
        self.elite_count = max(1, int(round(o["elite_fraction"] * self.batch_size)))
        self.smoothing = o["smoothing"]
        span = self.upper - self.lower
        self.mean = self.lower + span / 2.0
        self.std = span / 2.0
        self.min_std = o["min_std_fraction"] * span
        self._pending: list[np.ndarray] = []
        self._batch: list[tuple[np.ndarray, float]] = []

    def ready(self) -> int:  # the rest of the current generation
        return self.batch_size - len(self._batch) - self.outstanding

    def _ask(self) -> np.ndarray:
        if not self._pending:
            self._pending = list(self._sample(self.batch_size))
        return self._pending.pop(0)

    def _sample(self, n: int) -> np.ndarray:
        a = (self.lower - self.mean) / self.std
        b = (self.upper - self.mean) / self.std
        z = truncnorm.rvs(a, b, size=(n, self.dimension), random_state=self.rng)
        return np.clip(self.mean + z * self.std, self.lower, self.upper)

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        self._batch.append((self.X[-1], self.y[-1]))
        if len(self._batch) >= self.batch_size:
            self._refit()

    def _refit(self) -> None:
        scores = np.array([s for _, s in self._batch])
        points = np.array([x for x, _ in self._batch])
        self._batch = []
        self._pending = []
        # The elite is every sample scoring at least the elite quantile: ties at the threshold all
        # count (which ones the batch happened to list first says nothing). On a plateau, where the
        # elite would be the whole batch, the batch carries no information: the distribution stays.
        threshold = np.sort(scores)[::-1][self.elite_count - 1]
        elite = points[scores >= threshold]
        if len(elite) == len(points):
            return
        a = self.smoothing
        self.mean = a * elite.mean(axis=0) + (1 - a) * self.mean
        self.std = np.maximum(a * elite.std(axis=0) + (1 - a) * self.std, self.min_std)


class BucketCrossEntropy(Optimizer):
    """VerifAI's cross-entropy sampler, the one the paper ran (VerifAI's ContinuousCrossEntropySampler).

    Each dimension of the box is cut into ``buckets`` equal buckets with a categorical distribution
    over them; a sample draws a bucket per dimension, then a point uniformly inside it. When a sample
    scores above ``threshold`` (0: a counterexample, in the paper's sign) its buckets gain weight:
    dist = alpha * dist + (1 - alpha) * one-hot. Nothing changes otherwise: this sampler learns from
    successes only, which is why it trails ``ce`` on the same budget.
    """

    name = "ce-bucket"
    OPTIONS = {"buckets": (10, 2, 1000), "alpha": (0.9, 0.0, 1.0), "threshold": (0.0, -1e9, 1e9)}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.buckets = self.options["buckets"]
        self.dist = np.full((self.dimension, self.buckets), 1.0 / self.buckets)
        self._buckets_of: list[np.ndarray] = []

    def _ask(self) -> np.ndarray:
        chosen = np.array([self.rng.choice(self.buckets, p=p / p.sum()) for p in self.dist])
        self._buckets_of.append(chosen)
        return self._unit_to_box((chosen + self.rng.random(self.dimension)) / self.buckets)

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        chosen = self._buckets_of.pop(0) if self._buckets_of else np.minimum(
            (self._box_to_unit(x) * self.buckets).astype(int), self.buckets - 1)
        if self.y[-1] > self.options["threshold"]:
            one_hot = np.zeros_like(self.dist)
            one_hot[np.arange(self.dimension), chosen] = 1.0
            self.dist = self.options["alpha"] * self.dist + (1.0 - self.options["alpha"]) * one_hot


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


class _Normals:
    """pycma's source of normal draws: the campaign's Generator (a class, not a lambda, so that the
    optimiser's state pickles: a sweep sends it between processes)."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def __call__(self, lam: int, n: int) -> np.ndarray:
        return self.rng.standard_normal((lam, n))


class BayesianOptimization(Optimizer):
    name = "bo"
    OPTIONS = {"initial_points": (10, 1, 10_000), "refit_every": (10, 1, 10_000), "candidates": (500, 10, 1_000_000),
               "local_fraction": (0.8, 0.0, 1.0), "local_scale": (0.1, 1e-4, 1.0), "xi": (0.01, 0.0, 10.0),
               "batch_size": (5, 1, 64)}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        self.initial_points = min(o["initial_points"], self.budget)
        self.refit_every = o["refit_every"]
        self.candidates = o["candidates"]
        self.local_fraction = o["local_fraction"]
        self.local_scale = o["local_scale"]
        self.xi = o["xi"]
        self.batch_size = o["batch_size"]
        self._initial = qmc.Halton(d=self.dimension, scramble=True, seed=self.rng)
        self._kernel = None  # the learned covariance (amplitude x Matern), without the noise term
        self._noise = 1.0  # the learned noise variance, in units of the normalised scores
        self._gp = None
        self._fitted = 0  # the scores the GP was fitted to
        self._pending: list[np.ndarray] = []  # asked, not told yet (unit box)

    def ready(self) -> int:
        if self.asked < self.initial_points:  # the initial design does not depend on scores
            return self.initial_points - self.asked
        return self.batch_size if not self.outstanding else 0

    def _ask(self) -> np.ndarray:
        if len(self.y) < self.initial_points:
            z = self._initial.random(1)[0]
        else:
            z = self._propose()
        self._pending.append(z)
        return self._unit_to_box(z)

    def _model(self):
        """The GP of every score told, fitted when first needed after new scores (once per batch)."""
        n = len(self.y)
        if self._gp is None or self._fitted != n:
            # re-learn the hyperparameters at the first fit and each time refit_every more were told
            relearn = self._kernel is None or ((n - self.initial_points) // self.refit_every
                                               > (self._fitted - self.initial_points) // self.refit_every)
            gp = self._fit(np.asarray(self.X_unit), np.asarray(self.y), relearn)
            self._kernel = gp.kernel_.k1
            self._noise = float(gp.noise_) if gp.noise_ is not None else self._noise
            self._gp, self._fitted = gp, n
        return self._gp

    def _propose(self) -> np.ndarray:
        from skopt.acquisition import gaussian_ei

        gp, scores = self._model(), np.asarray(self.y)
        if self._pending:  # a batch (constant liar): each point asked but not told scores the worst seen
            lies = np.full(len(self._pending), scores.min())
            gp = self._fit(np.vstack([self.X_unit, self._pending]), np.concatenate([scores, lies]), relearn=False)
        Z = np.asarray(self.X_unit)
        best = Z[int(np.argmax(self.y))]
        n_local = int(self.candidates * self.local_fraction)
        local = np.clip(best + self.rng.normal(0.0, self.local_scale, size=(n_local, self.dimension)), 0.0, 1.0)
        glob = self.rng.random((self.candidates - n_local, self.dimension))
        cand = np.vstack([local, glob])
        # skopt minimises: the GP models -score
        ei = gaussian_ei(cand, gp, y_opt=float(np.min(-scores)), xi=self.xi)
        return cand[int(np.argmax(ei))]

    @property
    def X_unit(self) -> list[np.ndarray]:
        return [self._box_to_unit(x) for x in self.X]

    def tell(self, x: np.ndarray, score: float) -> None:
        super().tell(x, score)
        if self._pending:
            self._pending.pop(0)  # told in the order asked

    def _fit(self, Z: np.ndarray, scores: np.ndarray, relearn: bool):
        """A GP of -score over the unit box; its hyperparameters re-learned, or the learned ones kept."""
        from skopt.learning import GaussianProcessRegressor
        from skopt.learning.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        kernel = self._kernel
        if kernel is None:
            kernel = ConstantKernel(1.0, (0.01, 1000.0)) * Matern(
                length_scale=np.ones(self.dimension), length_scale_bounds=(0.01, 100.0), nu=2.5
            )
        # The noise term is explicit, so that between re-learnings the GP keeps the learned noise
        # (skopt zeroes the white kernel in kernel_ after a fit, for noise-free predictions).
        noise = WhiteKernel(noise_level=float(np.clip(self._noise, 1e-5, 1e5)), noise_level_bounds=(1e-5, 1e5))
        gp = GaussianProcessRegressor(
            kernel=kernel + noise,
            normalize_y=True,
            noise="gaussian",
            n_restarts_optimizer=0,
            optimizer="fmin_l_bfgs_b" if relearn else None,
            random_state=int(self.rng.integers(2**31 - 1)) if relearn else 0,
        )
        with warnings.catch_warnings():  # hyperparameters at their bounds are expected early on
            warnings.simplefilter("ignore")
            gp.fit(Z, -scores)
        return gp


_FACTORIES: dict[str, Callable[..., Optimizer]] = {
    "bo": BayesianOptimization,
    "ce": CrossEntropy,
    "ce-bucket": BucketCrossEntropy,
    "cmaes": CMAES,
    "random": RandomSearch,
    "halton": Halton,
}


#: options added after campaigns were stored, each with the value those campaigns ran with: a campaign's
#: definition leaves such an option out at that value, and a stored definition without it gets it back,
#: so stored campaigns keep their identity and replay as they ran (bo proposed one point per score)
OPTIONS_SINCE: dict[str, dict[str, float]] = {"bo": {"batch_size": 1}}


def stored_options(name: str, options: dict) -> dict:
    """The options as a campaign's definition holds them (see OPTIONS_SINCE)."""
    since = OPTIONS_SINCE.get(name, {})
    return {k: v for k, v in options.items() if not (k in since and since[k] == v)}


def resolve_options(name: str, options: dict | None) -> dict:
    """Every option of optimiser ``name``, defaults filled in, each value checked."""
    if name not in _FACTORIES:
        raise ConfigError("search.optimizer", name, f"one of {', '.join(OPTIMIZERS)}")
    spec = _FACTORIES[name].OPTIONS
    options = dict(options or {})
    for key in options:
        if key not in spec:
            allowed = f"a key of [search.{name}]: {', '.join(spec)}" if spec else f"nothing: {name} has no options"
            raise ConfigError(f"search.{name}.{key}", options[key], allowed)
    resolved = {}
    for key, (default, low, high) in spec.items():
        value = options.get(key, default)
        field = f"search.{name}.{key}"
        resolved[key] = check_int(field, value, low, high) if isinstance(default, int) else check_number(field, value, low, high)
    return resolved


def make_optimizer(name: str, lower, upper, *, budget: int, rng: np.random.Generator, options: dict | None = None) -> Optimizer:
    if name not in _FACTORIES:
        raise ConfigError("optimizer", name, f"one of {', '.join(OPTIMIZERS)}")
    return _FACTORIES[name](np.asarray(lower, float), np.asarray(upper, float), budget, rng, **(options or {}))
