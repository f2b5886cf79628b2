"""What every earlier release stored, held: the databases each release of d4sumo wrote (tests/data/releases/, written
by tools/earlier_databases.py from each release's own code), read by this one. Each stored campaign keeps its
identity, and so resumes under its key; its samples replay as they were stored."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from d4sumo.search.campaign import Campaign, open_store
from d4sumo.search.store import campaign_key

ROOT = Path(__file__).resolve().parents[2]
RELEASES = ROOT / "tests" / "data" / "releases"
DATABASES = sorted(RELEASES.glob("*.sqlite"), key=lambda p: (tuple(int(n) for n in p.name.split("-")[0].removesuffix(".sqlite")
                                                                          .split(".")), p.name))


def _campaigns(db: Path, tmp_path: Path):
    copy = tmp_path / db.name  # a fixture is never written, not even its journal
    shutil.copy(db, copy)
    with open_store(copy, create=False) as store:
        return store.campaigns(), {c.id: store.samples(c.id) for c in store.campaigns()}


def test_every_release_since_0_2_wrote_a_database_here_at_both_ends():
    """Each version's release (its first commit) and the last commit that carried it: what a database that says it
    was created by it may hold."""
    names = {p.name for p in DATABASES}
    for version in ("0.2.0", "0.10.1", "0.19.0", "0.20.0"):
        assert {f"{version}.sqlite", f"{version}-last.sqlite"} <= names
    assert len(DATABASES) == 40


@pytest.mark.parametrize("db", DATABASES, ids=lambda p: p.name[:-len(".sqlite")])
def test_each_campaign_a_release_stored_keeps_its_definition_and_identity_byte_for_byte(db, tmp_path):
    campaigns, _ = _campaigns(db, tmp_path)
    assert campaigns
    for row in campaigns:
        restored = Campaign.from_definition(row.definition, samples=row.budget).definition()
        assert json.dumps(restored, sort_keys=True) == json.dumps(row.definition, sort_keys=True), (db.name, row.id)
        assert campaign_key(restored) == row.key


def _replays(db: Path, tmp_path: Path) -> list[str]:
    """Each campaign of a release's database resumed by this version (its optimiser asked for each stored point again,
    and for two more) and its samples played again: what differs from what it stored."""
    from d4sumo.search.runner import CampaignRunner, Evaluator, stored_results

    copy = tmp_path / db.name
    shutil.copy(db, copy)
    differ = []
    with open_store(copy, create=False) as store:
        for row in store.campaigns():
            campaign = Campaign.from_definition(row.definition, samples=row.budget + 2)
            evaluator = Evaluator(campaign)
            stored = stored_results(store, row.id, row.budget)
            runner = CampaignRunner(campaign, evaluator, stored=stored, where=f"{db.name} campaign {row.id}")
            assert runner.done == len(stored) and runner.numerics_differ_at is None
            runner._fill()  # it goes on: the next points asked
            assert runner.queue
            for s in stored:
                again = evaluator(s.index, s.params)
                if (again.outcome, again.collision, again.min_gaps, again.robustness) != (s.outcome, s.collision, s.min_gaps,
                                                                                          s.robustness):
                    differ.append(f"{db.name} campaign {row.id} ({row.definition['optimizer']}) sample {s.index}: stored "
                                  f"{s.outcome} {s.robustness!r} {s.collision}, now {again.outcome} {again.robustness!r} "
                                  f"{again.collision}")
    return differ


@pytest.mark.sumo
@pytest.mark.parametrize("db", DATABASES, ids=lambda p: p.name[:-len(".sqlite")])
def test_each_sample_a_release_stored_replays_bit_for_bit(db, tmp_path, monkeypatch):
    """Outcome, collision, minimum gaps and robustness, to the bit. A road of one's own was named by its path from
    the checkout's root (examples/roads/three_edges), as the releases ran it."""
    monkeypatch.chdir(ROOT)
    assert _replays(db, tmp_path) == []


@pytest.mark.parametrize("db", DATABASES, ids=lambda p: p.name[:-len(".sqlite")])
def test_each_campaign_a_release_ran_by_its_optimisers_defaults_is_found_by_one_set_of_the_earlier_options(db, tmp_path):
    """`optimizers.EARLIER_OPTIONS`, derived from the ledger, names the options that give back each release's
    campaigns run with its defaults: the campaign with today's defaults, those options set, has the stored key
    (regression: the hand-written list had no set for 0.10.0's auto, which stored suffix and not patience, nor
    for 0.7.0's, which ran 256 inducing points)."""
    from d4sumo.search.optimizers import EARLIER_OPTIONS, resolve_options

    campaigns, _ = _campaigns(db, tmp_path)
    found = 0
    for row in campaigns:
        campaign = Campaign.from_definition(row.definition, samples=row.budget)
        if campaign.optimizer not in EARLIER_OPTIONS:
            continue
        today = campaign.replace(optimizer_options=tuple(resolve_options(campaign.optimizer, {}).items()))
        keys = {campaign_key(today.with_options(e).definition()) for e in ({}, *EARLIER_OPTIONS[campaign.optimizer])}
        assert row.key in keys, (db.name, row.id, campaign.optimizer)
        found += 1
    assert found >= 2
