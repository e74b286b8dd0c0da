"""Scenes built in code from quads: a box's faces split into a grid, and a Scene of polygons."""

from __future__ import annotations

import numpy as np

from iat.io.scene import Scene


def box_quads(lo, hi, k: int, inward: bool = True):
    """The faces of the axis-aligned box [lo, hi] (m), each split into k x k quads facing in (or out):
    ``[(axis, side, i, j, q)]``, side the face's coordinate on that axis, (i, j) the quad's place in
    its face's grid and q its (4, 3) corners."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = (lo + hi) / 2
    out = []
    for axis in range(3):
        a, b = [x for x in range(3) if x != axis]
        ga, gb = np.linspace(lo[a], hi[a], k + 1), np.linspace(lo[b], hi[b], k + 1)
        for side in (lo[axis], hi[axis]):
            for i in range(k):
                for j in range(k):
                    q = np.zeros((4, 3))
                    q[:, axis] = side
                    q[:, a] = ga[[i, i + 1, i + 1, i]]
                    q[:, b] = gb[[j, j, j + 1, j + 1]]
                    normal = np.cross(q[2] - q[0], q[3] - q[1])
                    if (normal @ (centre - q.mean(axis=0)) > 0) != inward:
                        q = q[[0, 3, 2, 1]]
                    out.append((axis, side, i, j, q))
    return out


def scene_of(polys, material_ids, materials, lights=(), sky=None) -> Scene:
    """A Scene of polygons (each (3, 3) or (4, 3) corners, m) with their material indices."""
    verts, corners = [], []
    for q in polys:
        idx = list(range(len(verts), len(verts) + len(q)))
        verts.extend(q)
        corners.append(idx + [-1] * (4 - len(q)))
    return Scene(
        np.array(verts, float),
        np.array(corners),
        np.array(material_ids),
        materials,
        lights=list(lights),
        sky=sky,
    )
