"""The C heap of a long run (glibc's malloc), set explicitly by the caller like the thread
settings: the CLI and the benchmark call it through :func:`amrvio.pipeline.threads.run_settings`;
the library itself never does, since the setting is the whole process's.

glibc serves a block of 128 KiB or more (an image, a pyramid level, a BA matrix) from its own
mapping and gives it back to the system when it is freed. But once such a block is freed, glibc
raises that threshold to the block's size (up to 32 MiB) and the heap's trim threshold to twice
it: from then on the large arrays come from the heap, and the pages of those freed below the
heap's top stay resident. On bench_speed's 20 min drive, the peak resident set above the run's
start was 144 and 152 MiB left alone, 131 and 138 MiB with both thresholds fixed (124 and
126 against 118-122 MiB over 1 min); at the end of the run, 35-40 MiB of freed heap stayed
resident, against 15-18 MiB.
"""

from __future__ import annotations

import ctypes

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 128 * 1024
"""glibc's own starting value, kept fixed."""
TRIM_THRESHOLD_BYTES = 1024 * 1024
"""Free memory at the heap's top above this goes back to the system."""


def bound_heap(mmap_threshold: int = MMAP_THRESHOLD_BYTES, trim_threshold: int = TRIM_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap and trim thresholds for the rest of the process (see the module). True
    when both were set; False where the C library has no ``mallopt`` or refused (not glibc:
    nothing changes)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold))) and bool(mallopt(M_TRIM_THRESHOLD, int(trim_threshold)))


__all__ = ["MMAP_THRESHOLD_BYTES", "TRIM_THRESHOLD_BYTES", "bound_heap"]
