"""A campaign: one configuration, one attack family, one optimiser, a budget and a seed; what identifies
it in the results database (its definition), and the one reader of stored definitions.

`runner` plays campaigns: the optimiser proposes parameter vectors, SUMO plays them, the specification
scores them, each sample is stored as soon as it and those before it have finished, and the robustness
goes back to the optimiser.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import ledger
from ..errors import ConfigError, NotSimulable, check_int, check_number
from ..model.attacks.pedals import FAMILY_CLASSES, AttackFamily, make_attack, resolve_attack_options
from ..model.config import EpisodeConfig
from ..model.controllers.table import as_stored_ran
from ..model.world.network import network_digest
from ..model.controllers.control import user_code
from ..model.controllers.plugins import ControllerImportError, names_only
from ..model.attacks.messages import MESSAGE_KEYS, attack_box, lie_label
from . import situation
from .optimizers import DEFAULT_OPTIMIZER, OPTIMIZERS, resolve_options, stored_options
from .spec import Specification, parsed
from .store import DefinitionError, Store

#: the versions whose inputs `Campaign.with_inputs_of` plays, newest first: each changed what a campaign's keys do
INPUTS_CHANGED = ("0.20", "0.19", "0.18")
#: what an earlier version did with an input that no key of the ledger holds (the definition says it otherwise:
#: `EpisodeConfig.others_cut_in`), the value that does it
THEN = {"v2v.match_in_maneuvers": True}


def _flag_value(value) -> str:
    """A value as ``--set`` takes it: true, false, a bare word."""
    return ("true" if value else "false") if isinstance(value, bool) else str(value)

log = logging.getLogger(__name__)

MAX_SAMPLES = 100_000
_ANNOUNCED: set[str] = set()  # users' controller modules this process said it imports


@dataclass(frozen=True)
class Campaign:
    config: EpisodeConfig = field(default_factory=EpisodeConfig)
    attack: str = "knots"
    optimizer: str = DEFAULT_OPTIMIZER
    samples: int = 100
    seed: int = 0
    d_safe_m: float = 0.0
    formula: str | None = None
    attack_options: tuple[tuple[str, float], ...] = ()  # the attack family's options (knots: delta_s, horizon_s), resolved
    optimizer_options: tuple[tuple[str, Any], ...] = ()  # the [search.<optimizer>] table, resolved
    #: score the specification from the attack's start (after a warm-up); campaigns stored before this
    #: existed scored the whole episode, and keep doing so
    score_from_attack_start: bool = True
    #: a message attack on the attacker's V2V beacons (`messages`: offset, scaling, ...), searched with its
    #: pedals; "": it tells the truth
    message: str = ""
    message_field: str = "accel"  # the field of the beacons it falsifies (accel, speed, position)
    message_sender: int = 0  # whose beacons lie: 0 the attacker, K an insider follower vK
    #: keys of the scenario searched with the attack (`situation`): each a range, (key, low, high), or choices,
    #: (key, (choice, ...))
    situation: tuple[tuple, ...] = ()
    #: the share of its samples spent locating the boundary between the situations where attacks mostly succeed and
    #: those where they mostly fail (`optimizers.boundary`), rather than on the worst attack; 0: none
    boundary: float = 0.0

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen dataclass)
        if not isinstance(self.config, EpisodeConfig):
            raise ConfigError("config", self.config, "an EpisodeConfig")
        if not isinstance(self.attack, str) or self.attack not in FAMILY_CLASSES:  # (one registered from Python too)
            raise ConfigError("attack.family", self.attack, f"one of {', '.join(FAMILY_CLASSES)}")
        attack_options = dict(self.attack_options) if not isinstance(self.attack_options, dict) else self.attack_options
        fix("attack_options", tuple(resolve_attack_options(self.attack, attack_options).items()))
        self.family()  # validates the options together (knots: a horizon of whole steps of delta_s)
        if self.optimizer not in OPTIMIZERS:
            raise ConfigError("search.optimizer", self.optimizer, f"one of {', '.join(OPTIMIZERS)}")
        fix("samples", check_int("search.samples", self.samples, 1, MAX_SAMPLES))
        fix("seed", check_int("search.seed", self.seed, 0, 2**63 - 1))
        fix("d_safe_m", check_number("spec.d_safe_m", self.d_safe_m, -1e3, 1e3, "m"))
        if self.formula is not None and not isinstance(self.formula, str):
            raise ConfigError("spec.formula", self.formula, "an STL formula in rtamt syntax (a string)")
        options = self.optimizer_options
        if isinstance(options, dict):
            options = tuple(options.items())
        fix("optimizer_options", tuple(resolve_options(self.optimizer, dict(options)).items()))
        fix("situation", situation.check(self.config, tuple(self.situation)))
        fix("boundary", check_number("search.boundary", self.boundary, 0.0, 1.0, "(a share of the samples)"))
        if self.boundary and not self.situation:
            raise ConfigError("search.boundary", self.boundary, "0 where the campaign searches no situation: give a range "
                                                                "(scenario.setpoint_m = [3, 10]) to locate a boundary over")
        if self.config.attack_start_step == 0:  # nothing before the attack: the same window either way
            fix("score_from_attack_start", True)
        elif not isinstance(self.score_from_attack_start, bool):
            raise ConfigError("spec.from_attack_start", self.score_from_attack_start, "true or false")

    def family(self) -> AttackFamily:
        """The search's box: the signal family's, plus the lane change time when the attacker changes lanes,
        plus a message attack's parameters (`messages`), plus the situation's ranges (`situation`)."""
        return situation.box(attack_box(self.config, make_attack(self.attack, dict(self.attack_options)), self.message,
                                        self.message_field, dict(self.attack_options), self.message_sender), self.situation)

    def config_for(self, params, family: AttackFamily | None = None) -> EpisodeConfig:
        """The configuration a sample with these parameters plays: the campaign's, with the situation's keys at the
        sample's values (``family``: the campaign's, if at hand)."""
        if not self.situation:
            return self.config
        return situation.config_for(self.config, family or self.family(), self.situation, params)

    @property
    def lie(self) -> str:
        """Its message attack in a few words (`messages.lie_label`), or "": the attacker's pedals alone."""
        return lie_label(self.message, self.message_field, self.message_sender) if self.message else ""

    def specification(self) -> Specification:
        c = self.config
        start = c.attack_start_step if self.score_from_attack_start else 0
        return parsed(followers=c.followers, step_s=c.step_s, formula=self.formula, d_safe_m=self.d_safe_m,
                      duration_s=c.total_s - start * c.step_s, start_step=start, maneuver=c.maneuver,
                      traffic=c.traffic is not None)

    def definition(self) -> dict[str, Any]:
        """What identifies the campaign in the database (the budget is not part of it)."""
        attack: dict[str, Any] = {"family": self.attack, **dict(self.attack_options)}
        if self.message:  # stored where there is one: earlier campaigns keep their identity
            attack.update(message=self.message, message_field=self.message_field)
            if self.message_sender:
                attack.update(message_sender=self.message_sender)
        definition = {
            "config": self.config.to_dict(),
            "attack": attack,
            "optimizer": self.optimizer,
            "optimizer_options": stored_options(self.optimizer, dict(self.optimizer_options)),
            "seed": self.seed,
            # (from the attack's start only where it starts later)
            "spec": ledger.stored("spec", {"formula": self.formula, "d_safe_m": self.d_safe_m, "from_attack_start":
                                           bool(self.config.attack_start_step and self.score_from_attack_start)}),
        }
        if self.situation:  # stored where there is one: every other campaign keeps its identity
            definition["situation"] = situation.stored(self.situation)
        if self.boundary:
            definition["boundary"] = self.boundary
        return definition

    @classmethod
    def from_definition(cls, definition: dict[str, Any], samples: int = 100, where: str = "the database", *,
                        imports: bool = False) -> "Campaign":
        """The campaign a stored definition describes, with its defaults for what earlier versions did not
        store (the one reader of stored campaigns); a damaged one is a `DefinitionError` naming ``where``.

        A user's follower controller is a name only (its module is not imported: reading a database
        runs no code) unless ``imports``, for a campaign about to be simulated; then a module that does
        not import here is a ConfigError saying how to make it importable, not damage."""
        with names_only():
            named = cls._from_definition(definition, samples, where)
        if imports:
            _check_road(named.config, where)
        if not imports or not named.user_modules:
            return named
        for module in named.user_modules:
            if module not in _ANNOUNCED:  # once a process: a report replays many samples
                _ANNOUNCED.add(module)
                log.warning("%s %s (a follower controller of %s) to simulate it",
                            "loading" if module.startswith("fmu:") else "importing", module, where)
        return cls._from_definition(definition, samples, where)

    @classmethod
    def _from_definition(cls, definition: dict[str, Any], samples: int, where: str) -> "Campaign":
        try:
            attack = definition["attack"]
            config = definition["config"]  # keys later versions added, as the earlier ones played it:
            config = {**config, "scenario": ledger.restored("scenario", config.get("scenario", {}))}
            if isinstance(config.get("vehicle"), dict):  # [vehicle]'s own keys (a car's [vehicle.vI] holds what differs)
                base = {k: v for k, v in config["vehicle"].items() if not isinstance(v, dict)}
                cars = {k: v for k, v in config["vehicle"].items() if isinstance(v, dict)}
                config = {**config, "vehicle": {**ledger.restored("vehicle", base), **cars}}
            if isinstance(config.get("v2v"), dict) and "match_radar" in config["v2v"] and config.get("traffic") is None:
                # only 0.20.0 stored it without traffic: in its lane-changing maneuvers, which it matched too
                config = {**config, "v2v": {**config["v2v"], "match_in_maneuvers": True}}
            for table in ("traffic", "v2v"):
                if isinstance(config.get(table), dict):
                    config = {**config, table: ledger.restored(table, config[table])}
            controller = config.get("controller")  # the authors' options a Python controller ran with
            config = {**config, "controller": ([as_stored_ran(t) for t in controller] if isinstance(controller, list)
                                               else as_stored_ran(controller))} if controller is not None else config
            return cls(
                config=EpisodeConfig.from_dict(config),
                attack=attack["family"],
                optimizer=definition["optimizer"],
                samples=samples,
                seed=definition["seed"],
                d_safe_m=definition["spec"]["d_safe_m"],
                formula=definition["spec"]["formula"],
                attack_options=tuple((k, v) for k, v in attack.items() if k not in ("family", *MESSAGE_KEYS)),
                message=attack.get("message", ""),
                message_field=attack.get("message_field", "accel"),
                message_sender=attack.get("message_sender", 0),
                optimizer_options=tuple(ledger.restored(f"search.{definition['optimizer']}",
                                                        definition.get("optimizer_options", {})).items()),
                score_from_attack_start=ledger.restored("spec", definition["spec"])["from_attack_start"],
                situation=situation.restored(definition.get("situation", {})),
                boundary=definition.get("boundary", 0.0),
            )
        except ControllerImportError as exc:  # not damage: the database is fine, this machine lacks the module
            raise NotSimulable(f"{where}: its follower controller {exc.given} cannot be simulated here: {exc.hint}") from None
        except ConfigError as exc:
            raise DefinitionError(f"{where}: damaged results database (a campaign definition: {exc})", exc.field) from None
        except (KeyError, TypeError, AttributeError) as exc:
            raise DefinitionError(f"{where}: damaged results database (a campaign definition: {exc})") from None

    @property
    def user_modules(self) -> list[str]:
        """The users' code its follower controllers run (modules it imports, FMUs it loads) to be simulated."""
        return sorted({m for c in self.config.controllers if (m := user_code(c.cls))})

    def replace(self, **changes: Any) -> "Campaign":
        if "optimizer" in changes and "optimizer_options" not in changes:  # another optimiser: its own defaults
            changes["optimizer_options"] = ()
        return dataclasses.replace(self, **changes)

    def with_inputs_of_before(self) -> "Campaign":
        """The campaign as d4sumo 0.16 and before ran it: every input a later version changed what it does with
        (`ledger`: its road's files without a digest, its traffic entering after the warm-up without insertion
        checks, its platoon driving through red lights, ...) as it was then."""
        return self._with_earlier([e.key for e in ledger.added_after("0.16") if e.did])

    def with_inputs_of(self, version: str) -> "Campaign":
        """The campaign as d4sumo ``version`` (one of `INPUTS_CHANGED`) and before ran it (`changes_of`); itself where
        that is what it does."""
        return self._with_earlier([key for key, _, _ in self.changes_of(version)])

    def _with_earlier(self, keys) -> "Campaign":
        """The campaign with each of these keys of its scenario, traffic or channel at the value campaigns stored
        without it ran with (`ledger`); itself where that changes nothing."""
        config = self.config
        for key in keys:
            table, _, name = key.rpartition(".")
            value = THEN[key] if key in THEN else ledger.earlier(table)[name]
            if table == "scenario":
                config = dataclasses.replace(config, **{name: value})
            elif getattr(config, table, None) is not None:
                config = dataclasses.replace(config, **{table: dataclasses.replace(getattr(config, table), **{name: value})})
        return self if config == self.config else self.replace(config=config)

    def changes_of(self, version: str) -> list[tuple[str, str, str]]:
        """What d4sumo ``version`` and before did otherwise with this campaign's inputs: (the key, its value then, what
        it did), each: every key added since (`ledger`) that its definition holds, and, 0.19 and before, a folder
        holding a network file rebuilt (`EpisodeConfig.rebuild`)."""
        stored = self.config.to_dict()
        changes = [(entry.key, _flag_value(entry.earlier), entry.did) for entry in ledger.added_after(version)
                   if entry.did and entry.table in stored and entry.name in (stored[entry.table] or {})]
        if version == "0.19" and not self.config.rebuild and Path(self.config.network).is_dir():
            changes.insert(0, ("scenario.rebuild", "true", "its folder's network file rebuilt from plain XML"))
        v2v = self.config.v2v
        if (version == "0.20" and v2v is not None and v2v.match_radar and not v2v.match_in_maneuvers
                and self.config.traffic is None and self.config.maneuver_class.lateral):
            changes.append(("v2v.match_in_maneuvers", "true", "cooperative followers in a lane-changing maneuver falling "
                            "back where their radar saw another car than the beacons' sender"))
        return changes

    def with_options(self, options: dict) -> "Campaign":
        """The campaign with ``options`` of its optimiser changed (as an earlier version ran it, say)."""
        return self.replace(optimizer_options=tuple({**dict(self.optimizer_options), **options}.items()))


_SAID: set[str] = set()  # the roads played from their kept copies, said once


def _check_road(config: EpisodeConfig, where: str) -> None:
    """A campaign about to be simulated plays on the road it ran on: its network's files as they were (a
    changed road is another one, as a changed demand or FMU is another system); where they are not, the copy
    this machine kept of them when the campaign ran (`networks.keep_road`)."""
    from ..engine.networks import use_kept_road

    now = network_digest(config.network)
    if config.network_sha256 and not now and (kept := use_kept_road(config.network, config.network_sha256)):
        if config.network not in _SAID:  # once a process: a report replays many samples
            _SAID.add(config.network)
            log.warning("no road %s here: playing the copy of the road the campaign ran, kept in %s", config.network, kept)
    if config.network_sha256 and now not in ("", config.network_sha256):
        raise NotSimulable(f"{where}: its road {config.network} cannot be simulated here: its files have changed since "
                           f"the campaign ran (sha256 {config.network_sha256[:16]}..., now {now[:16]}...): another road")


def check_definition(definition: dict[str, Any], where: str) -> None:
    """A stored definition describes a valid campaign (every value checked, nothing imported), else a
    `DefinitionError` naming ``where``: the check a `Store` is given."""
    Campaign.from_definition(definition, where=where)


def open_store(path: str | Path, *, create: bool = True) -> Store:
    """A results database whose campaign definitions are checked as campaigns (`check_definition`)."""
    return Store(path, create=create, check_definition=check_definition)


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
