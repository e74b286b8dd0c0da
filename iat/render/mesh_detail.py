"""Detail textures in mesh mode: the solution's vertices on detail materials, as IAT mode draws them.

IAT mode's texels on a patch whose material has a detail texture hold the incoming light
``radiance / albedo``, and the shader multiplies by the detail texture (:mod:`iat.bake.baker`).
Mesh mode does the same per vertex: :func:`mesh_detail` gives, for each vertex of the drawn mesh
(:func:`iat.radiosity.solution.drawn_mesh`), the detail texture's uv (the patch's corner uvs
interpolated as the lattice places the vertex: the same drawn mesh with the uvs as corners), whether
it is on such a patch (:meth:`iat.io.scene.Scene.detail_patches`, the Baker's rule) and the divisor
that turns its radiance into incoming light; ``mesh.glsl`` multiplies.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from iat.radiosity.solution import drawn_mesh

#: what :func:`~iat.radiosity.solution.drawn_mesh` reads of a solution besides its corners
_DRAWN_FIELDS = (
    "max_depth",
    "patch_is_quad",
    "vert_key",
    "tri_vertices",
    "clip_uv",
    "clip_patch",
    "patch_transmission",
)


def mesh_detail(solution, drawn, scene):
    """``(detail_uv (N, 2) float32, detail (N,) float32 0/1, divisor (N, 3) float32, tri_key (T,))``
    for the N vertices and T triangles of ``drawn`` (the solution's drawn mesh); ``tri_key`` is the
    material of a detail triangle, else -1. None when ``scene`` (the Scene shown) is None, belongs to
    another model (patch counts differ) or has no detail patch
    (:meth:`~iat.io.scene.Scene.detail_patches`, the Baker's rule)."""
    corners = np.asarray(solution.patch_corners).reshape(-1, 4, 3)
    if scene is None or scene.patch_uv is None or scene.n_patches != len(corners):
        return None
    if getattr(solution, "patch_albedo", None) is None or getattr(solution, "patch_material", None) is None:
        return None
    albedo = np.asarray(solution.patch_albedo, dtype=np.float64).reshape(-1, 3)
    on = scene.detail_patches(albedo)
    if not on.any():
        return None
    patch_uv = np.asarray(scene.patch_uv, dtype=np.float64).reshape(-1, 4, 2)
    uv3 = np.concatenate([patch_uv, np.zeros((len(corners), 4, 1))], axis=2)
    fields = [k for k in _DRAWN_FIELDS if hasattr(solution, k)]
    as_uv = SimpleNamespace(patch_corners=uv3, **{k: getattr(solution, k) for k in fields})
    duv = drawn_mesh(as_uv).position[:, :2].astype(np.float32)
    patch = np.asarray(drawn.patch, dtype=np.int64)
    flag = on[patch]
    divisor = np.where(flag[:, None], 1.0 / np.maximum(albedo[patch], 1e-4), 1.0).astype(np.float32)
    mat = np.asarray(solution.patch_material, dtype=np.int64).reshape(-1)
    tris = np.asarray(drawn.triangles, dtype=np.int64).reshape(-1, 3)
    v0 = tris[:, 0]
    tri_key = np.where(flag[v0], mat[patch[v0]], -1) if len(tris) else np.zeros(0, np.int64)
    return duv, flag.astype(np.float32), divisor, tri_key
