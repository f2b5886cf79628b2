"""Locating the boundary between safe and unsafe situations (`optimizers.boundary`, ``[search] boundary``): which
samples are spent so, where they go, and that the optimiser beside them proposes what it would alone. No SUMO but
the last test's."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from d4sumo.cli import main
from d4sumo.errors import ConfigError
from d4sumo.inputs import campaign_of
from d4sumo.results.failure_map import failure_maps
from d4sumo.results.records import Record
from d4sumo.search.campaign import Campaign
from d4sumo.search.optimizers import make_optimizer
from d4sumo.search.optimizers.boundary import BLOCK, BoundarySearch
from d4sumo.search.situation import locating
from d4sumo.search.store import Store

LOWER, UPPER = np.array([-1.0, -1.0, -1.0, 3.0, 20.0]), np.array([1.0, 1.0, 1.0, 15.0, 30.0])  # 3 attack, 2 situation


def _score(x: np.ndarray) -> float:
    """An attack succeeds (positive) at setpoints under 8 m, however it drives."""
    return 1.0 if x[3] < 8.0 else -1.0


def _locate(share: float, budget: int, one_at_a_time: bool, inner: str = "random") -> tuple[list, BoundarySearch]:
    rng = np.random.default_rng(0)
    opt = BoundarySearch(make_optimizer(inner, LOWER, UPPER, budget=max(1, BoundarySearch.inner_budget(budget, share)), rng=rng),
                         LOWER, UPPER, budget, np.random.default_rng((0, 1)), situation=2, share=share)
    asked = []
    while opt.asked < budget:
        xs = [opt.ask()] if one_at_a_time else [opt.ask() for _ in range(min(opt.ready(), budget - opt.asked))]
        assert xs, "ready() said nothing may be asked with nothing outstanding"
        for x in xs:
            opt.tell(x, _score(x))
        asked += xs
    return asked, opt


def test_the_samples_spent_locating_are_an_even_share_of_the_budget():
    assert [i for i in range(12) if locating(i, 0.25)] == [3, 7, 11]
    assert all(locating(i, 1.0) for i in range(50)) and not any(locating(i, 0.0) for i in range(50))
    for share in (0.1, 0.3, 0.5, 0.9):
        assert sum(locating(i, share) for i in range(1000)) == int(1000 * share)
    assert BoundarySearch.inner_budget(100, 0.3) == 70


@pytest.mark.parametrize("inner", ["random", "ce"])
def test_asked_a_batch_at_a_time_it_asks_what_it_asks_one_score_at_a_time(inner):
    """ready(): every locating point of a batch is what it would ask with all earlier scores told, beside an optimiser
    whose own points are so too (a campaign asks what ready() allows, however many episodes then share a SUMO)."""
    batched, _ = _locate(0.4, 90, one_at_a_time=False, inner=inner)
    alone, _ = _locate(0.4, 90, one_at_a_time=True, inner=inner)
    assert len(batched) == 90 and all(np.array_equal(a, b) for a, b in zip(batched, alone))


def test_the_optimiser_beside_it_proposes_what_it_would_alone():
    asked, opt = _locate(0.3, 100, one_at_a_time=False)
    own = [x for i, x in enumerate(asked) if not locating(i, 0.3)]
    alone = make_optimizer("random", LOWER, UPPER, budget=70, rng=np.random.default_rng(0))
    assert all(np.array_equal(x, alone.ask()) for x in own) and len(opt.inner.y) == 70


def test_the_samples_spent_locating_gather_at_the_boundary_with_random_attacks():
    asked, opt = _locate(1.0, 160, one_at_a_time=False)
    first, later = np.array(asked[:BLOCK]), np.array(asked[4 * BLOCK:])
    assert np.mean(np.abs(later[:, 3] - 8.0)) < 0.5 * np.mean(np.abs(first[:, 3] - 8.0))  # the setpoint near 8 m
    assert np.ptp(later[:, 4]) > 7.0  # along the whole boundary: every speed
    assert np.ptp(later[:, :3]) > 1.5 and abs(np.mean(later[:, :3])) < 0.2  # each a uniformly random attack
    assert opt.modelled == set(range(BLOCK, 160))  # the first block, uniform, is the seed's alone


def test_a_campaign_stores_its_share_and_refuses_one_without_a_situation_or_out_of_range():
    searched = campaign_of({"scenario": {"setpoint_m": [3, 15]}, "search": {"boundary": 0.25}})
    assert searched.boundary == 0.25 and searched.definition()["boundary"] == 0.25
    stored = json.loads(json.dumps(searched.definition(), sort_keys=True))
    assert Campaign.from_definition(stored, samples=searched.samples) == searched
    assert "boundary" not in campaign_of({"scenario": {"setpoint_m": [3, 15]}}).definition()
    with pytest.raises(ConfigError, match="search.boundary: got 0.5; allowed: 0 where the campaign searches no situation"):
        campaign_of({"search": {"boundary": 0.5}})
    with pytest.raises(ConfigError, match="search.boundary: got 1.5; allowed: a number in \\[0, 1\\]"):
        campaign_of({"scenario": {"setpoint_m": [3, 15]}, "search": {"boundary": 1.5}})


def test_the_map_is_drawn_from_the_samples_spent_locating_where_a_campaign_has_them():
    base = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "auto", 0, 6.0, (0.0,) * 9, 0.1, "no_crash", None, None,
                  None, None)
    rng = np.random.default_rng(0)
    records = []
    for i in range(200):
        setpoint, spent = float(rng.uniform(3, 15)), locating(i, 0.5)
        # the optimiser's worst attacks succeed everywhere; random ones below 8 m alone
        records.append(dataclasses.replace(base, sample_id=i, index=i, locating=spent, situation=(("setpoint_m", setpoint),),
                                           outcome="success" if not spent or setpoint < 8 else "no_crash"))
    ((label, m),) = failure_maps(records)
    assert label == "switching, start rest, locating the boundary" and len(m.points) == 100 and m.rate[np.argmin(abs(m.axes[0] - 12.0))] < 0.2


@pytest.mark.sumo
def test_in_sumo_a_campaign_locating_its_boundary_plays_batched_as_alone(tmp_path, capsys):
    args = ["falsify", "--set", "scenario.setpoint_m=[3, 15]", "--set", "scenario.speed_mps=[20, 30]", "--set", "search.boundary=0.5",
            "--duration", "15", "--samples", "40"]
    batched, alone = tmp_path / "batched.sqlite", tmp_path / "alone.sqlite"
    assert main([*args, "--db", str(batched)]) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if "locating the boundary" in line]
    assert len(said) == 1 and said[0].startswith("  locating the boundary: 20 of the samples, a random attack each, ")
    assert main([*args, "--db", str(alone), "--batch", "1"]) == 0

    def samples(db):
        with Store(db, create=False) as store:
            return [(s.index, s.params, s.robustness, s.outcome) for s in store.samples()]

    assert samples(batched) == samples(alone) and len(samples(batched)) == 40
