"""A sweep file: the grid of campaigns it describes, each built and checked before anything runs."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..engine.scenarios import build_road
from ..engine.simulation import check_episode, check_traffic
from ..errors import ConfigError
from ..inputs import campaign_of, check_document, with_overrides
from ..tomlfiles import read_toml
from ..model.attacks.maneuvers import MANEUVERS
from ..search.campaign import Campaign
from ..search.optimizers import DEFAULT_OPTIMIZER, EARLIER_DEFAULT_OPTIMIZER
from ..search.store import campaign_key

log = logging.getLogger(__name__)

SCENARIO_GRID_KEYS = ("network", "followers", "setpoint_m", "speed_mps", "start",
                      *dict.fromkeys(k for m in MANEUVERS.values() for k in m.settings))  # maneuver, cutin_follower, ...
GRID_KEYS = (*SCENARIO_GRID_KEYS, "controller", "radar", "traffic", "v2v", "attack", "optimizer", "seed")
#: a grid axis -> the document key it sets (a controller replaces the whole [controller]: a name, a
#: table, or a list of them for a mixed platoon)
GRID_TO_KEY = {**{k: f"scenario.{k}" for k in SCENARIO_GRID_KEYS}, "controller": "controller", "radar": "radar",
               "traffic": "traffic", "v2v": "v2v", "attack": "attack.family",
               "optimizer": "search.optimizer", "seed": "search.seed"}


def _unused_settings_only(a: dict, b: dict, campaign: Campaign) -> bool:
    """Whether two grid points differ only in maneuver settings the campaign's maneuver does not read
    (a cut-in's offset for the in-lane attack): the same campaign, counted once."""
    used = set(campaign.config.maneuver_class.settings)
    settings = {f"scenario.{k}" for m in MANEUVERS.values() for k in m.settings}
    differ = {k for k in a if a[k] != b[k]}
    return bool(differ) and all(k in settings and k.removeprefix("scenario.") not in used for k in differ)


def part_text(part) -> str:
    """`` (part K of N)`` for a sweep's part (k, n), as a sweep or a database's record holds it; "" for none."""
    return f" (part {part[0]} of {part[1]})" if part else ""


@dataclass(frozen=True)
class Sweep:
    name: str
    campaigns: tuple[Campaign, ...]
    part: tuple[int, int] | None = None  # (k, n): part k of n (`part_of`)

    def part_of(self, text: str) -> "Sweep":
        """Part ``K/N`` of the sweep (1 <= K <= N <= its campaigns): every N-th campaign of the grid from the
        K-th on, for one of N clients that share it, each with its own database (`d4sumo report` reads them
        together). A part's grid is its own: its database is refused to another part."""
        k, slash, n = text.partition("/") if isinstance(text, str) else ("", "", "")
        if not (slash and k.strip().isdigit() and n.strip().isdigit() and 1 <= int(k) <= int(n) <= len(self.campaigns)):
            raise ConfigError("--part", text, f"K/N with 1 <= K <= N <= {len(self.campaigns)} (the sweep's campaigns), "
                                              "e.g. 2/4")
        k, n = int(k), int(n)
        return dataclasses.replace(self, campaigns=self.campaigns[k - 1::n], part=(k, n))

    @property
    def label(self) -> str:
        """The sweep's name, and its part where it is one: as the lines about a database name it."""
        return repr(self.name) + part_text(self.part)

    @property
    def samples(self) -> int:
        return sum(c.samples for c in self.campaigns)

    def fingerprint(self) -> str:
        """Identifies the grid (not the budget): the same sweep may be resumed or extended."""
        keys = sorted(campaign_key(c.definition()) for c in self.campaigns)
        return hashlib.sha256(json.dumps(keys).encode()).hexdigest()[:20]

    def as_run_before(self, optimizer: str, earlier: dict) -> "Sweep":
        """The sweep with ``earlier`` options (`optimizers.EARLIER_OPTIONS`) for every ``optimizer`` campaign."""
        return dataclasses.replace(self, campaigns=tuple(
            c.with_options(earlier) if c.optimizer == optimizer else c for c in self.campaigns))

    def with_inputs_of_before(self) -> "Sweep":
        """The sweep as d4sumo 0.16 and before ran it: its roads' files without a digest, its traffic entering
        after the warm-up without insertion checks, its platoons driving through red lights (`ledger`)."""
        campaigns = tuple(c.with_inputs_of_before() for c in self.campaigns)
        return self if campaigns == self.campaigns else dataclasses.replace(self, campaigns=campaigns)

    def with_inputs_of(self, version: str) -> "Sweep":
        """The sweep as d4sumo ``version`` and before ran it (`Campaign.with_inputs_of`)."""
        campaigns = tuple(c.with_inputs_of(version) for c in self.campaigns)
        return self if campaigns == self.campaigns else dataclasses.replace(self, campaigns=campaigns)

    def with_default_of_before(self) -> "Sweep":
        """The sweep as d4sumo 0.7 and before ran it where the file names no optimiser: every campaign of
        today's default optimiser, with its default options, run by the earlier default instead."""
        default = Campaign(optimizer=DEFAULT_OPTIMIZER).optimizer_options
        campaigns = tuple(c.replace(optimizer=EARLIER_DEFAULT_OPTIMIZER)
                          if c.optimizer == DEFAULT_OPTIMIZER and c.optimizer_options == default else c for c in self.campaigns)
        return self if campaigns == self.campaigns else dataclasses.replace(self, campaigns=campaigns)

    @classmethod
    def load(cls, path: str | Path) -> "Sweep":
        path = Path(path)
        doc = read_toml(path, "SWEEP")
        return cls.from_dict(doc, default_name=path.stem, source=path.name)

    @classmethod
    def from_dict(cls, doc: dict[str, Any], default_name: str = "sweep", source: str = "sweep") -> "Sweep":
        check_document(doc, source, extra_keys=("name", "grid"))
        name = doc.get("name", default_name)
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(f"{source}: name", name, "a non-empty string")
        grid = doc.get("grid")
        if not isinstance(grid, dict) or not grid:
            raise ConfigError(f"{source}: [grid]", "missing" if grid is None else grid, f"a table of lists over {', '.join(GRID_KEYS)}")
        for key, values in grid.items():
            if key not in GRID_KEYS:
                raise ConfigError(f"grid.{key}", values, f"a key of [grid]: {', '.join(GRID_KEYS)}")
            if not isinstance(values, list) or not values:
                raise ConfigError(f"grid.{key}", values, "a non-empty list")
            if len(set(map(repr, values))) != len(values):
                raise ConfigError(f"grid.{key}", values, "a list without repeated values")
        base = {k: v for k, v in doc.items() if k not in ("name", "grid")}
        for table in ("radar", "traffic", "v2v"):
            if table in grid and table in base:
                raise ConfigError(f"{source}: [{table}]", base[table], f"no [{table}] table beside grid.{table}, which sets it for every campaign")
        if "controller" in grid and "controller" in base:
            raise ConfigError(f"{source}: [controller]", base["controller"],
                              "no [controller] beside grid.controller: give each controller's values in the grid")
        for axis in grid:  # the grid would win silently over a fixed value of the same key
            table, _, key = GRID_TO_KEY[axis].partition(".")
            if key and isinstance(base.get(table), dict) and key in base[table]:
                raise ConfigError(f"{source}: [{table}] {key}", base[table][key],
                                  f"no fixed value beside grid.{axis}, which sets it for every campaign")
        campaigns, points, merged = [], {}, []
        for values in itertools.product(*grid.values()):
            point = {GRID_TO_KEY[k]: v for k, v in zip(grid, values)}
            try:
                campaign = campaign_of(with_overrides(base, point))
            except ConfigError as exc:  # one grid point's: say which
                raise ConfigError(f"{source}: grid point {point}: {exc.field}", exc.given, exc.allowed) from None
            key = campaign_key(campaign.definition())
            if key in points:
                if _unused_settings_only(points[key], point, campaign):  # inlane x cutin_offset_m: one inlane campaign
                    merged.append((points[key], point))
                    continue
                # e.g. a controller's defaults written out, or one table per follower alike
                raise ConfigError(f"{source}: [grid]", f"{points[key]} and {point}", "grid points that are different campaigns")
            points[key] = point
            campaigns.append(campaign)
        read = {f"scenario.{k}" for c in campaigns for k in c.config.maneuver_class.settings}
        for a, b in merged:  # an axis no maneuver of the grid reads changes nothing at all: a mistake
            if any(a[k] != b[k] and k not in read for k in a):
                raise ConfigError(f"{source}: [grid]", f"{a} and {b}", "grid points that are different campaigns")
        return cls(name=name.strip(), campaigns=tuple(campaigns))

    def check(self) -> None:
        """Build every road and check every campaign fits it, and every formula parses: before running."""
        roads = {}
        for c in self.campaigns:
            key = c.config.network, c.config.route, c.config.lane, c.config.whole_network, c.config.network_given  # whole: a demand drives it all
            if key not in roads:
                roads[key] = build_road(c.config.network, route=c.config.route, lane=c.config.lane,
                                         whole=c.config.whole_network, given=c.config.network_given)
            check_episode(c.config, roads[key])
            check_traffic(c.config, roads[key])
        seen = set()
        for c in self.campaigns:
            key = (c.config.followers, c.config.step_s, c.config.total_s, c.formula, c.d_safe_m, c.config.maneuver)
            if key not in seen:
                seen.add(key)
                c.specification()
