"""Keep freed memory in the process (glibc): numpy work arrays of a few hundred KB are
otherwise mmap'd fresh and page-faulted on every call, which on virtual machines costs more
than the arithmetic (measured: a 311x419 bilinear resample 7.9 ms -> 1.2 ms).

Arrays under 64 MiB come from the heap, and up to 256 MiB of freed heap is kept for reuse.
numpy's advice that large arrays use huge pages is turned off (numpy/numpy#31590): with the
kernel's transparent huge pages at defrag=madvise (Debian's and Ubuntu's default), a first touch
of advised memory waits for the kernel to compact memory once it is fragmented -- bench/batch.py's
basis path with its 81 MB outputs kept, as a program writing them keeps them: 1,150-1,250 frames/s
with the advice, 1,700-2,030 without (this VM, the same run of rounds).

A process-wide setting, so importing mimica never does it: the command line, batch jobs and the
benchmarks call `keep_memory()`; a Python user may.  MIMICA_MALLOC=default leaves the
allocator and numpy alone.
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
    import numpy as np
    advise = getattr(getattr(getattr(np, "_core", None), "multiarray", None), "_set_madvise_hugepage", None)
    if advise is not None:
        advise(False)
    _done = ok
    return ok
