"""Where the system fails, over the situation its campaigns searched (`search.situation`): the probability that
an attack succeeds, estimated from the samples at each point of the searched box, with its uncertainty, and the
boundary where it crosses one half.

The estimate at a point weighs every sample by a Gaussian of its distance there (each key scaled to the box,
``bandwidth`` of it): with s the weighted successes and n the weighted samples, the success rate is the mean of
Beta(1 + s, 1 + n - s), a uniform prior updated, and its standard deviation the uncertainty
(`situation.kernel_estimate`, which a campaign locating the boundary estimates with too). Far from every sample
(n under `LEAST_WEIGHT`) the map says nothing. Where a campaign spent samples locating the boundary
(``[search] boundary``), the map is drawn from those alone: a random attack each, so that the rate is the
situation's, not the optimiser's. Pure numbers: `figures` draws it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import ConfigError
from ..search.situation import kernel_estimate
from .records import Record

#: where the samples near a point weigh less than this, the map leaves it blank
LEAST_WEIGHT = 1.0
LABELS = {"setpoint_m": "setpoint [m]", "speed_mps": "target speed [m/s]"}


@dataclass(frozen=True)
class FailureMap:
    keys: tuple[str, ...]  # the searched ranges, one axis each (at most two; choices pooled)
    axes: tuple[np.ndarray, ...]  # each axis's points
    rate: np.ndarray  # the estimated success probability at each point (axes' shape; NaN: too far from samples)
    std: np.ndarray  # its standard deviation
    weight: np.ndarray  # the samples' weight there
    points: np.ndarray  # each sample's situation (samples x keys)
    successes: np.ndarray  # whether each sample succeeded

    def label(self, i: int) -> str:
        return LABELS.get(self.keys[i], self.keys[i])


def situated(records: Sequence[Record]) -> list[Record]:
    """The records of campaigns that searched their situation, scored (an errored sample tells nothing)."""
    return [r for r in records if r.situation and r.outcome != "error"]


def searched_keys(records: Sequence[Record]) -> tuple[str, ...]:
    """The keys every record's situation holds a number for, in the order of their names (a named choice, the start,
    is no axis)."""
    records = situated(records)
    return tuple(k for k, v in records[0].situation
                 if not isinstance(v, str) and all(k in dict(r.situation) for r in records)) if records else ()


def failure_map(records: Sequence[Record], keys: Sequence[str] | None = None, *, bandwidth: float = 0.1,
                cells: int = 60) -> FailureMap | None:
    """The map over ``keys``, one or two keys the records' situations share (none: the first two), or None where no
    record searched one."""
    records = situated(records)
    if not records:
        return None
    keys = tuple(keys) if keys else searched_keys(records)[:2]
    records = [r for r in records if all(k in dict(r.situation) for k in keys)]  # (given keys: the records that hold them)
    if not keys or not records:
        return None
    points = np.array([[dict(r.situation)[k] for k in keys] for r in records], dtype=float)
    successes = np.array([r.outcome == "success" for r in records])
    low, high = points.min(axis=0), points.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    axes = tuple(np.linspace(lo, hi, cells) for lo, hi in zip(low, high))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(keys))  # (points, keys)
    rate, std, n = kernel_estimate((points - low) / span, successes.astype(float), (grid - low) / span, bandwidth)
    far = n < LEAST_WEIGHT
    shape = tuple(len(x) for x in axes)
    rate, std = np.where(far, np.nan, rate).reshape(shape), np.where(far, np.nan, std).reshape(shape)
    return FailureMap(keys, axes, rate, std, n.reshape(shape), points, successes)


#: at most this many panels (a system and a start each) in one figure: the ones with the most samples
MOST_PANELS = 8


def failure_maps(records: Sequence[Record], keys: Sequence[str] | None = None) -> list[tuple[str, FailureMap]]:
    """One map for each system and start of the records that searched their situation (a system fails in its own
    situations; a start from rest is another situation than one from steady state), most samples first, at most
    `MOST_PANELS`; empty where none searched one. ``keys``: one or two keys to draw it over (none: the first two);
    a key no record searched is a ConfigError naming those it searched."""
    if keys is not None:
        shared = sorted({k for r in situated(records) for k, v in r.situation if not isinstance(v, str)})
        if not 1 <= len(keys) <= 2 or len(set(keys)) != len(keys) or any(k not in shared for k in keys):
            raise ConfigError("--keys", ",".join(keys), f"one or two of the searched keys: {', '.join(shared) or 'none searched'}")
    groups: dict[tuple[str, str], list[Record]] = {}
    for r in situated(records):
        groups.setdefault((r.system, r.start), []).append(r)
    groups = {k: [r for r in rs if r.locating] or rs for k, rs in groups.items()}  # (see the module)
    maps = [(f"{system}, start {start}{', locating the boundary' if rs[0].locating else ''}", failure_map(rs, keys))
            for (system, start), rs in
            sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))[:MOST_PANELS]]
    return [(label, m) for label, m in maps if m is not None]
