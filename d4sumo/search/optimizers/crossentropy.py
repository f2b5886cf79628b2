"""Cross-entropy samplers: ours over truncated normals, and VerifAI's over buckets (the paper's)."""

from __future__ import annotations

import numpy as np
from scipy.stats import truncnorm

from .base import Optimizer


class CrossEntropy(Optimizer):
    """Cross-entropy method with independent truncated normals over the box.

    Each batch of ``batch_size`` samples is drawn from the current distribution; the best
    ``elite_fraction`` of the batch refit the mean and standard deviation, blended with the old
    ones by ``smoothing`` (1: take the elite's fit entirely). Each refit then widens every standard
    deviation in quadrature by ``noise_fraction`` of its range (the noisy cross-entropy method of
    Szita and Lorincz, 2006): on a plateau of nearly equal scores the elite of a small batch is two
    or three points chosen by noise, and without it the spread collapses within a few batches onto
    one of them (in 40 dimensions, below random search's rate of falsification).
    """

    name = "ce"
    OPTIONS = {"batch_size": (10, 2, 10_000), "elite_fraction": (0.2, 0.01, 1.0), "smoothing": (0.7, 0.01, 1.0),
               "min_std_fraction": (0.02, 0.0, 1.0), "noise_fraction": (0.1, 0.0, 1.0)}

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
        self.noise = o["noise_fraction"] * span
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
        if self.options["noise_fraction"] > 0.0:  # 0: campaigns stored before it replay exactly
            self.std = np.sqrt(self.std ** 2 + self.noise ** 2)


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
