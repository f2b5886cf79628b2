"""The platoon's longitudinal control, one step at a time: pure code, no SUMO.

`Platoon.advance` takes the sensed state (positions and speeds, front to back) and returns the speed
each car reaches at the end of the step: the attacker plays its attack signal (or cruises where the
signal is NaN), each follower runs its controller, and every command goes through the car's actuator.
The SUMO co-simulation calls it each step; `integrate` runs it with SUMO's ballistic position update
for SUMO-free physics tests.
"""

from __future__ import annotations

import numpy as np

from .config import EpisodeConfig
from .control import Actuator, CruiseControl, SwitchingParams, acceleration_to_command
from .errors import D4sumoError
from .trace import Collision, Episode, Trace


class ControllerError(D4sumoError, ValueError):
    """A follower controller returned something that is not a command."""


#: The rearmost car's front bumper starts this far from the road's start [m].
REAR_START_M = 10.0


def initial_state(config: EpisodeConfig) -> tuple[list[float], list[float]]:
    """Front-bumper positions and speeds at t = 0, front (attacker) to back, spaced at the setpoint."""
    n = config.followers + 1
    spacing = config.vehicle.length_m + config.setpoint_m
    rear = config.vehicle.length_m + REAR_START_M
    positions = [rear + spacing * (n - 1 - i) for i in range(n)]
    speed = config.speed_mps if config.start == "steady" else 0.0  # rest and warmup start standing
    return positions, [speed] * n


def road_needed_m(config: EpisodeConfig, speed_limit_mps: float) -> float:
    """Road length an episode may use: the attacker, clamped to the limit, is always in front."""
    return initial_state(config)[0][0] + speed_limit_mps * config.total_s


def collisions_at(time_s: float, positions: list[float], speeds: list[float], length_m: float) -> tuple[Collision, ...]:
    """Every bumper overlap (gap < 0) at the end of a step, frontmost pair first.

    This is the definition of a collision, whether SUMO reports it or not (SUMO ignores overlaps up to
    1 mm). The gap is computed with the trace's arithmetic, so the outcome, the collision record and
    the trace's minimum gaps always agree. The position is the follower's front bumper, where it hit.
    """
    return tuple(
        Collision(f"v{i}", f"v{i + 1}", time_s, positions[i + 1], (speeds[i + 1] - speeds[i]) * 3.6)
        for i in range(len(positions) - 1)
        if positions[i] - length_m - positions[i + 1] < 0.0
    )


class Platoon:
    def __init__(self, config: EpisodeConfig, attack_u: np.ndarray, attacker_max_speed_mps: float):
        attack_u = np.asarray(attack_u, dtype=float)
        if attack_u.shape != (config.steps,):
            raise ValueError(f"attack signal has shape {attack_u.shape}, expected ({config.steps},)")
        self.config = config
        self.attack_u = attack_u.tolist()  # plain floats: fast in the step loop
        vehicle, dt = config.vehicle, config.step_s
        self.length_m = vehicle.length_m
        cls = config.controller.controller_class()
        params = config.controller.build_params()
        # The attacker is the same kind of car: it cruises with the followers' PID gains when they
        # run the switching controller, with the default gains otherwise.
        cruise_params = params if isinstance(params, SwitchingParams) else SwitchingParams()
        self.attacker_cruise = CruiseControl(cruise_params, config.speed_mps, dt)
        self.followers = [
            cls(params, setpoint_m=config.setpoint_m, target_speed_mps=config.speed_mps, vehicle=vehicle, step_s=dt)
            for _ in range(config.followers)
        ]
        self.actuators = [Actuator(vehicle, dt, attacker_max_speed_mps)]
        self.actuators += [Actuator(vehicle, dt, float("inf")) for _ in range(config.followers)]
        self.records_modes = all(hasattr(f, "mode") for f in self.followers)
        self._attacking = False
        self.commands: list[list[float]] = []
        self.modes: list[list[float]] = []

    def advance(self, k: int, positions: list[float], speeds: list[float]) -> list[float]:
        """Commands for step k from the sensed state; returns each car's speed at the step's end."""
        u = self.attack_u[k]
        if u != u:  # NaN: no attack here, the attacker cruises like everyone else
            if self._attacking:  # a new cruise window: the PID starts afresh (no kick, no stale integral)
                self.attacker_cruise.reset()
                self._attacking = False
            u = acceleration_to_command(self.attacker_cruise.acceleration(speeds[0]), self.config.vehicle)
        else:
            self._attacking = True
        commands = [u]
        length = self.length_m
        for i, follower in enumerate(self.followers, start=1):
            c = follower.command(positions[i - 1] - length - positions[i], speeds[i], speeds[i - 1])
            if not -1.0 <= c <= 1.0:  # NaN fails too: a user's controller must not corrupt the trace
                raise ControllerError(f"the controller of v{i} returned {c!r} at step {k}; allowed: a command in [-1, 1]")
            commands.append(c)
        self.commands.append(commands)
        if self.records_modes:
            self.modes.append([f.mode for f in self.followers])
        return [a.apply(c, v) for a, c, v in zip(self.actuators, commands, speeds)]

    def trace(self, times_s: np.ndarray, positions: np.ndarray, speeds: np.ndarray) -> Trace:
        """Assemble the Trace from the sensed rows (samples x cars) and the recorded commands."""
        n_samples = times_s.size
        n = self.config.followers + 1
        cmds = np.array(self.commands, dtype=float).reshape(-1, n)
        if cmds.shape[0] < n_samples:  # the last sample has no step after it: hold its command
            cmds = np.vstack([cmds, np.repeat(cmds[-1:], n_samples - cmds.shape[0], axis=0)])
        accel = np.zeros_like(speeds)
        accel[1:] = np.diff(speeds, axis=0) / self.config.step_s
        signals: dict[str, np.ndarray] = {}
        for i in range(n):
            signals[f"pos_v{i}"] = positions[:, i]
            signals[f"speed_v{i}"] = speeds[:, i]
            signals[f"accel_v{i}"] = accel[:, i]
            signals[f"cmd_v{i}"] = cmds[:n_samples, i]
        for i in range(n - 1):  # the same arithmetic as collisions_at: verdicts and trace agree exactly
            signals[f"gap_{i}"] = positions[:, i] - self.length_m - positions[:, i + 1]
        if self.records_modes and self.modes:
            modes = np.array(self.modes, dtype=float)
            if modes.shape[0] < n_samples:
                modes = np.vstack([modes, np.repeat(modes[-1:], n_samples - modes.shape[0], axis=0)])
            for i in range(1, n):
                signals[f"mode_v{i}"] = modes[:n_samples, i - 1]
        return Trace(times_s=times_s, signals=signals, followers=self.config.followers)


def integrate(config: EpisodeConfig, attack_u: np.ndarray, attacker_max_speed_mps: float = float("inf")) -> Episode:
    """Run the platoon without SUMO: ballistic positions (mean of old and new speed, as SUMO's
    --step-method.ballistic), stopping at the first bumper overlap. For physics tests and checks."""
    platoon = Platoon(config, attack_u, attacker_max_speed_mps)
    positions, speeds = initial_state(config)
    dt, length = config.step_s, config.vehicle.length_m
    rows_x, rows_v = [positions], [speeds]
    collisions: tuple[Collision, ...] = ()
    for k in range(config.steps):
        new_speeds = platoon.advance(k, positions, speeds)
        positions = [x + 0.5 * (v + w) * dt for x, v, w in zip(positions, speeds, new_speeds)]
        speeds = new_speeds
        rows_x.append(positions)
        rows_v.append(speeds)
        collisions = collisions_at((k + 1) * dt, positions, speeds, length)
        if collisions:
            break
    times = np.arange(len(rows_x)) * dt
    return Episode(platoon.trace(times, np.array(rows_x), np.array(rows_v)), tuple(collisions))
