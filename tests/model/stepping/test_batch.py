"""Episodes advanced together over arrays against the same episodes played alone: no SUMO."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_same_episode, random_plans

from d4sumo.engine.ballistic import integrate, integrate_batch
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.world.sensing import RadarParams
from d4sumo.model.world.v2v import ChannelParams
from d4sumo.model.world.vehicle import VehicleParams
from d4sumo.model.controllers.commands import ControllerError


def attacks(config: EpisodeConfig, count: int, seed: int = 0, family: str = "knots") -> np.ndarray:
    return np.array([p.u for p in random_plans(config, count, seed, family)])


class Flaky:
    """A user's controller that returns NaN once its gap opens past 16 m."""

    from d4sumo.model.controllers.control import SwitchingParams as Params

    def __init__(self, params, **kwargs):
        from d4sumo.model.controllers.control import SwitchingController

        self.inner = SwitchingController(params, **kwargs)
        self.mode = 0.0

    def command(self, gap_m, speed_mps, lead_speed_mps):
        u = self.inner.command(gap_m, speed_mps, lead_speed_mps)
        self.mode = self.inner.mode
        return float("nan") if gap_m > 16.0 else u


@pytest.mark.parametrize("config", [
    EpisodeConfig(),
    EpisodeConfig(start="steady", setpoint_m=12.0, speed_mps=20.0),
    EpisodeConfig(start="warmup", setpoint_m=3.0, followers=5),
    EpisodeConfig(controller=ControllerConfig("timegap", params=(("time_gap_s", 0.6),)), setpoint_m=4.0),
    EpisodeConfig(controller=(ControllerConfig("switching"), ControllerConfig("timegap", where="controller.v2"),
                              ControllerConfig("switching", params=(("acc_kp", 0.5),), where="controller.v3")), setpoint_m=5.0),
], ids=["rest", "steady", "warmup-5", "timegap", "mixed"])
@pytest.mark.parametrize("family", ["knots", "persistent"])
@pytest.mark.parametrize("detach_at_step", [None, 0, 250])
def test_an_episode_in_a_batch_is_the_episode_played_alone(config, family, detach_at_step):
    """Also when the batch hands its episodes over to go on one at a time, midway."""
    signals = attacks(config, 12, family=family)
    batched = integrate_batch(config, signals, 40.0, detach_at_step=detach_at_step)
    assert len(batched) == len(signals)
    for u, episode in zip(signals, batched):
        assert_same_episode(episode, integrate(config, u, 40.0))
    assert len({(e.outcome, len(e.trace)) for e in batched}) >= 2  # not twelve copies of one episode


def test_the_batch_ends_episodes_apart_and_covers_every_outcome():
    config = EpisodeConfig(setpoint_m=4.0)
    signals = attacks(config, 40, seed=3)
    batched = integrate_batch(config, signals, 40.0)
    assert {e.outcome for e in batched} == {"success", "attacker_crash", "no_crash"}
    assert len({len(e.trace) for e in batched}) > 5  # they ended at different steps


def test_a_user_controller_without_an_array_form_runs_per_episode_and_fails_alone():
    import sys

    sys.modules[__name__].Flaky = Flaky
    config = EpisodeConfig(setpoint_m=7.0, controller=ControllerConfig(f"{__name__}:Flaky"))
    signals = attacks(config, 8, seed=1)
    batched = integrate_batch(config, signals, 40.0, detach_at_step=200)
    kinds = set()
    for u, result in zip(signals, batched):
        try:
            alone = integrate(config, u, 40.0)
        except ControllerError as exc:
            assert isinstance(result, ControllerError) and str(result) == str(exc)
            kinds.add("error")
            continue
        assert_same_episode(result, alone)
        kinds.add("episode")
    assert kinds == {"error", "episode"}


MIXED = {  # several campaigns' configurations in one batch: setpoints, target speeds, rest and steady
    "switching": [EpisodeConfig(setpoint_m=s, speed_mps=v, start=start)
                  for s, v, start in ((3.0, 20.0, "rest"), (7.0, 25.0, "steady"), (12.0, 30.0, "rest"), (9.0, 20.0, "steady"))],
    "timegap": [EpisodeConfig(setpoint_m=s, speed_mps=v, start="steady",
                              controller=ControllerConfig("timegap", params=(("time_gap_s", 0.6),)))
                for s, v in ((4.0, 20.0), (8.0, 30.0))],
    # a campaign that searches its situation: each row its own gains, time gap and actuator lag
    "gains": [EpisodeConfig(setpoint_m=s, start=start, controller=ControllerConfig(
                  "switching", params=(("acc_kp", kp), ("acc_kv", kv), ("cruise_kp", ckp), ("eps_x_m", eps))),
                  vehicle=VehicleParams(actuator_lag_s=lag))
              for s, kp, kv, ckp, eps, lag, start in ((5.0, 0.9304, 2.1599, 0.4, 1.0, 0.5, "rest"), (5.0, 0.5, 1.5, 0.7, 0.5, 0.3, "steady"),
                                                      (7.5, 1.4, 2.6, 0.2, 2.0, 0.8, "rest"))],
    "time gaps": [EpisodeConfig(setpoint_m=3.0, start="steady", controller=ControllerConfig("timegap", params=(("time_gap_s", h),)))
                  for h in (0.4, 0.9, 1.5)],
}


@pytest.mark.parametrize("name", MIXED)
@pytest.mark.parametrize("detach_at_step", [None, 300])
def test_episodes_of_several_configurations_in_one_batch_are_each_the_episode_alone(name, detach_at_step):
    """A sweep's campaigns share one batch: each row keeps its own setpoint, target speed and start."""
    configs = MIXED[name] * 3
    signals = np.array([random_plans(c, 1, seed=i)[0].u for i, c in enumerate(configs)])
    batched = integrate_batch(configs, signals, 40.0, detach_at_step=detach_at_step)
    for config, u, episode in zip(configs, signals, batched):
        assert_same_episode(episode, integrate(config, u, 40.0))
    assert len({(e.outcome, len(e.trace)) for e in batched}) >= 2


def test_a_batch_refuses_configurations_that_differ_in_more_than_setpoint_speed_and_start():
    from d4sumo.model.stepping.batch import batch_key

    configs = [EpisodeConfig(), EpisodeConfig(followers=4)]
    signals = np.zeros((2, configs[0].steps))
    with pytest.raises(ValueError, match="differ in more than"):
        integrate_batch(configs, signals)
    assert batch_key(EpisodeConfig(setpoint_m=3, speed_mps=20, start="steady")) == batch_key(EpisodeConfig())
    assert batch_key(EpisodeConfig(start="warmup")) != batch_key(EpisodeConfig())
    sumo = ControllerConfig("sumo:ACC")
    assert batch_key(EpisodeConfig(controller=sumo, speed_mps=20)) != batch_key(EpisodeConfig(controller=sumo))
    assert batch_key(EpisodeConfig(controller=sumo, setpoint_m=3)) == batch_key(EpisodeConfig(controller=sumo))
    # what each platoon carries per episode: a Python controller's numbers, the actuator's lag, the radar, the channel
    gains = ControllerConfig("switching", params=(("acc_kp", 0.5),))
    assert batch_key(EpisodeConfig(controller=gains, vehicle=VehicleParams(actuator_lag_s=0.2))) == batch_key(EpisodeConfig())
    assert batch_key(EpisodeConfig(controller=ControllerConfig("sumo:ACC", (("tau", 1.5),)))) != batch_key(EpisodeConfig(controller=sumo))
    assert batch_key(EpisodeConfig(vehicle=VehicleParams(length_m=4.0))) != batch_key(EpisodeConfig())
    noisy = EpisodeConfig(radar=RadarParams(gap_noise_m=0.2))
    assert batch_key(noisy) != batch_key(EpisodeConfig())  # the arrays command the one, each platoon the other
    assert batch_key(noisy) == batch_key(EpisodeConfig(radar=RadarParams(gap_noise_m=0.5, seed=3)))
    cacc = ControllerConfig("cacc")
    assert batch_key(EpisodeConfig(controller=cacc, v2v=ChannelParams(loss=0.3))) == batch_key(EpisodeConfig(controller=cacc))


def test_a_user_controller_in_a_batch_runs_with_each_episodes_own_parameters():
    import sys

    sys.modules[__name__].Flaky = Flaky
    configs = [EpisodeConfig(setpoint_m=7.0, controller=ControllerConfig(f"{__name__}:Flaky", params=(("acc_kp", kp),)))
               for kp in (0.4, 0.9304, 1.6)] * 2
    signals = np.array([random_plans(c, 1, seed=i)[0].u for i, c in enumerate(configs)])
    for detach_at_step in (None, 150):
        batched = integrate_batch(configs, signals, 40.0, detach_at_step=detach_at_step)
        for config, u, result in zip(configs, signals, batched):
            try:
                alone = integrate(config, u, 40.0)
            except ControllerError as exc:
                assert isinstance(result, ControllerError) and str(result) == str(exc)
                continue
            assert_same_episode(result, alone)
