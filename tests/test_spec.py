"""The paper's specification psi, computed directly."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.spec import paper_formula, psi_robustness
from d4sumo.trace import Trace


def trace_of(gaps):
    gaps = np.asarray(gaps, dtype=float)
    return Trace(np.arange(gaps.shape[0]) * 0.05, {f"gap_{i}": gaps[:, i] for i in range(gaps.shape[1])}, gaps.shape[1])


def test_followers_colliding_with_the_attacker_clear_is_positive():
    assert psi_robustness(trace_of([[7, 7, 7], [5, 2, 7], [4, -0.3, 6]])) == pytest.approx(0.3)


def test_no_collision_is_negative_by_the_closest_approach():
    assert psi_robustness(trace_of([[7, 7, 7], [5, 2, 7], [4, 1.5, 6]])) == pytest.approx(-1.5)


def test_an_attacker_crash_is_negative_even_when_followers_collide():
    assert psi_robustness(trace_of([[7, 7, 7], [-0.2, -1.0, 7]])) == pytest.approx(-0.2)


def test_d_safe_shifts_the_threshold():
    assert psi_robustness(trace_of([[7, 7], [5, 1.5]]), d_safe_m=2.0) == pytest.approx(0.5)


def test_psi_needs_two_followers():
    with pytest.raises(ConfigError, match="at least 2"):
        psi_robustness(trace_of([[7], [3]]))
    assert paper_formula(3) == "(eventually((gap_1 <= 0.0) or (gap_2 <= 0.0))) and (always(gap_0 > 0.0))"
