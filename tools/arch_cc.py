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

Integrated here by explicit Euler at ``DT`` with the charts' transitions taken at each step, outputs
sampled every ``SAMPLE_S`` for the specifications. Simulink integrates with a variable-step solver and
locates the transitions, and these charts make the difference felt: a car in Keeping backs away at its
speed and in Chasing speeds up, so a car that hovers between the two oscillates faster and faster, and a
transition taken a step late overshoots its threshold by speed x ``DT``. CC4's verdict near its
threshold moves with the step (``simulate(..., dt=)``): of the 29 held inputs in 20,000 that falsify it
here, 23 still do at 1 ms, and CC4-2019's 8 all do (`bench_arch.py --held 20000 --recheck-dt 0.001`).
FalCAuN's published counterexample to its CC4 (throttle 1 for 10 s then 0, brake 1:
MasWag/FalCAuN-ARCH-COMP, FalCAuN_ARCH2024_validation.csv) scores 0.87 here and 2.3 at 1 ms, where car 5
never leaves Keeping: Simulink's trajectory differs from both, and CC4's figures compare across tools
only roughly.

The specifications as the competition states them (ARCH-COMP 2021's falsification category; quoted from
the benchmark file of STGEM, a participant: mshaheryarmalik/stgem,
problems/arch-comp-2021/cc/benchmark.py), with d21 = y2 - y1, d54 = y5 - y4:
- CC1: always[0,100]( d54 <= 40 )
- CC2: always[0,70]( eventually[0,30]( d54 >= 15 ) )
- CC3: always[0,80]( (always[0,20]( d21 <= 20 )) or (eventually[0,20]( d54 >= 40 )) )
- CC4: always[0,65]( eventually[0,30]( always[0,20]( d54 >= 8 ) ) )
- CC5: always[0,72]( eventually[0,8]( always[0,5]( d21 >= 9 ) implies always[5,20]( d54 >= 9 ) ) )
- CCx: always[0,50]( y_{i+1} - y_i > 7.5 ) for every i
FalStar's configuration of 2019 (ERATOMMSD/falstar, falstar/resource/configuration/qest2019-journal/
instance1/cc.cfg) has an older CC3 (``<= 40`` in the second disjunct, which no input falsifies) and CC4
(``always (0 5)`` inside), which FalCAuN's ARCH-COMP scripts still check (MasWag/FalCAuN-ARCH-COMP,
CC/CC4.main.kts, in steps of its 5 s samples, on the least d54 since the previous sample): here
``CC4-2019``, in continuous time, not among the competition's ``SPECS``. Windows that reach past 100 s
are cut at the trace's end.

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
EARLIER_SPECS = ("CC4-2019",)  # formulas other tools' published figures were measured on


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


def simulate(params: np.ndarray, instance: int = 2, dt: float = DT) -> np.ndarray:
    """Positions y1..y5 (runs x samples x 5) every SAMPLE_S over 100 s, for rows of 40 parameters, by
    Euler steps of ``dt`` (a divisor of SAMPLE_S; finer than DT to see how far a verdict moves with it)."""
    params = np.atleast_2d(np.asarray(params, dtype=float))
    steps = int(round(DURATION_S / dt))
    throttle, brake = inputs(params, instance, np.arange(steps) * dt)
    return np.array([_one_run(throttle[r].tolist(), brake[r].tolist(), dt) for r in range(len(params))])


def _one_run(throttle: list[float], brake: list[float], dt: float) -> np.ndarray:
    """One run, step by step in plain floats: the charts switch every few steps (about 460 times a car in
    100 s of random inputs), which keeps numpy's arrays of 5 cars busy with overhead; this loop is 25 times
    faster than one over arrays and gives the same numbers."""
    every = int(round(SAMPLE_S / dt))
    y = [0.0, 10.0, 20.0, 30.0, 40.0]
    v = [0.0] * 5
    mode = [KEEPING] * 5  # cars 2-5 (index 0 unused)
    out = [list(y)]
    for k in range(len(throttle)):
        for i in range(1, 5):  # the charts' transitions, from the gap to the car ahead at this step
            gap, m = y[i] - y[i - 1], mode[i]
            if m == CHASING and gap <= 10.0:
                m = KEEPING
            if m == KEEPING:
                if gap >= 15.0:
                    m = CHASING
                elif gap <= 5.0:
                    m = BRAKING
            if m == BRAKING and gap >= 20.0:
                m = CHASING
            mode[i] = m
        lead = v[0]
        v[0] = lead + dt * (-throttle[k] - brake[k] * lead)
        y[0] = y[0] + dt * lead
        for i in range(1, 5):
            vi = v[i]
            if mode[i] == KEEPING:  # v' = 0, y' = v
                y[i] = y[i] + dt * vi
            elif mode[i] == CHASING:  # v' = 1, y' = -v
                y[i] = y[i] + dt * -vi
                v[i] = vi + dt * 1.0
            else:  # Braking: v' = -v, y' = -v
                y[i] = y[i] + dt * -vi
                v[i] = vi + dt * -vi
        if (k + 1) % every == 0:
            out.append(list(y))
    return np.array(out)


def _window(x: np.ndarray, a_s: float, b_s: float, reduce) -> np.ndarray:
    """reduce (np.min or np.max) of x over [t + a, t + b] for every sample t, the window cut at the end of
    the trace (a specification may look past 100 s: CC4's horizon is 115 s; the competition scores what
    the trace holds). A window wholly past the end is +inf for always and -inf for eventually."""
    a, b = int(round(a_s / SAMPLE_S)), int(round(b_s / SAMPLE_S))
    pad = np.inf if reduce is np.min else -np.inf
    padded = np.concatenate([x, np.full(x.shape[:-1] + (b,), pad)], axis=-1)
    view = np.lib.stride_tricks.sliding_window_view(padded, b - a + 1, axis=-1)[..., a:a + x.shape[-1], :]
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
        second = _eventually(d54 - 40.0, 0, 20)
        return _always(np.maximum(first, second), 0, 80)[:, 0]
    if spec == "CC4":
        return _always(_eventually(_always(d54 - 8.0, 0, 20), 0, 30), 0, 65)[:, 0]
    if spec == "CC4-2019":
        return _always(_eventually(_always(d54 - 8.0, 0, 5), 0, 30), 0, 65)[:, 0]
    if spec == "CC5":
        implies = np.maximum(-_always(d21 - 9.0, 0, 5), _always(d54 - 9.0, 5, 20))
        return _always(_eventually(implies, 0, 8), 0, 72)[:, 0]
    if spec == "CCx":
        gaps = y[:, :, 1:] - y[:, :, :-1]
        return np.min(_always(np.moveaxis(gaps - 7.5, 1, 2), 0, 50)[:, :, 0], axis=1)
    raise ValueError(spec)
