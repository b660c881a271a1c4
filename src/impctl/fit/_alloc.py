"""Keep freed heap memory in the process instead of handing it back to the kernel (glibc).

The batched fit allocates and frees tensors of a few MB thousands of times per batch. With
glibc's defaults each one is a fresh ``mmap`` (or trimmed heap) whose every page faults on first
touch: a fleet batch spent ~25 % of its CPU time in the kernel on page faults. Raising the mmap
threshold to its maximum (32 MB) and switching trimming off serves them from the heap again
(``bench/fleet.py --profile``: 750,000 → 100,000 page faults, sys time 2.0 → 0.3 s per batch
of 16). The price is that the resident memory stays at its peak (flat over a fleet run).
Process-wide, so only the fleet's worker processes and batched fits call it.
"""

from __future__ import annotations

import ctypes
import ctypes.util

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_MMAP_MAX = 32 * 2**20   # glibc's upper limit for M_MMAP_THRESHOLD on 64-bit
_done = False


def retain_freed_memory() -> bool:
    """Apply the settings once per process; False where the C library is not glibc."""
    global _done
    if _done:
        return True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    _done = bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_MAX)) and bool(
        mallopt(_M_TRIM_THRESHOLD, 2**30))
    return _done
