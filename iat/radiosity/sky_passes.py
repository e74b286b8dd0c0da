"""The sky's later estimates at a vertex traced only where the light can change (issue 41).

A vertex's sky is estimated from cosine-distributed directions, one in each stratum of a grid on the
unit square (rotated per vertex, :func:`.sampling.rotated_disk`). A noisy vertex is estimated again
with the grid twice as fine: its old directions and 3 new ones in each old stratum
(:func:`.sampling.nested_pattern`). Through a window most strata are wall and a few are sky, and
only the strata along the window's outline hold both. So a later estimate traces its new directions
only in the strata whose value differs from a neighbour's (:func:`settled_strata`); in the others
they take their stratum's value and light (the super-sampling of RADIANCE's ambient divisions,
``-as``). An opening that no direction of a settled neighbourhood met is missed, so the estimate
errs dark on the whole (docs/benchmarks.md gives how much).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iat.radiosity.sampling import finer_strata, nested_pattern


@dataclass(frozen=True)
class SkyLevel:
    """The new directions of a later estimate, on a grid of ``2 g`` strata a side.

    points : (3 g², 2) in [0, 1)^2, before the vertex's rotation; 3 a stratum of the g x g grid.
    parent : (3 g²,) int, each point's stratum on the g x g grid (row-major).
    cell : (3 g²,) int, each point's stratum on the 2g x 2g grid.
    old_cell : (g²,) int, the stratum on the 2g x 2g grid of the point in each stratum of the g x g grid.
    """

    points: np.ndarray
    parent: np.ndarray
    cell: np.ndarray
    old_cell: np.ndarray


def sky_levels(pattern: np.ndarray, side: int, estimates: int, rng: np.random.Generator) -> list[SkyLevel]:
    """The new directions of the estimates after the first, ``pattern`` (side * side, 2), one point
    a stratum of the side x side grid in row-major order: ``estimates - 1`` levels drawn with
    ``rng``."""
    a, b = np.divmod(np.arange(side * side), side)
    every, strata = pattern, np.stack([a, b], axis=1)  # each grid stratum's point, row-major
    levels = []
    for k in range(1, estimates):
        g = side << (k - 1)
        pts, st = nested_pattern(every, strata, g, rng)
        up, old = st // 2, finer_strata(strata, every, g)
        cell, old_cell = st[:, 0] * 2 * g + st[:, 1], old[:, 0] * 2 * g + old[:, 1]
        levels.append(SkyLevel(pts, up[:, 0] * g + up[:, 1], cell, old_cell))
        nxt = np.empty((4 * g * g, 2))
        nxt[old_cell], nxt[cell] = every, pts
        every = nxt
        a, b = np.divmod(np.arange(4 * g * g), 2 * g)
        strata = np.stack([a, b], axis=1)
    return levels


def settled_strata(grid: np.ndarray, rot: np.ndarray, radius: int) -> np.ndarray:
    """(k, g * g) bool: the strata of per-vertex grids ``grid`` (k, g * g) of a g x g pattern
    rotated by ``rot`` (k, 2) whose value every stratum within ``radius`` (on the torus the rotation
    wraps) shares. The stratum row and column that the rotation's wrap cuts are never settled: its
    two parts lie apart on the disc. A negative ``radius`` settles none (every new direction is
    traced)."""
    k, gg = grid.shape
    if radius < 0:
        return np.zeros((k, gg), dtype=bool)
    g = int(round(np.sqrt(gg)))
    v = grid.reshape(k, g, g)
    row = np.ones(v.shape, dtype=bool)  # the stratum's row within radius shares its value
    for db in range(1, radius + 1):
        row &= (np.roll(v, db, axis=2) == v) & (np.roll(v, -db, axis=2) == v)
    same = row.copy()  # and so does each row within radius above and below, all of it
    for da in (d for a in range(1, radius + 1) for d in (a, -a)):
        same &= np.roll(row, da, axis=1) & (np.roll(v, da, axis=1) == v)
    cut = np.floor(g * (1.0 - rot)).astype(np.int64)  # (k, 2); g where nothing is cut
    a = np.arange(g)
    same &= (a[None, :, None] != cut[:, 0, None, None]) & (a[None, None, :] != cut[:, 1, None, None])
    return same.reshape(k, gg)


def quarter_sums(values: np.ndarray) -> np.ndarray:
    """(k, 4) the sums of per-vertex grids ``values`` (k, g * g) over the four interleaved quarters
    of the grid (the strata whose row and column are even, even; even, odd; odd, even; odd, odd)."""
    gg = values.shape[1]
    g = int(round(np.sqrt(gg)))
    a, b = np.divmod(np.arange(gg), g)
    return values @ np.eye(4)[(a % 2) * 2 + b % 2]
