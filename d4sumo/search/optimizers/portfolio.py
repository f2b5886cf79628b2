"""``auto``: Bayesian optimisation and uniform random sampling as one portfolio over one model.

On a plateau (most inputs score alike) expected improvement has nothing to go on and BO narrows around
an incumbent that is one point of the plateau among many: ARCH-COMP's CC2 is such a case, where random
search falsifies where BO does not. ``auto`` keeps both: after BO's initial design, each point it proposes
is drawn uniformly in the box with probability ``random_share``, and by BO's expected improvement
otherwise. Every score is told to the one GP, whichever arm proposed it. The share then moves to the arm
that improves the best score: each improvement credits its arm, and the share is the random arm's
credits over all (each arm starts with one), kept within [``share_min``, ``share_max``] so that
neither arm starves. Where BO's model informs, its points improve the best and take the budget; on a
plateau random points find the way off it, and take the budget.
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError
from .bayes import BayesianOptimization
from .gp import GaussianProcess


class Portfolio(BayesianOptimization):
    name = "auto"
    OPTIONS = {**BayesianOptimization.OPTIONS, "random_share": (0.5, 0.0, 1.0), "share_min": (0.2, 0.0, 1.0),
               "share_max": (0.8, 0.0, 1.0), "inducing": (256, 0, 100_000), "learn_points": (256, 16, 100_000)}

    @staticmethod
    def check_together(options: dict) -> None:
        if not options["share_min"] <= options["random_share"] <= options["share_max"]:
            raise ConfigError("search.auto.random_share", options["random_share"],
                              f"a share within [share_min, share_max] = [{options['share_min']}, {options['share_max']}]")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        # thousands of scores: conditioned through inducing points, learned from a subset (`gp`)
        self._process = GaussianProcess(self.dimension, inducing=o["inducing"], learn_points=o["learn_points"])
        #: credits of (BO, random): one each to start, so that the share starts where random_share says
        self._credits = np.array([1.0 - o["random_share"], o["random_share"]]) * 2.0
        self._arms: list[int] = []  # the arm of each point asked and not told yet, in the order asked (0 BO, 1 random)

    @property
    def random_share(self) -> float:
        """The probability that the next point after the initial design is drawn uniformly."""
        share = self._credits[1] / self._credits.sum()
        return float(np.clip(share, self.options["share_min"], self.options["share_max"]))

    def _ask(self) -> np.ndarray:
        if len(self.y) - self._run < self.initial_points:
            self._arms.append(0)
            return super()._ask()
        if self.rng.random() < self.random_share:
            z = self.rng.random(self.dimension)
            self._pending.append(z)
            self._arms.append(1)
            return self._unit_to_box(z)
        self._arms.append(0)
        return super()._ask()

    def tell(self, x: np.ndarray, score: float) -> None:
        best = max(self.y) if self.y else -np.inf
        super().tell(x, score)
        arm = self._arms.pop(0)
        if len(self.y) > self.initial_points and self.y[-1] > best:
            self._credits[arm] += 1.0
