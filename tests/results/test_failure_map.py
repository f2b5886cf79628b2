"""Where the system fails (`results.failure_map`): the success rate over a searched situation, estimated from
the samples, with its uncertainty; and its figure."""

from __future__ import annotations

import dataclasses

import numpy as np

from d4sumo.results import figures
from d4sumo.results.failure_map import failure_map, failure_maps
from d4sumo.results.records import Record


def _records(count: int, seed: int = 0, keys=("setpoint_m", "speed_mps")) -> list[Record]:
    """Samples over setpoint 2-14 m and speed 20-30 m/s that succeed where the setpoint is under 6 m."""
    rng = np.random.default_rng(seed)
    base = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, (0.0,) * 9, 0.1, "no_crash", None, None,
                  None, None)
    out = []
    for i in range(count):
        situation = {"setpoint_m": float(rng.uniform(2, 14)), "speed_mps": float(rng.uniform(20, 30))}
        out.append(dataclasses.replace(base, sample_id=i, outcome="success" if situation["setpoint_m"] < 6 else "no_crash",
                                       situation=tuple((k, situation[k]) for k in keys)))
    return out


def test_the_map_finds_the_boundary_and_grows_surer_with_samples():
    m = failure_map(_records(300))
    assert m.keys == ("setpoint_m", "speed_mps") and m.rate.shape == (60, 60)
    setpoint = m.axes[0]
    low, high = np.argmin(abs(setpoint - 3.0)), np.argmin(abs(setpoint - 10.0))
    assert np.nanmin(m.rate[low]) > 0.8 and np.nanmax(m.rate[high]) < 0.2
    crossing = setpoint[np.argmax(np.nanmean(m.rate, axis=1) < 0.5)]  # where the rate, along the setpoint, falls under a half
    assert 5.0 < crossing < 7.0
    few = failure_map(_records(30))
    assert np.nanmean(few.std) > np.nanmean(m.std)


def test_one_searched_key_gives_a_curve_no_searched_key_no_map_and_far_from_samples_the_map_is_blank():
    m = failure_map(_records(100, keys=("setpoint_m",)))
    assert m.keys == ("setpoint_m",) and m.rate.shape == (60,)
    plain = [dataclasses.replace(r, situation=()) for r in _records(10)]
    assert failure_map(plain) is None
    two = _records(2)
    assert np.isnan(failure_map(two, bandwidth=0.01).rate).any()  # between two samples, nothing to say


def test_a_map_for_each_system_and_start_and_the_figure_draws_both_kinds(tmp_path):
    records = _records(40) + [dataclasses.replace(r, start="steady") for r in _records(60, seed=1)]
    records += [dataclasses.replace(r, system="cacc") for r in _records(30, seed=2)]
    maps = failure_maps(records)
    assert [label for label, _ in maps] == ["switching, start steady", "switching, start rest", "cacc, start rest"]
    assert [len(m.points) for _, m in maps] == [60, 40, 30]
    assert failure_maps([dataclasses.replace(r, situation=()) for r in records]) == []
    for keys in (("setpoint_m", "speed_mps"), ("speed_mps",)):
        path = figures.failure_map(failure_maps(_records(80, keys=keys)), "Where the system fails", tmp_path / f"{len(keys)}.png")
        assert path.stat().st_size > 10_000


def test_the_map_is_drawn_over_the_keys_named_and_a_key_not_searched_is_one_line():
    import pytest

    from d4sumo.errors import ConfigError

    records = _records(60)
    m = failure_maps(records, ("speed_mps", "setpoint_m"))[0][1]
    assert m.keys == ("speed_mps", "setpoint_m") and m.rate.shape == (60, 60)
    assert failure_maps(records, ("speed_mps",))[0][1].keys == ("speed_mps",)
    for keys in (("v2v.loss",), ("setpoint_m", "setpoint_m"), ("setpoint_m", "speed_mps", "start")):
        with pytest.raises(ConfigError, match="--keys: .*allowed: one or two of the searched keys: setpoint_m, speed_mps"):
            failure_maps(records, keys)
