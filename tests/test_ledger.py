"""The ledger of keys added to stored definitions (`d4sumo.ledger`): pure, no SUMO."""

from __future__ import annotations

import dataclasses
import json

import pytest

from d4sumo import ledger
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.world.traffic import TrafficParams
from d4sumo.model.world.v2v import ChannelParams
from d4sumo.model.world.vehicle import VehicleParams
from d4sumo.search.optimizers import OPTIMIZERS, resolve_options

TABLES = {"scenario": EpisodeConfig, "vehicle": VehicleParams, "traffic": TrafficParams, "v2v": ChannelParams}


@pytest.mark.parametrize("entry", ledger.LEDGER, ids=lambda e: e.key)
def test_each_key_the_ledger_names_is_one_a_definition_may_hold_since_a_release(entry):
    assert entry.since in ledger.RELEASES
    if entry.table in TABLES:
        assert entry.name in {f.name for f in dataclasses.fields(TABLES[entry.table])}
    elif entry.table == "spec":
        assert entry.name == "from_attack_start"
    else:
        optimizer = entry.table.removeprefix("search.")
        assert optimizer in OPTIMIZERS and entry.name in resolve_options(optimizer, {})


def test_a_key_at_its_earlier_value_is_left_out_and_given_back_and_a_bool_is_never_the_number_it_equals():
    assert ledger.stored("traffic", {"seed": 0, "insertion_checks": False, "per_sample": True}) == {"seed": 0, "per_sample": True}
    assert ledger.restored("traffic", {"seed": 0})["insertion_checks"] is False
    assert ledger.stored("scenario", {"route": [], "lane": None, "rebuild": True, "signals": "obey"}) == {"signals": "obey"}
    assert ledger.stored("search.auto", {"per_signal": 0, "stall": False}) == {"stall": False}  # False is no option's 0
    assert [e.key for e in ledger.added_after("0.19")] == ["traffic.edging_sensed", "v2v.match_radar", "search.auto.learn_points",
                                                         "search.bo.edges", "search.auto.edges", "search.bo.novelty", "search.auto.novelty"]


def test_every_default_campaign_of_today_holds_no_key_at_its_earlier_value():
    """What identity leaves out comes from the ledger alone: a definition never holds a key at the value campaigns
    stored without it ran with."""
    from d4sumo.search.campaign import Campaign

    for config in (EpisodeConfig(), EpisodeConfig(start="steady", traffic={}),
                   EpisodeConfig(start="steady", maneuver="cutin", controller=ControllerConfig("cacc"))):
        definition = Campaign(config=config).definition()
        for entry in ledger.LEDGER:
            held = (definition["config"].get(entry.table) if entry.table in TABLES else
                    definition["optimizer_options"] if entry.table == f"search.{definition['optimizer']}" else
                    definition.get(entry.table))
            if isinstance(held, dict) and entry.name in held:
                assert held[entry.name] != entry.earlier, entry.key


def test_as_ran_gives_each_releases_values_newest_first_with_the_defaults_it_had_otherwise():
    assert ledger.as_ran("search.ce") == ({"noise_fraction": 0.0},)
    sets = ledger.as_ran("search.auto")
    new = {"edges": 0.0, "novelty": 0.0}  # the options 0.22 added
    assert sets[0] == new and sets[1] == {"learn_points": 128, **new}  # 0.21's, 0.20's
    assert sets[2] == {"per_signal": 0, "learn_points": 128, **new}
    assert sets[-1] == {"version": 1, "stall": 0, "suffix": 0.0, "patience": 0, "per_signal": 0, "learn_points": 256,
                        "inducing": 256, **new}  # 0.7's, which ran 256 of each by default
    assert len(sets) == len({json.dumps(s, sort_keys=True) for s in sets})
    assert ledger.as_ran("scenario")[-1]["signals"] == "ignore" and ledger.as_ran("nothing") == ()


@pytest.mark.parametrize("was", ledger.DEFAULTS_CHANGED, ids=lambda w: w.key)
def test_each_changed_default_names_a_release_and_a_key_of_the_ledgers_tables(was):
    assert was.until in ledger.RELEASES and was.key.count(".") >= 1
