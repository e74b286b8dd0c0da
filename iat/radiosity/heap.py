"""The C heap under a long solve: every array of ``MMAP_THRESHOLD`` bytes or more is taken
straight from the system and given back when freed. glibc's default raises that threshold each
time such an array is freed (up to 32 MiB), after which a solve's many short-lived arrays of a
few MiB live in its arenas, which keep the pages freed in between: a 3-storey building's solve
peaked at 1 414 MiB, 996 MiB with the threshold fixed, for ~5 % more time (docs/benchmarks.md,
"The large building's memory")."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

#: arrays of this many bytes or more are mapped and unmapped on their own (128 KiB, glibc's initial
#: value, held the 3-storey building to 948 MiB but cost the sample house ~8 % of its time)
MMAP_THRESHOLD = 1024 * 1024
_M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter


@functools.cache
def fix_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold at :data:`MMAP_THRESHOLD` for the process (once). False where
    the C library is not glibc: nothing changes there."""
    name = ctypes.util.find_library("c")
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD))
