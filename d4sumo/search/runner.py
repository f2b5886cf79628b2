"""Running campaigns: the runner owns the loop (ask, play side by side, score, store in order, tell), several
campaigns step together in shared SUMOs, and an interrupted campaign resumes where it stopped. The evaluator
that plays and scores a sample is `evaluator`'s."""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Callable, Sequence

import numpy as np

from ..engine.scenarios import MAX_COPIES
from ..model.stepping.batch import DEFAULT_BATCH
from .campaign import Campaign, CampaignSummary, SampleResult
from .evaluator import Evaluator, Job, play_together
from .optimizers import make_optimizer
from .optimizers.boundary import BoundarySearch
from .store import Store, StoreError

log = logging.getLogger(__name__)


def numerics_note(where: str, index: int) -> str:
    """What a resumed campaign says once when a stored point is not what this machine's model proposes."""
    return (f"{where}: resumed on a machine whose numerics differ from the one that began it (stored sample "
            f"{index} is not what this machine's model proposes there): the stored samples stand, and the samples "
            "this run plays follow this machine's proposals")


def _score(result: SampleResult, history: list[float]) -> float:
    """What the optimiser is told: the robustness, or for an errored sample the worst seen so far."""
    if result.robustness is not None and math.isfinite(result.robustness):
        return result.robustness
    return min(history) if history else -1.0


class CampaignRunner:
    """The ask-simulate-score-tell loop of one campaign, without storage.

    The optimiser is asked for as many points as it can propose before its next score
    (`Optimizer.ready`); they are played in batches of at most ``batch`` episodes side by side and
    told in order. Built from the samples stored so far, which are the truth: the optimiser is asked
    again and told each stored point and score in order (a point the seed alone decides must be the
    one asked; one a model proposed may differ where another machine's numerics began the campaign,
    `numerics_note`; a sample missing in between, if a database lacks one, is played again) or
    from the ``state`` a previous runner of the same campaign handed over; ``state`` is plain
    picklable data (the optimiser, the scores told, the points asked and not yet played, the stored
    samples not reached yet), so a
    campaign can move between processes or machines between steps and still end as if it had run
    in one piece, whatever the batch size.
    """

    def __init__(self, campaign: Campaign, evaluator: Evaluator, *, stored: Sequence[SampleResult] = (),
                 state: tuple | None = None, where: str = "the database", batch: int = DEFAULT_BATCH):
        if evaluator.campaign.definition() != campaign.definition():
            raise ValueError("the evaluator was built for another campaign")
        self.campaign = campaign
        self.evaluate = evaluator
        self.batch = max(1, min(int(batch), MAX_COPIES))
        self.where = where
        self.stored: dict[int, SampleResult] = {}
        for r in stored:
            if r.index in self.stored or not 0 <= r.index < campaign.samples:
                raise StoreError(f"{where}: campaign samples are not numbered 0, 1, 2, ... (sample {r.index} twice or out of range)")
            self.stored[r.index] = r
        if state is not None:
            self.optimizer, self.scores, self.queue, stored_later, self.numerics_differ_at = state
            self.stored.update(stored_later)
            return
        #: the first stored sample whose point this machine's model proposes otherwise (None: none)
        self.numerics_differ_at: int | None = None
        rng = np.random.default_rng(campaign.seed)
        family = evaluator.family
        share = campaign.boundary
        self.optimizer = make_optimizer(campaign.optimizer, family.lower, family.upper, rng=rng, signals=family.signals,
                                        budget=max(1, BoundarySearch.inner_budget(campaign.samples, share)) if share else campaign.samples,
                                        options=dict(campaign.optimizer_options))
        if share:  # a share of the samples locates the boundary; the optimiser proposes the rest as it would alone
            self.optimizer = BoundarySearch(self.optimizer, family.lower, family.upper, campaign.samples,
                                            np.random.default_rng((campaign.seed, 1)), situation=len(campaign.situation), share=share)
        self.scores: list[float] = []
        self.queue: list[np.ndarray] = []  # asked for, not played yet: samples done, done + 1, ..
        self._replay()

    @property
    def done(self) -> int:
        return len(self.scores)

    @property
    def state(self) -> tuple:
        """Everything to go on with: the optimiser, the scores told, the points asked and not played, the
        stored samples not reached yet (a database may have a gap before them), and the first stored
        sample this machine's model proposed otherwise."""
        return self.optimizer, self.scores, self.queue, dict(self.stored), self.numerics_differ_at

    def _fill(self) -> None:
        if not self.queue:
            count = min(self.optimizer.ready(), self.campaign.samples - self.optimizer.asked)
            self.queue = [self.optimizer.ask() for _ in range(max(count, 1))]

    def _replay(self) -> None:
        """Tell the optimiser the stored samples, in order, as far as they go without a gap."""
        while self.done < self.campaign.samples and self.done in self.stored:
            self._fill()
            x = self.queue.pop(0)
            r = self.stored.pop(self.done)
            self._check(x, r)
            self._tell(r)

    def _check(self, x: np.ndarray, r: SampleResult) -> None:
        """A stored sample stands where this machine asks for its point, or where a model asked for it
        (`Optimizer.modelled`: another machine's BLAS may have proposed another point there). A point the
        seed and the stored scores alone decide (a design, a sampler's draws, an exploring arm's), one
        outside the box or of another length, is another campaign's or was changed."""
        if len(r.params) == len(x) and np.allclose(x, r.params, rtol=0, atol=1e-12):
            return
        opt = self.optimizer
        params = np.asarray(r.params, dtype=float)
        slack = 1e-9 * np.maximum(1.0, np.maximum(np.abs(opt.lower), np.abs(opt.upper)))  # a bound's rounding
        inside = len(params) == len(x) and bool(np.all((params >= opt.lower - slack) & (params <= opt.upper + slack)))
        if not inside or r.index not in opt.modelled:
            what = ("a point this seed draws alike on every machine" if inside
                    else "not a point of this campaign's box")
            raise StoreError(f"{self.where}: stored sample {r.index} is not what this seed asks for ({what}); "
                             "the database holds another campaign or was changed: use a new database")
        if self.numerics_differ_at is None:
            self.numerics_differ_at = r.index

    def numerics_note(self) -> str | None:
        """One line for a resumed campaign whose stored points another machine's numerics proposed."""
        if self.numerics_differ_at is None:
            return None
        return numerics_note(self.where, self.numerics_differ_at)

    def _tell(self, r: SampleResult) -> None:
        """Tell the optimiser a sample as it is stored (or played): its point and score."""
        score = _score(r, self.scores)
        self.optimizer.tell(np.asarray(r.params, dtype=float), score)
        self.scores.append(score)

    def pending(self) -> list[tuple[int, list[np.ndarray]]]:
        """The next batch of asked points that still has to be played: runs of consecutive samples
        (first index, points); samples stored already are not played again."""
        if self.done >= self.campaign.samples:
            raise ValueError(f"the campaign's budget of {self.campaign.samples} samples is spent")
        self._fill()
        first, xs = self.done, self.queue[:self.batch]
        for i, x in enumerate(xs):  # a batch interrupted before: only its missing samples play
            if first + i in self.stored:
                self._check(x, self.stored[first + i])
        missing = [i for i in range(len(xs)) if first + i not in self.stored]
        return [(first + run[0], [xs[i] for i in run]) for run in _runs(missing)]

    def accept(self, played: dict[int, SampleResult]) -> list[SampleResult]:
        """Tell the optimiser the batch `pending` gave, now played (index -> result); the new samples'
        results in order."""
        first, xs = self.done, self.queue[:self.batch]
        results = []
        for i, x in enumerate(xs):
            r = self.stored.pop(first + i, None) or played[first + i]
            self._tell(r)
            if first + i in played:
                results.append(r)
        del self.queue[:len(xs)]
        self._replay()
        return results

    def step(self, on_result: Callable[[SampleResult], None] | None = None) -> list[SampleResult]:
        """Play the next batch of asked points (samples stored already are not played again), tell the
        optimiser; the new samples' results in order. ``on_result`` hears of each as it finishes."""
        played: dict[int, SampleResult] = {}
        for first, xs in self.pending():  # consecutive missing samples play as one batch
            for r in self.evaluate.batch(first, xs, on_result):
                played[r.index] = r
        return self.accept(played)


def step_together(runners: Sequence[CampaignRunner], batch: int = DEFAULT_BATCH,
                  on_result: Callable[[CampaignRunner, SampleResult], None] | None = None) -> list[list[SampleResult]]:
    """One step of several campaigns at once: each runner's next batch, played side by side in as few
    SUMO instances as hold them (`play_pending`). The same samples as stepping each runner alone.
    ``on_result(runner, result)`` hears of each sample as its episode ends."""
    jobs, owner = [], []
    for runner in runners:
        for first, xs in runner.pending():
            jobs.append((runner.evaluate, first, xs))
            owner.append(runner)
    heard = (lambda j, r: on_result(owner[j], r)) if on_result else None
    played = play_pending(jobs, batch, heard)
    by_runner: dict[int, dict[int, SampleResult]] = {id(r): {} for r in runners}
    for runner, results in zip(owner, played):
        by_runner[id(runner)].update((r.index, r) for r in results)
    return [runner.accept(by_runner[id(runner)]) for runner in runners]


def play_pending(jobs: Sequence[Job], batch: int = DEFAULT_BATCH,
                 on_result: Callable[[int, SampleResult], None] | None = None) -> list[list[SampleResult]]:
    """Play runs of consecutive samples of several campaigns (each job: its evaluator, first index and
    points, as `CampaignRunner.pending` gives them) side by side in as few SUMO instances as hold them (at
    most ``batch`` episodes each); campaigns whose configurations do not share a `batch.batch_key` and
    road play apart. Each job's results in order, each the one its evaluator gives alone.
    ``on_result(job, result)`` hears of each sample as its episode ends."""
    cap = max(1, min(int(batch), MAX_COPIES))
    groups: dict[tuple, list[tuple[int, int, Sequence[np.ndarray]]]] = {}
    for j, (evaluator, first, xs) in enumerate(jobs):
        groups.setdefault((evaluator.batch_key, evaluator.network), []).append((j, first, xs))
    played: list[list[SampleResult]] = [[] for _ in jobs]
    for members in groups.values():
        loads: list[list[tuple[int, int, Sequence[np.ndarray]]]] = [[]]
        for j, first, xs in members:  # fill one SUMO after the other, each with at most `cap` episodes
            for at in range(0, len(xs), cap):
                part = xs[at:at + cap]
                if sum(len(p) for _, _, p in loads[-1]) + len(part) > cap:
                    loads.append([])
                loads[-1].append((j, first + at, part))
        for load in loads:
            heard = (lambda k, r, load=load: on_result(load[k][0], r)) if on_result else None
            for (j, _, _), results in zip(load, play_together([(jobs[j][0], first, xs) for j, first, xs in load], heard)):
                played[j] += results
    return played


def _runs(indices: list[int]) -> list[list[int]]:
    """Consecutive runs of sorted indices: [0, 1, 3] -> [[0, 1], [3]]."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and runs[-1][-1] == i - 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def stored_results(store: Store, campaign_id: int, limit: int) -> list[SampleResult]:
    return [SampleResult(row.index, row.params, row.robustness, row.outcome, row.collision, row.min_gaps, row.wall_s,
                         row.error, row.id) for row in store.samples(campaign_id) if row.index < limit]


def run_campaign(
    campaign: Campaign,
    store: Store | None = None,
    *,
    sweep: str | None = None,
    evaluator: Evaluator | None = None,
    on_sample: Callable[[SampleResult], None] | None = None,
    batch: int = DEFAULT_BATCH,
) -> CampaignSummary:
    """Run (or resume) a campaign; every sample is in ``store`` as soon as it and those before it have
    finished. ``batch``: at most this many episodes side by side in one SUMO (1: one at a time); the
    results are the same.

    Pass an ``evaluator`` built beforehand to have every input checked before anything is written."""
    evaluate = evaluator or Evaluator(campaign)
    # read and check what is stored (and that the evaluator is this campaign's) before writing anything
    campaign_id = store.find_campaign(campaign.definition()) if store else None
    results = stored_results(store, campaign_id, campaign.samples) if campaign_id is not None else []
    runner = CampaignRunner(campaign, evaluate, stored=results, where=f"{store.path if store else ''}: campaign {campaign_id}",
                            batch=batch)
    if store is not None:
        campaign_id = store.open_campaign(campaign.definition(), campaign.samples, sweep)
    if results:
        log.info("campaign %s: resumed after %d stored samples", campaign_id, len(results))
    said = [False]

    def say_numerics() -> None:  # once, when found: at the start, or past a gap in the stored samples
        if runner.numerics_note() and not said[0] and runner.done < campaign.samples:
            said[0] = True
            log.warning("%s", runner.numerics_note())

    say_numerics()
    if on_sample:
        for r in results:
            on_sample(r)

    # A sample is stored as soon as its episode and those before it have ended: row ids then follow the
    # samples' order whatever the batch size, and a kill loses only episodes still waiting in a batch.
    done = {r.index for r in results}
    waiting: dict[int, SampleResult] = {}
    following = [0]  # the next index to store

    def finished(r: SampleResult) -> None:
        waiting[r.index] = r
        while following[0] in waiting or following[0] in done:
            r = waiting.pop(following[0], None)
            following[0] += 1
            if r is None:
                continue
            if store is not None:
                r = dataclasses.replace(r, id=store.add_sample(campaign_id, r.index, r.params, r.robustness, r.outcome,
                                                               r.collision, r.min_gaps, r.wall_s, r.error))
            results.append(r)
            if on_sample:
                on_sample(r)

    while runner.done < campaign.samples:
        runner.step(finished)
        say_numerics()
    results.sort(key=lambda r: r.index)
    return CampaignSummary(campaign_id, results)
