"""The traffic lights along a platoon's route, as its drivers see them each step (`signals.Stop`).

Each junction of the route whose link from the platoon's lane to its lane on the next edge a traffic
light controls is a signal: its stop line is where that lane ends, a distance along the route (as a car's
position is: where it started plus SUMO's odometer). Each step, a car whose front bumper is before a stop
line within `LOOKAHEAD_M` sees that signal's state for its link (SUMO's link state letter); once past the
line it sees the next one. Only what SUMO says of the lights is read here: what a driver does about them
is the model's (`model.signals`).
"""

from __future__ import annotations

from ..model.world.signals import Stop
from .calls import route_junctions

#: how far ahead of a car a signal is seen [m]: more than stopping from 45 m/s comfortably takes
LOOKAHEAD_M = 300.0


def route_signals(api, route: tuple[str, ...], path: tuple[int, ...]) -> list[tuple[float, str, int]]:
    """The signals along the route: (stop line's distance along the route [m], light's id, link index), in order."""
    links: dict[tuple[str, str], tuple[str, int]] = {}
    for tls in api.trafficlight.getIDList():
        for index, controlled in enumerate(api.trafficlight.getControlledLinks(tls)):
            for into, out, _ in controlled:
                links.setdefault((into, out), (tls, index))
    return [(line, *links[lane, to_lane]) for _, lane, to_lane, line, _ in route_junctions(api, route, path)
            if (lane, to_lane) in links]


#: the link states a driver drives on at (green, off, blinking): where every light within reach shows one, nobody
#: needs to be told more
_GO = frozenset("GgsoO")


def signal_tracks(lights: "RouteLights") -> tuple[tuple[float, str, str], ...]:
    """What a platoon's route lights recorded: each signal's stop line along the route [m], its light's id, and its
    state at each step (SUMO's link state letters, one a step)."""
    if not lights.recorded:
        return ()
    return tuple((line, tls, "".join(step[i] for step in lights.recorded)) for i, (line, tls, _) in enumerate(lights.signals))


class RouteLights:
    """What each car of one platoon sees of the route's signals, step by step (see the module)."""

    def __init__(self, api, signals: list[tuple[float, str, int]], cars: int, record: bool = False):
        self.signals = signals
        self.first = 0  # the first signal ahead of the rearmost car
        self.next = [0] * cars  # each car's next signal: cars never drive backwards
        self.get_state = api.trafficlight.getRedYellowGreenState
        #: with ``record`` (a replay that writes its FCD, for its time-space diagram): every signal's state at each
        #: step, a letter a signal (`Episode.signals`)
        self.recorded: list[str] | None = [] if record else None

    def __call__(self, x: list[float]) -> list[Stop | None] | None:
        """The signal each car at positions ``x`` along the route sees, or None (none within reach); None for
        all of them where every light within their reach lets them on."""
        signals, get_state = self.signals, self.get_state
        if self.recorded is not None:
            states_now = {tls: get_state(tls) for _, tls, _ in signals}
            self.recorded.append("".join(states_now[tls][index] for _, tls, index in signals))
        j, rear, front = self.first, min(x), max(x)
        while j < len(signals) and rear > signals[j][0]:
            j += 1
        self.first = j
        states: dict[str, str] = {}
        demands = False
        for line, tls, index in signals[j:]:
            if line - front > LOOKAHEAD_M:
                break
            if tls not in states:
                states[tls] = get_state(tls)
            demands = demands or states[tls][index] not in _GO
        if not demands:
            return None
        out: list[Stop | None] = []
        for i, car in enumerate(x):
            k = self.next[i]
            while k < len(signals) and car > signals[k][0]:
                k += 1
            self.next[i] = k
            if k == len(signals) or signals[k][0] - car > LOOKAHEAD_M:
                out.append(None)
                continue
            line, tls, index = signals[k]
            if tls not in states:
                states[tls] = get_state(tls)
            out.append(Stop(k, line - car, states[tls][index]))
        return out
