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

`prefaulted(shape)`, for one array: a large output whose pages another thread maps while the
caller computes (the basis path maps its 81 MB of frames during its solve).
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


_MADV_POPULATE_WRITE = 23          # Linux 5.14+


def _populate(a) -> None:
    """Have the kernel map every page of `a` now: one madvise(MADV_POPULATE_WRITE) over its
    whole pages (ctypes lets go of the GIL meanwhile), else a write to each page."""
    import mmap
    page = mmap.PAGESIZE
    start, end = a.ctypes.data, a.ctypes.data + a.nbytes
    lo, hi = -(-start // page) * page, end // page * page
    if hi > lo and sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            libc.madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
            if libc.madvise(lo, hi - lo, _MADV_POPULATE_WRITE) == 0:
                return
        except (OSError, AttributeError):
            pass
    a.reshape(-1).view("u1")[::page] = 0


def prefaulted(shape, dtype="f8"):
    """An uninitialized array whose memory is mapped on another thread while the caller goes
    on, and the function that waits for it (call it before writing the array from several
    threads).  A large fresh array's first touch costs a page fault a page (on this VM 81 MB:
    26-39 ms mapped at once, 34-45 ms touched page by page), which the idle core of a
    single-threaded stage can take on instead."""
    import threading
    import numpy as np
    a = np.empty(shape, dtype)
    t = threading.Thread(target=_populate, args=(a,), name="mimica-prefault", daemon=True)
    t.start()
    return a, t.join
