"""The SUMO-free world: ballistic positions (the mean of old and new speed times the step, as SUMO's
--step-method.ballistic) for platoons of Python-commanded cars in one lane. The step loop
(`engine.loop.play`) drives it exactly as it drives SUMO, so a physics test and a SUMO run differ only
in the world."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import ConfigError
from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import AttackPlan, initial_state
from ..model.stepping.trace import Episode
from .loop import DETACH_AT, play


class BallisticWorld:
    """Platoons on a road without end, each car moved by the speed Python commands."""

    def __init__(self, configs: Sequence[EpisodeConfig], attacker_max_speed_mps: float = float("inf")):
        config = configs[0]
        if config.sumo_driven:
            raise ConfigError("controller.class", config.system_label, "Python controllers only: this runs without SUMO")
        if config.maneuver_class.lateral:
            raise ConfigError("scenario.maneuver", config.maneuver, "inlane: lane changes need SUMO")
        self.attacker_max_speed_mps = attacker_max_speed_mps
        self.dt = config.step_s
        names = config.vehicle_ids
        self.platoons = [names if len(configs) == 1 else tuple(f"{e}.{vid}" for vid in names) for e in range(len(configs))]
        self.x: dict[str, float] = {}
        self.v: dict[str, float] = {}
        for ids, c in zip(self.platoons, configs):
            positions, speeds = initial_state(c)
            self.x.update(zip(ids, positions))
            self.v.update(zip(ids, speeds))
        self.commanded: dict[str, float] = {}
        self.get_position, self.get_speed, self.set_speed = self.x.__getitem__, self.v.__getitem__, self.commanded.__setitem__

    def step(self) -> None:
        x, v, dt = self.x, self.v, self.dt
        for vid, w in self.commanded.items():
            x[vid] = x[vid] + 0.5 * (v[vid] + w) * dt
            v[vid] = w

    def remove(self, e: int) -> None:
        for vid in self.platoons[e]:
            del self.x[vid], self.v[vid]
            self.commanded.pop(vid, None)

    def lateral_rows(self, e: int) -> None:
        return None


def integrate(config: EpisodeConfig, attack_u: np.ndarray, attacker_max_speed_mps: float = float("inf")) -> Episode:
    """One episode without SUMO, stopping at the first bumper overlap: for physics tests and checks of
    the paper's maneuver (lane changes and SUMO's models need SUMO)."""
    world = BallisticWorld([config], attacker_max_speed_mps)
    result = play(world, [config], [AttackPlan(np.asarray(attack_u, dtype=float))])[0]
    if isinstance(result, Exception):
        raise result
    return result


def integrate_batch(config: EpisodeConfig | Sequence[EpisodeConfig], attacks_u: np.ndarray,
                    attacker_max_speed_mps: float = float("inf"), *, detach_at_step: int | None = None,
                    detach_at: int = 0) -> list[Episode | Exception]:
    """`integrate` for many attacks at once (of one configuration, or of one each), commanded by the
    batch's arrays to the end (``detach_at`` 0) or, from step ``detach_at_step`` on, each episode alone:
    for physics tests of the array laws against the scalar ones."""
    from ..model.stepping.batch import episode_configs

    attacks_u = np.asarray(attacks_u, dtype=float)
    configs = episode_configs(config, attacks_u.shape[0])
    world = BallisticWorld(configs, attacker_max_speed_mps)
    return play(world, configs, [AttackPlan(u) for u in attacks_u], detach_at=detach_at, detach_at_step=detach_at_step)


__all__ = ["BallisticWorld", "integrate", "integrate_batch", "DETACH_AT"]
