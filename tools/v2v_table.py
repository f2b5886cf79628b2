"""The measured table of docs/v2v.md: cooperative platoons against the attacker's pedals, its lies over the
air, and both together, at two beacon settings, with the mitigation off and on.

Usage:
    python tools/v2v_table.py                        # 103 campaigns of 100 samples (about 4 min on 2 cores)
    python tools/v2v_table.py --samples 20 --db t.sqlite

The scenario is the paper's in-lane attack from steady state at 25 m/s, setpoint 5 m, 40 s, 3 followers.
Each cell: the campaign's successes (followers crash, the attacker untouched) of its samples, and in
brackets the attacker crashes. The attacks:

    pedals     the knots family alone: the attacker's throttle and brake (the paper's attack)
    lie        the attacker cruises and lies in its beacons: knots on its acceleration, or an offset on its
               speed or its position
    both       the pedals and the lie searched together, one cyber-physical attack

The paper's controller (ACC on radar, no beacons) meets the pedals only. In the insider's rows follower v1
lies, the attacker drives (both) or cruises (lie). The campaigns are stored in the
database (a sweep named "v2v-table"): run again, it resumes; ``d4sumo report DB`` draws them.
"""

from __future__ import annotations

import dataclasses
import sys
from collections import Counter

from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.search.campaign import Campaign, open_store
from d4sumo.sweep import Sweep, run_sweep
from toolargs import Parser, run_main

CHANNELS = {"beacons 0.1 s": None, "latency 0.2 s, loss 0.3": {"latency_s": 0.2, "loss": 0.3}}
CONTROLLERS = ("cacc", "ploeg", "consensus")
#: (column, pedal family, message attack, its field)
ATTACKS = (("pedals", "knots", "", "accel"),
           ("lie: knots on accel", "cruise", "knots", "accel"),
           ("lie: offset on speed", "cruise", "offset", "speed"),
           ("lie: offset on position", "cruise", "offset", "position"),
           ("both: knots on accel", "knots", "knots", "accel"),
           ("both: offset on speed", "knots", "offset", "speed"),
           ("both: offset on position", "knots", "offset", "position"))
FALLBACK_MPS = 1.0


def campaigns(samples: int) -> dict[tuple[str, str, str], Campaign]:
    """Every cell's campaign by (row, channel, column)."""
    base = EpisodeConfig(start="steady", speed_mps=25.0, setpoint_m=5.0, duration_s=40.0)
    out = {("switching (the paper's ACC, radar)", "no beacons", "pedals"): Campaign(config=base, samples=samples)}
    for channel, v2v in CHANNELS.items():
        for cls in CONTROLLERS:
            for fallback in (0.0, FALLBACK_MPS):
                params = (("fallback_mps", fallback),) if fallback else ()
                config = dataclasses.replace(base, controller=ControllerConfig(cls, params), v2v=v2v)
                row = f"{cls}, mitigated" if fallback else cls
                for column, family, message, field in ATTACKS:
                    out[row, channel, column] = Campaign(config=config, attack=family, message=message, message_field=field,
                                                         samples=samples)
    for cls in CONTROLLERS:  # an insider: v1 lies to the cars behind it that read its beacons
        config = dataclasses.replace(base, controller=ControllerConfig(cls))
        for column, family, message, field in ATTACKS[1:]:
            out[f"{cls}, insider v1 lies", "beacons 0.1 s", column] = Campaign(
                config=config, attack=family, message=message, message_field=field, message_sender=1, samples=samples)
    return out


def table(cells: dict[tuple[str, str, str], Counter]) -> str:
    columns = [a[0] for a in ATTACKS]
    lines = ["| controller | channel | " + " | ".join(columns) + " |", "|---|---|" + "---|" * len(columns)]
    rows = dict.fromkeys((row, channel) for row, channel, _ in cells)
    for row, channel in rows:
        out = []
        for column in columns:
            counts = cells.get((row, channel, column))
            out.append("" if counts is None else f"{counts['success']} ({counts['attacker_crash']})")
        lines.append(f"| `{row}` | {channel} | " + " | ".join(out) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = Parser(__doc__)
    parser.add_argument("--db", default="v2v-table.sqlite")
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args(argv)
    parser.check_counts({"--samples": (args.samples, 1), "--workers": (args.workers, 1)})
    cells = campaigns(args.samples)
    sweep = Sweep(name="v2v-table", campaigns=tuple(cells.values()))
    from tqdm import tqdm

    with tqdm(total=sweep.samples, unit="sample", file=sys.stderr) as bar:
        def progress(done: int, total: int, successes: int) -> None:
            bar.update(done - bar.n)
            bar.set_postfix(successes=successes)

        result = run_sweep(sweep, args.db, workers=args.workers, progress=progress)
    counts = {}
    with open_store(args.db, create=False) as store:
        for key, campaign in cells.items():
            cid = store.find_campaign(campaign.definition())
            counts[key] = Counter(s.outcome for s in store.samples(cid))
    print(f"{len(cells)} campaigns, {sweep.samples} samples, {result.wall_s:.0f} s; successes (attacker crashes) of "
          f"{args.samples} a campaign:\n")
    print(table(counts))
    return 0


if __name__ == "__main__":
    run_main(main)
