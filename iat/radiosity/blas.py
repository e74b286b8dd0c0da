"""numpy's OpenBLAS on one thread, set when the solver's kernels are imported (issue 41).

A solve's matrix products are small ((n, 3) by (3, 3): the sky's colours, (n, 3) by (3,): its
angles to the sun) and are made from the gather threads, where OpenBLAS's own threads only wait
and spin: on 2 cores, Preetham's sky for 131 k directions took 100 ms instead of 13, and the sky
gather of house_day's vertices twice the CPU time; the results are the same bits. An explicit
``$OPENBLAS_NUM_THREADS`` is left as it is.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numpy as np

_SETTERS = ("scipy_openblas_set_num_threads64_", "openblas_set_num_threads64_", "openblas_set_num_threads")


def one_thread() -> bool:
    """Set numpy's bundled OpenBLAS to one thread; whether it was found and set."""
    if os.environ.get("OPENBLAS_NUM_THREADS"):
        return False
    libs = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), "numpy.libs", "*openblas*")
    for path in glob.glob(libs):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _SETTERS:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.argtypes = [ctypes.c_int]
                fn(1)
                return True
    return False


one_thread()
