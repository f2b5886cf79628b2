"""Stored samples as records: each sample of a results database with the settings of the campaign it
ran under, read through the one reader of stored campaigns (`search.campaign`). The tables
(`analysis`), the clusters (`clusters`) and the figures work on these records and read no database.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..errors import ConfigError
from ..model.config import EpisodeConfig
from ..model.control import names_only
from ..model.maneuvers import LANE_CHANGE_PARAMETER, MANEUVERS, lane_change_steps

#: the scenario keys of the lane-changing maneuvers (not the maneuver's name): what sets two such campaigns apart
MANEUVER_SETTINGS = tuple(dict.fromkeys(k for m in MANEUVERS.values() for k in m.settings if k != "maneuver"))


@dataclass(frozen=True)
class Record:
    """One stored sample with the campaign settings it ran under."""

    db: str
    sample_id: int
    campaign_id: int
    network: str
    followers: int
    setpoint_m: float
    speed_mps: float
    start: str
    attack: str
    optimizer: str
    seed: int
    delta_s: float | None
    params: tuple[float, ...]
    robustness: float | None
    outcome: str
    pair: str | None
    time_s: float | None
    position_m: float | None
    speed_diff_kmh: float | None
    attack_start_s: float = 0.0  # simulation time at which the attack starts (after a warm-up, else 0)
    system: str = "switching"  # the system under test: its controller(s), see EpisodeConfig.system_label
    maneuver: str = "inlane"  # the attacker's maneuver: inlane (the paper's), cutin or cutout
    maneuver_settings: str = ""  # its settings ("cutin_follower=2, cutin_offset_m=0.0, lane_change_s=2.0")
    step_s: float = 0.05
    end_s: float = 60.0  # when the episode ends without a collision (warm-up included)
    param_names: tuple[str, ...] = ()  # the attack parameters' names, as the family (and maneuver) name them

    @property
    def time_from_attack_start_s(self) -> float | None:
        """The collision time counted from the attack's start: what the attack had to cause it."""
        return None if self.time_s is None else self.time_s - self.attack_start_s

    @property
    def lane_change_at_s(self) -> float | None:
        """When the attacker began its lane change, in simulation time (None: the paper's maneuver, or an
        episode that ended before the change began)."""
        if LANE_CHANGE_PARAMETER not in self.param_names:
            return None
        t_lc_s = self.params[self.param_names.index(LANE_CHANGE_PARAMETER)]
        at = self.attack_start_s + lane_change_steps(t_lc_s, self.step_s) * self.step_s  # as played
        return None if at >= (self.end_s if self.time_s is None else self.time_s) else at

    @property
    def configuration(self) -> tuple:
        """What makes two campaigns different experiments (the seed does not)."""
        return (self.network, self.followers, self.setpoint_m, self.speed_mps, self.start, self.attack_start_s,
                self.system, self.maneuver, self.maneuver_settings, self.attack, self.optimizer)


def system_label(config: dict) -> str:
    """The system under test of a stored campaign config, as EpisodeConfig.system_label names it (a
    user's controller by its name: nothing is imported)."""
    with names_only():
        return EpisodeConfig.from_dict(config).system_label


def load_records(paths: Sequence[str | Path]) -> list[Record]:
    """Every stored sample of the databases with its campaign's settings, read through the one reader of
    stored campaigns (`Campaign.from_definition`: its defaults, nothing imported)."""
    from ..search.campaign import Campaign, open_store  # here: the records alone import no optimiser

    records: list[Record] = []
    for path in paths:
        with open_store(path, create=False) as store:
            campaigns = {c.id: Campaign.from_definition(c.definition, where=f"{path}: campaign {c.id}")
                         for c in store.campaigns()}
            rows = {}
            for cid, c in campaigns.items():
                cfg = c.config
                start_s = cfg.warmup_s if cfg.start == "warmup" else 0.0
                settings = ", ".join(f"{k}={v}" for k, v in cfg.to_dict()["scenario"].items() if k in MANEUVER_SETTINGS)
                rows[cid] = (cfg.network, cfg.followers, cfg.setpoint_m, cfg.speed_mps, cfg.start, c.attack, c.optimizer,
                             c.seed, dict(c.attack_options).get("delta_s"), start_s, cfg.system_label,
                             cfg.maneuver, settings, cfg.step_s, start_s + cfg.duration_s, c.family().names)
            for s in store.iter_samples():
                (network, followers, setpoint, speed, start, attack, optimizer, seed, delta_s, start_s, system, maneuver,
                 settings, step_s, end_s, names) = rows[s.campaign_id]
                records.append(Record(
                    str(path), s.id, s.campaign_id, network, followers, setpoint, speed, start, attack, optimizer, seed,
                    delta_s, s.params, s.robustness, s.outcome, s.pair, s.time_s, s.position_m, s.speed_diff_kmh,
                    start_s, system, maneuver, settings, step_s, end_s, names,
                ))
    if not records:
        raise ConfigError("DB", ", ".join(map(str, paths)), "databases holding at least one sample")
    return records

