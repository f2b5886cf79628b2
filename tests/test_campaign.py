"""Campaigns in SUMO: exact repetition, resume without loss, errored samples."""

from __future__ import annotations

import numpy as np
import pytest

import d4sumo.campaign as campaign_module
from d4sumo.campaign import Campaign, run_campaign
from d4sumo.errors import ConfigError, SumoError
from d4sumo.store import Store, StoreError

pytestmark = pytest.mark.sumo

SMALL = Campaign(optimizer="bo", samples=14, seed=3)  # past BO's 10 initial points


def signature(summary):
    return [(s.params, s.robustness, s.outcome) for s in summary.samples]


def test_one_seed_reproduces_a_campaign_exactly(tmp_path):
    a = run_campaign(SMALL, Store(tmp_path / "a.sqlite"))
    b = run_campaign(SMALL, Store(tmp_path / "b.sqlite"))
    assert signature(a) == signature(b)
    c = run_campaign(SMALL.replace(seed=4))
    assert signature(c) != signature(a)


def test_an_interrupted_campaign_resumes_with_nothing_lost_or_counted_twice(tmp_path):
    uninterrupted = run_campaign(SMALL)
    path = tmp_path / "r.sqlite"

    class Interrupt(Exception):
        pass

    def stop_after_eleven(sample):
        if sample.index == 10:
            raise Interrupt

    with pytest.raises(Interrupt):
        run_campaign(SMALL, Store(path), on_sample=stop_after_eleven)
    with Store(path) as store:
        assert len(store.samples()) == 11
        resumed = run_campaign(SMALL, store)
        assert signature(resumed) == signature(uninterrupted)
        assert [s.index for s in store.samples()] == list(range(14))


def test_a_larger_budget_extends_the_stored_campaign(tmp_path):
    with Store(tmp_path / "r.sqlite") as store:
        run_campaign(SMALL.replace(optimizer="ce", samples=5), store)
        longer = run_campaign(SMALL.replace(optimizer="ce", samples=8), store)
        assert len(store.campaigns()) == 1 and len(store.samples()) == 8
    assert signature(longer) == signature(run_campaign(SMALL.replace(optimizer="ce", samples=8)))


def test_stored_samples_that_this_seed_would_not_ask_are_refused(tmp_path):
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        run_campaign(SMALL.replace(optimizer="random", samples=3), store)
        store.db.execute("UPDATE sample SET params = '[0,0,0,0,0,0,0,0,0]' WHERE idx = 1")
        with pytest.raises(StoreError, match="not what this seed asks for"):
            run_campaign(SMALL.replace(optimizer="random", samples=5), store)
        assert len(store.samples()) == 3


def test_an_episode_that_fails_in_sumo_is_stored_as_errored_and_the_campaign_goes_on(tmp_path, monkeypatch):
    real = campaign_module.simulate
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise SumoError("SUMO failed during the episode: test")
        return real(*args, **kwargs)

    monkeypatch.setattr(campaign_module, "simulate", flaky)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_campaign(SMALL.replace(optimizer="random", samples=4), store)
        rows = store.samples()
    assert [r.outcome == "error" for r in rows] == [False, True, False, False]
    assert rows[1].robustness is None and "test" in rows[1].error
    assert summary.count("error") == 1


def test_robustness_positive_exactly_for_successes_with_the_papers_psi():
    summary = run_campaign(Campaign(optimizer="random", samples=20, seed=1))
    for s in summary.samples:
        assert (s.robustness > 0) == (s.outcome == "success"), s


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(optimizer="annealing"), "optimizer"),
        (dict(attack="zigzag"), "attack"),
        (dict(samples=0), "samples"),
        (dict(seed=-1), "seed"),
        (dict(delta_s=5.0), "attack.horizon_s"),
    ],
)
def test_bad_campaigns_name_the_field(changes, field):
    with pytest.raises(ConfigError) as info:
        Campaign(**changes)
    assert info.value.field == field
