"""Processes d4sumo starts that must not outlive the one that started them."""

from __future__ import annotations

import os
import signal
import threading
import time


def die_with_parent(parent_pid: int) -> None:
    """Called first in a child process: it dies when ``parent_pid``, its parent, does, even by kill -9."""
    try:  # Linux: the kernel kills the child when its parent dies
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(1)

    def watch() -> None:  # everywhere else: notice within a second
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()
