"""Crashes that are the traffic's doing: a traffic campaign's episodes played again with the attacker only
cruising (no pedal attack, no lane change, no lie), each in the traffic its samples met.

Among traffic a platoon may crash without any attack: a traffic car that cuts in too close, a merge, a
queue at a red light. A crash is the traffic's doing where the same traffic, without the attack, crashes the
same way (a follower, or the attacker) no later than the sample did; else it counts for the attack. Where every sample of a campaign meets the same traffic one episode tells; where each
meets its own (``traffic.per_sample``) the episode of each sample that crashed is played.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, Iterable

from .analysis import crash_kind

#: the outcomes a baseline speaks of: the crashes
CRASHES = ("success", "attacker_crash")


@dataclass
class Baseline:
    """One campaign's crashes with and without the attack: ``played`` episodes without it, ``crashed`` of them
    with a crash (by kind, `analysis.crash_kind`), and of its ``crashes`` (by outcome) those whose traffic crashes
    the same way without the attack (``traffics``)."""

    played: int = 0
    crashed: int = 0
    kinds: Counter = field(default_factory=Counter)
    crashes: Counter = field(default_factory=Counter)
    traffics: Counter = field(default_factory=Counter)
    #: the first collision of the one episode without the attack, where all samples meet the same traffic
    collision: object = None

    def add(self, other: "Baseline") -> None:
        self.played += other.played
        self.crashed += other.crashed
        for mine, theirs in ((self.kinds, other.kinds), (self.crashes, other.crashes), (self.traffics, other.traffics)):
            mine.update(theirs)


def campaign_baseline(without_attack: Callable[[int], object], per_sample: bool,
                      samples: Iterable[tuple[int, str, float | None]], progress: Callable[[], None] | None = None,
                      step_s: float = 0.0) -> Baseline:
    """The baseline of a campaign among traffic: ``without_attack(index)`` plays sample ``index``'s episode with the
    attacker cruising (`runner.Evaluator.without_attack`); ``samples``: each sample's (index, outcome, time of its
    first collision [s]). A crash is the traffic's doing where the same traffic without the attack crashes the
    same way (a follower's, or the attacker's) no later than it did (within ``step_s``)."""
    samples = list(samples)
    out = Baseline(crashes=Counter(o for _, o, _ in samples if o in CRASHES))
    crashed = [(i, o, t) for i, o, t in samples if o in CRASHES]
    if not per_sample:  # one traffic for all: one episode tells
        played = [(None, without_attack(0))]
        out.collision = played[0][1].first_collision
    else:
        played = []
        for i, _, _ in crashed:
            played.append((i, without_attack(i)))
            if progress:
                progress()
    out.played = len(played)
    first_of = {}
    for i, episode in played:
        first_of[i] = (episode.outcome, episode.first_collision.time_s if episode.first_collision else None)
        if episode.outcome in CRASHES:
            out.crashed += 1
            out.kinds[crash_kind(episode.first_collision.pair)] += 1
    for i, outcome, time_s in crashed:
        alone, alone_s = first_of.get(None if not per_sample else i, (None, None))
        if alone == outcome and alone_s is not None and (time_s is None or alone_s <= time_s + step_s + 1e-9):
            out.traffics[outcome] += 1
    return out


def baseline_text(b: Baseline) -> str:
    """A campaign's baseline in a line."""
    if not b.crashed:
        return ("without the attack (the attacker only cruising, in the same traffic): no crash in "
                f"{b.played} episode{'s' if b.played != 1 else ''}")
    what = ", ".join(f"{n} {k}" for k, n in sorted(b.kinds.items()))
    first = f" ({b.collision.pair} at {b.collision.time_s:.2f} s)" if b.collision is not None else ""
    doing = ", ".join(f"{b.traffics[o]} of {b.crashes[o]} {o.replace('_', ' ')}{'es' if b.crashes[o] != 1 else ''}"
                      for o in CRASHES if b.crashes[o])
    return (f"without the attack (the attacker only cruising, in the same traffic): {b.crashed} of {b.played} "
            f"episode{'s' if b.played != 1 else ''} crashed ({what}){first}; the traffic's doing: {doing or 'none'}")


def table_without_attack(records, evaluator_of, progress: Callable[[], None] | None = None):
    """Per run among traffic (`analysis.runs`): its campaigns' episodes without the attack (`campaign_baseline`),
    how many crashed and how, and how many of its successes and attacker crashes the same traffic does without
    the attack. ``evaluator_of(record)``: the evaluator of a record's campaign (`report.evaluator_of`)."""
    from ..errors import NotSimulable
    from .analysis import CRASH_KINDS, Table, run_label, runs

    rows = []
    for key, rs in runs([r for r in records if dict(r.scenario).get("traffic", "none") != "none"], "attack", "optimizer")[1].items():
        total, unplayed = Baseline(), 0
        by_campaign: dict[tuple, list] = {}
        for r in rs:
            by_campaign.setdefault((r.db, r.campaign_id), []).append(r)
        for members in by_campaign.values():
            try:
                evaluator = evaluator_of(members[0])
            except NotSimulable:  # its controller cannot be had here: counted as not played
                unplayed += len(members)
                continue
            without_attack, per_sample = evaluator.without_attack_of({r.index: r.params for r in members})
            total.add(campaign_baseline(without_attack, per_sample, ((r.index, r.outcome, r.time_s) for r in members),
                                        progress, evaluator.campaign.config.step_s))
        kinds = ", ".join(f"{total.kinds[k]} {k}" for k in CRASH_KINDS if total.kinds[k]) or "-"
        rows.append((run_label(key), str(len(rs) - unplayed), str(total.played), str(total.crashed), kinds,
                     f"{total.traffics['success']} of {total.crashes['success']}",
                     f"{total.traffics['attacker_crash']} of {total.crashes['attacker_crash']}"))
    return Table("Without the attack: the attacker only cruising, in the traffic the samples met (the traffic's doing: the "
                 "same crash without the attack)",
                 ("attack", "samples", "episodes without it", "crashed", "first collisions", "successes the traffic's doing",
                  "attacker crashes the traffic's doing"), tuple(rows))
