"""Radiosity: analytic form factors, embreex visibility, the adaptive progressive solver, solutions."""

from .solution import Solution
from .solver import SolveOptions, solve

__all__ = ["SolveOptions", "Solution", "solve"]
