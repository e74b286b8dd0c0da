"""Triangulating one planar polygon (an OBJ n-gon) with mapbox-earcut, never as a fan.

:func:`polygon_triangles` projects the polygon on the plane of the dominant axis of
its Newell normal and ear-cuts the outline there. A keyhole outline (out to a hole
along a bridge edge, round the hole, back along the bridge) is a simple polygon to
earcut, so a "holed" OBJ face keeps its hole. Polygons earcut cannot cover exactly
(self-intersecting outlines) fall back to a fan, with a logged warning.
"""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)

_AREA_RTOL = 1e-7  # earcut's triangles must cover the outline's signed area to this


def newell_normal(points: np.ndarray) -> np.ndarray:
    """(..., 3) float64 Newell normals of polygons ``points`` (..., n, 3): length twice the area."""
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=-2)
    d, s = p - q, p + q
    return np.stack(
        [
            np.sum(d[..., 1] * s[..., 2], axis=-1),
            np.sum(d[..., 2] * s[..., 0], axis=-1),
            np.sum(d[..., 0] * s[..., 1], axis=-1),
        ],
        axis=-1,
    )


def fan(n: int) -> np.ndarray:
    """(n - 2, 3) int64 fan triangles ``(0, i, i + 1)`` of an n-gon."""
    i = np.arange(1, n - 1)
    return np.stack([np.zeros_like(i), i, i + 1], axis=1)


def _signed_areas(xy: np.ndarray, tris: np.ndarray) -> np.ndarray:
    a, b, c = xy[tris[:, 0]], xy[tris[:, 1]], xy[tris[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def polygon_triangles(points: np.ndarray, what: str = "polygon") -> np.ndarray:
    """Triangles (k, 3) int64 of local corner indices covering the polygon ``points`` (n, 3).

    Each triangle is wound like the polygon (its normal along the Newell normal).
    A polygon of zero area comes back as a fan (its triangles are dropped as
    degenerate later); one earcut cannot cover exactly is a fan too, with a
    warning naming ``what``.
    """
    import mapbox_earcut

    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    normal = newell_normal(p)
    axis = int(np.argmax(np.abs(normal)))
    if n < 3 or not normal[axis] != 0.0:  # zero area, or NaN coordinates
        return fan(n)
    # the two other axes in cyclic order: the outline keeps its orientation when normal[axis] > 0
    xy = p[:, [(axis + 1) % 3, (axis + 2) % 3]]
    sign = np.sign(normal[axis])
    tris = (
        mapbox_earcut.triangulate_float64(xy, np.array([n], dtype=np.uint32)).astype(np.int64).reshape(-1, 3)
    )
    area = sign * _signed_areas(xy, tris) if len(tris) else np.zeros(0)
    flip = area < 0
    tris[flip] = tris[flip][:, ::-1]
    outline = 0.5 * abs(normal[axis])
    if len(tris) == 0 or abs(np.abs(area).sum() - outline) > _AREA_RTOL * outline:
        log.warning("%s: %d-corner polygon is self-intersecting; triangulated as a fan", what, n)
        return fan(n)
    return tris
