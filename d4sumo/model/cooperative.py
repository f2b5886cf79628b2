"""A cooperative platoon's followers stepped in C (the `_cooperative` extension, built when d4sumo is
installed): the same commands and speeds as `platoon.Platoon.advance`'s Python, bit for bit, at a fraction
of its cost (docs/benchmarks.md).

It plays the platoons whose every follower runs d4sumo's `cacc`, `ploeg` or `consensus` (the classes
themselves, not a subclass) without the mitigation (``fallback_mps``), on a perfect radar, over a channel
that delivers every beacon as it is sent (no latency, no loss, no message attack), in the paper's column
(no lane change, no traffic). Everything else the Python plays, as it does everywhere when the extension
could not be built (no C compiler at install). The attacker and the maneuver's other car are always
Python's.
"""

from __future__ import annotations

import sys
from typing import Callable

from .control import ConsensusCACC, PathCACC, PloegCACC

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
    """``advance(k, positions, speeds, pairs, commands, new_speeds)`` of ``platoon``'s followers in C, or
    None where the Python plays them (see the module)."""
    channel, config = platoon.channel, platoon.config
    if (Followers is None or not ENABLED or channel is None or not channel.direct or channel.falsify is not None
            or not platoon._one_ahead or (config.radar is not None and not config.radar.perfect)
            or len(platoon._python) != config.followers):
        return None
    laws = []
    for follower in platoon.followers:
        controller = follower.controller
        law = LAWS.get(type(controller))
        if law is None or controller.fallback is not None:
            return None
        if law == 1:
            gains = (controller.a1, controller.a2, controller.a3, controller.a4, controller.a5)
        elif law == 2:
            gains = (controller.params.h_s, controller.params.kp, controller.params.kd, 0.0, 0.0)
        else:
            p = controller.params
            gains = (p.b, p.k_leader_v1, p.k_leader, p.k_front, p.h_s)
        vehicle, actuator = controller.vehicle, follower.actuator
        laws.append((law, (controller.setpoint_m, controller.target_speed_mps, controller.step_s, vehicle.max_accel_mps2,
                           vehicle.max_decel_mps2), tuple(float(g) for g in gains), float(getattr(controller, "u", 0.0)),
                     (actuator.accel_max, actuator.decel_max, actuator.alpha, actuator.step_s, actuator.max_speed_mps,
                      actuator.accel_mps2, actuator.coast)))
    from .platoon import checked_command  # the Python's error for a command that is not one

    return Followers(channel.step_s, channel.every, list(channel.lengths), laws, checked_command).advance
