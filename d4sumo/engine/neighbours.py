"""Who is ahead of whom among SUMO's traffic: each car of a platoon, its leader and follower as SUMO sees them
in its lane (a traffic car, or a car of its own platoon), with the gap between their bumpers; for a
lane-changing attacker, in each lane it covers. The pairs the step loop scores, the speeds its cars sense.
Where each lane of the route lies, along it and across it (`RouteLanes`)."""

from __future__ import annotations

from ..errors import SumoError
from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import Pair
from ..model.world.lanes import CAR_WIDTH_M, FREE_ROAD_GAP_M, lane_pairs, occupied_lanes
from .calls import native_lateral_pairs, native_traffic_pairs, route_junctions, vehicle_call, via_lanes
from .scenarios import Road


class RouteLanes:
    """Where each lane of one copy of the route lies: where it starts along the route [m], and its place
    across the road counted from the platoon's lane on its edge (0 the platoon's, 1 the one to its left, -1
    an on-ramp's acceleration lane to its right). That covers every lane of the route's edges and the
    junction lanes between two of them, each of those counted from the lane it leaves.

    An on-ramp adds a lane on the right, so SUMO's index of the platoon's lane, and of every lane beside it,
    changes along the route (`Road.lane_path`): a place across the road is read from the lane's own edge.
    Along the route, a lane of an edge starts where the edge does (the platoon's odometer, `route_position`:
    the edges' lanes, and the junction lanes between the corridor's, are as long as each other,
    `Road.even_lanes`); on a road of one edge that is 0, and a position along it is the lane position itself."""

    def __init__(self, api, route: tuple[str, ...], path: tuple[int, ...]):
        #: lane id -> (its start along the route [m], its place across the road, SUMO's index of the platoon's
        #: lane's place on its edge: the lane's own index minus its place)
        self.lanes: dict[str, tuple[float, int, int]] = {}
        junctions = [(end, end + length) for _, _, _, end, length in route_junctions(api, route, path)]
        for k, edge in enumerate(route):
            count = api.edge.getLaneNumber(edge)
            for i in range(count):
                self.lanes[f"{edge}_{i}"] = (junctions[k - 1][1] if k else 0.0, i - path[k], path[k])
            if k + 1 == len(route):
                break
            for i in range(count):  # the junction lanes from each lane of the edge into the next one
                for to_lane in sorted({link[0] for link in api.lane.getLinks(f"{edge}_{i}")
                                       if link[0].rpartition("_")[0] == route[k + 1]}):
                    start = junctions[k][0]
                    for via in via_lanes(api, f"{edge}_{i}", to_lane):
                        index = int(via.rpartition("_")[2])
                        self.lanes.setdefault(via, (start, i - path[k], index - (i - path[k])))
                        start += api.lane.getLength(via)
        #: place across the road -> the lanes there along the route, in order: (start, end [m], lane id)
        self.by_place: dict[int, list[tuple[float, float, str]]] = {}
        for lane, (start, place, _) in self.lanes.items():
            self.by_place.setdefault(place, []).append((start, start + api.lane.getLength(lane), lane))
        for lanes in self.by_place.values():
            lanes.sort()

    def place(self, lane: str) -> int:
        """The lane's place across the road (SumoError off the route: never a silent guess)."""
        try:
            return self.lanes[lane][1]
        except KeyError:
            raise SumoError(f"a car of the platoon drove lane {lane}, off its route") from None

    def index(self, lane: str, place: int) -> int:
        """SUMO's index, on the edge of ``lane``, of the lane at ``place`` across the road."""
        return self.lanes[lane][2] + place


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
        #: the same step in C++ with libsumo's own functions, where they can be had (`calls.native_traffic_pairs`)
        self._native = native_traffic_pairs(api)

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        """The step's pairs, and the extended ids (each traffic car by its SUMO id), positions (a traffic
        car's front bumper, from its gap) and speeds they index."""
        if self._native is not None:
            return self._native(self.ids, self.lengths, self.min_gaps, self.names, x, v)
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
    """Who follows whom among traffic when the attacker changes lanes (`maneuvers.LaneChange`): in every
    lane each car covers (from its lateral position, a car changing lanes covering
    both), the nearest cars, a traffic car included (`lanes.lane_pairs`: the arithmetic of the
    maneuver alone, bit for bit, between cars of the platoon). The traffic cars that may be next to a car
    of the platoon are SUMO's: its leader and follower, and its leaders and followers in the lanes beside
    it. A traffic car is placed along and across the road by its lane (`RouteLanes`); one on no lane of
    the route (an on-ramp, a junction lane from it) is on none of the platoon's lanes, and is left out
    (inside a junction, `junctions` sees it in 2D). Returns what `_TrafficSense` returns.

    SUMO names only the nearest car of each lane beside a car, and none past the car's own edge. A traffic
    car farther on in that lane, already edging into the car's own lane, covers it, and may be nearer than
    anything SUMO names there. With ``traffic.edging_sensed`` (`_edging`), each lane beside a platoon car
    is walked, car by car, from SUMO's nearest and from the nearest past the car's edge, up to the nearest
    car known in its own lanes, and every car edging across a line on the way is added.
    Without it, as d4sumo 0.21 and before sensed the traffic, such a car is sensed once SUMO has it in
    the lane (their stored campaigns replay so)."""

    def __init__(self, api, config: EpisodeConfig, ids: tuple[str, ...], lateral, road: Road):  # lateral: `sumo._Lateral`
        self.ids, self.index, self.lateral = ids, {vid: i for i, vid in enumerate(ids)}, lateral
        self.names = list(config.vehicle_ids)
        self.lengths = [v.length_m for v in config.car_vehicles]
        self.width, self.route_lanes = road.lane_width_m, lateral.route_lanes
        self.edging_sensed = config.traffic.edging_sensed
        #: a campaign stored before (one edge then): every car SUMO names placed as 0.21 placed it, off the route too
        self.as_0_21, self.platoon_lane = not self.edging_sensed and road.one_edge, road.platoon_lane
        #: a car this far or farther from its lane's centre reaches across a line [m] (`lanes.occupied_lanes`)
        self.edging_m = (road.lane_width_m - CAR_WIDTH_M) / 2.0
        call = lambda name: vehicle_call(api, name)  # noqa: E731
        self.get_leader, self.get_follower, self.get_neighbors = call("getLeader"), call("getFollower"), call("getNeighbors")
        self.get_position, self.get_speed, self.get_length = call("getLanePosition"), call("getSpeed"), call("getLength")
        self.get_lane, self.get_lateral = call("getLaneID"), call("getLateralLanePosition")
        self.get_vehicles = api.lane.getLastStepVehicleIDs
        #: the longest vehicle type SUMO has [m]: how far behind its lane's start a car's rear may be
        self.longest_m = max((api.vehicletype.getLength(t) for t in api.vehicletype.getIDList()), default=0.0)
        #: the same step in C++ with libsumo's own functions, where they can be had (`calls.native_lateral_pairs`)
        native = native_lateral_pairs(api)
        self._native = None
        if native is not None:
            sense, self._native = native
            self._state = sense(tuple(ids), self.lengths, self.width, self.edging_m, self.longest_m, self.edging_sensed,
                                self.as_0_21, self.platoon_lane, self.route_lanes.lanes, self.route_lanes.by_place)

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        lanes = self.lateral.sense()  # the platoon's cars' lanes (and the attacker's lateral position, recorded)
        if self._native is not None:
            return self._native(self._state, self.names, x, v, lanes)
        near: set[str] = set()
        beside: list[tuple[int, int, tuple]] = []  # (car, mode, SUMO's neighbours there)
        unseen: list[tuple[bool, bool]] = []  # whether SUMO named no leader, no follower: its search may have ended early
        for b, vid in enumerate(self.ids):
            hits = (self.get_leader(vid, FREE_ROAD_GAP_M), self.get_follower(vid, FREE_ROAD_GAP_M))
            unseen.append(tuple(not (hit and hit[0]) for hit in hits))
            for hit in hits:
                if hit and hit[0]:
                    near.add(hit[0])
            for mode in range(4):  # the lanes to its right and left, followers and leaders
                found = self.get_neighbors(vid, mode)
                near.update(other for other, _ in found)
                beside.append((b, mode, found))
        found = self._pairs(near, x, v, lanes)
        if self.edging_sensed:
            edging = self._edging(beside, found[0], near, x, unseen)
            if edging:
                found = self._pairs(near | edging, x, v, lanes)
        return found

    def _pairs(self, near: set[str], x: list[float], v: list[float],
               lanes: list[tuple[int, ...]]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        placed = self.route_lanes.lanes
        traffic, along, across = [], [], []
        for t in sorted(near - self.index.keys()):
            lane_id = self.get_lane(t)
            lane = placed.get(lane_id)
            if lane is None and self.as_0_21:  # a car off the route's one edge, at its own lane's position, as 0.21 had it
                lane = (0.0, int(lane_id.rpartition("_")[2]) - self.platoon_lane, 0)
            if lane is not None:
                traffic.append(t)
                along.append(lane[0] + self.get_position(t))  # on a road of one edge, 0 + the lane position
                across.append(lane[1])
        xs = list(x) + along
        vs = list(v) + [self.get_speed(t) for t in traffic]
        lengths = self.lengths + [self.get_length(t) for t in traffic]
        covered = list(lanes) + [occupied_lanes((place + 0.5) * self.width + self.get_lateral(t), self.width)
                                 for t, place in zip(traffic, across)]
        pairs = [p for p in lane_pairs(xs, covered, lengths, apart=len(self.ids)) if p[2] < FREE_ROAD_GAP_M or max(p[:2]) < len(self.ids)]
        return pairs, self.names + traffic, xs, vs

    def _edging(self, beside: list[tuple[int, int, tuple]], pairs: list[Pair], near: set[str], x: list[float],
                unseen: list[tuple[bool, bool]]) -> set[str]:
        """The traffic cars in a lane beside a platoon car, up to the nearest car known in the platoon car's
        own lanes (ahead for leaders, behind for followers), that edge across a line toward it; and the
        nearest car of that lane past the platoon car's edge, which SUMO's search of the lanes beside a car
        leaves out (it stays on the car's edge). The walk goes from each car of that lane to the next: SUMO's
        leader (or follower) of a car in it; of a car only reaching into it from farther off, its nearest in
        it. SUMO's gaps along the walk leave out the cars' lengths: it walks a little farther, and a car it
        adds beyond the nearest changes no pair."""
        ahead = [FREE_ROAD_GAP_M] * len(self.ids)
        behind = [FREE_ROAD_GAP_M] * len(self.ids)
        for a, b, gap in pairs:
            if b < len(self.ids):
                ahead[b] = min(ahead[b], gap)
            if a < len(self.ids):
                behind[a] = min(behind[a], gap)
        placed = self.route_lanes.lanes
        edging: set[str] = set()
        for b, mode, found in beside:
            side = -1 if mode & 1 else 1  # SUMO's modes: bit 1 the lane to the right, bit 2 leaders
            leaders = bool(mode & 2)
            step, bound = (self.get_leader, ahead[b]) if leaders else (self.get_follower, behind[b])
            own = placed.get(self.get_lane(self.ids[b]))
            if own is None:
                continue
            lane = own[1] + side  # the lane beside, by its place across the road
            if mode == 2:  # once a car: its own lane past its edge, where SUMO's search, finding nobody, may have ended at a junction
                for look, leaders_own, at_own, bound_own in ((unseen[b][0], True, x[b], ahead[b]),
                                                             (unseen[b][1], False, x[b] - self.lengths[b], behind[b])):
                    own_past = self._past_edge(own[0], own[1], leaders_own, at_own, bound_own) if look else None
                    if own_past is not None:
                        edging.add(own_past[0])
            starts = list(found)
            # SUMO's nearest beside is on the car's edge, nearer than any past it: the walk goes on from it
            past = None if found else self._past_edge(own[0], lane, leaders, x[b] - (0.0 if leaders else self.lengths[b]), bound)
            if past is not None:
                edging.add(past[0])
                starts.append(past)
            for other, distance in starts:
                car = other
                for _ in range(64):
                    at = placed.get(self.get_lane(car))
                    if at is None:
                        break
                    if at[1] == lane:
                        if car not in near and car not in self.index and abs(self.get_lateral(car)) >= self.edging_m:
                            edging.add(car)
                        hit = step(car, FREE_ROAD_GAP_M)
                    else:  # reaching into the lane from the one beyond: the lane's next car from it
                        nearest = self.get_neighbors(car, (2 if leaders else 0) + (1 if lane < at[1] else 0))
                        hit = nearest[0] if nearest else None
                    if not hit or not hit[0]:
                        break
                    car, distance = hit[0], distance + hit[1]
                    if distance > bound:
                        break
        edging.difference_update(self.index)
        return edging

    def _past_edge(self, start: float, place: int, leaders: bool, at: float, bound: float) -> tuple[str, float] | None:
        """The nearest car at ``place`` across the road on the lanes after (leaders) or before the one that
        starts at ``start``, within ``bound`` of ``at`` (the platoon car's front, or rear), with its distance."""
        lanes = self.route_lanes.by_place.get(place, ())
        for lane_start, lane_end, lane in (lanes if leaders else reversed(lanes)):
            if (lane_start <= start) if leaders else (lane_start >= start):
                continue
            if (lane_start - at - self.longest_m if leaders else at - lane_end) > bound:  # a car's rear may
                return None  # still be on the lane before
            cars = self.get_vehicles(lane)
            if cars:  # SUMO lists a lane's cars from its rearmost
                car = cars[0] if leaders else cars[-1]
                front = lane_start + self.get_position(car)
                return car, (front - self.get_length(car) - at) if leaders else (at - front)
        return None
