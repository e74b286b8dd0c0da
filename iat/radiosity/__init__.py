"""Radiosity: analytic form factors, embreex visibility, the adaptive progressive solver, solutions."""

import functools
import hashlib
from pathlib import Path

from iat.radiosity.options import SolveOptions
from iat.radiosity.resolving import resolve
from iat.radiosity.solution import Solution
from iat.radiosity.solver import solve

__all__ = ["SolveOptions", "Solution", "resolve", "solve", "solver_fingerprint"]


@functools.cache
def solver_fingerprint() -> str:
    """First 12 hex digits of a hash of the source of this package and of what builds its input
    (``iat.io``, ``iat.geometry``): part of every solution cache key, so a cached solution is never
    reused after the solver or the loader changed (the options alone do not say)."""
    h = hashlib.sha256()
    root = Path(__file__).parent.parent
    for f in sorted(
        [
            *root.joinpath("radiosity").glob("*.py"),
            *root.joinpath("io").glob("*.py"),
            *root.joinpath("geometry").glob("*.py"),
        ]
    ):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:12]
