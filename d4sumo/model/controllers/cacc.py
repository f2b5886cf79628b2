"""The cooperative laws: followers that read V2V beacons (`v2v`) as well as their radar. Rajamani's CACC (PATH),
Ploeg's and the consensus controller, as Plexe has them, with Plexe's cruise control where nobody is ahead, the
mitigation the platoon-security literature proposes (`Fallback`), and their ACC where their radar sees another
car than the one whose beacons they read (`unmatched`). Pure code, no SUMO; each is also stepped in C, bit for
bit (`compiled`, `_followers.c`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import check_number
from ..world.vehicle import VehicleParams, acceleration_to_command


@dataclass(frozen=True)
class PathParams:
    """Rajamani's CACC (Plexe's "CACC", the PATH controller; Rajamani, Vehicle Dynamics and Control, Eq.
    7.39), with Plexe's defaults."""

    c1: float = 0.5  # C1: how much the platoon leader's acceleration weighs against the car ahead's
    xi: float = 1.0  # the damping ratio (at least 1)
    omega_n: float = 0.2  # the bandwidth [rad/s]
    #: the mitigation (`Fallback`): fall back to ACC while the car ahead's beacon and the radar disagree on
    #: its speed by more than this [m/s]; 0: never
    fallback_mps: float = 0.0
    fallback_headway_s: float = 1.2  # the ACC's time headway it falls back to

    def __post_init__(self) -> None:
        check_number("controller.c1", self.c1, 0.0, 1.0)
        check_number("controller.xi", self.xi, 1.0, 10.0)
        check_number("controller.omega_n", self.omega_n, 0.0, 10.0, "rad/s", low_open=True)
        check_number("controller.fallback_mps", self.fallback_mps, 0.0, 50.0, "m/s")
        check_number("controller.fallback_headway_s", self.fallback_headway_s, 0.1, 10.0, "seconds")


#: modes a cooperative controller with the mitigation records (signal ``mode_vI``)
MODE_CACC, MODE_FALLBACK = 0.0, 1.0
#: Plexe's cruise control (Rajamani's Eq. 5.5, no integral): its gain [1/s] and its bounds [m/s^2]
CC_KP, CC_ACCEL_MPS2, CC_DECEL_MPS2 = 1.0, 1.5, 1.5


def cruise_acceleration(speed_mps: float, target_speed_mps: float) -> float:
    """Plexe's cruise control at the target speed: what a cooperative controller asks for with nobody ahead."""
    return min(CC_ACCEL_MPS2, max(-CC_DECEL_MPS2, -CC_KP * (speed_mps - target_speed_mps)))


def below_target(acceleration_mps2: float, speed_mps: float, target_speed_mps: float, step_s: float) -> float:
    """An acceleration that takes the car no faster than the target speed within the step: as SUMO holds
    its cars to their maximum speed (the target speed, for SUMO's own CC model)."""
    return min(acceleration_mps2, (target_speed_mps - speed_mps) / step_s)


def acc_acceleration(obs, headway_s: float) -> float:
    """Plexe's ACC (Rajamani's Eq. 6.18: a = -(v - v_ahead + lambda (h v + 2 - gap)) / h, lambda 0.1) on what the
    radar measures: what a cooperative controller falls back to."""
    return -(obs.speed_mps - obs.lead_speed_mps + 0.1 * (headway_s * obs.speed_mps + 2.0 - obs.gap_m)) / headway_s


class Fallback:
    """The mitigation the platoon-security literature proposes: where the car ahead's newest beacon and the
    radar disagree on its speed by more than ``fallback_mps``, the car distrusts the channel and falls back
    to an ACC (`acc_acceleration`) on what its radar measures; it trusts the channel again once they agree.
    Its mode is recorded (falling back where its radar sees another car than the beacons', too: `unmatched`)."""

    def __init__(self, threshold_mps: float, headway_s: float):
        self.threshold, self.headway = threshold_mps, headway_s
        self.mode = MODE_CACC

    def check(self, obs) -> float | None:
        """The ACC's acceleration while the channel is distrusted, else None."""
        ahead = obs.front_message
        if ahead is None or abs(ahead.speed_mps - obs.lead_speed_mps) <= self.threshold or not obs.leader:
            self.mode = MODE_CACC
            return None
        self.mode = MODE_FALLBACK
        return acc_acceleration(obs, self.headway)


def unmatched(controller, obs) -> float:
    """The acceleration of a cooperative ``controller`` whose radar sees another car than the one whose beacons
    it reads (`sensing.Observation.matched`): its ACC at its fallback headway, as CACC systems do where a car
    cut in, no faster than the target speed; its mitigation's mode, where it has one, says it fell back."""
    if controller.fallback is not None:
        controller.fallback.mode = MODE_FALLBACK
    return below_target(acc_acceleration(obs, controller.params.fallback_headway_s), obs.speed_mps,
                        controller.target_speed_mps, controller.step_s)


class PathCACC:
    """Rajamani's CACC (PATH), as Plexe's ``CACC``: constant spacing (the scenario's setpoint),

        a = a1 a_ahead + a2 a_leader + a3 (v - v_ahead) + a4 (v - v_leader) + a5 (d - gap)

    with a1 = 1 - C1, a2 = C1, a3 = -(2 xi - C1 (xi + sqrt(xi^2 - 1))) w, a4 = -C1 (xi + sqrt(xi^2 - 1)) w,
    a5 = -w^2; the speeds and accelerations of the car ahead and of the platoon's leader from their
    newest beacons, the gap from the radar. Until a beacon of each has arrived it asks for nothing (0),
    as Plexe's. It drives no faster than the target speed (`below_target`), and with nobody ahead it
    cruises (`cruise_acceleration`)."""

    Params = PathParams
    listens = True  # it reads V2V beacons: its platoon exchanges them (`v2v`)

    def __init__(self, params: PathParams, *, setpoint_m: float, target_speed_mps: float, vehicle: VehicleParams,
                 step_s: float):
        root = math.sqrt(params.xi ** 2 - 1.0)
        w = params.omega_n
        self.a1, self.a2 = 1.0 - params.c1, params.c1
        self.a3 = -(2.0 * params.xi - params.c1 * (params.xi + root)) * w
        self.a4 = -params.c1 * (params.xi + root) * w
        self.a5 = -w * w
        self.params, self.setpoint_m, self.vehicle, self.target_speed_mps, self.step_s = (params, setpoint_m, vehicle,
                                                                                           target_speed_mps, step_s)
        self.fallback = Fallback(params.fallback_mps, params.fallback_headway_s) if params.fallback_mps else None

    @property
    def mode(self) -> float:
        return self.fallback.mode

    def desired_acceleration(self, gap_m: float, speed_mps: float, ahead, leader) -> float:
        """The law, given the beacons of the car ahead and of the leader (``Message``s)."""
        return (self.a1 * ahead.accel_mps2 + self.a2 * leader.accel_mps2 + self.a3 * (speed_mps - ahead.speed_mps)
                + self.a4 * (speed_mps - leader.speed_mps) + self.a5 * (self.setpoint_m - gap_m))

    def observe(self, obs) -> float:
        ahead, leader = obs.front_message, obs.leader_message
        if not obs.leader:  # nobody ahead within its radar's range: it cruises
            return acceleration_to_command(cruise_acceleration(obs.speed_mps, self.target_speed_mps), self.vehicle)
        if not obs.matched:  # another car is ahead than the one whose beacons it reads
            return acceleration_to_command(unmatched(self, obs), self.vehicle)
        if self.fallback is not None and (acc := self.fallback.check(obs)) is not None:
            return acceleration_to_command(below_target(acc, obs.speed_mps, self.target_speed_mps, self.step_s), self.vehicle)
        if ahead is None or leader is None:
            return 0.0
        speed = obs.speed_mps
        a = self.desired_acceleration(obs.gap_m, speed, ahead, leader)
        return acceleration_to_command(min(a, (self.target_speed_mps - speed) / self.step_s), self.vehicle)  # below_target, inlined



@dataclass(frozen=True)
class PloegParams:
    """Ploeg's CACC (Plexe's "PLOEG"; Ploeg et al. 2011), with Plexe's defaults."""

    h_s: float = 0.5  # the time headway of its spacing policy: the scenario's setpoint plus h v
    kp: float = 0.2  # [1/s^2] on the spacing error
    kd: float = 0.7  # [1/s] on its derivative
    fallback_mps: float = 0.0  # the mitigation, as PathParams'
    fallback_headway_s: float = 1.2

    def __post_init__(self) -> None:
        check_number("controller.h_s", self.h_s, 0.0, 10.0, "seconds", low_open=True)
        check_number("controller.kp", self.kp, 0.0, 100.0)
        check_number("controller.kd", self.kd, 0.0, 100.0)
        check_number("controller.fallback_mps", self.fallback_mps, 0.0, 50.0, "m/s")
        check_number("controller.fallback_headway_s", self.fallback_headway_s, 0.1, 10.0, "seconds")


class PloegCACC:
    """Ploeg's CACC, as Plexe's ``PLOEG``: spacing d + h v (d the scenario's setpoint), its command u
    integrated each step, u' = (-u + kp (gap - d - h v) + kd (v_ahead - v - h a) + a_ahead) / h; the car
    ahead's speed from the radar, its acceleration from its newest beacon, the car's own acceleration
    its last step's. Until a beacon has arrived it asks for nothing (0), as Plexe's. It drives no faster
    than the target speed (`below_target`), and with nobody ahead it cruises (`cruise_acceleration`)."""

    Params = PloegParams
    listens = True

    def __init__(self, params: PloegParams, *, setpoint_m: float, target_speed_mps: float, vehicle: VehicleParams,
                 step_s: float):
        self.params, self.setpoint_m, self.vehicle, self.step_s = params, setpoint_m, vehicle, step_s
        self.target_speed_mps = target_speed_mps
        self.u = 0.0  # its command [m/s^2], integrated
        self.fallback = Fallback(params.fallback_mps, params.fallback_headway_s) if params.fallback_mps else None

    @property
    def mode(self) -> float:
        return self.fallback.mode

    def observe(self, obs) -> float:
        ahead = obs.front_message
        if not obs.leader:  # nobody ahead within its radar's range: it cruises
            self.u = cruise_acceleration(obs.speed_mps, self.target_speed_mps)
            return acceleration_to_command(self.u, self.vehicle)
        if not obs.matched:  # another car is ahead than the one whose beacons it reads: it goes on from its ACC
            self.u = unmatched(self, obs)
            return acceleration_to_command(self.u, self.vehicle)
        if self.fallback is not None and (acc := self.fallback.check(obs)) is not None:
            self.u = below_target(acc, obs.speed_mps, self.target_speed_mps, self.step_s)  # it goes on from there
            return acceleration_to_command(self.u, self.vehicle)
        if ahead is None:
            return 0.0
        p = self.params
        spacing_error = obs.gap_m - (self.setpoint_m + p.h_s * obs.speed_mps)
        speed_error = obs.lead_speed_mps - obs.speed_mps - p.h_s * obs.accel_mps2
        self.u += (-self.u + p.kp * spacing_error + p.kd * speed_error + ahead.accel_mps2) / p.h_s * self.step_s
        # below_target, inlined: nor does the integrator wind up
        self.u = u = min(self.u, (self.target_speed_mps - obs.speed_mps) / self.step_s)
        return acceleration_to_command(u, self.vehicle)



@dataclass(frozen=True)
class ConsensusParams:
    """Santini et al.'s consensus controller (Plexe's "CONSENSUS"; Santini, Salvi, Valente, Pescape,
    Segata, Lo Cigno 2015), with Plexe's defaults: its gains are Plexe's divided by the 1000 its law divides
    by, and its spacing the scenario's setpoint plus ``h_s`` times the leader's speed (Plexe fixes that
    standstill distance at 15 m)."""

    b: float = 1.8  # [1/s] on the speed error against the leader (Plexe's b, 1800)
    k_leader_v1: float = 0.46  # [1/s^2] on v1's spacing error to the leader (Plexe's K[1][0], 460)
    k_leader: float = 0.08  # [1/s^2] on the others' spacing error to the leader (K[i][0], 80)
    k_front: float = 0.86  # [1/s^2] on the spacing error to the car ahead (K[i][i-1], 860)
    h_s: float = 0.8  # the time headway of its spacing policy [s]
    fallback_mps: float = 0.0  # the mitigation, as PathParams'
    fallback_headway_s: float = 1.2

    def __post_init__(self) -> None:
        for name in ("b", "k_leader_v1", "k_leader", "k_front"):
            check_number(f"controller.{name}", getattr(self, name), 0.0, 100.0)
        check_number("controller.h_s", self.h_s, 0.0, 10.0, "seconds")
        check_number("controller.fallback_mps", self.fallback_mps, 0.0, 50.0, "m/s")
        check_number("controller.fallback_headway_s", self.fallback_headway_s, 0.1, 10.0, "seconds")


class ConsensusCACC:
    """The consensus controller, as Plexe's ``CONSENSUS`` computes it: from the positions, speeds and
    lengths in the beacons of every car ahead (GPS, no radar), at the time its command acts (a step on:
    its own position moved on by its speed, each beacon's by its speed since it was sent),

        a = -b (v - v_leader) + (1 / |N|) sum_j k_j (|x_j - x| - d_j)   over j in N = {leader, car ahead}

    with d_j the desired distance from its front bumper to car j's: for each car k from j to the one
    ahead of it, h v_leader + length_k + d (d the scenario's setpoint). Until a beacon of every car ahead
    has arrived it asks for nothing (0), as Plexe's. It drives no faster than the target speed
    (`below_target`)."""

    Params = ConsensusParams
    listens = True
    hears_all = True  # it reads every car ahead's beacons (their lengths, in the desired distances)

    def __init__(self, params: ConsensusParams, *, setpoint_m: float, target_speed_mps: float, vehicle: VehicleParams,
                 step_s: float):
        self.params, self.setpoint_m, self.vehicle, self.step_s = params, setpoint_m, vehicle, step_s
        self.target_speed_mps = target_speed_mps
        self.fallback = Fallback(params.fallback_mps, params.fallback_headway_s) if params.fallback_mps else None
        self._gains: dict[int, tuple] = {}  # by its place in the platoon: (car j, its gain) for j in N

    @property
    def mode(self) -> float:
        return self.fallback.mode

    def desired_acceleration(self, position_m: float, speed_mps: float, time_s: float, messages) -> float:
        """The law at the step that starts at ``time_s``, given every car ahead's newest beacon by sender."""
        p, dt = self.params, self.step_s
        car = len(messages)  # its place in the platoon: a beacon of every car ahead
        leader = messages[0]
        acting = time_s + dt
        own = position_m + speed_mps * dt
        spacing = p.h_s * leader.speed_mps + self.setpoint_m
        gains = self._gains.get(car)
        if gains is None:  # N and its gains, the same at every step once every car ahead was heard
            gains = self._gains[car] = ((0, p.k_leader_v1),) if car == 1 else ((0, p.k_leader), (car - 1, p.k_front))
        spacing_error = 0.0
        for j, k in gains:
            m = messages[j]
            desired = sum([spacing + messages[i].length_m for i in range(j, car)])
            distance = abs(m.position_m + (acting - m.time_s) * m.speed_mps - own)
            spacing_error += k * (distance - desired)
        return -p.b * (speed_mps - leader.speed_mps) + spacing_error / len(gains)

    def observe(self, obs) -> float:
        if not obs.matched and obs.leader:  # another car is ahead than the one whose beacons it reads
            return acceleration_to_command(unmatched(self, obs), self.vehicle)
        if self.fallback is not None and (acc := self.fallback.check(obs)) is not None:
            return acceleration_to_command(below_target(acc, obs.speed_mps, self.target_speed_mps, self.step_s), self.vehicle)
        messages = obs.messages
        if messages is None or obs.front_message is None or len(messages) < obs.front_message.sender + 1:
            return 0.0
        speed = obs.speed_mps
        a = self.desired_acceleration(obs.position_m, speed, obs.time_s, messages)
        return acceleration_to_command(min(a, (self.target_speed_mps - speed) / self.step_s), self.vehicle)  # below_target, inlined
