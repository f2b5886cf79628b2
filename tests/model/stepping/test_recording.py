"""What an episode recorded, as its trace (`recording`): pure code."""

from __future__ import annotations

import numpy as np

from d4sumo.model.stepping.recording import _lane_gaps, _min_at, _window_minima


def test_the_least_gaps_over_arrays_are_what_min_gives_in_order_nan_and_signed_zeros_included():
    """Found by review: np.fmin.at took the second of 0.0 and -0.0, and an array's min() a NaN, where Python's min()
    keeps the first of equal values and never takes a NaN it meets later."""
    rng = np.random.default_rng(0)
    for trial in range(2000):
        n, m = int(rng.integers(0, 40)), int(rng.integers(1, 6))
        slots = rng.integers(0, m, n)
        values = (rng.choice([0.0, -0.0, np.nan, 1000.0, 1200.0, 3.0, -1.0], n) if trial % 2 else rng.uniform(-5.0, 1500.0, n))
        out, expected = np.full(m, 1000.0), np.full(m, 1000.0)
        _min_at(out, slots, values)
        for slot, value in zip(slots, values):
            expected[slot] = min(expected[slot], value)
        assert np.array_equal(out, expected, equal_nan=True) and np.array_equal(np.signbit(out), np.signbit(expected))
    signals: dict = {}
    rows = _lane_gaps(("v0", "v1", "v2"), signals, [[(0, 1, 0.0), (0, 1, -0.0), (1, 2, 3.0)], [(1, 2, float("nan")), (1, 2, 2.0)]],
                      None)
    assert not np.signbit(signals["gap_v1"][0]) and signals["gap_v2"].tolist() == [3.0, 2.0]
    assert _window_minima(rows, 0, 2) == {"v0-v1": 0.0, "v1-v2": 2.0}
    minima = _window_minima({"v1-v2": (np.array([0, 1]), np.array([float("nan"), 2.0]))}, 0, 2)
    assert np.isnan(minima["v1-v2"])  # min() of [nan, 2.0], as before
