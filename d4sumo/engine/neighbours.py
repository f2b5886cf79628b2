"""Who is ahead of whom among SUMO's traffic: each car of a platoon, its leader and follower as SUMO sees them
in its lane (a traffic car, or a car of its own platoon), with the gap between their bumpers; for a
lane-changing attacker, in each lane it covers. The pairs the step loop scores, the speeds its cars sense."""

from __future__ import annotations

from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import Pair
from ..model.world.lanes import FREE_ROAD_GAP_M, lane_pairs, occupied_lanes
from .calls import vehicle_call
from .scenarios import Road


class _TrafficSense:
    """Who is ahead of each car of one platoon in its lane, a traffic car included, as SUMO's leader says,
    and who follows its rear car: the pairs of the step (`maneuvers.Pair`), with the traffic cars in them.

    Between two platoon cars next to each other it is their pair, its gap from their positions (the
    arithmetic of the platoon alone, bit for bit); where a traffic car is between them, or ahead of the
    attacker, or behind the rear car, the pair is with it, its gap SUMO's (bumper to bumper: SUMO's leader
    gap leaves out the follower's minGap, which is added back). A traffic car is index ``n + j`` of the
    step's extended ids, positions and speeds (j in order of appearance); pairs of two traffic cars are
    not the platoon's and are left out."""

    def __init__(self, api, config: EpisodeConfig, ids: tuple[str, ...]):
        self.ids = ids
        self.index = {vid: i for i, vid in enumerate(ids)}
        self.names = config.vehicle_ids
        self.lengths = [v.length_m for v in config.car_vehicles]
        self.min_gaps = [api.vehicle.getMinGap(vid) for vid in ids]
        self.get_leader, self.get_follower = vehicle_call(api, "getLeader"), vehicle_call(api, "getFollower")
        self.get_speed, self.get_length = vehicle_call(api, "getSpeed"), vehicle_call(api, "getLength")
        self.get_min_gap = vehicle_call(api, "getMinGap")

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        """The step's pairs, and the extended ids (each traffic car by its SUMO id), positions (a traffic
        car's front bumper, from its gap) and speeds they index."""
        ids, n, look = self.ids, len(self.ids), FREE_ROAD_GAP_M
        names, xs, vs = list(self.names), list(x), list(v)
        traffic: dict[str, int] = {}
        pairs: list[Pair] = []

        def other(vid: str, front_m: float) -> int:
            if vid not in traffic:
                traffic[vid] = len(names)
                names.append(vid)
                xs.append(front_m)
                vs.append(self.get_speed(vid))
            return traffic[vid]

        for b in range(n):
            hit = self.get_leader(ids[b], look)
            if b and (not hit or hit[0] == ids[b - 1]):  # the car ahead in the column
                pairs.append((b - 1, b, x[b - 1] - self.lengths[b - 1] - x[b]))
                continue
            if not hit or not hit[0]:
                continue  # nobody ahead of the attacker
            if hit[0] in self.index:  # another car of the platoon (a car ahead of it left the lane): their pair
                a = self.index[hit[0]]
                pairs.append((a, b, x[a] - self.lengths[a] - x[b]))
                continue
            gap = hit[1] + self.min_gaps[b]
            if gap >= look:
                continue
            t = other(hit[0], x[b] + gap + self.get_length(hit[0]))
            pairs.append((t, b, gap))
            for _ in range(64) if b else ():  # traffic between two platoon cars: the first of it follows the car ahead
                ahead = self.get_leader(names[t], look)
                if not ahead or not ahead[0] or (ahead[0] in ids and ahead[0] != ids[b - 1]):
                    break
                gap = ahead[1] + self.get_min_gap(names[t])
                if ahead[0] == ids[b - 1]:
                    pairs.append((b - 1, t, gap))
                    break
                t = other(ahead[0], xs[t] + gap + self.get_length(ahead[0]))
        behind = self.get_follower(ids[-1], look)
        if behind and behind[0] and behind[0] not in ids:
            gap = behind[1] + self.get_min_gap(behind[0])
            if gap < look:
                pairs.append((n - 1, other(behind[0], x[-1] - self.lengths[-1] - gap), gap))
        return pairs, names, xs, vs


class _LateralTrafficSense:
    """Who follows whom among traffic when the attacker changes lanes (`maneuvers.LaneChange`, a road of
    one edge): in every lane each car covers (from its lateral position, a car changing lanes covering
    both), the nearest cars, a traffic car included (`lanes.lane_pairs`: the arithmetic of the
    maneuver alone, bit for bit, between cars of the platoon). The traffic cars that may be next to a car
    of the platoon are SUMO's: its leader and follower, and its leaders and followers in the lanes beside
    it. Returns what `_TrafficSense` returns."""

    def __init__(self, api, config: EpisodeConfig, ids: tuple[str, ...], lateral, road: Road):  # lateral: `sumo._Lateral`
        self.ids, self.index, self.lateral = ids, {vid: i for i, vid in enumerate(ids)}, lateral
        self.names = list(config.vehicle_ids)
        self.lengths = [v.length_m for v in config.car_vehicles]
        self.width, self.base = road.lane_width_m, road.platoon_lane
        call = lambda name: vehicle_call(api, name)  # noqa: E731
        self.get_leader, self.get_follower, self.get_neighbors = call("getLeader"), call("getFollower"), call("getNeighbors")
        self.get_position, self.get_speed, self.get_length = call("getLanePosition"), call("getSpeed"), call("getLength")
        self.get_lane, self.get_lateral = call("getLaneIndex"), call("getLateralLanePosition")

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        lanes = self.lateral.sense()  # the platoon's cars' lanes (and the attacker's lateral position, recorded)
        near: set[str] = set()
        for vid in self.ids:
            for hit in (self.get_leader(vid, FREE_ROAD_GAP_M), self.get_follower(vid, FREE_ROAD_GAP_M)):
                if hit and hit[0]:
                    near.add(hit[0])
            for mode in range(4):  # the lanes to its right and left, followers and leaders
                near.update(other for other, _ in self.get_neighbors(vid, mode))
        traffic = sorted(near - self.index.keys())
        xs = list(x) + [self.get_position(t) for t in traffic]  # a road of one edge: the lane position is along it
        vs = list(v) + [self.get_speed(t) for t in traffic]
        lengths = self.lengths + [self.get_length(t) for t in traffic]
        covered = list(lanes) + [occupied_lanes((self.get_lane(t) - self.base + 0.5) * self.width + self.get_lateral(t), self.width)
                                 for t in traffic]
        pairs = [p for p in lane_pairs(xs, covered, lengths, apart=len(self.ids)) if p[2] < FREE_ROAD_GAP_M or max(p[:2]) < len(self.ids)]
        return pairs, self.names + traffic, xs, vs
