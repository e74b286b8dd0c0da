"""The texture memory budget: the threshold and scale that fit it (:func:`choose_policy`,
:func:`resolve_budget`), and the per-depth cost model behind its order (:func:`cost_model`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from iat.bake import atlas
from iat.bake.flatten import SolutionIndex, scaled_side, tile_side
from iat.bake.formats import BYTES_PER_TEXEL
from iat.bake.memory import INDEX_BYTES, MESH_VERTEX_BYTES, MIB, TEX_VERTEX_BYTES, memory_report
from iat.bake.policy import BakePolicy
from iat.errors import BakeError, OptionError

#: cost model: one triangle's transform/setup cost, in byte-equivalents (Myszkowski-style weight)
TRIANGLE_COST_BYTES = 64
#: the budget search's ladder runs down to base scale x this in quarter octaves, then on to the
#: scale of 2-texel tiles (:func:`scale_ladder`)
MIN_SCALE_FACTOR = 0.25


def _texture_bytes(depth, t, scale, policy: BakePolicy) -> float:
    """Exact texture bytes of textured set ``depth >= t`` at ``scale`` (inf if a tile cannot fit)."""
    d = depth[depth >= t]
    if not len(d):
        return 0.0
    m = scaled_side(tile_side(d), scale)
    align = 1 << (policy.mip_levels - 1)
    try:
        pk = atlas.pack(np.stack([m, m], axis=1), policy.page_size, policy.gutter, align)
    except BakeError:
        return float("inf")
    return float(memory_report(pk, policy).texture_bytes)


def scale_ladder(base_scale: float, deepest: int) -> list[float]:
    """Scales the budget search tries for a textured set whose deepest tree is ``deepest``, largest
    first: ``base_scale * 2**(-q/4)`` for ``q = 0, 1, ...`` down to base / 4
    (:data:`MIN_SCALE_FACTOR`), then on down to the first scale at which every tile of the set is
    2 texels a side (the smallest a tile can be: :func:`~iat.bake.flatten.scaled_side`)."""
    out = [base_scale * 2.0 ** (-q / 4) for q in range(int(round(-4 * np.log2(MIN_SCALE_FACTOR))) + 1)]
    while scaled_side(tile_side(int(deepest)), out[-1]) > 2:
        out.append(out[-1] * 2.0 ** (-1 / 4))
    return out


def resolve_budget(depth: np.ndarray, budget_mb: float, base: BakePolicy) -> tuple[BakePolicy, dict]:
    """The search of :func:`choose_policy` on patch depths ``(P,)`` int: ``(policy, info)`` with
    ``info = dict(budget_mb=, too_small=)`` (for :func:`~iat.bake.memory.set_budget`)."""
    budget = float(budget_mb) * MIB
    deepest = int(depth.max()) if len(depth) else 0
    base = dataclasses.replace(base, budget_mb=None)
    all_mesh = dataclasses.replace(base, threshold=max(base.threshold, deepest + 1))
    info = {"budget_mb": float(budget_mb), "too_small": False}
    if budget <= 0:
        return all_mesh, info
    for t in range(int(base.threshold), deepest + 1):
        ladder = scale_ladder(base.scale, int(depth[depth >= t].max()))
        if _texture_bytes(depth, t, ladder[-1], base) > budget:
            continue  # even 2-texel tiles do not fit: texture fewer (deeper-only) patches
        if _texture_bytes(depth, t, ladder[0], base) <= budget:
            return dataclasses.replace(base, threshold=t), info
        lo, hi = 0, len(ladder) - 1  # ladder[lo] does not fit, ladder[hi] fits
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if _texture_bytes(depth, t, ladder[mid], base) <= budget:
                hi = mid
            else:
                lo = mid
        return dataclasses.replace(base, threshold=t, scale=float(ladder[hi])), info
    info["too_small"] = deepest >= base.threshold  # some texture was wanted and none fits
    return all_mesh, info


def choose_policy(solution, budget_mb: float | None, base_policy: BakePolicy | None = None) -> BakePolicy:
    """Threshold and scale that fit ``budget_mb`` MiB of texture memory, with the best image.

    Texturing order follows a Myszkowski-style cost model (:func:`cost_model`): a mesh costs
    its vertex bytes plus a per-triangle cost, a texture its texel bytes; the saving per texture
    byte grows with tree depth, so the deepest trees are textured first (that is the threshold).
    Search: threshold ``t`` from ``base.threshold`` upwards; at each ``t`` take the largest scale
    on the ladder ``base.scale * 2**(-q/4)``, ``q = 0, 1, ...`` (:func:`scale_ladder`: down to
    base.scale / 4, then on down to 2-texel tiles) whose exact packed texture bytes fit; only if
    even the 2-texel tiles do not fit, raise ``t`` (a smaller budget blurs the textures before it
    gives patches back to the mesh: half the budget does not multiply the triangles). Budget 0, or a
    budget smaller than any texture, gives all mesh (threshold above the deepest tree).
    The returned policy has ``budget_mb = None`` (resolved). ``budget_mb=None`` returns the base.
    """
    base = (base_policy or BakePolicy()).validate()
    if budget_mb is None:
        return base
    if not (np.isfinite(budget_mb) and budget_mb >= 0):
        raise OptionError(f"budget_mb must be >= 0, got {budget_mb!r}")
    return resolve_budget(solution.patch_depth().astype(np.int64), budget_mb, base)[0]


def cost_model(solution, policy: BakePolicy | None = None, index: SolutionIndex | None = None) -> dict:
    """Per-depth costs (Myszkowski-style), for the budget search and the viewer.

    Returns {depth: dict(patches, vertices, triangles, mesh_cost, texture_bytes, gain)} where
    ``mesh_cost = vertices x 24 + triangles x (12 + TRIANGLE_COST_BYTES)``, ``texture_bytes``
    is the boxes' texels x bytes/texel x mip factor at ``policy.scale`` (before atlas waste),
    plus the textured polygons' vertex/triangle costs, and ``gain = mesh_cost - texture cost``.
    """
    policy = (policy or BakePolicy()).validate()
    idx = index or SolutionIndex(solution)
    levels = policy.mip_levels
    align = 1 << (levels - 1)
    bpt = BYTES_PER_TEXEL[policy.pixel_format]
    out = {}
    for d in np.unique(idx.depth):
        sel = idx.depth == d
        k = int(sel.sum())
        v = int(idx.patch_n_vertices[sel].sum())
        t = int(idx.patch_n_triangles[sel].sum())
        m = scaled_side(tile_side(int(d)), policy.scale)
        box = int(atlas.align_up(m + 2 * policy.gutter, align))
        tex = k * atlas.mip_chain_texels(box, box, levels) * bpt
        nq = int(idx.is_quad[sel].sum())
        tex_cost = (
            tex
            + (4 * nq + 3 * (k - nq)) * TEX_VERTEX_BYTES
            + (2 * nq + (k - nq)) * (INDEX_BYTES + TRIANGLE_COST_BYTES)
        )
        mesh = v * MESH_VERTEX_BYTES + t * (INDEX_BYTES + TRIANGLE_COST_BYTES)
        out[int(d)] = dict(
            patches=k, vertices=v, triangles=t, mesh_cost=mesh, texture_bytes=tex, gain=mesh - tex_cost
        )
    return out
