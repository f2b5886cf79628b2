"""An episode's configuration as a campaign's definition stores it, and back: its [scenario], [vehicle],
[controller], [radar], [traffic] and [v2v] tables. What identity leaves out (a key without effect, a key
added later where it holds what earlier campaigns ran: `ledger`) is decided here, once.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from .. import ledger
from ..errors import ConfigError, check_keys
from .controllers.table import ControllerConfig
from .attacks.maneuvers import MANEUVERS as MANEUVER_CLASSES
from .world.network import is_network_path
from .world.sensing import RadarParams
from .world.traffic import TrafficParams
from .world.v2v import ChannelParams
from .world.vehicle import VehicleParams

#: the fields of EpisodeConfig that are tables of their own, not [scenario] keys
TABLES = ("vehicle", "vehicles", "controller", "radar", "traffic", "v2v")
#: [scenario] keys that identify a campaign's inputs (its road's files' digest), not describe its scenario
IDENTITY_KEYS = ("network_sha256", "additional_sha256")


def stored(config) -> dict:
    """``config`` (an `config.EpisodeConfig`) as a definition stores it."""
    scenario = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name not in TABLES}
    # Keys without effect are not part of what identifies the episode.
    if config.start != "warmup":
        del scenario["warmup_s"]
    if not config.sumo_driven:  # only SUMO's models read what the attacker declares
        del scenario["attacker_declared_decel_mps2"]
    for key in {k for m in MANEUVER_CLASSES.values() for k in m.settings} - set(config.maneuver_class.settings):
        del scenario[key]  # a maneuver's settings have no effect on another
    scenario = ledger.stored("scenario", scenario)  # keys added later, where they hold what earlier campaigns ran
    if "route" in scenario:
        scenario["route"] = list(scenario["route"])
    if not is_network_path(config.network):  # d4sumo's own roads have no traffic lights: one configuration
        scenario.pop("signals", None)
    if "additional" in scenario:
        scenario["additional"] = list(scenario["additional"])
    if "sumo_options" in scenario:
        scenario["sumo_options"] = dict(scenario["sumo_options"])
    controller = (config.controller.to_dict() if isinstance(config.controller, ControllerConfig)
                  else [c.to_dict() for c in config.controller])
    vehicle = config.vehicle.to_dict()
    vehicle.update({car: dict(differs) for car, differs in config.vehicles})  # [vehicle.vI]: where a car differs
    out = {"scenario": scenario, "vehicle": vehicle, "controller": controller}
    if config.radar is not None:  # stored where there is one: earlier campaigns keep their identity
        out["radar"] = config.radar.to_dict()
    if config.traffic is not None:
        out["traffic"] = config.traffic.to_dict()
        if not is_network_path(config.network):  # d4sumo's own roads are one edge: no junction to look into
            out["traffic"].pop("junction_collisions", None)
    if config.v2v is not None:
        out["v2v"] = config.v2v.to_dict()
        if not config.others_cut_in:  # what campaigns stored before it was a key hold (`ledger`), and the same
            out["v2v"].pop("match_radar", None)
    return out


def tables(doc: Mapping[str, Any], scenario_keys: list[str]) -> dict[str, Any]:
    """An EpisodeConfig's arguments from the [scenario], [vehicle] and [controller] tables of a document (the
    [scenario] keys being ``scenario_keys``); [controller] may be a list of tables (TOML's [[controller]]) or
    names, one per follower."""
    tables = {name: dict(_table(doc, name)) for name in ("scenario", "vehicle")}
    check_keys("scenario", tables["scenario"], scenario_keys)
    if tables["scenario"].get("route", None) == []:  # left out (or restored: ()), the network's one chain; given, edges
        raise ConfigError("scenario.route", [], "a list of one edge id or more, e.g. [\"e1\", \"e2\"] (leave it out "
                                                "for a network of one chain of edges)")
    # [vehicle.vI]: a car's own table (the config checks the car); any other key is one of [vehicle]
    keys = [f.name for f in dataclasses.fields(VehicleParams)]
    cars = {k: tables["vehicle"].pop(k) for k in list(tables["vehicle"])
            if isinstance(tables["vehicle"][k], Mapping) and k not in keys}
    check_keys("vehicle", tables["vehicle"], keys + ["vI (a car's own table)"])
    given = doc.get("controller", {})
    if isinstance(given, (list, tuple)):
        controller: Any = tuple(ControllerConfig.from_table(t, f"controller.v{i}") for i, t in enumerate(given, 1))
    else:
        controller = ControllerConfig.from_table(_table(doc, "controller"))
    radar = RadarParams.from_table(doc["radar"]) if doc.get("radar") is not None else None
    traffic = TrafficParams.from_table(doc["traffic"]) if doc.get("traffic") is not None else None
    v2v = ChannelParams.from_table(doc["v2v"]) if doc.get("v2v") is not None else None
    return dict(**tables["scenario"], vehicle=VehicleParams(**tables["vehicle"]), vehicles=tuple(cars.items()),
                controller=controller, radar=radar, traffic=traffic, v2v=v2v)


def _table(doc: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    value = doc.get(name, {})
    if not isinstance(value, Mapping):
        raise ConfigError(f"[{name}]", value, "a table")
    return value
