"""``auto``: Bayesian optimisation and uniform random sampling as one portfolio over one model.

On a plateau (most inputs score alike) expected improvement has nothing to go on and BO narrows around
an incumbent that is one point of the plateau among many: ARCH-COMP's CC2 is such a case, where random
search falsifies where BO does not. ``auto`` keeps both arms. After BO's initial design, each point is
drawn uniformly in the box with probability ``random_share`` and proposed by BO's expected improvement
otherwise; every score is told to the one GP, whichever arm proposed it. The share moves to the arm
that improves the best score: each improvement credits its arm, and the share is the random arm's
credits over all (each arm starts with one), kept within [``share_min``, ``share_max``] so that neither
arm starves. Where BO's model informs, its points improve the best and take the budget; on a plateau,
random points find the way off it.

The arms draw from a stream of their own (spawned, so the campaign's stream is not advanced): BO's
proposals are bo's own until a random point is played. Its GP is bo's, conditioned through
``inducing`` points past that many scores (`gp`).
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError
from .bayes import BayesianOptimization

BO, RANDOM = 0, 1


class Portfolio(BayesianOptimization):
    name = "auto"
    OPTIONS = {**BayesianOptimization.OPTIONS, "random_share": (0.5, 0.0, 1.0), "share_min": (0.2, 0.0, 1.0),
               "share_max": (0.8, 0.0, 1.0)}

    @staticmethod
    def check_together(options: dict) -> None:
        if not options["share_min"] <= options["random_share"] <= options["share_max"]:
            raise ConfigError("search.auto.random_share", options["random_share"],
                              f"a share within [share_min, share_max] = [{options['share_min']}, {options['share_max']}]")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        #: credits of (BO, random), two in all to start, split as random_share says
        self.credits = np.array([1.0 - o["random_share"], o["random_share"]]) * 2.0
        self._arms: list[int] = []  # the arm of each point asked and not told yet, in the order asked
        self._arm_rng = self.rng.spawn(1)[0]

    @property
    def random_share(self) -> float:
        """The probability that the next point after the initial design is drawn uniformly."""
        share = self.credits[RANDOM] / self.credits.sum()
        return float(np.clip(share, self.options["share_min"], self.options["share_max"]))

    def _ask(self) -> np.ndarray:
        if len(self.y) - self._run < self.initial_points or self._arm_rng.random() >= self.random_share:
            self._arms.append(BO)
            return super()._ask()
        z = self._arm_rng.random(self.dimension)
        self._pending.append(z)
        self._arms.append(RANDOM)
        return self._unit_to_box(z)

    def tell(self, x: np.ndarray, score: float) -> None:
        best = max(self.y) if self.y else -np.inf
        super().tell(x, score)
        arm = self._arms.pop(0)
        if len(self.y) > self.initial_points and self.y[-1] > best:
            self.credits[arm] += 1.0
