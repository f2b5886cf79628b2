"""A campaign: one configuration, one attack family, one optimiser, a budget and a seed.

The runner owns the loop: the optimiser asks for a parameter vector, the attack family turns it into
the attacker's signal, SUMO plays the episode, the specification scores it, the sample is stored at
once, and the robustness goes back to the optimiser. Samples already in the database are told to the
optimiser again first (its asks must match them exactly), so an interrupted campaign resumes where it
stopped and ends as if it had never been interrupted.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .attacks import AttackFamily, make_attack
from .config import EpisodeConfig
from .errors import ConfigError, SumoError, check_number
from .optimizers import OPTIMIZERS, make_optimizer
from .scenarios import Road, build_road
from .simulation import check_road, simulate
from .spec import Specification
from .store import Store, StoreError

log = logging.getLogger(__name__)

MAX_SAMPLES = 100_000


@dataclass(frozen=True)
class Campaign:
    config: EpisodeConfig = field(default_factory=EpisodeConfig)
    attack: str = "knots"
    optimizer: str = "bo"
    samples: int = 100
    seed: int = 0
    d_safe_m: float = 0.0
    formula: str | None = None
    delta_s: float = 6.0  # knot spacing (knots/spline)
    horizon_s: float = 48.0  # last knot (knots/spline)

    def __post_init__(self) -> None:
        self.family()  # validates attack, delta_s, horizon_s
        if self.optimizer not in OPTIMIZERS:
            raise ConfigError("optimizer", self.optimizer, f"one of {', '.join(OPTIMIZERS)}")
        if not isinstance(self.samples, int) or isinstance(self.samples, bool) or not 1 <= self.samples <= MAX_SAMPLES:
            raise ConfigError("samples", self.samples, f"a whole number in [1, {MAX_SAMPLES}]")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ConfigError("seed", self.seed, "a whole number >= 0")
        check_number("spec.d_safe_m", self.d_safe_m, -1e3, 1e3, "m")

    def family(self) -> AttackFamily:
        return make_attack(self.attack, delta_s=self.delta_s, horizon_s=self.horizon_s)

    def specification(self) -> Specification:
        return Specification(followers=self.config.followers, step_s=self.config.step_s, formula=self.formula, d_safe_m=self.d_safe_m)

    def definition(self) -> dict[str, Any]:
        """What identifies the campaign in the database (the budget is not part of it)."""
        attack: dict[str, Any] = {"family": self.attack}
        if self.attack in ("knots", "spline"):
            attack.update(delta_s=self.delta_s, horizon_s=self.horizon_s)
        return {
            "config": self.config.to_dict(),
            "attack": attack,
            "optimizer": self.optimizer,
            "seed": self.seed,
            "spec": {"formula": self.formula, "d_safe_m": self.d_safe_m},
        }

    @classmethod
    def from_definition(cls, definition: dict[str, Any], samples: int = 100) -> "Campaign":
        attack = definition["attack"]
        return cls(
            config=EpisodeConfig.from_dict(definition["config"]),
            attack=attack["family"],
            optimizer=definition["optimizer"],
            samples=samples,
            seed=definition["seed"],
            d_safe_m=definition["spec"]["d_safe_m"],
            formula=definition["spec"]["formula"],
            delta_s=attack.get("delta_s", 6.0),
            horizon_s=attack.get("horizon_s", 48.0),
        )

    def replace(self, **changes: Any) -> "Campaign":
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class SampleResult:
    index: int
    params: tuple[float, ...]
    robustness: float | None
    outcome: str  # success | attacker_crash | no_crash | error
    collision: dict | None
    min_gaps: dict | None
    wall_s: float
    error: str | None = None
    id: int | None = None  # row id in the database


@dataclass
class CampaignSummary:
    campaign_id: int | None
    samples: list[SampleResult]

    def count(self, outcome: str) -> int:
        return sum(1 for s in self.samples if s.outcome == outcome)

    @property
    def best(self) -> SampleResult | None:
        scored = [s for s in self.samples if s.robustness is not None]
        return max(scored, key=lambda s: s.robustness) if scored else None


class Evaluator:
    """Simulates and scores parameter vectors of one campaign (road built and formula parsed once)."""

    def __init__(self, campaign: Campaign, road: Road | None = None):
        self.campaign = campaign
        self.family = campaign.family()
        self.spec = campaign.specification()
        self.road = road or build_road(campaign.config.network)
        check_road(campaign.config, self.road)
        config = campaign.config
        self.times_s = np.arange(config.steps) * config.step_s

    def signal(self, params) -> np.ndarray:
        return self.family.signal(params, self.times_s)

    def __call__(self, index: int, params: np.ndarray) -> SampleResult:
        t0 = time.perf_counter()
        x = tuple(float(v) for v in params)
        try:
            episode = simulate(self.campaign.config, self.signal(x), road=self.road)
            rho = self.spec.robustness(episode.trace)
        except (SumoError, ValueError) as exc:
            log.warning("sample %d failed: %s", index, exc)
            return SampleResult(index, x, None, "error", None, None, time.perf_counter() - t0, str(exc))
        collision = episode.first_collision.to_dict() if episode.first_collision else None
        gaps = {k: round(v, 6) for k, v in episode.min_gaps_m().items()}
        return SampleResult(index, x, rho, episode.outcome, collision, gaps, time.perf_counter() - t0)


def _score(result: SampleResult, history: list[float]) -> float:
    """What the optimiser is told: the robustness, or for an errored sample the worst seen so far."""
    if result.robustness is not None and math.isfinite(result.robustness):
        return result.robustness
    return min(history) if history else -1.0


def run_campaign(
    campaign: Campaign,
    store: Store | None = None,
    *,
    sweep: str | None = None,
    evaluator: Evaluator | None = None,
    on_sample: Callable[[SampleResult], None] | None = None,
) -> CampaignSummary:
    """Run (or resume) a campaign; every sample is in ``store`` as soon as it finishes.

    Pass an ``evaluator`` built beforehand to have every input checked before anything is written."""
    evaluate = evaluator or Evaluator(campaign)
    rng = np.random.default_rng(campaign.seed)
    optimizer = make_optimizer(campaign.optimizer, evaluate.family.lower, evaluate.family.upper, budget=campaign.samples, rng=rng)
    campaign_id = store.open_campaign(campaign.definition(), campaign.samples, sweep) if store else None
    results: list[SampleResult] = []
    scores: list[float] = []

    def record(x: np.ndarray, r: SampleResult) -> None:
        score = _score(r, scores)
        optimizer.tell(x, score)
        scores.append(score)
        results.append(r)
        if on_sample:
            on_sample(r)

    if store is not None:
        for row in store.samples(campaign_id)[: campaign.samples]:
            x = optimizer.ask()
            if not np.allclose(x, row.params, rtol=0, atol=1e-12):
                raise StoreError(
                    f"{store.path}: stored sample {row.index} of campaign {campaign_id} is not what this seed asks for; "
                    "it was written by another d4sumo version or changed: use a new database"
                )
            record(x, SampleResult(row.index, row.params, row.robustness, row.outcome, row.collision, row.min_gaps,
                                   row.wall_s, row.error, row.id))
        if results:
            log.info("campaign %s: resumed after %d stored samples", campaign_id, len(results))
    for index in range(len(results), campaign.samples):
        x = optimizer.ask()
        r = evaluate(index, x)
        if store is not None:
            row_id = store.add_sample(campaign_id, index, r.params, r.robustness, r.outcome, r.collision, r.min_gaps, r.wall_s, r.error)
            r = dataclasses.replace(r, id=row_id)
        record(x, r)
    return CampaignSummary(campaign_id, results)

