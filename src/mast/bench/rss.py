"""Peak resident memory of this process, for benchmarks that run each step in a child.

Light on purpose (standard library only): a benchmark's child imports it after
its measured work without loading anything the measured command did not.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

__all__ = ["peak_rss_mb"]


def peak_rss_mb() -> float:
    """This process's peak resident memory, MB.

    On Linux, the high-water mark of this program's own memory (``VmHWM``):
    ``ru_maxrss`` also counts the parent's, which a child started by
    ``vfork`` and ``exec`` inherits. Elsewhere ``ru_maxrss``.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024  # kB
    except OSError:
        pass
    try:
        import resource
    except ImportError:  # not on this platform
        return math.nan
    peak = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    # kilobytes on Linux, bytes on macOS
    return peak / 1e6 if sys.platform == "darwin" else peak / 1024
