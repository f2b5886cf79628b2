"""A platoon's followers stepped in C (the `_followers` extension, built when d4sumo is installed): the
same commands, modes and speeds as `platoon.Platoon.advance`'s Python, bit for bit, at a fraction of its
cost (docs/v2v.md, docs/benchmarks.md).

It plays the platoons whose every follower runs d4sumo's `switching` (the paper's controller as printed),
`timegap` (each as printed or with the authors' code's options: `control.SwitchingParams`), `idm`, an FMU
(`fmu:PATH`: its FMI calls made from C, on the instance fmpy made), `cacc`, `ploeg` or `consensus` (the classes
themselves, not a subclass), the cooperative ones with or without the mitigation (and, beside an attacker stepped
here without a channel, followers SUMO's models drive: nothing of theirs), without traffic lights: their radars
(range, noise, latency), their channel (interval, latency, loss) and a message attack on it, each drawing from the
Python's own generators and lying with the Python's own falsifier, in the order the Python does. In the paper's
column each follows the car before it; without a channel, also where the attacker changes lanes or traffic is
around, each follows the nearest car the step's pairs put ahead of it, a traffic car included. The switching law in
C is the one the FMUs d4sumo ships run (`fmus/switching.h`). The attacker too, where it only plays its attack and
cruises (no traffic, no motion), as printed or as the authors' code has it. Everything else the Python plays, as it
does everywhere when the extension could not be built (no C compiler at install: the same episodes, slower). Where
every episode left in a SUMO (or the ballistic world) is such a platoon in the paper's column, the step loop itself
goes on in C (`play_column`, `engine.loop`): each step's commands, the world's calls and the collision checks, as
the Python's loop makes them.
"""

from __future__ import annotations

import ctypes
import sys
from typing import Callable

from .commands import ControllerError, checked_command  # the Python's error for a command that is not one
from .cacc import ConsensusCACC, PathCACC, PloegCACC
from .control import CodePID, SwitchingController, TimeGapController
from .fmu import FmuController
from .laws.idm import IDMController
from ..attacks.messages import BeaconFalsifier
from ..world.sensing import Radar
from ..world.v2v import Message

try:
    from ._followers import Followers, play_column
except ImportError:  # not built: the Python plays every platoon
    Followers = play_column = None

#: whether the platoons it may play are stepped in C (tests turn it off to compare with the Python)
ENABLED = True

#: a follower SUMO drives, as the extension reads it: law 0, no mode, its numbers zeros
SUMO_DRIVES = (0, False, (0.0,) * 5, (0.0,) * 5, 0.0, (0.0, 0.0), (0.0,) * 7, None)

#: each controller's law, as the extension numbers them
LAWS = {PathCACC: 1, PloegCACC: 2, ConsensusCACC: 3, SwitchingController: 4, TimeGapController: 5, IDMController: 6}
if sys.version_info >= (3, 12):  # the consensus law sums with sum(), which is compensated from Python 3.12 on
    del LAWS[ConsensusCACC]


def compiled_followers(platoon, attacker: bool = False) -> Callable | None:
    """``advance(k, positions, speeds, pairs, commands, new_speeds, modes)`` of ``platoon``'s followers in C,
    or None where the Python plays them (see the module). Made before the platoon's first step: it takes
    the channel's and the radars' generators as they start, and the controllers' state as it is (carried on from a
    batch's arrays: `batch.PlatoonBatch.detach`). With ``attacker`` (one that plays its attack and
    cruises, nothing else, as printed or as the authors' code has it: `platoon.Platoon`) the attacker is stepped in C
    too, its command and speed first."""
    channel, config = platoon.channel, platoon.config
    # followers SUMO drives (its models) with the attacker stepped here: nothing of theirs is, no beacon for them
    sumo_driven = attacker and channel is None and not platoon._sumo_listening
    if (Followers is None or not ENABLED or not platoon._one_ahead and channel is not None  # a channel: the column only
            or len(platoon._python) != config.followers and not sumo_driven
            or (channel is not None and channel.falsify is not None
                and (type(channel.falsify) is not BeaconFalsifier  # d4sumo's lies: none renames its sender
                     or channel.liar not in channel.senders))):
        return None
    laws = []
    for i, follower in enumerate(platoon.followers, start=1):
        if follower.sumo_driven:
            laws.append(SUMO_DRIVES)
            continue
        radar = None
        if config.radar is not None and not config.radar.perfect:  # its own, as the Python's starts: the same draws
            r = Radar(config.radar, config.step_s, i)
            radar = (r.params.range_m, r.params.gap_noise_m, r.params.speed_noise_mps, r.readings.maxlen - 1, r.rng.normal)
        law = _law(follower.controller, follower.actuator, follower.has_mode, radar, channel is not None, i, follower.config.cls)
        if law is None:
            return None
        laws.append(law)
    ours = None
    if attacker:
        ours = _attacker(platoon) if platoon._attacker_as_run is None else _attacker_as_run(platoon)
        if ours is None:
            return None
    if channel is None:
        # out of the paper's column (a lane change, traffic) each follows the nearest car its pairs put ahead of it
        return Followers(None, [0.0] * (config.followers + 1), [()] * config.followers, [], None, laws, checked_command,
                         ours, not platoon._one_ahead).advance
    sources = [channel.sources[i] for i in range(1, config.followers + 1)]
    randoms = [channel.rngs[s, i].random for i, srcs in enumerate(sources, start=1) for s in srcs] if channel.rngs else []
    lie = (channel.falsify, channel.liar, Message, channel.sent) if channel.falsify is not None else None
    return Followers((channel.step_s, channel.every, channel.delay, float(channel.params.loss)), list(channel.lengths), sources,
                     randoms, lie, laws, checked_command, ours).advance


def _law(controller, actuator, has_mode: bool, radar: tuple | None, channel: bool, car: int, name: str) -> tuple | None:
    """What the C reads of one car's controller (a follower's, or the authors' attacker's): its law, its numbers, its state
    as it is (as it starts, or carried on from a batch); None where the C does not step it."""
    law = 7 if isinstance(controller, FmuController) else LAWS.get(type(controller))
    if law is None or (law < 4 and not channel):
        return None
    switching = law in (4, 5)
    if law == 7:  # an FMU: nothing of its own but its instance (`_fmu`)
        gains = (0.0,) * 5
    elif law == 6:  # the IDM: as its constructor made it
        p = controller.params
        gains = (p.time_gap_s, p.accel_mps2, p.delta, controller._root_ab, 2.0)  # (gap wanted / gap) ** 2
    elif switching:  # the paper's controller (as printed, or with the authors' code's options: `_as_run`), or its time-gap variant
        p = controller.params
        gains = (p.cruise_kp, p.cruise_ki, p.cruise_kd, p.cruise_integral_clamp, p.cruise_output_limit_mps2,
                 p.acc_kp, p.acc_kv, p.eps_x_m, p.eps_v_mps) + ((controller.time_gap_s,) if law == 5 else ())
    elif law == 1:  # PATH's coefficients, as its constructor derived them
        gains = (controller.a1, controller.a2, controller.a3, controller.a4, controller.a5)
    elif law == 2:
        p = controller.params
        gains = (p.h_s, p.kp, p.kd, 0.0, 0.0)
    else:
        p = controller.params
        gains = (p.b, p.k_leader_v1, p.k_leader, p.k_front, p.h_s)
    fallback = getattr(controller, "fallback", None)
    mitigation = (fallback.threshold, fallback.headway) if fallback is not None else (0.0, 0.0)
    vehicle = controller.vehicle
    if law == 7:  # its step
        own = (0.0, 0.0, controller.step_s, vehicle.max_accel_mps2, vehicle.max_decel_mps2)
    elif law == 6:  # its standstill gap and target speed (no step of its own)
        own = (controller.s0_m, controller.v0_mps, 0.0, vehicle.max_accel_mps2, vehicle.max_decel_mps2)
    else:
        step_s = controller.cruise.step_s if switching else controller.step_s  # the step its cruise PID integrates over
        own = (controller.setpoint_m, controller.target_speed_mps, step_s, vehicle.max_accel_mps2, vehicle.max_decel_mps2)
    drive = (actuator.accel_max, actuator.decel_max, actuator.alpha, actuator.step_s, actuator.max_speed_mps,
             actuator.accel_mps2, actuator.coast)
    numbers = (*own, *gains, *mitigation, *drive, *(radar[:3] if radar else ()))
    if not all(type(x) is float or type(x) is int for x in numbers):  # a numpy float32 computes otherwise in the Python
        return None
    state = ()
    if law == 7:
        state = (_fmu(controller, car, name),)
    elif switching:  # its state (carried on from a batch, or as it starts): its cruise's, its mode
        cruise = (float(controller.cruise.integral), controller.cruise.prev_error, float(controller.mode),
                  bool(controller._mode_known))
        if cruise[1] is not None and type(cruise[1]) is not float:
            return None
        state = (cruise,)
        if controller._as_run:
            run = _as_run(controller)
            if run is None:
                return None
            state = (cruise, run)
    return (law, has_mode, own, tuple(float(g) for g in gains), float(getattr(controller, "u", 0.0)),
            tuple(float(m) for m in mitigation), drive, radar, *state)


def _as_run(controller: SwitchingController) -> tuple | None:
    """What the C reads of the authors' code's options and their state (`SwitchingController._as_run_setup`), as it is;
    None where a number is not a plain float (the Python then computes otherwise)."""
    p = controller.params

    def pid(pid: CodePID | None) -> tuple | None:
        return None if pid is None else (pid.kp, pid.ki, pid.kd, pid.period_s, pid.filter_s, pid.clamp, pid.limit,
                                         pid.integral, pid.prev_error, pid.filtered, pid.prev_filtered)

    cruise = pid(getattr(controller, "_code_cruise", None) if p.cruise_pid == "code" else None)
    low = pid(getattr(controller, "_low", None) if p.low_level == "pid" else None)
    run = (controller._every, controller._calls, controller._period_s, controller.held, controller._prev_speed,
           p.switching_rule == "code", p.cruise_pid == "code", p.low_level == "pid", bool(p.first_command_zero),
           controller._engage_m, controller._release_m, cruise, low)
    numbers = (run[2], run[3], run[4], run[9], run[10], *(cruise or ()), *(low or ()))
    if not all(x is None or type(x) is float or type(x) is int for x in numbers):
        return None
    return run


def _fmu(controller: FmuController, car: int, name: str) -> tuple:
    """What the C reads of an FMU follower: its FMI version, its instance and the three functions fmpy loaded, its inputs'
    and outputs' references, whether it answers an acceleration, its clock; and how a failed call is said, as the Python
    says a user's controller's error (`platoon._named_errors`)."""
    def fail(message: str):
        try:
            raise RuntimeError(message)
        except RuntimeError as exc:
            raise ControllerError(f"the controller of v{car} ({name}) raised RuntimeError: {exc}") from exc

    address = lambda f: ctypes.cast(f, ctypes.c_void_p).value  # noqa: E731
    return (controller.fmu.version, controller._handle if isinstance(controller._handle, int) else controller._handle.value,
            address(controller._set_real), address(controller._do_step), address(controller._get_real),
            tuple(controller._in_vr), tuple(controller._out_vr), controller._acceleration, float(controller.time_s), fail)


def _attacker_as_run(platoon) -> tuple | None:
    """What the C reads of the authors' attacker: its attack, the steps between two of its pedals, their controller (on a
    free road: no radar, no mode recorded) with its actuator."""
    law = _law(platoon._attacker_as_run, platoon.attacker_actuator, False, None, False, 0, "")
    return None if law is None else (platoon.attack_u, platoon._attacker_every, law)


def _attacker(platoon) -> tuple | None:
    """What the C reads of the attacker: its attack, its cruise control's gains, its car, its actuator, its state; among
    traffic, the careful driver it is where it does not attack (`control.CautiousDriver`: its cruise is the driver's)."""
    driver = platoon._attacker_driver
    cruise = platoon.attacker_cruise if driver is None else driver.cruise
    actuator, vehicle = platoon.attacker_actuator, platoon.attacker_vehicle
    careful = None if driver is None else (driver.setpoint_m, driver.time_gap_s, driver._kp, driver._kv)
    if careful is not None and not all(type(x) is float or type(x) is int for x in careful):
        return None
    return (platoon.attack_u, (cruise.kp, cruise.ki, cruise.kd, cruise.clamp, cruise.limit),
            (cruise.target_mps, cruise.step_s, vehicle.max_accel_mps2, vehicle.max_decel_mps2),
            (actuator.accel_max, actuator.decel_max, actuator.alpha, actuator.step_s, actuator.max_speed_mps,
             actuator.accel_mps2, actuator.coast),
            (float(cruise.integral), cruise.prev_error, float(platoon._attacking)),  # its state: as it starts, or carried on
            careful)
