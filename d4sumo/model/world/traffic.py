"""Traffic around the platoon, the [traffic] table: what SUMO inserts, and how the platoon joins it.

Pure code, no SUMO. SUMO drives the traffic with its own models; d4sumo writes the demand (`demand_xml`)
and the world (`engine.sumo`) plays it:

- the user's own SUMO demand, ``demand``: route files of vehicles, flows and trips as SUMO reads them
  (sumo-rl and Flow take the same), from t = 0 of SUMO's clock. Every vehicle's id gets the prefix
  `TRAFFIC_ID` (so it never meets a platoon car's), and SUMO's insertion checks where it sets none. The
  files' content is part of the campaign (``demand_sha256``): a changed file is other traffic, and is
  refused where the campaign's is expected;
- and, or instead (the default when no demand is given: 1200), a flow of ``vehicles_per_hour`` in every
  lane of the route's first edge that leads on through the route, along the platoon's route, its
  departures a Poisson process (exponential headways, as free-flowing motorway traffic arrives); each
  vehicle is of one of the ``types`` (a share of the flow each, SUMO's <vType> attributes as given: its
  car-following and lane-changing models and their parameters; none: SUMO's default passenger car,
  Krauss and LC2013 with its speed spread);
- a warm-up of ``warmup_s`` with the traffic alone, so it is in its own equilibrium along the road when
  the platoon joins it;
- the platoon's places are then cleared: every traffic car whose body is in a lane of the platoon's,
  between ``clear_m`` behind the platoon's rear bumper and ``clear_m`` ahead of its front car, leaves;
  the platoon is inserted there, and the episode's clock (t = 0 of the trace) starts;
- SUMO's random streams (departures, speed spread, lane changes) are seeded with ``seed``: every episode
  of a configuration meets the same traffic, so a sample's score depends on its attack alone, and a
  replay reproduces it; with ``per_sample`` each sample of a campaign meets traffic of its own, seeded
  by the seed and the sample's index (`for_sample`).

The traffic inserts itself with SUMO's insertion checks (the platoon's cars are placed where they are
put). The followers sense whatever is ahead of them in their lane, a traffic car included; a collision of
a platoon car with a traffic car is the platoon's (`maneuvers.Pair`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence
from xml.sax.saxutils import quoteattr

from ... import ledger
from ...errors import ConfigError, check_int, check_number, is_number, table_of

#: the flow per lane without a demand of the user's [vehicles per hour per lane]
DEFAULT_VPH = 1200.0
#: the prefix of every traffic vehicle's id (and the name its pairs go by in the minimum gaps)
TRAFFIC_ID = "traffic"
#: a vehicle type's name: SUMO's ids allow more, a flow's id is built from it
_TYPE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
#: <vType> attributes d4sumo sets itself (the type's id)
_OWN_ATTRIBUTES = ("id",)


@dataclass(frozen=True)
class TrafficParams:
    """SUMO's traffic around the platoon, the [traffic] table (see the module)."""

    #: a Poisson flow per lane of the route's first edge [vehicles per hour per lane]; none: 1200 without a
    #: demand, no flow beside one
    vehicles_per_hour: float | None = None
    #: the user's SUMO route files (paths), their vehicles, flows and trips the traffic
    demand: tuple[str, ...] = ()
    #: the demand files' content (sha256 over them, in order), taken when they are first read: what identifies them
    demand_sha256: str = ""
    warmup_s: float = 60.0  # the traffic alone before the platoon joins it
    clear_m: float = 50.0  # traffic this close behind or ahead of the platoon, in its lanes, leaves at its insertion
    seed: int = 0  # SUMO's random streams: every episode of the configuration meets the same traffic
    #: each sample of a campaign meets traffic of its own, seeded by the seed and its index (`for_sample`)
    per_sample: bool = False
    #: vehicle types by name, each its share of the flow and SUMO <vType> attributes, as ((name, ((key,
    #: value), ...)), ...) (a mapping of tables is taken too); none: SUMO's default passenger car
    types: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    #: traffic that enters after the warm-up, with the platoon on the road, does so with SUMO's insertion
    #: checks, as in the warm-up (false: with none, as d4sumo 0.16 and before played it: a car then entered
    #: onto the one before it; their stored campaigns replay so)
    insertion_checks: bool = True
    #: several demand files (and d4sumo's flow beside them) are SUMO's route files each, which SUMO merges by
    #: departure, as ``sumo -r a,b`` does (false: one after the other in one file, as d4sumo 0.18 and before
    #: played them: the second file's vehicles entered once the first's had; their stored campaigns replay so)
    merge_by_departure: bool = True
    #: a platoon car running into a vehicle inside a junction (crossing, merging, turning across its way) is a
    #: collision, seen in 2D (`engine.junctions`); false: unseen, as d4sumo 0.18 and before played it (their
    #: stored campaigns replay so)
    junction_collisions: bool = True
    #: with an attacker that changes lanes, a traffic car edging into a platoon car's lane from the one beside
    #: it is sensed there from the moment its body crosses the line, however far past SUMO's nearest car of
    #: that lane, and a lane beside's nearest car past the platoon car's edge is sensed (`engine.neighbours`);
    #: false: as d4sumo 0.21 and before sensed them, once SUMO had them in the lane or beside (their stored
    #: campaigns replay so)
    edging_sensed: bool = True

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen dataclass)
        if self.vehicles_per_hour is not None:
            fix("vehicles_per_hour", check_number("traffic.vehicles_per_hour", self.vehicles_per_hour, 0.0, 3600.0,
                                                  "vehicles per hour per lane", low_open=True))
        if isinstance(self.demand, str):
            fix("demand", (self.demand,))
        if not isinstance(self.demand, (list, tuple)) or not all(isinstance(p, str) and p for p in self.demand):
            raise ConfigError("traffic.demand", self.demand, "SUMO route files, e.g. \"demand.rou.xml\" or a list of them")
        fix("demand", tuple(self.demand))
        if self.vehicles_per_hour is None and not self.demand:  # no demand of the user's: d4sumo's flow
            fix("vehicles_per_hour", DEFAULT_VPH)
        if self.demand and not self.demand_sha256:
            fix("demand_sha256", demand_digest(self.demand))
        if not isinstance(self.demand_sha256, str) or (self.demand_sha256 and not self.demand):
            raise ConfigError("traffic.demand_sha256", self.demand_sha256, "the digest d4sumo takes of traffic.demand (leave it out)")
        fix("warmup_s", check_number("traffic.warmup_s", self.warmup_s, 0.0, 3600.0, "seconds"))
        fix("clear_m", check_number("traffic.clear_m", self.clear_m, 0.0, 1000.0, "metres"))
        fix("seed", check_int("traffic.seed", self.seed, 0, 2**31 - 1))
        for name in ("per_sample", "insertion_checks", "merge_by_departure", "junction_collisions", "edging_sensed"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"traffic.{name}", getattr(self, name), "true or false")
        fix("types", _checked_types(self.types))
        if not self.merges:  # one route file: nothing to merge, one configuration whatever it says
            fix("merge_by_departure", True)

    @classmethod
    def from_table(cls, table: Any) -> "TrafficParams":
        return table_of(cls, table, "traffic")

    def to_dict(self) -> dict:
        """As a definition stores it: every key that has an effect (the traffic is part of what identifies
        the episode)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("types", "demand")}
        if self.vehicles_per_hour is None:
            del out["vehicles_per_hour"]
        if self.demand:
            out["demand"] = list(self.demand)
        else:
            del out["demand_sha256"]
        out = ledger.stored("traffic", out)  # keys added later, where they hold what earlier campaigns ran
        if not self.merges:  # without effect where there is one file
            out.pop("merge_by_departure", None)
        if self.types and self.vehicles_per_hour is not None:
            out["types"] = {name: dict(attributes) for name, attributes in self.types}
        return out

    @property
    def merges(self) -> bool:
        """Whether the traffic is more than one route file: several demand files, or one beside d4sumo's flow."""
        return len(self.demand) + (self.vehicles_per_hour is not None) > 1

    def for_sample(self, index: int) -> "TrafficParams":
        """The traffic sample ``index`` of a campaign meets: this one, or with ``per_sample`` its own, seeded
        by the seed and the index (a replay of the sample meets it again)."""
        if not self.per_sample:
            return self
        digest = hashlib.sha256(f"{self.seed}:{index}".encode()).digest()
        return dataclasses.replace(self, seed=int.from_bytes(digest[:4], "big") & 0x7FFFFFFF, per_sample=False)

    @property
    def label(self) -> str:
        """In a few words: ``1200 veh/h/lane, seed 0`` (the types' names where given, the demand files'; traffic
        entering without insertion checks says so)."""
        parts = [Path(p).name for p in self.demand]
        if self.vehicles_per_hour is not None:
            types = f" of {', '.join(name for name, _ in self.types)}" if self.types else ""
            parts.append(f"{self.vehicles_per_hour:g} veh/h/lane{types}")
        return (f"{' + '.join(parts)}, seed {self.seed}" + (" per sample" if self.per_sample else "")
                + ("" if self.insertion_checks else ", entering unchecked"))  # as 0.16 played it: another experiment

    @property
    def type_shares(self) -> list[tuple[str, float, dict[str, Any]]]:
        """Each vehicle type: its name, its share of the flow (they sum to 1) and its <vType> attributes."""
        types = self.types or (("car", (("share", 1.0),)),)
        total = sum(dict(a).get("share", 1.0) for _, a in types)
        return [(name, dict(a).get("share", 1.0) / total, {k: v for k, v in a if k != "share"}) for name, a in types]


def _checked_types(types: Any) -> tuple:
    if isinstance(types, Mapping):
        types = tuple(types.items())
    if not isinstance(types, (list, tuple)):
        raise ConfigError("traffic.types", types, "tables of vehicle types, e.g. [traffic.types.car] share = 0.9")
    out = []
    for item in types:
        if not (isinstance(item, (list, tuple)) and len(item) == 2):
            raise ConfigError("traffic.types", types, "tables of vehicle types, e.g. [traffic.types.car] share = 0.9")
        name, attributes = item
        if not isinstance(name, str) or not _TYPE_NAME.match(name):
            raise ConfigError(f"traffic.types.{name}", name, "a type name of letters, digits and _ (a letter first, at most 32)")
        if isinstance(attributes, Mapping):
            attributes = tuple(attributes.items())
        if not isinstance(attributes, (list, tuple)):
            raise ConfigError(f"traffic.types.{name}", attributes, "a table of share and SUMO <vType> attributes")
        checked = []
        for key, value in attributes:
            field = f"traffic.types.{name}.{key}"
            if key == "share":
                value = check_number(field, value, 0.0, 1e6, "(its part of the flow)", low_open=True)
            elif key in _OWN_ATTRIBUTES:
                raise ConfigError(field, value, "a <vType> attribute other than id (the table's name is the type's)")
            elif not isinstance(key, str) or not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", key):
                raise ConfigError(field, value, "a SUMO <vType> attribute, e.g. carFollowModel, tau, speedFactor, lcStrategic")
            elif not (isinstance(value, str) or is_number(value)) or isinstance(value, bool):
                raise ConfigError(field, value, "a number or a string, as SUMO's <vType> attribute reads it")
            checked.append((key, value))
        out.append((name, tuple(sorted(checked))))
    names = [name for name, _ in out]
    if len(set(names)) != len(names):
        raise ConfigError("traffic.types", names, "types of distinct names")
    return tuple(sorted(out))


def demand_digest(paths: Sequence[str]) -> str:
    """sha256 over the demand files' bytes, in order; an unreadable file is a ConfigError naming it."""
    digest = hashlib.sha256()
    for path in paths:
        try:
            digest.update(Path(path).read_bytes())
        except OSError as exc:
            raise ConfigError("traffic.demand", path, f"a readable SUMO route file ({exc.strerror or exc})") from None
        digest.update(b"\0")
    return digest.hexdigest()


#: the demand elements that are vehicles (or make them): their ids get the traffic's prefix
_VEHICLE_TAGS = ("vehicle", "flow", "trip")


def user_demand_xml(path: str) -> list[str]:
    """A user's route file as the traffic plays it: every vehicle's, flow's and trip's id prefixed with
    `TRAFFIC_ID` (a "-" in it an "_": pairs are named "leader-follower"), and SUMO's insertion checks
    where it sets none (d4sumo places the platoon's cars without them). A file that does not parse is a
    ConfigError naming it and the place. Returns the file's elements, each as XML."""
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise ConfigError("traffic.demand", path, f"a SUMO route file that parses (XML: {exc})") from None
    except OSError as exc:
        raise ConfigError("traffic.demand", path, f"a readable SUMO route file ({exc.strerror or exc})") from None
    root = tree.getroot()
    if root.tag != "routes":
        raise ConfigError("traffic.demand", path, f"a SUMO route file, its root <routes> (this one's is <{root.tag}>)")
    for element in root.iter():
        if element.tag in _VEHICLE_TAGS:
            element.set("id", f"{TRAFFIC_ID}.{element.get('id', '').replace('-', '_')}")
            element.attrib.setdefault("insertionChecks", "all")
    return [ET.tostring(child, encoding="unicode").strip() for child in root]


def demand_xml(params: TrafficParams, route_edges: Sequence[str], lanes: Sequence[int], end_s: float) -> str:
    """The traffic's demand in one route file, as d4sumo 0.18 and before wrote it: the user's demand files'
    elements one file after the other, then d4sumo's flow (`demand_files_xml`)."""
    _check_demand_content(params)
    return _routes([line for path in params.demand for line in _user_lines(path)]
                   + _flow_lines(params, route_edges, lanes, end_s))


def demand_files_xml(params: TrafficParams, route_edges: Sequence[str], lanes: Sequence[int], end_s: float) -> list[str]:
    """The traffic's demand as SUMO reads it: one route file for each of the user's demand files
    (`user_demand_xml`), which SUMO merges by departure as ``sumo -r a,b`` does, then one of d4sumo's flow
    where there is one: its vehicle types as one distribution, its route (the platoon's), and a flow per lane
    of the first edge (``lanes``, SUMO's indices) from t = 0 to ``end_s``. Without ``merge_by_departure``, all
    of it in one file, one after the other (`demand_xml`). Every traffic vehicle's id starts with
    `TRAFFIC_ID`. A demand file whose content is not the campaign's (``params.demand_sha256``) is refused."""
    if not params.merge_by_departure or not params.merges:
        return [demand_xml(params, route_edges, lanes, end_s)]
    _check_demand_content(params)
    files = [_routes(_user_lines(path)) for path in params.demand]
    flow = _flow_lines(params, route_edges, lanes, end_s)
    return files + ([_routes(flow)] if flow else [])


def _check_demand_content(params: TrafficParams) -> None:
    if params.demand and demand_digest(params.demand) != params.demand_sha256:
        raise ConfigError("traffic.demand", list(params.demand), "the demand files this campaign was run with (their "
                                                                  "content has changed since: other traffic)")


def _user_lines(path: str) -> list[str]:
    return [f"    {element}" for element in user_demand_xml(path)]


def _flow_lines(params: TrafficParams, route_edges: Sequence[str], lanes: Sequence[int], end_s: float) -> list[str]:
    """d4sumo's flow, where there is one, as the lines of a route file."""
    if params.vehicles_per_hour is None:
        return []
    shares = params.type_shares
    lines = [f"    {element}" for element in type_elements(params)]
    distribution = " ".join(f"{TRAFFIC_ID}_{name}" for name, _, _ in shares)
    probabilities = " ".join(repr(p) for _, p, _ in shares)
    lines.append(f'    <vTypeDistribution id="{TRAFFIC_ID}" vTypes="{distribution}" probabilities="{probabilities}"/>')
    lines.append(f'    <route id="{TRAFFIC_ID}" edges={quoteattr(" ".join(route_edges))}/>')
    for lane in lanes:
        # insertionChecks: the traffic enters only where SUMO's models find room (the platoon's cars are placed)
        lines.append(f'    <flow id="{TRAFFIC_ID}.{lane}" type="{TRAFFIC_ID}" route="{TRAFFIC_ID}" begin="0" end={quoteattr(repr(end_s))} '
                     f'period="exp({params.vehicles_per_hour / 3600.0!r})" departLane="{lane}" departPos="base" '
                     f'departSpeed="max" insertionChecks="all"/>')
    return lines


def _routes(lines: list[str]) -> str:
    return "\n".join(["<routes>", *lines, "</routes>"]) + "\n"


def type_elements(params: TrafficParams) -> list[str]:
    """The <vType> elements of d4sumo's flow, one per type of [traffic.types] (SUMO's default car without)."""
    return [f'<vType id="{TRAFFIC_ID}_{name}"' + "".join(f" {k}={quoteattr(_sumo_value(v))}" for k, v in attributes.items()) + "/>"
            for name, _, attributes in params.type_shares]


def _sumo_value(value: Any) -> str:
    return repr(float(value)) if is_number(value) and not isinstance(value, int) else str(value)


def is_traffic(vehicle_id: str) -> bool:
    """Whether a vehicle id is a traffic car's (`demand_xml`)."""
    return vehicle_id.startswith(TRAFFIC_ID + ".")
