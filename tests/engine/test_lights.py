"""Traffic lights obeyed (`engine.lights`, `model.signals`), for real in SUMO on SUMO's corridor example: its
main route crosses three signalised junctions, which the platoon drove through on red before."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from d4sumo.engine import lights
from d4sumo.engine.scenarios import config_road
from d4sumo.engine.simulation import simulate
from d4sumo.model.config import EpisodeConfig

pytestmark = pytest.mark.sumo

ROUTE = ("gneE27", "gneE25", "gneE18", "gneE29")


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """SUMO's corridor network and its demand, each flow given an end (SUMO plays a flow without one for ever)."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "corridor"
    demand = tmp_path_factory.mktemp("corridor") / "corridor_end.rou.xml"
    demand.write_text((game / "corridor.rou.xml").read_text().replace("<flow ", '<flow end="3600" '))
    return str(game / "corridor.net.xml"), str(demand)


@pytest.fixture
def passes(monkeypatch):
    """Each stop line a car of the platoon crosses: (car, signal, the state it showed the car the step before;
    "G" where every light within reach let the platoon on)."""
    seen: list[tuple[int, int, str]] = []
    measured = lights.RouteLights.__call__

    def call(self, x):
        out = measured(self, x)
        before, last = getattr(self, "_x", None), getattr(self, "_last", None)
        for i, car in enumerate(x if before is not None else ()):
            for k, (line, _, _) in enumerate(self.signals):
                if before[i] <= line < car:
                    stop = last[i] if last else None
                    seen.append((i, k, stop.state if stop is not None and stop.signal == k else "G"))
        self._x, self._last = list(x), out
        return out

    monkeypatch.setattr(lights.RouteLights, "__call__", call)
    return seen


def _config(corridor, **changes):
    """Along the corridor's main route, alone, joined 60 s into its signals' programs (a warm-up of a demand
    without a vehicle): through gneJ12 at green, gneJ11 ahead turns red."""
    empty = Path(corridor[1]).with_name("nobody.rou.xml")
    empty.write_text("<routes/>\n")
    changes.setdefault("rebuild", True)  # netconvert's programmes: its own give the main road green for 10005 s
    changes = {"duration_s": 45.0, **changes}
    return EpisodeConfig(network=corridor[0], route=ROUTE, start="steady", speed_mps=11.0, setpoint_m=8.0,
                         traffic={"demand": str(empty), "warmup_s": 60.0}, **changes)


def test_a_cruising_platoon_stops_for_red_where_before_it_drove_through(corridor, passes):
    road = config_road(_config(corridor))
    cruise = np.full(_config(corridor).steps, np.nan)
    obeying = simulate(_config(corridor), cruise, road=road)
    assert passes and not [p for p in passes if p[2] in "rRu"]  # lines crossed, none on red
    assert obeying.trace["speed_v0"].min() < 0.1  # it stopped, and waited
    assert obeying.trace["cmd_v0"].min() < 0  # its driver braked: the trace's command is what the pedals did
    red = obeying.trace["light_v0"] == 2.0  # what it saw of the lights, in the trace
    assert red.any() and obeying.trace["speed_v0"][red].min() < 0.1 and "light_v0" not in ignoring_names(corridor)
    assert obeying.outcome == "no_crash"
    ignoring = simulate(_config(corridor, signals="ignore"), cruise, road=road)
    assert ignoring.trace["speed_v0"].min() > 10.0  # before: on through red at the target speed


def test_an_attacker_that_runs_red_does_so_and_its_followers_stop(corridor, passes):
    config = _config(corridor, signals="attacker_runs_red")
    road = config_road(config)
    simulate(config, np.full(config.steps, np.nan), road=road)
    red = [p for p in passes if p[2] in "rRu"]
    assert red and {car for car, _, _ in red} == {0}  # the check can fail: the attacker crossed on red


def test_among_its_demand_a_cruising_platoon_that_ran_red_into_crossing_traffic_now_waits(corridor):
    network, demand = corridor
    config = EpisodeConfig(network=network, route=ROUTE, start="steady", speed_mps=13.0, duration_s=50.0,
                           traffic={"demand": demand, "seed": 1}, rebuild=True)
    road = config_road(config)
    cruise = np.full(config.steps, np.nan)
    import dataclasses

    before = simulate(dataclasses.replace(config, signals="ignore"), cruise, road=road)
    assert before.outcome == "success" and before.first_collision.pair == "v1-traffic.S10.6"  # no attack at all
    assert simulate(config, cruise, road=road).outcome == "no_crash"


def test_a_road_without_lights_plays_bit_for_bit_whatever_the_rule(tmp_path):
    road_dir = Path(__file__).resolve().parent.parent.parent / "examples" / "roads" / "three_edges"
    episodes = []
    for signals in ("obey", "ignore"):
        config = EpisodeConfig(network=str(road_dir), start="steady", duration_s=20.0, signals=signals)
        u = np.full(config.steps, np.nan)
        u[20:200] = -0.7
        episodes.append(simulate(config, u))
    a, b = episodes
    assert a.trace.names == b.trace.names
    assert all(np.array_equal(a.trace[n], b.trace[n]) for n in a.trace.names)


def ignoring_names(corridor) -> tuple[str, ...]:
    """The signals of an episode through the same lights, driven through: no light_X (nobody looked)."""
    config = _config(corridor, signals="ignore", duration_s=2.0)
    return simulate(config, np.full(config.steps, np.nan), road=config_road(config)).trace.names


def test_a_replay_records_each_signal_state_every_step_and_its_time_space_diagram_draws_the_red_it_stopped_at(
        corridor, tmp_path):
    from matplotlib.collections import LineCollection

    from d4sumo.results import timespace

    config = _config(corridor)
    road = config_road(config)
    cruise = np.full(config.steps, np.nan)
    assert simulate(config, cruise, road=road).signals == ()  # a campaign's episodes record nothing
    episode = simulate(config, cruise, road=road, fcd_path=tmp_path / "fcd.xml")
    assert [tls for _, tls, _ in episode.signals] == ["gneJ12", "gneJ11", "gneJ10"]
    assert all(len(states) == len(episode.trace) - 1 for _, _, states in episode.signals)  # one letter a step
    stopped = int(np.argmax(episode.trace["speed_v0"] < 0.1))
    line, _, states = next(s for s in episode.signals if s[0] > episode.trace["pos_v0"][stopped])
    assert states[stopped] in "rRu" and 0.0 < line - episode.trace["pos_v0"][stopped] < 10.0  # waiting at its stop line
    fcd = timespace.read_fcd(tmp_path / "fcd.xml", road.platoon_lanes)
    fcd.signals = episode.signals
    fig = timespace.time_space_figure(fcd, "red")
    bands = [c for c in fig.axes[0].collections if isinstance(c, LineCollection) and c.get_label().startswith("traffic light")
             or isinstance(c, LineCollection) and np.allclose([seg[0][1] for seg in c.get_segments()], line)]
    red = [seg for c in bands for seg, color in zip(c.get_segments(), c.get_colors()) if seg[0][1] == line
           and tuple(np.round(color[:3], 3)) == (0.839, 0.153, 0.157)]
    waited_s = fcd["v0"]["time"][stopped]  # on the FCD's clock
    assert any(seg[0][0] <= waited_s <= seg[1][0] for seg in red)  # a red band over the time it waited


@pytest.mark.parametrize("signals", ["obey", "attacker_runs_red"])
def test_at_its_lights_the_cars_stepped_in_c_play_the_pythons_episode(corridor, signals, monkeypatch):
    """Along the corridor, where a light turns red ahead: followers capped by their signals and the attacker (a careful
    driver between attacks, as among traffic, obeying or running red) stepped in C play the Python's episode, bit for
    bit."""
    from conftest import assert_same_episode
    from d4sumo.model.controllers import compiled

    config = _config(corridor, signals=signals)  # gneJ11 turns red ahead
    road = config_road(config)
    u = np.full(config.steps, np.nan)
    u[100:140] = -0.5  # an attack between cruises: its cruise starts afresh after it
    in_c = simulate(config, u, road=road)
    monkeypatch.setattr(compiled, "ENABLED", False)
    python = simulate(config, u, road=road)
    assert_same_episode(in_c, python)
    assert in_c.trace["light_v0"].max() == 2.0 and in_c.trace["cmd_v1"].min() < 0.0  # red seen, braked for
