"""ARCH-COMP's chasing cars (CC): the model and the specifications CC1-CC5 and CCx, in numpy.

The model is the Simulink/Stateflow model `cars.mdl` the falsification competition uses (the copy in
ERATOMMSD/falstar, falstar/resource/simulink/cars.mdl), read from its charts:

- car 1: ``v' = -throttle - brake * v``, ``y' = v`` (throttle and brake in [0, 1]; y decreases as it
  drives), from y = 0, v = 0;
- cars 2-5, each a chart with the position ``y_in`` of the car ahead, from y = 10, 20, 30, 40 and v = 0,
  starting in Keeping:
  Chasing (``v' = 1``, ``y' = -v``) -> Keeping when ``y - y_in <= 10``;
  Keeping (``y' = v``) -> Chasing when ``y - y_in >= 15``, -> Braking when ``y - y_in <= 5``;
  Braking (``v' = -v``, ``y' = -v``) -> Chasing when ``y - y_in >= 20``.

Integrated here by explicit Euler at ``DT`` with the charts' transitions taken at each step (Simulink
integrates with a variable-step solver and locates the transitions: robustness values near a threshold
may differ slightly), outputs sampled every ``SAMPLE_S`` for the specifications.

The specifications, quoted from FalStar's configuration for ARCH-COMP (ERATOMMSD/falstar,
falstar/resource/configuration/qest2019-journal/instance1/cc.cfg), d21 = y2 - y1, d54 = y5 - y4:
- CC1: (always (0 100) (<= d54 40))
- CC2: (always (0 70) (eventually (0 30) (>= d54 15)))
- CC3: (always (0 80) (or (always (0 20) (<= d21 20)) (eventually (0 20) (<= d54 40))))
- CC4: (always (0 65) (eventually (0 30) (always (0 5) (>= d54 8))))
- CC5: (always (0 72) (eventually (0 8) (implies (always (0 5) (>= d21 9)) (always (5 20) (>= d54 9)))))
- CCx (the competition's report of 2019, not in that file): always (0 50) of y_{i+1} - y_i > 7.5 for
  every i.

Input instances: 2, piecewise constant, 20 segments of 5 s for throttle and for brake (40 parameters);
1, piecewise linear through the same 40 values at 0, 5.26, ..., 100 s (arbitrary piecewise-continuous
inputs, as the competition's instance 1 allows).
"""

from __future__ import annotations

import numpy as np

DT = 0.01  # integration step [s]
SAMPLE_S = 0.1  # the outputs the specifications read, every this [s]
DURATION_S = 100.0
SEGMENTS = 20
CHASING, KEEPING, BRAKING = 0, 1, 2
SPECS = ("CC1", "CC2", "CC3", "CC4", "CC5", "CCx")


def inputs(params: np.ndarray, instance: int, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Throttle and brake (runs x times) from rows of 40 parameters (20 throttle values, then 20 brake)."""
    params = np.atleast_2d(params)
    throttle, brake = params[:, :SEGMENTS], params[:, SEGMENTS:]
    if instance == 2:
        index = np.minimum((times_s / (DURATION_S / SEGMENTS)).astype(int), SEGMENTS - 1)
        return throttle[:, index], brake[:, index]
    knots = np.linspace(0.0, DURATION_S, SEGMENTS)
    interp = lambda v: np.array([np.interp(times_s, knots, row) for row in v])  # noqa: E731
    return interp(throttle), interp(brake)


def simulate(params: np.ndarray, instance: int = 2) -> np.ndarray:
    """Positions y1..y5 (runs x samples x 5) every SAMPLE_S over 100 s, for rows of 40 parameters."""
    params = np.atleast_2d(np.asarray(params, dtype=float))
    runs = len(params)
    steps = int(round(DURATION_S / DT))
    every = int(round(SAMPLE_S / DT))
    throttle, brake = inputs(params, instance, np.arange(steps) * DT)
    y = np.tile(np.array([0.0, 10.0, 20.0, 30.0, 40.0]), (runs, 1))
    v = np.zeros((runs, 5))
    mode = np.full((runs, 4), KEEPING)
    out = np.empty((runs, steps // every + 1, 5))
    out[:, 0] = y
    for k in range(steps):
        gap = y[:, 1:] - y[:, :-1]  # y - y_in of cars 2-5
        # the charts' transitions, from the mode each car is in
        mode = np.where((mode == CHASING) & (gap <= 10.0), KEEPING, mode)
        mode = np.where((mode == KEEPING) & (gap >= 15.0), CHASING,
                        np.where((mode == KEEPING) & (gap <= 5.0), BRAKING, mode))
        mode = np.where((mode == BRAKING) & (gap >= 20.0), CHASING, mode)
        dv = np.empty_like(v)
        dy = np.empty_like(y)
        dv[:, 0] = -throttle[:, k] - brake[:, k] * v[:, 0]
        dy[:, 0] = v[:, 0]
        follower_v = v[:, 1:]
        dv[:, 1:] = np.where(mode == CHASING, 1.0, np.where(mode == BRAKING, -follower_v, 0.0))
        dy[:, 1:] = np.where(mode == KEEPING, follower_v, -follower_v)
        v = v + DT * dv
        y = y + DT * dy
        if (k + 1) % every == 0:
            out[:, (k + 1) // every] = y
    return out


def _window(x: np.ndarray, a_s: float, b_s: float, reduce) -> np.ndarray:
    """reduce (np.min or np.max) of x over [t + a, t + b] for every t whose window ends within x."""
    a, b = int(round(a_s / SAMPLE_S)), int(round(b_s / SAMPLE_S))
    n = x.shape[-1] - b
    view = np.lib.stride_tricks.sliding_window_view(x, b - a + 1, axis=-1)[..., a:a + n, :]
    return reduce(view, axis=-1)


def _always(x, a, b):
    return _window(x, a, b, np.min)


def _eventually(x, a, b):
    return _window(x, a, b, np.max)


def robustness(spec: str, y: np.ndarray) -> np.ndarray:
    """Robustness of a specification at t = 0 for each run (negative: falsified)."""
    d21, d54 = y[:, :, 1] - y[:, :, 0], y[:, :, 4] - y[:, :, 3]
    if spec == "CC1":
        return _always(40.0 - d54, 0, 100)[:, 0]
    if spec == "CC2":
        return _always(_eventually(d54 - 15.0, 0, 30), 0, 70)[:, 0]
    if spec == "CC3":
        first = _always(20.0 - d21, 0, 20)
        second = _eventually(40.0 - d54, 0, 20)
        return _always(np.maximum(first, second), 0, 80)[:, 0]
    if spec == "CC4":
        return _always(_eventually(_always(d54 - 8.0, 0, 5), 0, 30), 0, 65)[:, 0]
    if spec == "CC5":
        premise = _always(d21 - 9.0, 0, 5)
        conclusion = _always(d54 - 9.0, 5, 20)
        n = min(premise.shape[-1], conclusion.shape[-1])
        implies = np.maximum(-premise[:, :n], conclusion[:, :n])
        return _always(_eventually(implies, 0, 8), 0, 72)[:, 0]
    if spec == "CCx":
        gaps = y[:, :, 1:] - y[:, :, :-1]
        return np.min(_always(np.moveaxis(gaps - 7.5, 1, 2), 0, 50)[:, :, 0], axis=1)
    raise ValueError(spec)
