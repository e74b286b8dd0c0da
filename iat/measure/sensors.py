"""Illuminance at points in space (work-plane sensors), gathered from a solution.

:func:`irradiance_at` is RADIANCE's ``rtrace -I`` on our solution: from each sensor it traces
``side x side`` stratified cosine-distributed rays (a Cranley-Patterson shift per sensor) against
the solution's mesh as drawn; a ray that meets a surface brings that surface's radiance
(linear over the drawn triangle, as mesh mode draws it, emission included), one that leaves
brings the sky's, each times the transmittance of the glass it crossed; ``pi x`` their mean is the
diffuse irradiance. Point and spot lights and suns are added exactly (shadow rays; a sun's disc as
one direction). The solution must have been solved under the scene's sky and lights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iat.radiosity.sampling import hash_uniform
from iat.radiosity.sky import cosine_directions, sky_radiance
from iat.radiosity.visibility import Visibility

#: default samples per side of a sensor's hemisphere (4096 rays: about 1 % noise where a sixth of
#: the hemisphere is open sky)
SENSOR_SIDE = 64
#: sensors per block of rays
BLOCK = 64


@dataclass
class SensorScene:
    """What a sensor sees: the drawn mesh (opaque triangles, radiance at their corners) and the
    scene's glass, in one :class:`~iat.radiosity.visibility.Visibility`.

    vis : opaque drawn triangles first, then the scene's glass triangles (transmissive)
    corners : (T, 3, 3) float64 the opaque triangles' corners; radiance : (T, 3, 3) their radiance
    normals : (T, 3) float64 the front of each opaque triangle (its patch's normal)
    """

    vis: Visibility
    corners: np.ndarray
    radiance: np.ndarray
    scene: object
    normals: np.ndarray

    @classmethod
    def build(cls, scene, solution, threads: int | None = None) -> SensorScene:
        drawn = solution.drawn_mesh()
        rad = drawn.radiance(solution.vert_radiance).astype(np.float64)
        tri = np.asarray(drawn.triangles, dtype=np.int64).reshape(-1, 3)
        corners = drawn.position[tri]
        tau = scene.patch_transmission
        glass_tris = scene.world_triangles()[tau[scene.world_triangle_patch()] > 0]
        gtau = tau[scene.world_triangle_patch()][tau[scene.world_triangle_patch()] > 0]
        vis = Visibility(
            np.concatenate([corners, glass_tris]) if len(glass_tris) else corners,
            np.concatenate([np.zeros(len(corners)), gtau]) if len(glass_tris) else None,
            threads=threads,
        )
        return cls(vis, corners, rad[tri], scene, scene.patch_normal[drawn.patch[tri[:, 0]]])

    def close(self) -> None:
        self.vis.close()


def inside_solids(sc: SensorScene, points) -> np.ndarray:
    """(n,) bool: the ``points`` (n, 3) that lie inside a solid (a cabinet, a wall): four or more of
    the six rays along the axes meet the back of a face first (faces are one-sided, facing out of
    solids and into rooms; four, as a cabinet standing on the floor against a wall may be left open
    on those two sides). A sensor there would read about 0."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    o = np.repeat(pts, 6, axis=0)
    d = np.tile(axes, (len(pts), 1))
    tri, _ = sc.vis.first_hits(o, d, np.full(len(o), 1e7))
    back = (tri >= 0) & (np.einsum("nc,nc->n", sc.normals[np.maximum(tri, 0)], d) > 0)
    return back.reshape(-1, 6).sum(axis=1) >= 4


def _direct(sc: SensorScene, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n, 3) irradiance from the scene's point and spot lights and suns, with shadow rays."""
    out = np.zeros((len(points), 3))
    for lt in sc.scene.lights:
        if lt.kind == "directional":
            to = -np.asarray(lt.direction, dtype=np.float64)
            to /= max(float(np.linalg.norm(to)), 1e-300)
            cos = normals @ to
            far = np.full(len(points), 1e7)
            vis = sc.vis.visible(points, np.broadcast_to(to, points.shape), far)
            out += (np.maximum(cos, 0.0) * vis)[:, None] * lt.radiant_intensity
            continue
        d = lt.position[None, :] - points
        r = np.linalg.norm(d, axis=1)
        u = d / np.maximum(r, 1e-300)[:, None]
        cos = np.einsum("nc,nc->n", u, normals)
        att = np.ones(len(r))
        if lt.kind == "spot":  # the solver's fall-off (iat.radiosity.direct.DirectLight.light_kernel)
            di = lt.direction / max(float(np.linalg.norm(lt.direction)), 1e-300)
            co, ci = math.cos(lt.outer_cone), math.cos(lt.inner_cone)
            att = np.clip((-(u @ di) - co) / max(1e-3, ci - co), 0.0, 1.0) ** 2
        if lt.ies is not None:
            att = att * lt.ies.relative(-u, lt.direction)
        ok = np.flatnonzero((cos > 0) & (att > 0) & (r > 1e-9))
        if len(ok):
            vis = sc.vis.visible(points[ok], u[ok], r[ok] * (1.0 - 1e-6))
            out[ok] += (cos[ok] * att[ok] / (r[ok] * r[ok]) * vis)[:, None] * lt.radiant_intensity
    return out


def _gather(
    sc: SensorScene, points: np.ndarray, normals: np.ndarray, side: int, seed: int, first: int
) -> np.ndarray:
    """(n, 3) irradiance from the surfaces and the sky seen from the sensors (``pi x`` mean)."""
    n, s = len(points), side * side
    g = (np.arange(side) + 0.5) / side
    pat = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    rot = hash_uniform(first + np.arange(n, dtype=np.int64), 1009 + int(seed), 2)
    u = (pat[None, :, 0] + rot[:, :1]) % 1.0
    v = (pat[None, :, 1] + rot[:, 1:]) % 1.0
    d = cosine_directions(normals, u, v).reshape(-1, 3)
    o = np.repeat(points, s, axis=0)
    far = np.full(len(o), 1e7)
    tri, bary = sc.vis.first_hits(o, d, far)
    L = np.zeros((len(o), 3))
    hit = tri >= 0
    if hit.any():
        t = tri[hit]
        b1, b2 = bary[hit, 0], bary[hit, 1]
        w = np.stack([1.0 - b1 - b2, b1, b2], axis=1)
        L[hit] = np.einsum("kj,kjc->kc", w, sc.radiance[t])
        at = np.einsum("kj,kjc->kc", w, sc.corners[t])
        dist = np.linalg.norm(at - o[hit], axis=1)
        L[hit] *= sc.vis.visible(o[hit], d[hit], dist * (1.0 - 1e-6))[:, None]  # glass before the surface
    miss = ~hit
    if miss.any() and sc.scene.sky is not None:
        L[miss] = sky_radiance(sc.scene.sky, d[miss]) * sc.vis.visible(o[miss], d[miss], far[miss])[:, None]
    return np.pi * L.reshape(n, s, 3).mean(axis=1)


def irradiance_at(
    scene, solution, points, normals=(0.0, 1.0, 0.0), side: int = SENSOR_SIDE, seed: int = 0, sensors=None
) -> np.ndarray:
    """(n, 3) float64 irradiance, W/m² per unit colour, on small planes at ``points`` (n, 3) facing
    ``normals`` ((n, 3) or one (3,); default up) in the lit ``solution`` of ``scene``.

    side : rays per side of each hemisphere (``side**2`` rays a sensor)
    sensors : a :class:`SensorScene` of this scene and solution to reuse (else built and closed here)
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.broadcast_to(np.asarray(normals, dtype=np.float64), pts.shape).copy()
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    sc = SensorScene.build(scene, solution) if sensors is None else sensors
    try:
        out = _direct(sc, pts, nrm)
        for a in range(0, len(pts), BLOCK):
            out[a : a + BLOCK] += _gather(sc, pts[a : a + BLOCK], nrm[a : a + BLOCK], int(side), seed, a)
        return out
    finally:
        if sensors is None:
            sc.close()
