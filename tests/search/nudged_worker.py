"""A Dask worker's preload: the GP's numerics one ulp off in that worker, as on another CPU (its BLAS kernel)."""

from __future__ import annotations

import sys
from pathlib import Path


def dask_setup(worker) -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    import pytest
    from histories import nudge_numerics

    nudge_numerics(pytest.MonkeyPatch())
