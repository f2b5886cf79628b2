"""Playing and scoring a campaign's samples: the evaluator plays one (its road, its plan, its episode, its
score against the specification), and `play_together` plays many side by side in one SUMO, whichever
campaigns they belong to, each result the one it gives alone."""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..engine.networks import keep_road
from ..engine.scenarios import NetworkSource, Road, batch_road, build_road, network_source
from ..engine.simulation import check_episode, drives_one_lane, shares_sumo, simulate, simulate_batch
from ..errors import SumoError
from ..model.stepping.batch import PER_EPISODE, batch_key, known_key
from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import AttackPlan, attack_plan
from ..model.stepping.trace import Episode
from . import situation
from .campaign import Campaign, SampleResult

log = logging.getLogger(__name__)


def campaign_network(config: EpisodeConfig) -> NetworkSource | str:
    """What a campaign's roads are built from, by value where a route names a part of a network (Dask
    workers may not see the client's disk): the route's edges alone, or the network whole where a user's
    traffic demand drives its other ways (`EpisodeConfig.whole_network`)."""
    if not config.route:
        return config.network
    return network_source(config.network, route=() if config.whole_network else config.route, given=config.network_given)


def campaign_road(network: NetworkSource | str, config: EpisodeConfig) -> Road:
    """The road a campaign's episodes play alone on, from `campaign_network`'s ``network``."""
    if config.whole_network:
        return build_road(network, route=config.route, lane=config.lane, whole=True, given=config.network_given)
    return build_road(network, lane=config.lane, given=config.network_given)


class Evaluator:
    """Simulates and scores parameter vectors of one campaign (road built and formula parsed once):
    one at a time, or a batch side by side in one SUMO (`simulation.simulate_batch`)."""

    def __init__(self, campaign: Campaign, road: Road | None = None, *, network: NetworkSource | None = None):
        self.campaign = campaign
        self.family = campaign.family()
        self.spec = campaign.specification()
        config = campaign.config  # what batches' roads are built from: the network, or its route's edges alone
        if config.network_sha256:  # a road of one's own: kept, to replay from anywhere here
            keep_road(config.network, config.network_sha256)
        self.network = network or campaign_network(config)
        self.road = road or campaign_road(self.network, config)
        for corner in situation.corners(config, campaign.situation) or [config]:  # every situation it searches fits the road
            check_episode(corner, self.road)
        self._batch_road: Road | None = None
        self._configs: dict[tuple, EpisodeConfig] = {}  # the situation's values -> its configuration (`config_for`)
        self._failures: dict[str, int] = {}  # each failure's message: how many samples ended in it
        self._shares_sumo = shares_sumo(campaign.config)
        self.batch_key = batch_key(campaign.config)  # campaigns with one key may share a SUMO
        #: whether every sample's configuration has the campaign's key: its situation searches only the [scenario] keys a
        #: batch carries per episode (the speed not where SUMO's models read it from their vehicle type); another key
        #: (a gain, where one value may make the arrays play it and another not) is asked each configuration's own
        self._one_key = all(e[0] in PER_EPISODE and not (e[0] == "speed_mps" and config.sumo_driven) for e in campaign.situation)

    def plan(self, params) -> AttackPlan:
        """What the attacker does with these parameters: its signal, and its lane change if it makes one."""
        return attack_plan(self.family, params, self.config_for(params))

    def config_for(self, params) -> EpisodeConfig:
        """The configuration these parameters play: the campaign's, in the situation they hold (`situation`); made
        once a sample (its plan and its episode ask for it; a configuration costs about 55 us to check)."""
        if not self.campaign.situation:
            return self.campaign.config
        key = tuple(float(v) for v in params[len(params) - len(self.campaign.situation):])
        config = self._configs.get(key)
        if config is None:
            if len(self._configs) >= 256:
                self._configs.clear()
            config = self._configs[key] = self.campaign.config_for(params, self.family)
            if self._one_key:  # its key is the campaign's: it varies only what a batch carries per episode
                known_key(config, self.batch_key)
        return config

    def batch_key_for(self, params) -> str:
        """The `batch.batch_key` of the configuration these parameters play: samples with one key may share a SUMO."""
        return self.batch_key if self._one_key else batch_key(self.config_for(params))  # (kept by configuration)

    def simulate(self, index: int, params, *, fcd_path: str | Path | None = None, gui: bool = False) -> Episode:
        """Sample ``index``'s episode with these parameters, alone (a replay's, a figure's): in the traffic
        that sample meets (`EpisodeConfig.for_sample`)."""
        return simulate(self.config_for(params).for_sample(index), self.plan(params), road=self.road, fcd_path=fcd_path, gui=gui)

    def without_attack(self, index: int, params=None, *, fcd_path: str | Path | None = None) -> Episode:
        """Sample ``index``'s episode with the attacker only cruising: no pedal attack, no lane change, no lie, in
        the traffic that sample meets (`results.baseline`) and the situation its ``params`` hold (where the
        campaign searches one)."""
        if self.campaign.situation and params is None:
            raise ValueError("a campaign that searches its situation plays a sample without the attack in its situation: give its params")
        config = self.config_for(params) if params is not None else self.campaign.config
        return simulate(config.for_sample(index), AttackPlan(np.full(config.steps, np.nan)), road=self.road, fcd_path=fcd_path)

    def without_attack_of(self, params_of: dict) -> tuple[Callable[[int], Episode], bool]:
        """What `results.baseline.campaign_baseline` plays (sample index -> its episode without the attack, in its own
        situation: ``params_of``, index -> params) and whether each sample's is its own (its own traffic, or situation)."""
        traffic = self.campaign.config.traffic
        per_sample = bool(self.campaign.situation) or (traffic is not None and traffic.per_sample)
        return (lambda index: self.without_attack(index, params_of.get(index))), per_sample

    def __call__(self, index: int, params: np.ndarray, *, fcd_path: str | Path | None = None) -> SampleResult:
        t0 = time.perf_counter()
        x = tuple(float(v) for v in params)
        try:
            episode = self.simulate(index, x, fcd_path=fcd_path)
        except Exception as exc:  # SUMO or a user's controller: store the sample as errored, go on
            return self._failed(index, x, exc, time.perf_counter() - t0)
        return self._scored(index, x, episode, t0)

    def batch(self, first: int, params: Sequence[np.ndarray],
              on_result: Callable[[SampleResult], None] | None = None) -> list[SampleResult]:
        """Samples ``first``, ``first`` + 1, .. played side by side in one SUMO: each result is the one
        `__call__` gives alone. ``on_result`` hears of each as its episode ends (in any order). A
        sample's wall time is its share of the batch's time until its episode ended, plus its scoring."""
        return play_together([(self, first, params)], on_result and (lambda _, r: on_result(r)))[0]

    def batch_road(self, episodes: int) -> Road:
        """The road with at least this many copies side by side (built once, then grown as needed)."""
        if self._batch_road is None or self._batch_road.copies < episodes and not self._batch_road.copies_unlike:
            config = self.campaign.config  # (a network whole is driven along the route; else the route is all of it)
            self._batch_road = batch_road(self.network, episodes, lane=config.lane, given=config.network_given,
                                          route=config.route if config.whole_network else (), one_lane=drives_one_lane(config))
        return self._batch_road

    def _scored(self, index: int, x: tuple[float, ...], episode, t0: float) -> SampleResult:
        try:
            rho = self.spec.robustness(episode.trace)
            if not math.isfinite(rho):
                raise ValueError(f"robustness is {rho}")
        except Exception as exc:  # a user's formula
            return self._failed(index, x, exc, time.perf_counter() - t0)
        collision = episode.first_collision_record()
        return SampleResult(index, x, rho, episode.outcome, collision, self.min_gaps(episode), time.perf_counter() - t0)

    def min_gaps(self, episode) -> dict[str, float]:
        """The minimum gaps over the window the specification scores: from the attack's start, or, for a
        campaign stored before that window existed (``score_from_attack_start`` false), the whole episode."""
        return episode.min_gaps_m() if self.spec.start_step else episode.min_gaps_with_warmup_m()

    @staticmethod
    def failure(exc: Exception) -> str:
        """How a sample that ended in ``exc`` stores its error."""
        return str(exc) if isinstance(exc, (SumoError, ValueError)) else f"{type(exc).__name__}: {exc}"

    def _failed(self, index: int, x: tuple[float, ...], exc: Exception, wall_s: float) -> SampleResult:
        message = self.failure(exc)
        # a failure that repeats is said twice, not once a sample (a warm-up collision ends every one alike)
        repeats = self._failures.get(message, 0)
        self._failures[message] = repeats + 1
        if repeats == 0:
            log.warning("sample index %d failed: %s", index, message)  # its index in the campaign (export's index column), not its id
        elif repeats == 1:
            log.warning("sample index %d failed the same way; later samples that do are counted, not shown", index)
        return SampleResult(index, x, None, "error", None, None, wall_s, message)


#: consecutive samples of one campaign to play: its evaluator, the first sample's index, their points
Job = tuple[Evaluator, int, Sequence[np.ndarray]]


class _CallerError(Exception):
    """Carries an exception raised by the caller's ``on_result`` out of a batch, untouched."""


def play_together(jobs: Sequence[Job], on_result: Callable[[int, SampleResult], None] | None = None) -> list[list[SampleResult]]:
    """Play the jobs' samples side by side in one SUMO, whichever campaigns they belong to (their
    configurations share one `batch.batch_key`; samples of a situation that changes it, in one SUMO per key):
    each result is the one `Evaluator.__call__` gives
    alone, each job's in order. ``on_result(job, result)`` hears of each sample as its episode ends
    (in any order; ``job``: its job's position in ``jobs``).
    A single episode, or followers that may not share SUMO, play one at a time instead."""
    if sum(len(params) for _, _, params in jobs) <= 1 or not all(ev._shares_sumo for ev, _, _ in jobs):
        out = []
        for j, (ev, first, params) in enumerate(jobs):  # alone, one after the other: the single-episode engine
            results = []
            for i, x in enumerate(params):
                results.append(ev(first + i, x))
                if on_result:
                    on_result(j, results[-1])
            out.append(results)
        return out
    t0 = time.perf_counter()
    samples = [(ev, first + i, tuple(float(v) for v in x)) for ev, first, params in jobs for i, x in enumerate(params)]
    job_of = [j for j, (_, _, params) in enumerate(jobs) for _ in params]
    results: list[SampleResult | None] = [None] * len(samples)

    def finish(s: int, r: SampleResult) -> None:
        results[s] = r
        if on_result:
            try:
                on_result(job_of[s], r)
            except BaseException as exc:  # the caller's own failure (storing, say): not the episode's
                raise _CallerError(exc) from exc

    def done(s: int, episode) -> None:
        ev, index, x = samples[s]
        t = time.perf_counter()
        if isinstance(episode, Exception):  # a user's controller failed in it
            r = ev._failed(index, x, episode, 0.0)
        else:
            r = ev._scored(index, x, episode, t)
        finish(s, dataclasses.replace(r, wall_s=r.wall_s + (t - t0) / len(samples)))  # plus its share so far

    # samples whose configurations share a batch key play side by side, one SUMO for each key (a situation that
    # searches a key a batch holds for all its episodes: the radar's noise, the controller's gains, the vehicle)
    groups: dict[str, tuple[list, list, list]] = {}  # batch key -> the plans, configurations and samples it plays
    try:
        for s, (ev, index, x) in enumerate(samples):
            try:
                plan, config, key = ev.plan(x), ev.config_for(x), ev.batch_key_for(x)
            except Exception as exc:
                finish(s, ev._failed(index, x, exc, 0.0))
                continue
            plans, configs, playing = groups.setdefault(key, ([], [], []))
            plans.append(plan)
            configs.append(config)
            playing.append(s)
        for plans, configs, playing in groups.values():
            try:
                road = jobs[0][0].batch_road(len(plans))
                simulate_batch(configs, plans, road=road, on_episode=lambda j, episode, playing=playing: done(playing[j], episode))
            except _CallerError:
                raise
            except Exception as exc:  # SUMO failed: the samples not yet finished play alone, as they would have
                log.warning("SUMO failed in a batch of %d episodes (%s); its unfinished ones play one at a time", len(plans), exc)
                for s in playing:
                    if results[s] is None:
                        ev, index, x = samples[s]
                        finish(s, ev(index, x))
    except _CallerError as exc:  # the caller's own exception, as it raised it
        raise exc.__cause__ from None
    out, s = [], 0
    for _, _, params in jobs:
        out.append(results[s:s + len(params)])  # type: ignore[arg-type]
        s += len(params)
    return out
