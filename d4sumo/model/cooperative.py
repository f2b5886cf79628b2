"""A cooperative platoon's followers stepped in C (the `_cooperative` extension, built when d4sumo is
installed): the same commands, modes and speeds as `platoon.Platoon.advance`'s Python, bit for bit, at a
fraction of its cost (docs/v2v.md).

It plays the platoons whose every follower runs d4sumo's `cacc`, `ploeg` or `consensus` (the classes
themselves, not a subclass), with or without the mitigation, in the paper's column (no lane change, no
traffic): their radars (range, noise, latency), their channel (interval, latency, loss) and a message
attack on it, each drawing from the Python's own generators and lying with the Python's own falsifier, in
the order the Python does. Everything else the Python plays, as it does everywhere when the extension could
not be built (no C compiler at install). The attacker and the maneuver's other car are always Python's.
"""

from __future__ import annotations

import sys
from typing import Callable

from .commands import checked_command  # the Python's error for a command that is not one
from .cacc import ConsensusCACC, PathCACC, PloegCACC
from .messages import BeaconFalsifier
from .sensing import Radar
from .v2v import Message

try:
    from ._cooperative import Followers
except ImportError:  # not built: the Python plays every platoon
    Followers = None

#: whether the platoons it may play are stepped in C (tests turn it off to compare with the Python)
ENABLED = True

#: each controller's law, as the extension numbers them
LAWS = {PathCACC: 1, PloegCACC: 2, ConsensusCACC: 3}
if sys.version_info >= (3, 12):  # the consensus law sums with sum(), which is compensated from Python 3.12 on
    del LAWS[ConsensusCACC]


def compiled_followers(platoon) -> Callable | None:
    """``advance(k, positions, speeds, pairs, commands, new_speeds, modes)`` of ``platoon``'s followers in C,
    or None where the Python plays them (see the module). Made before the platoon's first step: it takes
    the channel's and the radars' generators as they start."""
    channel, config = platoon.channel, platoon.config
    if (Followers is None or not ENABLED or channel is None or not platoon._one_ahead
            or len(platoon._python) != config.followers
            or (channel.falsify is not None and (type(channel.falsify) is not BeaconFalsifier  # d4sumo's lies: none renames its sender
                                                 or channel.liar not in channel.senders))):
        return None
    laws = []
    for i, follower in enumerate(platoon.followers, start=1):
        controller = follower.controller
        law = LAWS.get(type(controller))
        if law is None:
            return None
        if law == 1:  # PATH's coefficients, as its constructor derived them
            gains = (controller.a1, controller.a2, controller.a3, controller.a4, controller.a5)
        elif law == 2:
            p = controller.params
            gains = (p.h_s, p.kp, p.kd, 0.0, 0.0)
        else:
            p = controller.params
            gains = (p.b, p.k_leader_v1, p.k_leader, p.k_front, p.h_s)
        fallback = controller.fallback
        mitigation = (fallback.threshold, fallback.headway) if fallback is not None else (0.0, 0.0)
        radar = None
        if config.radar is not None and not config.radar.perfect:  # its own, as the Python's starts: the same draws
            r = Radar(config.radar, config.step_s, i)
            radar = (r.params.range_m, r.params.gap_noise_m, r.params.speed_noise_mps, r.readings.maxlen - 1, r.rng.normal)
        vehicle, actuator = controller.vehicle, follower.actuator
        own = (controller.setpoint_m, controller.target_speed_mps, controller.step_s, vehicle.max_accel_mps2, vehicle.max_decel_mps2)
        drive = (actuator.accel_max, actuator.decel_max, actuator.alpha, actuator.step_s, actuator.max_speed_mps,
                 actuator.accel_mps2, actuator.coast)
        numbers = (*own, *gains, *mitigation, *drive, *(radar[:3] if radar else ()))
        if not all(type(x) is float or type(x) is int for x in numbers):  # a numpy float32 computes otherwise in the Python
            return None
        laws.append((law, own, tuple(float(g) for g in gains), float(getattr(controller, "u", 0.0)),
                     tuple(float(m) for m in mitigation), drive, radar))
    sources = [channel.sources[i] for i in range(1, config.followers + 1)]
    randoms = [channel.rngs[s, i].random for i, srcs in enumerate(sources, start=1) for s in srcs] if channel.rngs else []
    lie = (channel.falsify, channel.liar, Message, channel.sent) if channel.falsify is not None else None
    return Followers((channel.step_s, channel.every, channel.delay, float(channel.params.loss)), list(channel.lengths), sources,
                     randoms, lie, laws, checked_command).advance
