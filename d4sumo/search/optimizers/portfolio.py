"""``auto``: Bayesian optimisation and exploring arms as one portfolio over one model.

On a plateau (most inputs score alike) expected improvement has nothing to go on and BO narrows around
an incumbent that is one point of the plateau among many: ARCH-COMP's CC2 is such a case, where random
search falsifies where BO does not. ``auto`` keeps BO and arms that explore. Once exploring has started
(after BO's initial design, when its points stop improving: ``patience``, below), each point is explored
with probability ``random_share`` and proposed by BO's expected improvement
otherwise; every score is told to the one GP, whichever arm proposed it. The share moves to the arms
that improve the best score: each improvement credits its arm, and the share is the exploring arms'
credits over all (two credits to start, split as ``random_share`` says), kept within [``share_min``, ``share_max``] so that no arm
starves. Where BO's model informs, its points improve the best and take the budget; on a plateau, the
exploring points find the way off it.

The exploring arms read the parameters as a signal in time order (an attack's knots, a
pedal's values segment by segment) and propose held inputs, as falsification tools of the field do
(FalCAuN holds values from a small alphabet; extreme inputs falsify often):
- held sampling: each signal cut at random into 1 to ``0.4 n`` pieces (n its values; a scalar is a
  signal of one), each piece held at the lower bound, the upper bound or a uniform value, a third of the
  time each. (``per_signal = 0``, as 0.10 ran: the d parameters cut as one run into 1 to ``0.4 d``, a
  piece running from the throttle's last values into the brake's first.) On CC4 (80 seeds) cutting by
  signal took ``auto`` from 77 runs falsified to 80, in 433 simulations on average (421 before, over 77);
- piece moves on the incumbent: one of its pieces (a run of equal values) redrawn, cut from a random
  point to its end, or a random span set to one new value; or, a ``suffix`` share of them, a suffix
  move: the incumbent kept up to a random time and every signal after it redrawn as held pieces.
An exploring point is a piece move with probability the two arms' credits say; one that repeats a point
played or pending (a few parameters leave few held points) is replaced by a uniform one. On ARCH-COMP's chasing
cars, held inputs falsify CC1-CC3 one time in three or four, where uniform inputs do one time in 25 to
100, and the piece moves reach CC4, which no uniform search does.

A stall (no new best over the last ``stall`` scores, counted from the last new best, BO's points before
exploring starts included) marks the incumbent's neighbourhood as spent. In CC4's failed runs piece
moves crept up a dead end, a new best every 50 to 200 scores, while held sampling got a tenth of the
budget. Stalled, every exploring point is a fresh held one and the share is ``share_max``, whatever the
credits (``share_max = 0``: BO alone throughout); a new best ends the stall. Uniform exploration
(``version = 1``, 0.7's) knows no stalls, makes no piece moves and explores from the design on: its
``stall``, ``suffix`` and ``patience`` are 0. On CC4 (40 seeds) stalls took ``auto`` from 35 runs
falsified to 38.

Suffix moves search in time order, as time-causal falsifiers do (FalStar's adaptive tree search builds
an input segment by segment; Ernst et al. 2019): an input that falsifies often needs a good prefix, and
the incumbent's prefix is the best one known. The parameters' layout in time comes from the attack
family (``signals``, `Optimizer`): throttle and brake are two signals of 20 values on ARCH-COMP's chasing
cars, cut at the same time. On CC4 (40 seeds, exploring from the design on) they took ``auto`` from 38
runs falsified to 40, in 403 simulations on average instead of 475.

Exploring starts once the scores stop informing: until ``patience`` of BO's points in a row (after its
design) bring no new best, every point is BO's. Where BO's model informs, as on d4sumo's campaigns, it
finds the first attack on its own: exploring from the design on cost ``auto`` 0.8 distinct attacks a
campaign at the hard condition of `bench_falsify` (237 seeds), all of it in the fifth of the campaigns
whose design held no attack. On a plateau BO's points bring nothing and exploring starts a few points
after the design (``patience = 0``: at once, as 0.9 did). The arms compete from then on: BO earns no
credit for the improvements it made alone, which would hold the exploring share at its floor.

Exploring serves falsification, finding a first attack; a campaign then goes on to collect attacks
around the ones found, which BO does best (it finds the most distinct attacks on d4sumo's campaigns).
So once a score is positive (the attack specification satisfied, the benchmark falsified), every
point is BO's.

``version = 1`` is ``auto`` as d4sumo 0.7 ran it: uniform random exploration, whatever the scores;
``stall = 0`` as 0.8 ran it: piece moves whatever their progress; ``suffix = 0`` and ``patience = 0``
as 0.9 ran it.

The arms draw from a stream of their own (spawned, so the campaign's stream is not advanced): BO's
proposals are bo's own until an exploring point is played. Its GP is bo's, conditioned through
``inducing`` points past that many scores (`gp`).
"""

from __future__ import annotations

import numpy as np

from ...errors import ConfigError
from .bayes import BayesianOptimization
from .gp import LEARN_POINTS

BO, RANDOM, PIECE = 0, 1, 2  # RANDOM: held sampling (version 2) or uniform sampling (version 1)
PIECES_PER_DIMENSION = 0.4  # held sampling cuts d parameters into at most this many pieces per parameter
SAME = 1e-9  # values in the unit box this close are one value (a point's values come back from the box)


def _max_pieces(length: int) -> int:
    """The most pieces held sampling cuts ``length`` values into."""
    return max(1, int(round(PIECES_PER_DIMENSION * length)))


class Portfolio(BayesianOptimization):
    name = "auto"
    OPTIONS = {**BayesianOptimization.OPTIONS, "random_share": (0.5, 0.0, 1.0), "share_min": (0.2, 0.0, 1.0),
               "share_max": (0.8, 0.0, 1.0), "version": (2, 1, 2), "stall": (25, 0, 100_000),
               "suffix": (0.25, 0.0, 1.0), "patience": (5, 0, 100_000), "per_signal": (1, 0, 1),
               # the scores its GP's kernel is learned from: bo's since 0.8; 0.7's auto learned from 256
               "learn_points": (LEARN_POINTS, 16, 100_000)}

    @classmethod
    def resolve_together(cls, options: dict) -> dict:
        options = super().resolve_together(options)
        if not options["share_min"] <= options["random_share"] <= options["share_max"]:
            raise ConfigError("search.auto.random_share", options["random_share"],
                              f"a share within [share_min, share_max] = [{options['share_min']}, {options['share_max']}]")
        # version 1 is 0.7's auto: uniform exploration from the design on, no stalls, no piece moves (one
        # definition for one behaviour)
        return {**options, "stall": 0, "suffix": 0.0, "patience": 0, "per_signal": 0} if options["version"] == 1 else options

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        o = self.options
        self.held = o["version"] == 2
        # credits of (BO, exploring arms), two in all to start, split as random_share says; the exploring
        # share is split between held sampling and piece moves by their own credits
        explore = o["random_share"] * 2.0
        self.credits = np.array([2.0 - explore, explore / 2, explore / 2] if self.held else [2.0 - explore, explore, 0.0])
        self._arms: list[int] = []  # the arm of each point asked and not told yet, in the order asked
        self._arm_rng = self.rng.spawn(1)[0]
        self._max_pieces = _max_pieces(self.dimension)
        self._best, self._best_at = -np.inf, 0  # the best finite score, and how many scores there were then
        self._explores = self.options["patience"] == 0  # BO's points have gone ``patience`` without a new best

    @property
    def stalled(self) -> bool:
        """No new best over the last ``stall`` scores (0: never)."""
        stall = self.options["stall"]
        return stall > 0 and len(self.y) - self._best_at >= stall

    @property
    def random_share(self) -> float:
        """The probability that the next point after the initial design is an exploring arm's."""
        if (self.held and self.y and max(self.y) > 0.0) or not self._explores:
            return 0.0
        if self.stalled:
            return self.options["share_max"]
        share = self.credits[1:].sum() / self.credits.sum()
        return float(np.clip(share, self.options["share_min"], self.options["share_max"]))

    def _ask(self) -> np.ndarray:
        rng = self._arm_rng
        if len(self.y) - self._run < self.initial_points or rng.random() >= self.random_share:
            self._arms.append(BO)
            return super()._ask()
        if not self.held:
            arm, z = RANDOM, rng.random(self.dimension)
        else:
            if self.y and not self.stalled and rng.random() < self.credits[PIECE] / self.credits[1:].sum():
                arm, z = PIECE, self._piece_move(self._told[int(np.argmax(self.y))])
            else:
                arm, z = RANDOM, self._held()
            if any(self._pending_modelled):  # whether it repeats one depends on a model's points too
                self._modelled()
            if self._seen(z):  # a point already played or pending (a few parameters, few pieces): a uniform one
                z = rng.random(self.dimension)
        self._pending.append(z)
        self._pending_modelled.append(self.asked - 1 in self.modelled)
        self._arms.append(arm)
        return self._unit_to_box(z)

    def _value(self, other_than: float | None = None) -> float:
        """A piece's value in the unit box: a bound, or uniform; never ``other_than`` (a move changes)."""
        while True:
            kind = self._arm_rng.integers(3)
            value = 0.0 if kind == 0 else 1.0 if kind == 1 else float(self._arm_rng.random())
            if other_than is None or abs(value - other_than) > SAME:
                return value

    def _seen(self, z: np.ndarray) -> bool:
        played = np.array([*self._told, *self._pending])
        return bool(np.any(np.all(np.abs(played - z) <= SAME, axis=1)))

    def _held(self) -> np.ndarray:
        z = np.empty(self.dimension)
        if not self.options["per_signal"]:  # 0.10's: the parameters cut as one run, across signals
            self._hold(z, self._max_pieces)
            return z
        start = 0
        for n in self.signals:  # each signal cut on its own: a piece never runs from one into the next
            self._hold(z[start:start + n], _max_pieces(n))
            start += n
        return z

    def _hold(self, values: np.ndarray, max_pieces: int) -> None:
        """Fill ``values`` (a view) with 1 to ``max_pieces`` pieces, cut at random, each held at one value."""
        rng, d = self._arm_rng, len(values)
        pieces = int(rng.integers(1, max_pieces + 1))
        cuts = np.sort(rng.choice(np.arange(1, d), pieces - 1, replace=False)) if pieces > 1 else []
        for a, b in zip([0, *cuts], [*cuts, d]):
            values[a:b] = self._value()

    def _suffix_move(self, best: np.ndarray) -> np.ndarray:
        """The incumbent up to a random time, every signal after it redrawn as held pieces (a scalar, a
        signal of one value, when the time falls in its first half). It may redraw the incumbent itself:
        a repeat, replaced as any other."""
        z, longest = best.copy(), max(self.signals)
        cut = int(self._arm_rng.integers(1, longest))
        start = 0
        for n in self.signals:  # a signal of n values is cut at the same time: cut / longest of its length
            a = start + int(round(cut * n / longest))
            if a < start + n:
                self._hold(z[a:start + n], _max_pieces(start + n - a))
            start += n
        return z

    def _piece_move(self, best: np.ndarray) -> np.ndarray:
        rng, d, z = self._arm_rng, self.dimension, best.copy()
        if self.options["suffix"] > 0 and max(self.signals) > 1 and rng.random() < self.options["suffix"]:
            return self._suffix_move(best)
        starts = [0, *np.flatnonzero(np.abs(np.diff(z)) > SAME) + 1]  # pieces: runs of equal values
        move = rng.integers(3)
        if move == 2:  # a random span set to one new value
            a = int(rng.integers(d))
            z[a:int(rng.integers(a + 1, d + 1))] = self._value(other_than=z[a])
            return z
        i = int(rng.integers(len(starts)))
        a, b = starts[i], (starts[i + 1] if i + 1 < len(starts) else d)
        if move == 1:  # cut the piece: from a point in it to its end
            a = int(rng.integers(a, b))
        z[a:b] = self._value(other_than=z[a])
        return z

    def tell(self, x: np.ndarray, score: float) -> None:
        best = max(self.y) if self.y else -np.inf
        super().tell(x, score)
        arm = self._arms.pop(0)
        if self._explores and len(self.y) > self.initial_points and self.y[-1] > best:
            self.credits[arm] += 1.0  # the arms compete from when exploring starts: BO alone earns no credit
        if np.isfinite(score) and score > self._best:  # as told: NaN or inf (told as the worst seen, 0 if first) is none
            self._best, self._best_at = float(score), len(self.y)
        if not self._explores:  # every point after the design is BO's until then
            self._explores = len(self.y) - max(self._best_at, self.initial_points) >= self.options["patience"]
