"""Keep freed memory in the process (glibc): numpy work arrays of a few hundred KB are
otherwise mmap'd fresh and page-faulted on every call, which on virtual machines costs more
than the arithmetic (measured: a 311x419 bilinear resample 7.9 ms -> 1.2 ms).

Arrays under 64 MiB come from the heap, and up to 256 MiB of freed heap is kept for reuse.
A process-wide setting, so importing mimica never does it: the command line and the
benchmarks call `keep_memory()`; a Python user may.  MIMICA_MALLOC=default leaves the
allocator alone.
"""

from __future__ import annotations

import os
import sys

_done = False


def keep_memory() -> bool:
    global _done
    if _done or os.environ.get("MIMICA_MALLOC") == "default" or not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes
        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        ok = libc.mallopt(m_mmap_threshold, 64 << 20) == 1 and libc.mallopt(m_trim_threshold, 256 << 20) == 1
    except (OSError, AttributeError):
        return False
    _done = ok
    return ok
