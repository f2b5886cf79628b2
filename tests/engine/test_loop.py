"""The step loop (`engine.loop.play`): where every episode left is a platoon stepped in C in the paper's column, the
loop itself goes on in C (`compiled.play_column`); every episode is then the Python loop's, bit for bit."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from conftest import NATIVE_CALLS_EXPECTED, assert_same_episode, random_plans
from d4sumo.engine.ballistic import BallisticWorld
from d4sumo.engine import calls as sumo_calls
from d4sumo.engine.loop import play
from d4sumo.model.attacks.maneuvers import AttackPlan
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.world.sensing import RadarParams
from d4sumo.model.world.v2v import ChannelParams
from d4sumo.model.controllers import compiled
from d4sumo.presets import apply_preset

pytestmark = pytest.mark.skipif(compiled.play_column is None, reason="the C extension is not built")
ROADS = Path(__file__).resolve().parents[2] / "examples" / "roads"


@pytest.fixture
def in_c_counted(monkeypatch):
    """play_column, counted: a test that meant to play in C fails if the loop did not."""
    calls = []
    c_loop = compiled.play_column

    def counted(*args):
        calls.append(len(args[6]))
        return c_loop(*args)

    monkeypatch.setattr(compiled, "play_column", counted)
    return calls


def _both(monkeypatch, calls, run):
    """run() with the loop in C, then with the Python loop (the same followers in C); in C, also through libsumo's
    Python calls where it took SUMO's own (`calls.native_calls`): the same episodes."""
    in_c = run()
    assert calls, "the loop did not go on in C"
    with monkeypatch.context() as m:
        m.setattr(sumo_calls, "NATIVE", False)
        _assert_same(run(), in_c)
        m.setattr(compiled, "play_column", None)
        python = run()
    return in_c, python


def _assert_same(in_c, python):
    assert len(in_c) == len(python)
    for a, b in zip(in_c, python):
        if isinstance(b, Exception):
            assert type(a) is type(b) and str(a) == str(b)
        else:
            assert_same_episode(a, b)


CASES = {  # each configuration, and how many episodes share one SUMO
    "switching, batched then alone": (EpisodeConfig(setpoint_m=4.0), 20),
    "timegap, alone": (EpisodeConfig(controller=ControllerConfig("timegap"), setpoint_m=3.0, start="steady"), 1),
    "switching, noisy radars, late": (EpisodeConfig(setpoint_m=5.0, radar=RadarParams(gap_noise_m=0.3, speed_noise_mps=0.2,
                                                                                       latency_s=0.2)), 6),
    "cacc over a lossy channel": (EpisodeConfig(controller=ControllerConfig("cacc"), setpoint_m=5.0, start="steady",
                                                v2v=ChannelParams(loss=0.2, latency_s=0.1)), 6),
    "an end distance": (EpisodeConfig(setpoint_m=6.0, start="steady", end_distance_m=400.0), 5),
    "the IDM, an end distance": (EpisodeConfig(controller=ControllerConfig("idm"), setpoint_m=2.0, end_distance_m=300.0), 8),
    "SUMO's ACC, an end distance": (EpisodeConfig(controller=ControllerConfig("sumo:ACC"), setpoint_m=4.0, end_distance_m=300.0), 8),
    "SUMO's ACC, a switching follower and SUMO's IDM": (EpisodeConfig(controller=(
        ControllerConfig("sumo:ACC"), ControllerConfig("switching", where="controller.v2"),
        ControllerConfig("sumo:IDM", where="controller.v3")), setpoint_m=3.0), 6),
    "the paper as run (its preset), an end distance": (EpisodeConfig.from_dict(apply_preset(
        {"preset": "paper-as-run", "attack": {"family": "knots"}, "scenario": {"duration_s": 30.0, "end_distance_m": 250.0}})), 6),
}


@pytest.mark.sumo
@pytest.mark.parametrize("case", CASES)
def test_the_column_played_in_c_in_sumo_is_the_python_loop_bit_for_bit(case, monkeypatch, in_c_counted):
    from d4sumo.engine.simulation import simulate_batch

    config, m = CASES[case]
    plans = random_plans(config, m, seed=11)
    heard = []
    in_c, python = _both(monkeypatch, in_c_counted,
                         lambda: simulate_batch(config, plans, on_episode=lambda e, r: heard.append(e)))
    _assert_same(in_c, python)
    assert heard[:m] == heard[m:2 * m] == heard[2 * m:]  # each heard of as it ended, in the same order, each way
    ends = {(r.outcome, len(r.trace)) for r in in_c}
    if m > 4:
        assert len(ends) > 1, f"every episode ends alike {ends}: the ends are barely compared"
    if config.end_distance_m:
        assert any(len(r.trace) < config.steps + 1 for r in in_c)  # ended at the distance, before the last step


@pytest.mark.sumo
def test_a_route_of_three_edges_played_in_c_with_sumos_own_calls_is_the_python_loops(monkeypatch, in_c_counted):
    """Along a route of many edges a car's position is where it was inserted plus its odometer, in C as in the Python."""
    from d4sumo.engine.calls import native_calls
    from d4sumo.engine.simulation import simulate_batch

    import libsumo

    if NATIVE_CALLS_EXPECTED:
        assert native_calls(libsumo) is not None, "libsumo's own calls were not built (d4sumo/engine/_sumo_calls.cpp)"
    config = EpisodeConfig(network=str(ROADS / "three_edges"), setpoint_m=4.0)
    plans = random_plans(config, 6, seed=2)
    _assert_same(*_both(monkeypatch, in_c_counted, lambda: simulate_batch(config, plans)))


@pytest.mark.sumo
def test_an_error_of_sumos_in_the_loop_in_c_is_libsumos_own(monkeypatch):
    """A car SUMO no longer knows: SUMO's own calls raise what libsumo's Python calls raise (libsumo.TraCIException,
    which the world says as a SumoError), SUMO's message."""
    from d4sumo.engine.simulation import simulate_batch
    from d4sumo.errors import SumoError

    import libsumo

    config = EpisodeConfig(setpoint_m=3.0)
    plans = random_plans(config, 4, seed=1)

    def removes_another(e, result):  # the first episode to end takes another's attacker out of SUMO
        if not removes_another.done:
            removes_another.done = True
            libsumo.vehicle.remove(f"{(e + 1) % 4}.{config.vehicle_ids[0]}")

    said = []
    for native in (True, False):
        removes_another.done = False
        monkeypatch.setattr(sumo_calls, "NATIVE", native)
        with pytest.raises(SumoError) as error:
            simulate_batch(config, plans, on_episode=removes_another)
        said.append(str(error.value))
    assert said[0] == said[1] and "is not known" in said[0], said


@pytest.mark.sumo
def test_several_configurations_in_one_sumo_played_in_c_are_the_python_loops(monkeypatch, in_c_counted):
    from d4sumo.engine.simulation import simulate_batch

    configs = [EpisodeConfig(setpoint_m=s, speed_mps=(20.0, 25.0, 30.0)[i % 3], start=("rest", "steady")[i % 2])
               for i, s in enumerate((3.0, 7.0, 12.0, 5.0, 9.0, 4.0, 15.0, 6.0))]
    plans = [random_plans(c, 1, seed=i)[0] for i, c in enumerate(configs)]
    _assert_same(*_both(monkeypatch, in_c_counted, lambda: simulate_batch(configs, plans)))


class _Blinded(BallisticWorld):
    """A ballistic world whose v2's speed reads NaN from a step on: its follower's command is no number."""

    def __init__(self, configs, at: int):
        super().__init__(configs)
        self.steps, at_ = 0, at
        speeds = self.v.__getitem__

        def get_speed(vid):
            return math.nan if vid == "1.v2" and self.steps >= at_ else speeds(vid)
        self.get_speed = get_speed

    def step(self):
        self.steps += 1
        super().step()


def test_an_episode_whose_follower_fails_in_c_ends_with_the_python_loops_error_and_the_rest_go_on(monkeypatch, in_c_counted):
    config = EpisodeConfig(setpoint_m=5.0, start="steady")
    plans = [AttackPlan(u.u) for u in random_plans(config, 3, seed=5)]
    in_c, python = _both(monkeypatch, in_c_counted, lambda: play(_Blinded([config] * 3, at=40), [config] * 3, plans))
    _assert_same(in_c, python)
    assert isinstance(in_c[1], Exception) and "returned nan at step 40" in str(in_c[1])
    assert not isinstance(in_c[0], Exception) and not isinstance(in_c[2], Exception)


def test_the_ballistic_world_played_in_c_is_the_python_loops(monkeypatch, in_c_counted):
    config = EpisodeConfig(setpoint_m=9.0, followers=4)
    plans = [AttackPlan(p.u) for p in random_plans(config, 16, seed=3)]
    in_c, python = _both(monkeypatch, in_c_counted, lambda: play(BallisticWorld([config] * 16), [config] * 16, plans))
    _assert_same(in_c, python)
    assert in_c_counted == [16, 16]  # all in C from the start (the loop costs less than the arrays), twice: no SUMO calls to take
    assert len({r.outcome for r in in_c}) > 1, "one outcome: the ends are barely compared"


def test_a_ctrl_c_inside_a_followers_command_stops_the_loop_in_c_as_the_python_loop(monkeypatch, in_c_counted):
    """Found by review: the loop in C took a KeyboardInterrupt raised in the Python it calls (a lie, a command's check)
    for the episode's error, stored it and went on; the Python loop stops there."""
    def interrupted(c, i, k):
        raise KeyboardInterrupt

    monkeypatch.setattr(compiled, "checked_command", interrupted)
    config = EpisodeConfig(setpoint_m=5.0, start="steady")
    plans = [AttackPlan(u.u) for u in random_plans(config, 3, seed=5)]
    for c_loop in (compiled.play_column, None):
        monkeypatch.setattr(compiled, "play_column", c_loop)
        with pytest.raises(KeyboardInterrupt):
            play(_Blinded([config] * 3, at=40), [config] * 3, plans)
    assert in_c_counted == [3]


def test_the_loop_in_c_refuses_what_is_not_an_episode_in_one_error():
    """Found by review: a first episode that was no tuple crashed the process."""
    f = lambda *a: None  # noqa: E731
    for episodes in ([1], [(1, 2)], [tuple(range(10))]):
        with pytest.raises(TypeError, match="an episode"):
            compiled.play_column(0, 10, f, f, f, f, episodes, f, 0.0, 0.0, None)


@pytest.mark.sumo
def test_an_error_of_sumo_that_is_no_traci_refusal_is_libsumos_own_too(monkeypatch):
    """Found by review: the loop in C raised every error of SUMO's as libsumo.TraCIException, where libsumo raises
    FatalTraCIError for any but its own refusals (here: SUMO closed under the loop)."""
    from d4sumo.engine.simulation import simulate_batch

    import libsumo

    config = EpisodeConfig(setpoint_m=3.0)
    plans = random_plans(config, 4, seed=1)
    said = []
    for native in (True, False):
        monkeypatch.setattr(sumo_calls, "NATIVE", native)
        with pytest.raises(Exception) as error:
            simulate_batch(config, plans, on_episode=lambda e, r: libsumo.close())
        said.append((type(error.value), str(error.value)))
    assert said[0] == said[1], said
