"""A sweep's tasks: chunks of up to GANG_SIZE campaigns that a worker steps together, their episodes
sharing SUMO instances, and the client's bookkeeping of them (which campaigns go together, what to
send again after a failure)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..engine.scenarios import NetworkSource
from ..errors import D4sumoError
from ..model.stepping.batch import DEFAULT_BATCH, batch_key
from ..model.controllers.fmu import receive
from ..search.campaign import Campaign, SampleResult
from ..search.evaluator import campaign_road
from ..search.runner import CampaignRunner, Evaluator, play_pending, step_together
from ..search.store import campaign_key

log = logging.getLogger(__name__)


CHUNK_SAMPLES = 10  # a task returns once each of its campaigns has this many samples (a batch is played whole) ...


CHUNK_WALL_S = 2.0  # ... or after this long, so results reach the client often


MAX_TASK_FAILURES = 3  # a chunk that fails this often (a bug, not a lost worker) stops the sweep


#: a task steps up to this many campaigns together, their episodes side by side in one SUMO: a
#: campaign that proposes one point per score (the paper's BO) then still plays in batches
GANG_SIZE = 32


@dataclass(frozen=True)
class Chunk:
    """A task's share of one campaign: continue ``campaign`` from ``state`` (None: from the ``stored``
    samples) for a chunk."""

    campaign: Campaign
    network: NetworkSource
    stored: tuple[SampleResult, ...]
    state: tuple | None
    batch: int = DEFAULT_BATCH  # episodes side by side in one SUMO, at most
    fmus: tuple[tuple[str, bytes], ...] = ()  # its followers' FMUs, by value, for workers that cannot see the client's disk


_EVALUATORS: dict[str, Evaluator] = {}  # per worker process: roads built and formulas parsed once


def _evaluator(chunk: Chunk | Play) -> Evaluator:
    receive(chunk.fmus)
    key = campaign_key(chunk.campaign.definition())
    evaluator = _EVALUATORS.get(key)
    if evaluator is None:
        if len(_EVALUATORS) >= 8 * GANG_SIZE:
            _EVALUATORS.clear()
        evaluator = _EVALUATORS[key] = Evaluator(chunk.campaign, road=campaign_road(chunk.network, chunk.campaign.config),
                                                           network=chunk.network)
    return evaluator


def run_chunks(chunks: tuple[Chunk, ...]) -> list[tuple[list[SampleResult], tuple]]:
    """Worker task: the next samples of several campaigns (at least one each), stepped together so
    that their episodes share SUMO instances (`campaign.step_together`), and each optimiser's state
    after them. Each campaign's samples are the ones it gives run alone."""
    from threadpoolctl import threadpool_limits

    # One BLAS thread per task: the GP's matrices are small, and a BLAS pool per worker process
    # oversubscribes the cores (two workers on two cores ran no faster than one).
    with threadpool_limits(limits=1):
        runners = [CampaignRunner(c.campaign, _evaluator(c), stored=c.stored, state=c.state,
                                  where=f"campaign {campaign_key(c.campaign.definition())}", batch=c.batch)
                   for c in chunks]
        results: list[list[SampleResult]] = [[] for _ in chunks]
        t0 = time.monotonic()
        while True:
            going = [i for i, r in enumerate(runners) if r.done < r.campaign.samples and len(results[i]) < CHUNK_SAMPLES]
            if not going:
                break
            for i, new in zip(going, step_together([runners[i] for i in going], batch=chunks[0].batch)):
                results[i].extend(new)
            if time.monotonic() - t0 > CHUNK_WALL_S:
                break
    return [(r, runner.state) for r, runner in zip(results, runners)]


@dataclass(frozen=True)
class Play:
    """A task's share of one campaign whose optimiser runs on the client: play ``points``, samples
    ``first``, ``first`` + 1, ..."""

    campaign: Campaign
    network: NetworkSource
    first: int
    points: tuple[np.ndarray, ...]
    fmus: tuple[tuple[str, bytes], ...] = ()


def play_chunks(plays: tuple[Play, ...], batch: int = DEFAULT_BATCH) -> list[list[SampleResult]]:
    """Worker task: episodes only, no optimiser: each play's samples in order, side by side in as few SUMO
    instances as hold them. An episode is the same on every machine, whatever its numerics."""
    return play_pending([(_evaluator(p), p.first, p.points) for p in plays], batch)


@dataclass
class _Active:
    """The client's view of one running campaign."""

    campaign: Campaign
    campaign_id: int
    network: NetworkSource
    stored: tuple[SampleResult, ...]
    state: tuple | None = None
    done: int = 0
    failures: int = 0
    batch: int = DEFAULT_BATCH
    added: set = field(default_factory=set)  # indices stored by this sweep run (a stored campaign may have gaps)
    #: the first stored sample whose point this machine's model proposes otherwise (`CampaignRunner`)
    numerics_differ_at: int | None = None
    fmus: tuple[tuple[str, bytes], ...] = ()  # its followers' FMUs, for a Dask cluster's workers

    def chunk(self) -> Chunk:
        # the stored samples travel only until a state exists
        return Chunk(self.campaign, self.network, self.stored if self.state is None else (), self.state, self.batch,
                     self.fmus)


def _accept(active: _Active, chunk_result: tuple[list[SampleResult], tuple], store_results) -> bool:
    """Store a finished chunk; True when its campaign is complete."""
    results, state = chunk_result
    indices = [r.index for r in results]
    stored = {r.index for r in active.stored} | active.added
    if (indices != sorted(set(indices)) or any(i in stored or not 0 <= i < active.campaign.samples for i in indices)):
        raise D4sumoError(f"campaign {active.campaign_id}: a worker returned samples out of order or stored already; "
                          "nothing of them was stored")
    active.numerics_differ_at = state[-1]
    store_results(active, results)
    active.added.update(indices)
    active.state = state
    active.failures = 0
    return active.done >= active.campaign.samples


def _gangs(todo: list[_Active], workers: int) -> list[list[_Active]]:
    """The campaigns in tasks of up to GANG_SIZE that step together: ones whose episodes may share
    SUMO (one `batch.batch_key` and road) and that propose alike (one optimiser and batch size), so
    that they keep pace. Smaller tasks where there are few campaigns, to keep every worker busy."""
    size = max(1, min(GANG_SIZE, -(-len(todo) // (2 * workers))))
    groups: dict[tuple, list[_Active]] = {}
    for a in todo:
        c = a.campaign
        key = (batch_key(c.config), a.network, c.optimizer, dict(c.optimizer_options).get("batch_size"))
        groups.setdefault(key, []).append(a)
    gangs = []
    for g in groups.values():  # near-equal gangs: 78 campaigns in gangs of 32 at most are 26, 26, 26
        count = -(-len(g) // size)
        gangs += [g[i * len(g) // count:(i + 1) * len(g) // count] for i in range(count)]
    return gangs


def _share(gang: list[_Active], queue: list, busy: int, slots: int) -> list[_Active]:
    """Near the sweep's end, when a worker would idle, the gang goes on as two tasks: its half."""
    if not queue and busy < slots and len(gang) > 1:
        first, second = _halves(gang)
        queue.append(second)
        return first
    return gang


def _halves(gang: list[_Active]) -> list[list[_Active]]:
    return [gang[:len(gang) // 2], gang[len(gang) // 2:]]


def _task(gang: list[_Active]) -> tuple[Chunk, ...]:
    return tuple(a.chunk() for a in gang)


def _accept_gang(gang: list[_Active], chunk_results: list, store_results) -> list[_Active]:
    """Store a finished task's chunks; the gang's campaigns not complete yet."""
    if len(chunk_results) != len(gang):
        raise D4sumoError(f"a worker returned {len(chunk_results)} chunks for {len(gang)} campaigns; nothing of them was stored")
    return [a for a, result in zip(gang, chunk_results) if not _accept(a, result, store_results)]


def _after_failure(gang: list[_Active], why: str) -> list[list[_Active]]:
    """A task that failed runs again: a gang of several campaigns as two halves (the samples do not
    depend on the grouping, and a campaign that fails every time is found alone after a few
    failures), a single campaign as it was, until it has failed MAX_TASK_FAILURES times."""
    if len(gang) > 1:
        log.warning("a task of %d campaigns failed (%s); it runs again as two", len(gang), why)
        return _halves(gang)
    _check_failures(gang[0], why)
    return [gang]


def _check_failures(active: _Active, why: str) -> None:
    active.failures += 1
    if active.failures >= MAX_TASK_FAILURES:
        raise D4sumoError(f"campaign {active.campaign_id} failed {active.failures} times ({why}); every finished sample "
                          "is stored: run the same command to resume")
    log.warning("campaign %d: %s; running its chunk again", active.campaign_id, why)
