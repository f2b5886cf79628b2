"""Locating the boundary between safe and unsafe situations: a share of a campaign's samples spent where it is least
known whether an attack succeeds, rather than on the worst attack (``[search] boundary``).

A campaign that searches its situation (`search.situation`) runs its optimiser on the whole box; with a share s,
sample i is instead spent locating the boundary where floor((i + 1) s) > floor(i s) (a fixed, even interleaving:
s = 0.25 spends every fourth). Such a sample pairs a uniformly random attack with a situation chosen by the
straddle rule (Bryan et al., "Active learning for identifying function threshold boundaries", NIPS 2005): among
random candidates of the situation's box, the one of greatest 1.96 sd - |p - 1/2|, where p is the estimated
success rate of a random attack there and sd its uncertainty, from the earlier such samples as
`results.failure_map` estimates it (a Gaussian kernel a tenth of each range wide, a Beta with a uniform prior).
The rate is that of random attacks, so its half-way line is the situation's own boundary, not the optimiser's.

They come in blocks of `BLOCK` (one batch of episodes side by side): each block's situations are chosen together,
each chosen point then counted among the samples as the estimate expects it (a kriging believer), so how many
episodes share a SUMO changes no proposal. The first block, with nothing known, is uniform. The optimiser is told
only its own samples, and proposes exactly what it would with the rest of the budget alone.
"""

from __future__ import annotations

import numpy as np

from ..situation import kernel_estimate, locating
from .base import Optimizer

#: locating samples proposed together
BLOCK = 8
#: candidate situations the straddle rule scores for each choice
CANDIDATES = 1024


def straddle(points: np.ndarray, successes: np.ndarray, candidates: np.ndarray) -> tuple[int, float]:
    """The candidate (unit-cube rows) the straddle rule chooses, the greatest 1.96 sd - |p - 1/2| of
    `kernel_estimate`, and its estimated rate p."""
    rate, sd, _ = kernel_estimate(points, successes, candidates)
    best = int(np.argmax(1.96 * sd - np.abs(rate - 0.5)))
    return best, float(rate[best])


class BoundarySearch(Optimizer):
    """``inner`` (the campaign's optimiser, built for the samples it is left) on the whole box; a ``share`` of the
    samples (`locating`) a random attack in a situation chosen by the straddle rule. The situation is the last
    ``situation`` parameters of the box."""

    name = "boundary"

    def __init__(self, inner: Optimizer, lower, upper, budget: int, rng: np.random.Generator, *, situation: int, share: float):
        super().__init__(lower, upper, budget, rng)
        if not 0 < situation <= self.dimension or not 0.0 < share <= 1.0:
            raise ValueError(f"situation {situation} of {self.dimension} parameters, share {share}")
        self.inner, self.share, self.situation = inner, share, situation
        #: each locating sample's place among them (its block: place // BLOCK)
        self._place = {i: j for j, i in enumerate(i for i in range(budget) if locating(i, share))}
        self._chosen: dict[int, np.ndarray] = {}  # locating index -> its point, of the blocks chosen
        self._blocks: set[int] = set()  # the blocks chosen
        self._told: list[tuple[np.ndarray, bool]] = []  # the locating samples told: situation (unit cube), success
        self._outstanding_locating: set[int] = set()

    @staticmethod
    def inner_budget(budget: int, share: float) -> int:
        """The samples the campaign's optimiser is left."""
        return sum(not locating(i, share) for i in range(budget))

    def ready(self) -> int:
        """The points that may be asked now: the optimiser's while it is ready, locating ones while their block is
        chosen or may be (every earlier locating sample told)."""
        count, inner_ready, index = 0, None, self.asked
        pending = bool(self._outstanding_locating)  # a locating sample not told before the next block
        opened: set[int] = set()
        while index < self.budget:
            if index in self._place:
                block = self._place[index] // BLOCK
                if block not in self._blocks and block not in opened:
                    if pending:
                        break
                    opened.add(block)
                pending = True
            else:
                if inner_ready is None:
                    inner_ready = self.inner.ready()
                if inner_ready == 0:
                    break
                inner_ready -= 1
            count += 1
            index += 1
        return count

    def _ask(self) -> np.ndarray:
        index = self.asked - 1
        if index not in self._place:
            x = self.inner.ask()
            if self.inner.asked - 1 in self.inner.modelled:
                self._modelled()
            return x
        block = self._place[index] // BLOCK
        if block not in self._blocks:
            self._choose(block)
        if block:  # chosen by the estimate: its last bits are this machine's
            self._modelled()
        self._outstanding_locating.add(index)
        return self._chosen.pop(index)

    def _choose(self, block: int) -> None:
        """The block's points: each a uniformly random attack, in the situation the straddle rule chooses."""
        self._blocks.add(block)
        members = [i for i, j in self._place.items() if j // BLOCK == block]
        k, d = self.situation, self.dimension
        points = [p for p, _ in self._told]
        successes = [float(s) for _, s in self._told]
        for member in members:
            attack = self.rng.random(d - k)
            candidates = self.rng.random((CANDIDATES, k))
            if points:
                best, rate = straddle(np.array(points), np.array(successes), candidates)
                chosen = candidates[best]
                points.append(chosen)  # believed at the estimate's own rate, so that the next is chosen elsewhere
                successes.append(rate)
            else:
                chosen = candidates[0]
            self._chosen[member] = self._unit_to_box(np.concatenate([attack, chosen]))

    def tell(self, x: np.ndarray, score: float) -> None:
        index = len(self.y)
        super().tell(x, score)
        if index in self._place:
            self._outstanding_locating.discard(index)
            situation = self._box_to_unit(np.asarray(x, dtype=float))[-self.situation:]
            self._told.append((situation, bool(self.y[-1] > 0.0)))
        else:
            self.inner.tell(x, score)

