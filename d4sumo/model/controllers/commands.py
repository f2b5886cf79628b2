"""A follower controller's command, checked: whatever a controller returns (a user's, an FMU's, the compiled
followers') becomes the float it stands for in [-1, 1], or one clear error naming the car and the step."""

from __future__ import annotations

import math
import numbers

from ...errors import D4sumoError


class ControllerError(D4sumoError, ValueError):
    """A follower controller returned something that is not a command."""


def checked_command(c, car: int, k: int) -> float:
    """A follower controller's command as a float in [-1, 1] (a float32 or a numpy scalar becomes the
    float it stands for), or a ControllerError: a user's controller must not corrupt the trace."""
    # a float as it is (the common case, without numbers.Real's slow ABC check); not a string that reads as a number
    u = c if type(c) is float else float(c) if isinstance(c, numbers.Real) else math.nan
    if not -1.0 <= u <= 1.0:  # NaN fails too
        raise ControllerError(f"the controller of v{car} returned {c!r} at step {k}; allowed: a command in [-1, 1]")
    return u
