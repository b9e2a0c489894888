"""What this machine lends the process: the one place that counts the usable cores.

Import-light (the standard library only): the checker and the image writers use it.
"""

from __future__ import annotations

import os


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system has one, else all), at least 1."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity on this system (macOS, Windows)
        n = os.cpu_count() or 1
    return max(1, n)
