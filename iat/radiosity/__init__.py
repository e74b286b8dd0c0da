"""Radiosity: analytic form factors, embreex visibility, the adaptive progressive solver, solutions."""

from .solution import Solution
from .solver import SolveOptions, resolve, solve

__all__ = ["SolveOptions", "Solution", "resolve", "solve"]
