"""What each version of d4sumo stored: the one ledger of the keys added to a campaign's stored definition after
campaigns were stored without them.

A campaign is identified by its definition (`search.store.campaign_key`). A key added later would change the
identity of every campaign stored before it, which then would not resume, so each such key is left out of a
definition where it holds the value the campaigns stored without it ran with (`stored`), and a definition read
back without it gets that value again (`restored`). For each key the ledger says when it was added, that
value, and what those versions did, in words: the lines that tell how to go on with a campaign an earlier
version ran come from it too (`search.campaign.Campaign.changes_of`).

Tables: ``scenario``, ``vehicle``, ``traffic``, ``v2v``, ``spec``, and ``search.NAME`` for the options of
optimiser NAME. Pure data, no imports from the package: every layer reads it.

tests/search/test_releases.py holds the databases each release wrote: every campaign keeps its definition and
identity byte for byte, whatever this ledger becomes. A key's version is that of the first release that stores it
(a release: the commit that set its version, after the work that went into it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: the releases, oldest first: the versions a ledger entry may name
RELEASES = ("0.2", "0.3", "0.4", "0.5", "0.6", "0.7", "0.8", "0.9", "0.10", "0.10.1", "0.11", "0.12", "0.13", "0.14",
            "0.15", "0.16", "0.17", "0.18", "0.19", "0.20", "0.21", "0.22")


@dataclass(frozen=True)
class Added:
    """A key a definition holds since version ``since``; the campaigns stored without it ran with ``earlier``
    (``did``: what they did, in words, for the line that says how to go on with one)."""

    key: str  # "table.name"
    since: str
    earlier: Any
    did: str = ""

    @property
    def table(self) -> str:
        return self.key.rpartition(".")[0]

    @property
    def name(self) -> str:
        return self.key.rpartition(".")[2]


LEDGER = (
    # [scenario]
    Added("scenario.attacker_cruise_offset_mps", "0.6", 0.0),
    Added("scenario.end_distance_m", "0.6", 0.0),
    Added("scenario.collision_gap_m", "0.6", 0.0),
    Added("scenario.route", "0.6", ()),
    Added("scenario.lane", "0.12", None),
    Added("scenario.network_sha256", "0.17", "", "a road of one's own taken as found"),
    Added("scenario.rebuild", "0.19", True, "its network file rebuilt from plain XML"),
    Added("scenario.signals", "0.19", "ignore", "the platoon driving through red lights"),
    Added("scenario.additional", "0.19", ()),
    Added("scenario.additional_sha256", "0.19", ""),
    Added("scenario.sumo_options", "0.19", ()),
    Added("scenario.join_m", "0.19", 10.0),  # where every earlier platoon's rear started
    # [spec]
    Added("spec.from_attack_start", "0.12", False, "scored over the whole episode, its warm-up included"),
    # [vehicle]
    Added("vehicle.coast_decel_mps2", "0.6", 0.0),
    Added("vehicle.vclass", "0.6", "passenger"),
    Added("vehicle.shape", "0.6", ""),
    # [traffic]
    Added("traffic.per_sample", "0.14", False),
    Added("traffic.insertion_checks", "0.17", False, "traffic entering after the warm-up unchecked"),
    Added("traffic.merge_by_departure", "0.19", False, "its demand files one after the other"),
    Added("traffic.junction_collisions", "0.19", False, "collisions inside junctions unseen"),
    Added("traffic.edging_sensed", "0.22", False, "traffic edging into a lane sensed once SUMO had it in the lane, and none "
                                                   "beside past a car's own edge"),
    # [v2v]
    Added("v2v.match_radar", "0.20", False, "cooperative followers reading the beacons whatever their radar saw"),
    # the optimisers' options
    Added("search.bo.batch_size", "0.3", 1, "one point proposed per score"),
    Added("search.bo.gp_version", "0.4", 1, "scikit-optimize's GP"),
    Added("search.bo.inducing", "0.8", 0, "the exact GP however many scores"),
    Added("search.ce.noise_fraction", "0.5", 0.0, "no noise"),
    Added("search.auto.version", "0.8", 1, "uniform exploration"),
    Added("search.auto.stall", "0.9", 0, "no piece moves through stalls"),
    Added("search.auto.suffix", "0.10", 0.0, "no suffix moves"),
    Added("search.auto.patience", "0.10.1", 0, "exploring from the design on"),
    Added("search.auto.per_signal", "0.11", 0, "held sampling across signals"),
    # 0.7's auto stored it (256); it was gone from 0.8 to 0.19, which learned from bo's 128
    Added("search.auto.learn_points", "0.20", 128, "the GP's kernel learned from 128 scores"),
    Added("search.bo.edges", "0.22", 0.0),  # (its default: none of the candidates held at the box's bounds)
    Added("search.auto.edges", "0.22", 0.0),
    Added("search.bo.novelty", "0.22", 0.0),  # (its default: no proposal kept apart from the attacks found)
    Added("search.auto.novelty", "0.22", 0.0),
)



@dataclass(frozen=True)
class Was:
    """A key whose default changed after version ``until``: the campaigns ``until`` and before ran by default
    stored ``value`` (the key holds it, so nothing is restored; only finding such a campaign again needs it)."""

    key: str  # "table.name"
    until: str
    value: Any


DEFAULTS_CHANGED = (
    # 0.7 released auto with the inducing points and the kernel's learning at 256, its last commit at 128
    Was("search.auto.inducing", "0.7", 256),
    Was("search.auto.learn_points", "0.7", 256),
)

_BY_TABLE: dict[str, dict[str, Added]] = {}
for _entry in LEDGER:
    _BY_TABLE.setdefault(_entry.table, {})[_entry.name] = _entry


def earlier(table: str) -> dict[str, Any]:
    """Each key of ``table`` added later, with the value the campaigns stored without it ran with."""
    return {name: entry.earlier for name, entry in _BY_TABLE.get(table, {}).items()}


def stored(table: str, values: dict[str, Any]) -> dict[str, Any]:
    """``values`` as a definition holds them: without the keys added later that hold their earlier value."""
    added = _BY_TABLE.get(table, {})
    return {k: v for k, v in values.items() if not (k in added and _same(v, added[k].earlier))}


def restored(table: str, held: dict[str, Any]) -> dict[str, Any]:
    """A stored table with every key added later that it lacks, at the value its campaign ran with."""
    return {**earlier(table), **held}


def added_after(version: str) -> list[Added]:
    """The keys added after ``version`` (one of `RELEASES`), in the ledger's order."""
    return [entry for entry in LEDGER if newer(entry.since, version)]


def as_ran(table: str) -> tuple[dict[str, Any], ...]:
    """How the campaigns each earlier release stored ran ``table``'s keys added after it and those whose default
    it had otherwise, newest release first, each distinct set once: the values that give back what it did."""
    sets: list[dict[str, Any]] = []
    for version in reversed(RELEASES):
        then = {entry.name: entry.earlier for entry in added_after(version) if entry.table == table}
        then.update({was.key.rpartition(".")[2]: was.value for was in DEFAULTS_CHANGED
                     if was.key.rpartition(".")[0] == table and not newer(version, was.until)})
        if then and then not in sets:
            sets.append(then)
    return tuple(sets)


def newer(version: str, than: str) -> bool:
    return RELEASES.index(version) > RELEASES.index(than)


def _same(value: Any, earlier_value: Any) -> bool:
    """Whether a value is the earlier one: a list is the tuple it reads as, a bool never the number it equals."""
    if isinstance(value, list):
        value = tuple(value)
    return type(value) is type(earlier_value) and value == earlier_value if isinstance(earlier_value, bool) \
        else value == earlier_value and not isinstance(value, bool)
