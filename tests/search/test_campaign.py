"""Campaigns in SUMO: exact repetition, resume without loss, errored samples."""

from __future__ import annotations

import copy
from pathlib import Path
import json

import numpy as np
import pytest

import d4sumo.search.evaluator as evaluator_module
import d4sumo.search.runner as campaign_module
from d4sumo.errors import ConfigError, NotSimulable, SumoError
from d4sumo.model.config import EpisodeConfig
from d4sumo.search.campaign import Campaign
from d4sumo.search.runner import run_campaign
from d4sumo.search.store import Store, StoreError
from histories import nudge_numerics

pytestmark = pytest.mark.sumo

SMALL = Campaign(optimizer="bo", samples=14, seed=3)  # past BO's 10 initial points


class Interrupt(Exception):
    """A kill, as the campaign sees it: raised from its on_sample."""


def interrupt_at(index: int):
    def on_sample(sample):
        if sample.index == index:
            raise Interrupt
    return on_sample


def signature(summary):
    return [(s.params, s.robustness, s.outcome) for s in summary.samples]


def test_one_seed_reproduces_a_campaign_exactly(tmp_path):
    with Store(tmp_path / "a.sqlite") as sa, Store(tmp_path / "b.sqlite") as sb:
        a = run_campaign(SMALL, sa)
        b = run_campaign(SMALL, sb)
    assert signature(a) == signature(b)
    c = run_campaign(SMALL.replace(seed=4))
    assert signature(c) != signature(a)


def test_an_interrupted_campaign_resumes_with_nothing_lost_or_counted_twice(tmp_path):
    uninterrupted = run_campaign(SMALL)
    path = tmp_path / "r.sqlite"

    with pytest.raises(Interrupt), Store(path) as store:
        run_campaign(SMALL, store, on_sample=interrupt_at(10))
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


def stored_rows(store):
    return [(s.index, s.params, s.robustness, s.outcome) for s in store.samples()]


@pytest.mark.parametrize("optimizer, begun", [("turbo", 14), ("bo", 34), ("auto", 34), ("cmaes", 20)])
def test_a_campaign_begun_where_the_numerics_differ_resumes_with_its_stored_samples(tmp_path, monkeypatch, optimizer, begun):
    """Issue 36: a campaign interrupted on one machine and resumed on another (another CPU's BLAS kernel, a
    numpy upgrade) was refused ("stored sample 41 is not what this seed asks for") where its GP proposed
    otherwise. The stored samples are the truth: each is told to the optimiser in order, and the campaign
    goes on from there. Here the samples were begun with the GP's scores one ulp off (on the machine this
    was written on, turbo's proposals then differ from sample 10 on, bo's from 30)."""
    campaign = SMALL.replace(optimizer=optimizer)
    path = tmp_path / "r.sqlite"
    with monkeypatch.context() as other_machine:
        nudge_numerics(other_machine)
        with Store(path) as store:
            run_campaign(campaign.replace(samples=begun), store)
            stored = stored_rows(store)
    with Store(path) as store:
        resumed = run_campaign(campaign.replace(samples=begun + 4), store)
        assert stored_rows(store)[:begun] == stored and len(store.samples()) == begun + 4
    assert [s.params for s in resumed.samples[:begun]] == [p for _, p, _, _ in stored]


@pytest.mark.parametrize("edit, refused", [
    (("idx = 12", 1e-9), False),  # a point BO's model proposed (past its 10 initial points): another machine's
    (("idx = 4", 1e-9), True),  # a point of the initial design, which the seed draws alike everywhere
    (("idx = 12", 5.0), True),  # outside the box of knots in [-1, 1]
])
def test_a_stored_point_a_model_proposed_stands_and_one_the_seed_draws_must_match(tmp_path, caplog, edit, refused):
    """How a campaign begun on another machine is told from another campaign or an edited database:
    points the seed alone decides (a design, a sampler's draws) are the same on every machine, bit for
    bit; a point a model proposed (BLAS) may differ and stands, if it lies in the box."""
    where, change = edit
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        run_campaign(SMALL, store)
        params = store.db.execute(f"SELECT params FROM sample WHERE {where}").fetchone()[0]
        changed = [float(v) for v in params.strip("[]").split(",")]
        changed[0] = changed[0] + change if abs(change) < 1 else change
        store.db.execute(f"UPDATE sample SET params = ? WHERE {where}", (json.dumps(changed),))
        store.db.commit()
        before = stored_rows(store)
    with Store(path) as store:
        if refused:
            with pytest.raises(StoreError, match="another campaign or was changed"):
                run_campaign(SMALL.replace(samples=16), store)
            assert stored_rows(store) == before
            return
        with caplog.at_level("WARNING"):
            summary = run_campaign(SMALL.replace(samples=16), store)
        assert stored_rows(store)[:14] == before and len(summary.samples) == 16
    notes = [r.getMessage() for r in caplog.records if "numerics differ" in r.getMessage()]
    assert len(notes) == 1 and "stored sample 12 is not what this machine's model proposes" in notes[0]
    assert "the samples this run plays follow this machine's proposals" in notes[0]


def test_an_episode_that_fails_in_sumo_is_stored_as_errored_and_the_campaign_goes_on(tmp_path, monkeypatch):
    real = evaluator_module.simulate
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise SumoError("SUMO failed during the episode: test")
        return real(*args, **kwargs)

    monkeypatch.setattr(evaluator_module, "simulate", flaky)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_campaign(SMALL.replace(optimizer="random", samples=4), store, batch=1)
        rows = store.samples()
    assert [r.outcome == "error" for r in rows] == [False, True, False, False]
    assert rows[1].robustness is None and "test" in rows[1].error
    assert summary.count("error") == 1


def test_a_failure_every_sample_ends_in_is_said_twice_not_once_a_sample(tmp_path, monkeypatch, caplog):
    """A campaign whose warm-up always collides printed one line per sample; each is still stored."""
    def failing(*args, **kwargs):
        raise SumoError("the same failure")

    monkeypatch.setattr(evaluator_module, "simulate", failing)
    with Store(tmp_path / "r.sqlite") as store, caplog.at_level("WARNING"):
        run_campaign(SMALL.replace(optimizer="random", samples=6), store, batch=1)
        rows = store.samples()
    said = [r.getMessage() for r in caplog.records if "failed" in r.getMessage()]
    assert said == ["sample index 0 failed: the same failure",
                    "sample index 1 failed the same way; later samples that do are counted, not shown"]
    assert [r.outcome for r in rows] == ["error"] * 6


def test_when_sumo_fails_in_a_batch_its_finished_episodes_count_and_the_rest_play_alone(tmp_path, monkeypatch):
    """Regression: a SUMO failure errored every unfinished episode of the batch (in a sweep, of up to 32
    campaigns), where alone only the failing one would be: the results depended on the grouping."""
    real = evaluator_module.simulate_batch
    batches = []

    def failing_after_two(config, plans, *, road=None, on_episode=None):
        heard = []

        def hear(i, episode):
            on_episode(i, episode)
            heard.append(i)
            if len(heard) == 2 and len(batches) == 1:
                raise SumoError("SUMO failed during the episode: test")

        batches.append(len(plans))
        return real(config, plans, road=road, on_episode=hear)

    monkeypatch.setattr(evaluator_module, "simulate_batch", failing_after_two)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_campaign(SMALL.replace(optimizer="random", samples=6), store, batch=4)
        rows = store.samples()
    assert batches == [4, 2]
    assert sorted(r.index for r in rows) == list(range(6))
    assert summary.count("error") == 0
    assert full_signature(summary) == full_signature(run_campaign(SMALL.replace(optimizer="random", samples=6), batch=1))


def test_robustness_positive_exactly_for_successes_with_the_papers_psi():
    summary = run_campaign(Campaign(optimizer="random", samples=20, seed=1))
    for s in summary.samples:
        assert (s.robustness > 0) == (s.outcome == "success"), s


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(optimizer="annealing"), "search.optimizer"),
        (dict(attack="zigzag"), "attack.family"),
        (dict(samples=0), "search.samples"),
        (dict(seed=-1), "search.seed"),
        (dict(attack_options={"delta_s": 5.0}), "attack.horizon_s"),
    ],
)
def test_bad_campaigns_name_the_field(changes, field):
    with pytest.raises(ConfigError) as info:
        Campaign(**changes)
    assert info.value.field == field


class Raising:
    """A user's follower controller with a bug: it raises on a gap below 3 m."""

    from d4sumo.model.controllers.control import SwitchingParams as Params

    def __init__(self, params, **kwargs):
        from d4sumo.model.controllers.control import SwitchingController

        self.inner = SwitchingController(params, **kwargs)

    def command(self, gap_m, speed_mps, lead_speed_mps):
        if gap_m < 3.0:
            raise ZeroDivisionError("too close")
        return self.inner.command(gap_m, speed_mps, lead_speed_mps)


def test_a_users_controller_that_raises_is_an_errored_sample_and_the_campaign_goes_on(tmp_path):
    from d4sumo.model.config import ControllerConfig, EpisodeConfig

    config = EpisodeConfig(controller=ControllerConfig(cls="test_campaign:Raising"), setpoint_m=4.0)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_campaign(Campaign(config=config, optimizer="random", samples=6, seed=0), store)
        rows = store.samples()
    assert len(rows) == 6 and summary.count("error") >= 1
    errored = [r for r in rows if r.outcome == "error"]
    assert all("ZeroDivisionError: too close" in r.error and r.robustness is None for r in errored)


def test_an_evaluator_of_another_campaign_is_refused_before_anything_is_written(tmp_path):
    """Regression: run_campaign stored another campaign's results under this campaign, silently."""
    from d4sumo.search.runner import Evaluator

    path = tmp_path / "r.sqlite"
    other = Evaluator(SMALL.replace(seed=9))
    with Store(path) as store:
        with pytest.raises(ValueError, match="another campaign"):
            run_campaign(SMALL, store, evaluator=other)
        assert store.campaigns() == [] and store.samples() == []


def test_numpy_scalars_are_accepted_and_7_and_7_0_are_the_same_campaign():
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.search.store import campaign_key

    a = Campaign(config=EpisodeConfig(setpoint_m=7, followers=np.int64(3), speed_mps=np.float32(25.0)), samples=np.int64(5),
                 seed=np.int32(1), attack_options={"delta_s": np.float64(6)})
    b = Campaign(config=EpisodeConfig(setpoint_m=7.0, followers=3, speed_mps=25.0), samples=5, seed=1, attack_options={"delta_s": 6})
    assert campaign_key(a.definition()) == campaign_key(b.definition())
    assert type(a.config.setpoint_m) is float and type(a.seed) is int


@pytest.mark.sumo
def test_after_a_warm_up_the_specification_is_scored_from_the_attacks_start():
    """Regression: scored over the whole episode, the paper's psi was bounded by the warm-up's first
    instant (every gap at the setpoint), so every attack of a warm-up campaign scored -d alike."""
    from d4sumo.model.config import EpisodeConfig

    campaign = Campaign(config=EpisodeConfig(start="warmup", setpoint_m=3.0, speed_mps=20.0), attack="persistent",
                        optimizer="random", samples=8, seed=0)
    assert campaign.definition()["spec"]["from_attack_start"] is True
    scores = {r.robustness for r in run_campaign(campaign).samples}
    assert len(scores) > 1 and -3.0 not in scores
    # a campaign stored before (no key) keeps scoring the whole episode: its samples replay as stored
    old = copy.deepcopy(campaign.definition())
    del old["spec"]["from_attack_start"]
    before = Campaign.from_definition(old, samples=8)
    assert before.score_from_attack_start is False and before.specification().start_step == 0
    assert {r.robustness for r in run_campaign(before).samples} == {-3.0}
    # without a warm-up nothing changes, not even the stored definition
    assert "from_attack_start" not in Campaign().definition()["spec"]


def full_signature(summary):
    return [(s.index, s.params, s.robustness, s.outcome, s.collision, s.min_gaps) for s in summary.samples]


@pytest.mark.parametrize("optimizer, options", [
    ("random", {}), ("halton", {}), ("ce", {"batch_size": 6}), ("cmaes", {}), ("ce-bucket", {}),
    ("bo", {"initial_points": 6, "batch_size": 1}), ("bo", {"initial_points": 4, "batch_size": 3}),
    ("turbo", {"initial_points": 4, "batch_size": 3, "failure_tolerance": 1}),
])
def test_a_campaign_played_in_batches_is_the_campaign_played_one_episode_at_a_time(optimizer, options):
    """Issue 13: batches change the speed, never a sample."""
    campaign = Campaign(optimizer=optimizer, optimizer_options=options, samples=14, seed=2, config=SMALL.config.__class__(setpoint_m=5.0))
    alone = run_campaign(campaign, batch=1)
    for batch in (4, 32):
        assert full_signature(run_campaign(campaign, batch=batch)) == full_signature(alone), batch
    assert {s.outcome for s in alone.samples} - {"error"}


def test_a_campaign_interrupted_inside_a_batch_resumes_with_nothing_lost_or_counted_twice(tmp_path):
    """A batch's samples are stored in order as their episodes end; after a kill in the middle of a batch
    the campaign resumes and ends as if never interrupted, and the row ids follow the samples' order
    whatever the batch size."""
    campaign = Campaign(optimizer="ce", optimizer_options={"batch_size": 8}, samples=16, seed=1)
    uninterrupted = run_campaign(campaign)
    path = tmp_path / "r.sqlite"

    with pytest.raises(Interrupt), Store(path) as store:
        run_campaign(campaign, store, on_sample=interrupt_at(10))  # inside the second batch
    with Store(path) as store:
        assert [s.index for s in store.samples()] == list(range(11))
        resumed = run_campaign(campaign, store, batch=3)
        assert full_signature(resumed) == full_signature(uninterrupted)
        rows = store.samples()
        assert [s.index for s in rows] == list(range(16)) and [s.id for s in rows] == sorted(s.id for s in rows)


def test_samples_missing_between_stored_ones_are_played_and_nothing_else(tmp_path, monkeypatch):
    """A database may hold a campaign with gaps (a batch cut short by another writer): resuming plays
    exactly the missing samples, and the campaign ends as if it had run in one piece."""
    campaign = Campaign(optimizer="ce", optimizer_options={"batch_size": 8}, samples=16, seed=1)
    uninterrupted = run_campaign(campaign)
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        run_campaign(campaign.replace(samples=12), store)
        store.db.execute("DELETE FROM sample WHERE idx IN (3, 9, 10)")
        store.db.commit()
        played = []
        real = campaign_module.Evaluator.batch

        def spy(self, first, params, on_result=None):
            played.extend(range(first, first + len(params)))
            return real(self, first, params, on_result)

        monkeypatch.setattr(campaign_module.Evaluator, "batch", spy)
        resumed = run_campaign(campaign, store)
        assert full_signature(resumed) == full_signature(uninterrupted)
        assert sorted(s.index for s in store.samples()) == list(range(16))
    assert sorted(played) == [3, 9, 10, 12, 13, 14, 15]


def test_bo_with_a_constant_liar_proposes_a_batch_of_distinct_points_and_repeats_exactly():
    campaign = Campaign(optimizer="bo", optimizer_options={"initial_points": 5, "batch_size": 4}, samples=13, seed=0)
    a, b = run_campaign(campaign), run_campaign(campaign)
    assert full_signature(a) == full_signature(b)
    proposed = [s.params for s in a.samples[5:9]]
    assert len(set(proposed)) == 4
    assert "batch_size" in campaign.definition()["optimizer_options"]


@pytest.mark.parametrize("removed, kept, ran", [
    (("per_signal",), {"per_signal": 0}, (25, 0.25, 5)),
    (("per_signal", "suffix", "patience"), {"suffix": 0.0, "patience": 0, "per_signal": 0}, (25, 0.0, 0)),
    (("per_signal", "suffix", "patience", "stall"), {"stall": 0, "suffix": 0.0, "patience": 0, "per_signal": 0}, (0, 0.0, 0)),
    (("per_signal", "suffix", "patience", "stall", "version"), {"version": 1}, (0, 0.0, 0))])
def test_an_auto_campaign_an_earlier_version_stored_replays_as_it_ran_under_its_key(removed, kept, ran):
    """d4sumo 0.10 stored auto's definition without ``per_signal`` (held inputs cut across signals), 0.9
    without ``suffix`` and ``patience`` either (no suffix moves, exploring from the design on), 0.8
    without ``stall`` either (piece moves through stalls), 0.7 without ``version`` either (uniform
    exploration: no stalls, no piece moves)."""
    from d4sumo.search.store import campaign_key

    new = Campaign(optimizer="auto")
    assert new.definition()["optimizer_options"]["stall"] == 25 and new.definition()["optimizer_options"]["suffix"] == 0.25
    old = copy.deepcopy(new.definition())
    for key in removed:
        del old["optimizer_options"][key]
    stored = Campaign.from_definition(old, samples=12)
    options = dict(stored.optimizer_options)
    assert (options["stall"], options["suffix"], options["patience"], options["per_signal"]) == (*ran, 0)
    assert campaign_key(stored.definition()) == campaign_key(old)
    assert Campaign(optimizer="auto", optimizer_options=kept, samples=12).definition() == stored.definition()


def test_a_campaign_on_a_road_of_ones_own_holds_its_content_and_one_stored_before_keeps_its_identity(tmp_path):
    """The road's files are part of the campaign, as a demand's or an FMU's: a changed road is another one,
    and a stored campaign of it is refused (it went on over the changed road without a word). d4sumo 0.16
    and before stored no digest: their campaigns take the road as it is, under the same key."""
    import shutil

    from d4sumo.search.store import campaign_key

    road = tmp_path / "road"
    shutil.copytree(Path(__file__).resolve().parents[2] / "examples" / "roads" / "three_edges", road)
    new = Campaign(config=EpisodeConfig(network=str(road), start="steady"))
    stored = new.definition()
    assert len(stored["config"]["scenario"]["network_sha256"]) == 64
    assert Campaign.from_definition(stored).definition() == stored
    old = copy.deepcopy(stored)
    del old["config"]["scenario"]["network_sha256"]
    assert campaign_key(Campaign.from_definition(old).definition()) == campaign_key(old) != campaign_key(stored)
    edges = road / "road.edg.xml"
    edges.write_text(edges.read_text().replace('speed="', 'speed="1', 1))  # one edge's speed changed
    assert Campaign.from_definition(stored).definition() == stored  # read: the road need not be as it was ...
    with pytest.raises(NotSimulable, match="its road .* cannot be simulated here: its files have changed since"):
        Campaign.from_definition(stored, imports=True)  # ... played, it must
    assert Campaign.from_definition(old, imports=True).config.network_sha256 == ""  # as it ran: the road as it is
    assert Campaign(config=EpisodeConfig(network=str(road), start="steady")).definition() != stored  # another campaign
    shipped = Campaign(config=EpisodeConfig(start="steady")).definition()
    assert "network_sha256" not in shipped["config"]["scenario"]  # d4sumo's own roads: as before


def test_a_roads_digest_is_of_the_files_it_is_built_from_whatever_names_it(tmp_path, monkeypatch):
    """A road named by its folder's name alone (no "/") holds a digest too; a network file netconvert wrote
    beside the node and edge files, or a folder named like one, changes nothing (the road is built from the
    node and edge files); a digest that is none is refused in one line."""
    import shutil

    road = tmp_path / "mine"
    shutil.copytree(Path(__file__).resolve().parents[2] / "examples" / "roads" / "three_edges", road)
    monkeypatch.chdir(tmp_path)
    digest = EpisodeConfig(network="mine").network_sha256
    assert len(digest) == 64 and EpisodeConfig(network="./mine").network_sha256 == digest
    (road / "mine.net.xml").write_text("<net/>")
    (road / "old.net.xml").mkdir()
    assert EpisodeConfig(network="mine").network_sha256 == digest
    assert EpisodeConfig(network="highway_4lane").network_sha256 == ""  # a shipped variant's name
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(network="mine", network_sha256="bogus")
    assert info.value.field == "scenario.network_sha256"


def test_a_traffic_campaign_an_earlier_version_stored_keeps_its_identity_and_its_traffic():
    """d4sumo 0.16 and before stored [traffic] without ``insertion_checks``: it played the traffic entering
    after the warm-up with none, and its campaigns replay and resume so, under the same key."""
    from d4sumo.search.store import campaign_key

    new = Campaign(config=EpisodeConfig(start="steady", traffic={}))
    assert new.definition()["config"]["traffic"]["insertion_checks"] is True
    old = copy.deepcopy(new.definition())
    del old["config"]["traffic"]["insertion_checks"]
    stored = Campaign.from_definition(old, samples=12)
    assert stored.config.traffic.insertion_checks is False
    assert campaign_key(stored.definition()) == campaign_key(old) != campaign_key(new.definition())


def test_a_campaign_on_a_road_of_ones_own_an_earlier_version_stored_keeps_its_identity_and_drives_through_red():
    """d4sumo 0.18 and before stored no ``signals``: its platoon drove through red lights, and its campaigns on a
    road of one's own replay and resume so, under the same key; on d4sumo's own roads (no lights) nothing changed."""
    from d4sumo.search.store import campaign_key

    road = str(Path(__file__).resolve().parent.parent.parent / "examples" / "roads" / "three_edges")
    new = Campaign(config=EpisodeConfig(network=road, start="steady"))
    assert new.definition()["config"]["scenario"]["signals"] == "obey"
    old = copy.deepcopy(new.definition())
    del old["config"]["scenario"]["signals"]
    stored = Campaign.from_definition(old, samples=12)
    assert stored.config.signals == "ignore" and stored.config == new.with_inputs_of("0.18").config
    assert campaign_key(stored.definition()) == campaign_key(old) != campaign_key(new.definition())
    shipped = Campaign(config=EpisodeConfig(start="steady"))
    assert "signals" not in shipped.definition()["config"]["scenario"]
    assert Campaign.from_definition(shipped.definition(), samples=100) == shipped  # the same campaign, as it ran
    assert shipped.with_inputs_of("0.18") is shipped


@pytest.mark.parametrize("version, removed, kept", [
    ("0.2", ("batch_size", "gp_version"), {"batch_size": 1, "gp_version": 1}),
    ("0.3", ("gp_version",), {"batch_size": 5, "gp_version": 1})])
def test_a_bo_campaign_an_earlier_version_stored_keeps_its_identity_and_its_options(version, removed, kept):
    """d4sumo 0.2 stored bo campaigns without batch_size (one point per score) and 0.3 without
    gp_version (scikit-optimize's GP): they must resume and replay as they ran, under the same key."""
    from d4sumo.search.store import campaign_key

    new = Campaign(optimizer="bo")
    assert new.definition()["optimizer_options"]["batch_size"] == 5
    assert new.definition()["optimizer_options"]["gp_version"] == 2
    old = copy.deepcopy(new.definition())
    for key in removed:
        del old["optimizer_options"][key]
    stored = Campaign.from_definition(old, samples=12)
    assert {k: dict(stored.optimizer_options)[k] for k in kept} == kept
    assert campaign_key(stored.definition()) == campaign_key(old)
    same = Campaign(optimizer="bo", optimizer_options=kept, samples=12)
    assert same.definition() == stored.definition()


@pytest.mark.parametrize("where", ["a plan that fails", "SUMO failing"])
def test_the_callers_own_exception_comes_out_of_a_batch_as_it_was_raised(monkeypatch, where):
    """Regression: on these two paths an exception of the caller's on_result (Ctrl-C, a store error)
    came out wrapped in a private class, so Ctrl-C ended in a traceback instead of exit 130."""
    from d4sumo.search.runner import Evaluator

    evaluator = Evaluator(Campaign(optimizer="random", samples=4))
    params = [np.zeros(9), np.zeros(9)]
    if where == "a plan that fails":
        params[0] = np.full(9, 7.0)  # outside the knots' box
        with pytest.raises(ValueError):
            evaluator.plan(params[0])
    else:
        def failing(*args, **kwargs):
            raise SumoError("SUMO failed during the episode: test")

        monkeypatch.setattr(evaluator_module, "simulate_batch", failing)

    def interrupted(result):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        evaluator.batch(0, params, interrupted)


def test_a_campaign_whose_sumo_model_draws_random_numbers_is_the_same_batched_or_not():
    """EIDM draws from SUMO's random streams (dealt out by car): its episodes play one at a time, on the
    campaign's own road, whatever --batch says."""
    from d4sumo.model.config import ControllerConfig, EpisodeConfig

    campaign = Campaign(config=EpisodeConfig(controller=ControllerConfig("sumo:EIDM"), setpoint_m=4.0), optimizer="random",
                        samples=6, seed=1)
    assert full_signature(run_campaign(campaign, batch=6)) == full_signature(run_campaign(campaign, batch=1))


def test_campaigns_stepped_together_store_the_samples_each_gives_alone():
    """Issue 13: a sweep steps several campaigns at once, their episodes side by side in one SUMO
    (other setpoints, speeds, starts, attacks and optimisers; the paper's one-point BO among them)."""
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.search.runner import CampaignRunner, Evaluator, step_together

    campaigns = [
        Campaign(config=EpisodeConfig(setpoint_m=4.0, speed_mps=20.0), optimizer="bo", optimizer_options={"batch_size": 1, "initial_points": 4}, samples=9, seed=1),
        Campaign(config=EpisodeConfig(setpoint_m=9.0, speed_mps=30.0, start="steady"), optimizer="bo", optimizer_options={"batch_size": 1, "initial_points": 4}, samples=9, seed=2),
        Campaign(config=EpisodeConfig(setpoint_m=6.0, start="steady"), attack="persistent", optimizer="ce", optimizer_options={"batch_size": 4}, samples=9),
        Campaign(config=EpisodeConfig(followers=4), optimizer="random", samples=9),  # another key: its own SUMO
    ]
    alone = [full_signature(run_campaign(c, batch=1)) for c in campaigns]
    for batch in (3, 64):
        runners = [CampaignRunner(c, Evaluator(c), batch=batch) for c in campaigns]
        heard = {id(r): [] for r in runners}
        together = {id(r): [] for r in runners}
        while any(r.done < r.campaign.samples for r in runners):
            going = [r for r in runners if r.done < r.campaign.samples]
            for r, results in zip(going, step_together(going, batch, lambda r, s: heard[id(r)].append(s.index))):
                together[id(r)] += results
        for r, expected in zip(runners, alone):
            assert full_signature(campaign_module.CampaignSummary(None, together[id(r)])) == expected
            assert sorted(heard[id(r)]) == list(range(9))


def test_the_optimiser_reads_the_attack_familys_layout_in_time():
    """A lane-changing attack's time of change is a scalar after its knots: auto's suffix moves cut the
    knots at a time, and the scalar as a signal of its own."""
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.search.runner import CampaignRunner, Evaluator

    for config, signals in ((EpisodeConfig(maneuver="cutin", start="warmup", warmup_s=5.0), (9, 1)), (EpisodeConfig(), (9,))):
        campaign = Campaign(config=config, optimizer="auto", samples=4)
        assert CampaignRunner(campaign, Evaluator(campaign)).optimizer.signals == signals == campaign.family().signals


@pytest.mark.parametrize("from_attack_start", [True, False])
def test_minimum_gaps_after_a_warm_up_speak_of_the_window_robustness_and_outcome_do(tmp_path, from_attack_start):
    """Issue 36: after a warm-up from rest the stored minimum gaps were the warm-up's (7.00 m, the setpoint
    at the start, for every sample of a time-gap ACC campaign) beside a robustness of -36.7: the near-miss
    columns said nothing. They are taken over the window the specification scores: from the attack's
    start, or the whole episode for a campaign stored before that window existed."""
    from d4sumo.model.config import ControllerConfig, EpisodeConfig

    config = EpisodeConfig(start="warmup", controller=ControllerConfig(cls="timegap"))
    summary = run_campaign(Campaign(config=config, optimizer="random", samples=6, seed=0,
                                    score_from_attack_start=from_attack_start))
    for s in summary.samples:  # psi with d_safe 0: the followers' nearest gap negated, or the attacker's if less
        followers = min(g for pair, g in s.min_gaps.items() if pair != "v0-v1")
        assert s.robustness == min(-followers, s.min_gaps["v0-v1"])
    assert any(s.outcome == "no_crash" for s in summary.samples)


def test_a_stored_point_another_machine_proposed_past_a_gap_is_said_once(tmp_path, caplog):
    """Review of issue 36: a divergence found past a missing sample (where the resumed campaign checks the
    stored samples it does not play again) went unsaid."""
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        run_campaign(SMALL, store)
        params = json.loads(store.db.execute("SELECT params FROM sample WHERE idx = 12").fetchone()[0])
        store.db.execute("UPDATE sample SET params = ? WHERE idx = 12", (json.dumps([params[0] + 1e-9, *params[1:]]),))
        store.db.execute("DELETE FROM sample WHERE idx = 11")
        store.db.commit()
    with Store(path) as store, caplog.at_level("WARNING"):
        run_campaign(SMALL.replace(samples=16), store)
        assert sorted(s.index for s in store.samples()) == list(range(16))
    notes = [r.getMessage() for r in caplog.records if "numerics differ" in r.getMessage()]
    assert len(notes) == 1 and "stored sample 12" in notes[0]


def test_a_campaign_on_a_network_file_an_earlier_version_stored_replays_on_the_network_rebuilt():
    """d4sumo 0.18 and before rebuilt a network file from plain XML: its stored campaigns (no ``rebuild``) replay
    and resume so, under their key; a new campaign runs the file as given, another campaign."""
    from d4sumo.search.store import campaign_key
    from d4sumo.sumohome import sumo_home

    net = str(Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml")
    new = Campaign(config=EpisodeConfig(network=net, route=("gneE27", "gneE25"), start="steady"))
    old = copy.deepcopy(new.definition())
    del old["config"]["scenario"]["rebuild"], old["config"]["scenario"]["signals"]
    stored = Campaign.from_definition(old, samples=12)
    assert stored.config.rebuild is True and not stored.config.network_given and stored.config.signals == "ignore"
    assert stored.config == new.with_inputs_of("0.18").config
    assert campaign_key(stored.definition()) == campaign_key(old) != campaign_key(new.definition())
    assert [key for key, _, _ in new.changes_of("0.18")] == ["scenario.rebuild", "scenario.signals"]


def test_a_traffic_campaign_0_18_stored_on_a_road_of_ones_own_replays_with_collisions_inside_junctions_unseen():
    """0.18 saw no collision inside a junction: its stored campaigns among traffic (no ``junction_collisions``) replay
    and resume so, under their key; new ones see them; on d4sumo's own roads (one edge) nothing changed."""
    from d4sumo.search.store import campaign_key
    from d4sumo.sumohome import sumo_home

    net = str(Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml")
    new = Campaign(config=EpisodeConfig(network=net, route=("gneE27", "gneE25"), start="steady", traffic={}))
    assert new.definition()["config"]["traffic"]["junction_collisions"] is True
    old = copy.deepcopy(new.definition())
    del old["config"]["traffic"]["junction_collisions"]
    stored = Campaign.from_definition(old, samples=12)
    assert stored.config.traffic.junction_collisions is False
    assert campaign_key(stored.definition()) == campaign_key(old) != campaign_key(new.definition())
    assert "traffic.junction_collisions" in [key for key, _, _ in new.changes_of("0.18")]
    shipped = Campaign(config=EpisodeConfig(start="steady", traffic={}))
    assert "junction_collisions" not in shipped.definition()["config"]["traffic"]
    assert Campaign.from_definition(shipped.definition(), samples=100).config == shipped.config


def test_a_cooperative_campaign_0_19_stored_among_traffic_replays_with_beacons_read_whatever_the_radar_saw():
    """0.19's cooperative followers read the platoon's beacons whatever their radar saw: its stored campaigns among
    traffic (no ``match_radar``) replay and resume so, under their key; in the paper's column nothing changed."""
    from d4sumo.model.config import ControllerConfig
    from d4sumo.search.store import campaign_key

    new = Campaign(config=EpisodeConfig(start="steady", traffic={}, controller=ControllerConfig("cacc")))
    assert new.definition()["config"]["v2v"]["match_radar"] is True
    old = copy.deepcopy(new.definition())
    del old["config"]["v2v"]["match_radar"]
    stored = Campaign.from_definition(old, samples=12)
    assert stored.config.v2v.match_radar is False and stored.config == new.with_inputs_of("0.19").config
    assert campaign_key(stored.definition()) == campaign_key(old) != campaign_key(new.definition())
    assert [key for key, _, _ in new.changes_of("0.19")] == ["v2v.match_radar"]
    assert "v2v.match_radar" in [key for key, _, _ in new.changes_of("0.18")]
    column = Campaign(config=EpisodeConfig(start="steady", controller=ControllerConfig("cacc")))
    assert "match_radar" not in column.definition()["config"]["v2v"] and column.with_inputs_of("0.19") is column
    assert Campaign.from_definition(column.definition(), samples=100).config == column.config


def test_a_users_controller_whose_key_is_named_like_the_authors_options_replays_with_the_value_it_ran(tmp_path, monkeypatch):
    """Regression (0.20): a definition leaves the authors' code's options out where they hold the paper's value,
    by name, for every Python controller; a user's class with a key of that name and its own default
    (control_period_s = 0.5 here, run at 0) was read back with its default: its samples replayed otherwise."""
    import uuid

    from d4sumo.model.config import ControllerConfig
    from d4sumo.search.evaluator import Evaluator

    name = f"ctl_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(
        "from dataclasses import dataclass\n\n\n@dataclass(frozen=True)\nclass P:\n    gain: float = 0.5\n"
        "    control_period_s: float = 0.5\n\n\nclass Mine:\n    Params = P\n\n"
        "    def __init__(self, params, *, setpoint_m, target_speed_mps, vehicle, step_s):\n"
        "        self.p, self.d, self.v0 = params, setpoint_m, target_speed_mps\n\n"
        "    def observe(self, o):\n        k = self.p.gain + self.p.control_period_s\n"
        "        a = k * (o.gap_m - self.d) + (o.lead_speed_mps - o.speed_mps) if o.leader else self.v0 - o.speed_mps\n"
        "        return max(-1.0, min(1.0, a / 5.0))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    ran = Campaign(config=EpisodeConfig(controller=ControllerConfig(f"{name}:Mine", (("control_period_s", 0.0),)),
                                        start="steady", duration_s=20.0), samples=2)
    definition = ran.definition()
    assert "control_period_s" not in definition["config"]["controller"]  # stored as every release stored it: identity kept
    read = Campaign.from_definition(json.loads(json.dumps(definition)), 2, imports=True)  # as a replay reads it
    assert dict(read.config.controller.params)["control_period_s"] == 0.0
    assert read.definition() == definition
    x = np.full(ran.family().dimension, 0.5)
    assert Evaluator(read).simulate(0, x).min_gaps == Evaluator(ran).simulate(0, x).min_gaps
