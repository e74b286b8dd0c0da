"""Vertex colours that clip in a client as they clip in our renderer.

A glTF client clips ``COLOR_0`` to [0, 1] at the vertices and then interpolates; our renderer
interpolates radiance and clips the pixel. The two differ inside triangles whose vertices lie on
both sides of 1 in some channel (by a light: a pillar's colour there is darker, and tinted where
the channels clip at different places). :func:`slice_at_one` cuts each such triangle along the line
where that channel's linear interpolation is 1, channel after channel: in every piece each
channel is then at most 1 everywhere or at least 1 everywhere, so clipping at the vertices gives,
pixel for pixel, clip(interpolation). New vertices are linear combinations of an edge's two ends,
shared by the triangles on that edge (same two vertex indices), so the mesh stays watertight within
itself; across vertex-duplicating patch boundaries :mod:`iat.geometry.tjunctions` closes it after.
"""

from __future__ import annotations

import numpy as np

__all__ = ["slice_at_one"]

#: a cut this close (in edge parameter) to an end snaps to that end
_SNAP = 1e-6


def _slice_channel(pos, val, tri, k):
    """One channel ``k`` of :func:`slice_at_one`: (positions, values, triangles)."""
    f = val[:, k].astype(np.float64) - 1.0
    ft = f[tri]
    cross = (ft.min(axis=1) < 0) & (ft.max(axis=1) > 0)
    if not cross.any():
        return pos, val, tri
    t3 = tri[cross]
    neg = ft[cross] < 0
    # the lone vertex: the one on its own side (>= 0 counts with the non-negative side)
    lone = np.where(neg.sum(axis=1) == 1, np.argmax(neg, axis=1), np.argmax(~neg, axis=1))
    r = np.stack([lone, (lone + 1) % 3, (lone + 2) % 3], axis=1)
    a, b, c = (np.take_along_axis(t3, r[:, i : i + 1], axis=1)[:, 0] for i in range(3))
    # cut points on edges a-b and a-c, one vertex per (vertex pair): neighbours share it
    ends = np.concatenate([np.stack([a, b], 1), np.stack([a, c], 1)])
    lo, hi = ends.min(axis=1), ends.max(axis=1)
    key, inv = np.unique(np.stack([lo, hi], 1), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    u, v = key[:, 0], key[:, 1]
    t = f[u] / (f[u] - f[v])  # from the lower index: the same number for every triangle on the edge
    new_pos = pos[u] + t[:, None] * (pos[v] - pos[u])
    new_val = val[u] + t[:, None] * (val[v] - val[u])
    new_val[:, k] = 1.0
    idx = len(pos) + np.arange(len(key))
    idx = np.where(t <= _SNAP, u, np.where(t >= 1 - _SNAP, v, idx))
    p, q = np.split(idx[inv], 2)
    pieces = np.concatenate([np.stack([a, p, q], 1), np.stack([p, b, c], 1), np.stack([p, c, q], 1)])
    ok = (pieces[:, 0] != pieces[:, 1]) & (pieces[:, 1] != pieces[:, 2]) & (pieces[:, 0] != pieces[:, 2])
    src = np.concatenate([np.flatnonzero(cross)] * 3)[ok]
    keep = np.flatnonzero(~cross)
    tris = np.concatenate([tri[keep], pieces[ok]])
    order = np.argsort(np.concatenate([keep, src]), kind="stable")
    return np.concatenate([pos, new_pos]), np.concatenate([val, new_val.astype(val.dtype)]), tris[order]


def slice_at_one(positions, values, triangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut ``triangles`` where a channel of the linearly interpolated ``values`` crosses 1.

    positions : (n, 3) float; values : (n, c) float, at the file's exposure (1 = white)
    triangles : (t, 3) int
    Returns ``(positions (n', 3), values (n', c), triangles (t', 3) int64)``: the first n vertices
    are the input's; each input triangle's pieces stand in its place, in its winding. Unused
    vertices (cut points snapped to an end) are not removed.
    """
    pos = np.asarray(positions)
    val = np.asarray(values)
    tri = np.asarray(triangles, np.int64).reshape(-1, 3)
    for k in range(val.shape[1]):
        pos, val, tri = _slice_channel(pos, val, tri, k)
    return pos, val, tri
