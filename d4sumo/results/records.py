"""Stored samples as records: each sample of a results database with the settings of the campaign it
ran under, read through the one reader of stored campaigns (`search.campaign`). The tables
(`analysis`), the clusters (`clusters`) and the figures work on these records and read no database.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from ..errors import ConfigError
from ..model.config import EpisodeConfig
from ..model.definition import IDENTITY_KEYS, TABLES
from ..model.controllers.plugins import names_only
from ..search import situation
from ..model.attacks.maneuvers import LANE_CHANGE_PARAMETER, MANEUVERS, SwerveAttack, attack_of, lane_change_steps

#: the [scenario] keys the tables lay out as their rows and columns (setpoint, target speed, start mode).
#: Every other key a campaign stores (network, route, duration, step, warm-up, followers, the maneuver and
#: its settings, ...) is part of its scenario: what its collision times and locations mean.
GRID_KEYS = ("setpoint_m", "speed_mps", "start")


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
    step_s: float = 0.05
    end_s: float = 60.0  # when the episode ends without a collision (warm-up included)
    param_names: tuple[str, ...] = ()  # the attack parameters' names, as the family (and maneuver) name them
    #: how many of them are the signal family's (the knots), before what the maneuver adds (t_lc_s, lanes); 0: all
    signal_parameters: int = 0
    #: a swerving attacker's lane changes as planned: the step at whose start each begins (`lane_changes_at_s`)
    swerve_change_steps: tuple[int, ...] = ()
    #: the campaign's scenario: its [scenario] keys as stored (a key without effect is not), but GRID_KEYS;
    #: campaigns of different scenarios are never pooled (`analysis.scenario_labels`)
    scenario: tuple[tuple[str, Any], ...] = ()
    #: the sample's place in its campaign (0 the first): where each sample meets traffic of its own, its traffic
    index: int = 0
    #: the campaign's message attack in a few words (`messages.lie_label`: "a lie (offset on its speed)"), or
    #: "": the pedals alone; campaigns with and without a lie are never pooled
    lie: str = ""
    #: where its campaign searches its situation (`search.situation`): the values this sample played, exactly;
    #: its setpoint_m and speed_mps are then the cell of the range it fell in (`situation_cell`), so that the
    #: report's tables and maps group samples of nearby situations
    situation: tuple[tuple[str, float], ...] = ()
    #: whether its campaign spent it locating the boundary between safe and unsafe situations (``[search] boundary``):
    #: a random attack, in a situation chosen where the success rate is least known
    locating: bool = False

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
    def lane_changes_at_s(self) -> tuple[float, ...]:
        """When the attacker began each of its lane changes, in simulation time, those the episode played."""
        once = self.lane_change_at_s
        if once is not None:
            return (once,)
        played = round((self.end_s if self.time_s is None else self.time_s) / self.step_s)  # steps, as the episode counts
        return tuple(k * self.step_s for k in self.swerve_change_steps if k < played)

    @property
    def signal_params(self) -> tuple[float, ...]:
        """The signal family's parameters (the knots), without what the maneuver adds."""
        return self.params[:self.signal_parameters] if self.signal_parameters else self.params

    @property
    def configuration(self) -> tuple:
        """What makes two campaigns different experiments (the seed does not): the scenario, the grid's
        point in it, the system under test, the attack and the optimiser."""
        return (self.scenario, self.network, self.followers, self.setpoint_m, self.speed_mps, self.start,
                self.attack_start_s, self.system, self.maneuver, self.attack, self.lie, self.optimizer)


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
            settings = {cid: _campaign_settings(c) for cid, c in campaigns.items()}
            families = {cid: c.family() for cid, c in campaigns.items()}
            for s in store.iter_samples():
                c = campaigns[s.campaign_id]
                records.append(Record(
                    db=str(path), sample_id=s.id, campaign_id=s.campaign_id, params=s.params, robustness=s.robustness,
                    outcome=s.outcome, pair=s.pair, time_s=s.time_s, position_m=s.position_m,
                    speed_diff_kmh=s.speed_diff_kmh, index=s.index, locating=bool(c.boundary) and situation.locating(s.index, c.boundary),
                    swerve_change_steps=_swerve_change_steps(families[s.campaign_id], s.params, c.config),
                    **(settings[s.campaign_id] if not c.situation else
                       {**settings[s.campaign_id], **_situation_of(c, families[s.campaign_id], s.params)}),
                ))
    if not records:
        raise ConfigError("DB", ", ".join(map(str, paths)), "databases holding at least one sample")
    return records


#: how many cells the report splits a searched key's range into (at most: each cell a round width)
CELLS = 10


def situation_cell(low: float, high: float, value: float) -> float:
    """The low end of the cell of [low, high] that ``value`` falls in: the range split in cells of a round width
    (1, 2 or 5 times a power of ten) into at most `CELLS`, from a multiple of that width."""
    raw = (high - low) / CELLS
    decade = 10.0 ** math.floor(math.log10(raw))
    width = next(m * decade for m in (1, 2, 5, 10) if m * decade >= raw)
    return float(round(math.floor(value / width) * width, 12))


def _situation_of(campaign, family, params) -> dict[str, Any]:
    """A sample's situation, of a campaign that searches one (`search.situation`): its values, and the cells of
    the setpoint and speed the report groups it in (a damaged row keeps the campaign's: said where replayed)."""
    try:
        exact = situation.values(campaign.situation, family.situation_values(params))
    except ConfigError:
        return {}
    ranges = {e[0]: e[1:] for e in campaign.situation if len(e) == 3}
    return {"situation": tuple(exact.items()),  # (another key's value is in the situation alone: the report's grid is these)
            **{key: situation_cell(*ranges[key], v) if key in ranges else v for key, v in exact.items() if key in GRID_KEYS}}


def _swerve_change_steps(family, params, config) -> tuple[int, ...]:
    """The steps at which a swerving attacker's planned lane changes begin (none for other maneuvers, or
    parameters the family refuses: a damaged row is said where it is replayed)."""
    if not isinstance(attack_of(family)[0], SwerveAttack):
        return ()
    try:
        family, params = attack_of(family, params)  # a situation searched with it: its lanes are the attack's
        return tuple(k for k, _ in family.change_steps(params, config))
    except ConfigError:
        return ()


def _campaign_settings(campaign) -> dict[str, Any]:
    """The fields of a Record that its campaign gives (every sample of the campaign shares them)."""
    cfg = campaign.config
    start_s = cfg.warmup_s if cfg.start == "warmup" else 0.0
    return dict(
        network=cfg.network, followers=cfg.followers, setpoint_m=cfg.setpoint_m, speed_mps=cfg.speed_mps, start=cfg.start,
        attack=campaign.attack, optimizer=campaign.optimizer, seed=campaign.seed,
        delta_s=dict(campaign.attack_options).get("delta_s"), attack_start_s=start_s, system=cfg.system_label,
        maneuver=cfg.maneuver, step_s=cfg.step_s, end_s=start_s + cfg.duration_s, param_names=campaign.family().names,
        signal_parameters=len(getattr(campaign.family(), "longitudinal", campaign.family()).parameters),
        scenario=scenario_of(cfg),
        lie=campaign.lie,
    )


def scenario_of(config: EpisodeConfig) -> tuple[tuple[str, Any], ...]:
    """A campaign's scenario: its [scenario] keys but GRID_KEYS, in the config's order (a route as a tuple),
    and the traffic around the platoon ("none": it drives alone).
    A key the definition leaves out at its default so that earlier campaigns keep their identity (route,
    collision_gap_m, the inlane maneuver, ...) is part of it all the same; one it leaves out because it has
    no effect in this campaign (`NO_EFFECT_WHEN_LEFT_OUT`) is not."""
    stored = config.to_dict()["scenario"]
    out = []
    for key in SCENARIO_KEYS:
        if key in GRID_KEYS or key in IDENTITY_KEYS or (key not in stored and key in NO_EFFECT_WHEN_LEFT_OUT):
            continue  # (a road's digest identifies its files: the road is its network's name)
        value = stored.get(key, getattr(config, key))
        out.append((key, tuple(value) if isinstance(value, (list, tuple)) else value))
    out.append(("traffic", config.traffic.label if config.traffic is not None else "none"))  # alone is a scenario too
    return tuple(out)


#: the [scenario] keys: every field of EpisodeConfig but those of its [vehicle] and [controller] tables
SCENARIO_KEYS = tuple(f.name for f in dataclasses.fields(EpisodeConfig) if f.name not in TABLES)
#: the keys a definition leaves out where they have no effect: the warm-up's length without a warm-up, the
#: attacker's declared deceleration without a SUMO model to read it, another maneuver's settings, what the
#: platoon does at red lights on d4sumo's own roads (they have none)
NO_EFFECT_WHEN_LEFT_OUT = frozenset({"warmup_s", "attacker_declared_decel_mps2", "signals"} | {
    k for m in MANEUVERS.values() for k in m.settings if k != "maneuver"})
