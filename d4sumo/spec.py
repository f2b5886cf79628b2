"""The attacker's specification and its robustness (SPEC section 3).

    psi = F( OR_{i=1..N-1} gap_i <= d_safe )  and  G( gap_0 > d_safe )

rho > 0: the followers came within d_safe of each other (with d_safe = 0: collided) while the attacker
stayed clear of v1 the whole time: a successful attack. The optimisers maximise rho.
"""

from __future__ import annotations

import numpy as np

from .errors import ConfigError
from .trace import Trace


def paper_formula(followers: int, d_safe_m: float = 0.0) -> str:
    """psi in rtamt's syntax over the trace's gap signals."""
    _needs_pair(followers)
    pairs = " or ".join(f"(gap_{i} <= {d_safe_m!r})" for i in range(1, followers))
    return f"(eventually({pairs})) and (always(gap_0 > {d_safe_m!r}))"


def psi_robustness(trace: Trace, d_safe_m: float = 0.0) -> float:
    """Robustness of psi at t = 0, computed directly with numpy (discrete time, the trace's samples).

    F(x <= c) scores max_t (c - x); G(x > c) scores min_t (x - c); 'or' is max, 'and' is min.
    """
    _needs_pair(trace.followers)
    gaps = trace.gaps()
    adversarial = float(np.max(d_safe_m - gaps[:, 1:]))
    attacker_safe = float(np.min(gaps[:, 0] - d_safe_m))
    return min(adversarial, attacker_safe)


def _needs_pair(followers: int) -> None:
    if followers < 2:
        raise ConfigError(
            "scenario.followers", followers, "at least 2 for the paper's specification (two followers must be able to collide), or give your own formula"
        )
