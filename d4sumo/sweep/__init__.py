"""Sweeps: a grid of campaigns, run on local worker processes or on a Dask distributed cluster.

A sweep file is TOML:

    name = "paper-nonparametric"      # optional; the file's stem by default
    [grid]                            # lists; the sweep is every combination
    network = ["highway_4lane"]
    setpoint_m = [3, 5, 7]
    speed_mps = [20, 25, 30]
    start = ["rest", "steady"]
    maneuver = ["inlane", "cutin"]      # optional, and its settings: cutin_follower, cutin_offset_m, lane_change_s, ...
                                        # (a setting another maneuver does not read gives it one campaign)
    controller = ["switching", "timegap", "sumo:ACC", {class = "sumo:IDM", tau = 1.5}]   # optional
    attack = ["knots"]
    optimizer = ["bo", "ce"]
    seed = [0]
    [search]  samples = 100           # and [search.bo], [search.ce]: the optimisers' options
    [scenario], [vehicle], [controller], [attack], [spec]: fixed values, as in a config file

Every campaign is built and checked before anything runs. Workers send every few samples back to
the client, which alone writes the database, so killing the sweep loses nothing it stored; running
it again skips complete campaigns and resumes the others.
"""

from __future__ import annotations

from .dask_cluster import check_dask_address
from .grid import Sweep
from .run import SweepResult, claim, run_sweep
from .tasks import Chunk, run_chunks

__all__ = ["Chunk", "Sweep", "SweepResult", "check_dask_address", "claim", "run_chunks", "run_sweep"]
