"""Baked → GLB that opens in any glTF viewer.

What is written (``export_glb(baked, path, scene=None, layered=False)``):

- **Exposure.** glTF colours are at most 1 and base-colour textures are sRGB 8-bit,
  so every colour is ``radiance / radiance_scale`` (clamped to [0, 1]);
  ``radiance_scale`` is the 99.5th percentile of the non-zero stored values of
  the patches that do not emit (mesh vertices and page texels): walls use the
  8-bit range and **emitters clip to white** in the file (as in a tone-mapped
  render). Recorded as ``extras.iat.radiance_scale`` at the root and on every
  material: radiance = decoded colour x radiance_scale (below the clip).
- **Mesh part** (node ``iat_mesh``): POSITION, COLOR_0 = linear ``radiance /
  radiance_scale`` (float VEC3), material ``iat_mesh`` = white, KHR_materials_unlit.
- **Textured part**, ``layered=False`` (default): one PNG image per atlas page
  (sRGB 8-bit of ``page / radiance_scale``), sampled LINEAR without mipmaps and
  CLAMP_TO_EDGE (the atlas gutters only cover the levels the baker allows); one
  node ``iat_page<k>`` per page with POSITION, TEXCOORD_0 = atlas uv, an unlit
  material whose baseColorTexture is the page. Patches whose texels hold incoming
  light (``tex_detail == 1``) go to node ``iat_page<k>_detail`` with COLOR_0 = the
  material's albedo (scene albedo, else the detail texture's mean), so that
  base colour = texture x COLOR_0 = radiance (the detail pattern itself is not shown).
- **Textured part**, ``layered=True``: patches with a detail texture go to node
  ``iat_page<k>_mat<m>`` with TEXCOORD_0 = the scene's detail uv and TEXCOORD_1 =
  atlas uv; material ``iat_page<k>_mat<m>`` has baseColorTexture = the detail
  texture (albedo, texCoord 0, repeat + mipmaps) and, in its ``extras``,
  ``{"iat_illumination": {"index": <texture of page k>, "texCoord": 1,
  "radiance_scale": s, "combine": "multiply"}}``: colour = albedo(TEXCOORD_0) x
  illumination(TEXCOORD_1) x radiance_scale. A plain viewer shows the detail
  texture unlit. Patches without a detail texture are written as in the default.
- Root ``extras.iat``: radiance_scale, layered, policy, memory report.

The file is written atomically (``GlbBuilder.write``: temp file + fsync + os.replace).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image

from iat.color import srgb_encode
from iat.errors import BakeError
from iat.io.glb import GlbBuilder

__all__ = ["export_glb", "radiance_scale"]

_LINEAR = 9729
_CLAMP = 33071
_PERCENTILE = 99.5


class _IatGlb(GlbBuilder):
    """GlbBuilder plus shared textures (one image used by several materials) and a clamp sampler."""

    def __init__(self):
        super().__init__(generator="IAT iat.export")
        self._iat_base: dict[int, tuple[int, int]] = {}
        self._iat_clamped: set[int] = set()
        self._iat_material_extras: dict[int, dict] = {}

    def add_texture(self, png: bytes, name: str, clamp: bool = False) -> int:
        t = self._add_png_texture(png, name)
        if clamp:
            self._iat_clamped.add(t)
        return t

    def set_base_texture(self, material: int, texture: int, texcoord: int = 0) -> None:
        self._iat_base[material] = (texture, texcoord)

    def set_material_extras(self, material: int, extras: dict) -> None:
        self._iat_material_extras[material] = extras

    def to_json(self) -> dict:
        doc = super().to_json()
        if self._iat_clamped:
            samplers = doc.setdefault("samplers", [])
            clamp = {"magFilter": _LINEAR, "minFilter": _LINEAR, "wrapS": _CLAMP, "wrapT": _CLAMP}
            others = {t.get("sampler") for i, t in enumerate(doc["textures"]) if i not in self._iat_clamped}
            if samplers and 0 not in others:
                samplers[0] = clamp  # the builder's default sampler would be unused
                k = 0
            else:
                samplers.append(clamp)
                k = len(samplers) - 1
            for t in self._iat_clamped:
                doc["textures"][t]["sampler"] = k
        for m, (t, c) in self._iat_base.items():
            info = {"index": t}
            if c:
                info["texCoord"] = c
            doc["materials"][m]["pbrMetallicRoughness"]["baseColorTexture"] = info
        for m, ex in self._iat_material_extras.items():
            doc["materials"][m]["extras"] = ex
        return doc


def _png(rgb_linear01: np.ndarray) -> bytes:
    """sRGB 8-bit PNG of linear values in [0, 1], (h, w, 3)."""
    x = srgb_encode(np.clip(np.asarray(rgb_linear01, dtype=np.float64), 0.0, 1.0))
    img = Image.fromarray(np.round(x * 255.0).astype(np.uint8))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def _emissive_patches(baked, scene=None) -> np.ndarray | None:
    """(P,) bool of patches whose material emits, from the Baked (its Baker had the scene) or the
    scene; None when neither says."""
    e = getattr(baked, "patch_emissive", None)
    if e is not None and len(e):
        return np.asarray(e, dtype=bool)
    if scene is not None:
        return np.asarray(scene.patch_emission, dtype=np.float64).reshape(-1, 3).max(axis=1) > 0
    return None


def _tile_values(baked, drop: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Max-channel values of the textured patches' own texels and the world area each stands for:
    each tile once (no gutter or alignment padding, which repeat its edges), triangles' lower-left
    half only (the other half is extrapolated, never shown); patches with ``drop[patch]`` left out.
    Returns ``(values, areas)``, (k,) float each (areas in model units squared)."""
    tp = np.asarray(getattr(baked, "tex_patch", np.zeros(0)), dtype=np.int64)
    pages = np.asarray(baked.pages)
    if not pages.size:
        return np.zeros(0, np.float32), np.zeros(0)
    if not len(tp):  # no layout to read: every texel, equal weights
        v = pages.max(axis=-1).ravel()
        return v, np.ones(len(v))
    _, H, W, _ = pages.shape
    ps, first, nv = np.unique(tp, return_index=True, return_counts=True)
    if drop is not None:
        ok = (ps < len(drop)) & ~drop[np.minimum(ps, len(drop) - 1)]
        first, nv = first[ok], nv[ok]
    uv = np.asarray(baked.tex_uv, dtype=np.float64)
    pos = np.asarray(baked.tex_positions, dtype=np.float64)
    layer = np.asarray(baked.tex_layer, dtype=np.int64)
    # a patch's vertices are consecutive from `first`; slots 0, 1, 2 span the tile's first row and column
    span = np.stack([uv[first + k] for k in range(3)], axis=1)  # (k, 3, 2)
    x0 = np.rint(span[:, :, 0].min(axis=1) * W - 0.5).astype(np.int64)
    y0 = np.rint(span[:, :, 1].min(axis=1) * H - 0.5).astype(np.int64)
    side = np.rint(np.ptp(span[:, :, 0], axis=1) * W).astype(np.int64) + 1
    e = np.cross(pos[first + 1] - pos[first], pos[first + 2] - pos[first])
    area = np.linalg.norm(e, axis=1) * np.where(nv == 3, 0.5, 1.0)  # parallelogram / triangle
    vals_out, area_out = [], []
    for m in np.unique(side).tolist():  # a few distinct tile sides: one gather each
        sel = side == m
        a = np.arange(m)
        lay = layer[first[sel]][:, None, None]
        vals = pages[lay, y0[sel][:, None, None] + a[None, :, None], x0[sel][:, None, None] + a].max(axis=-1)
        tri = (nv[sel] == 3)[:, None, None]  # (k, m, m), row b, column a: triangles keep a + b <= m - 1
        inside = ~tri | ((a[:, None] + a[None, :]) <= m - 1)[None]
        per_texel = area[sel] / inside.sum(axis=(1, 2))
        vals_out.append(vals[inside])
        area_out.append(np.broadcast_to(per_texel[:, None, None], inside.shape)[inside])
    if not vals_out:
        return np.zeros(0, np.float32), np.zeros(0)
    return np.concatenate(vals_out), np.concatenate(area_out)


def _mesh_vertex_areas(baked) -> np.ndarray:
    """(M,) a third of the area of the mesh-part triangles around each vertex."""
    pos = np.asarray(baked.mesh_positions, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(baked.mesh_indices, dtype=np.int64).reshape(-1, 3)
    from iat.geometry.mesh import triangle_areas

    third = np.repeat(triangle_areas(pos, tri) / 3.0, 3)
    return np.bincount(tri.ravel(), third, minlength=len(pos)).astype(np.float64)


def _weighted_percentile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The value below which ``q`` percent of the total weight lies."""
    order = np.argsort(values, kind="stable")
    cw = np.cumsum(weights[order])
    k = int(np.searchsorted(cw, q / 100.0 * cw[-1]))
    return float(values[order][min(k, len(order) - 1)])


def radiance_scale(baked, scene=None) -> float:
    """The exposure scale export uses (1.0 if nothing is lit): the 99.5th percentile, by surface
    area, of the non-zero stored values of the patches that do not emit -- mesh-part vertices (a
    third of their triangles' area each) and each tile's own texels once (the tile's area over its
    texels; gutters and padding, copies of tile edges, left out) -- so that walls use the 8-bit
    range: neither a bright light nor the many texels of the deep trees around it decide it (a
    texel count would: adaptive meshing puts most texels where the light is brightest); emitters
    then clip to white in the file, as in a tone-mapped render. Emitters are known from
    ``baked.patch_emissive`` (baked with a scene) or ``scene``; without either, or when only
    emitters are stored, every stored value counts."""
    emissive = _emissive_patches(baked, scene)
    mesh = np.asarray(baked.mesh_radiance, dtype=np.float32).reshape(-1, 3).max(axis=1)
    mesh_area = _mesh_vertex_areas(baked)
    if len(mesh_area) != len(mesh):
        mesh_area = np.ones(len(mesh))
    keep_mesh = None
    if emissive is not None and emissive.any():
        mp = np.asarray(getattr(baked, "mesh_patch", np.zeros(0)), dtype=np.int64)
        if len(mp) == len(mesh) and (not len(mp) or mp.max() < len(emissive)):
            keep_mesh = ~emissive[mp]
    else:
        emissive = None

    def values(km, drop):
        tv, ta = _tile_values(baked, drop)
        v = np.concatenate([mesh if km is None else mesh[km], tv])
        w = np.concatenate([mesh_area if km is None else mesh_area[km], ta])
        ok = np.isfinite(v) & (v > 0) & (w > 0)
        return v[ok], w[ok]

    v, w = values(keep_mesh, emissive)
    if not len(v):
        v, w = values(None, None)
    if not len(v):
        return 1.0
    s = _weighted_percentile(v, w, _PERCENTILE)
    return s if s > 0 else 1.0


def _sub_mesh(positions, tri, *attrs):
    """Compact the vertices used by ``tri`` (t, 3): returns (positions, indices, *attrs)."""
    used, inv = np.unique(tri.reshape(-1), return_inverse=True)
    return (positions[used], inv.reshape(-1, 3).astype(np.uint32)) + tuple(a[used] for a in attrs)


def export_glb(baked, path, scene=None, layered: bool = False) -> Path:
    """Write ``baked`` as a GLB at ``path`` (atomically); returns the path. See the module docstring.

    scene : the Scene (albedo of detail materials, names); optional
    layered : write detail (albedo) on TEXCOORD_0 and illumination on TEXCOORD_1 (see above)
    """
    path = Path(path)
    s = radiance_scale(baked, scene)
    g = _IatGlb()
    common = {"radiance_scale": s}
    g.extras = {
        "iat": {
            "radiance_scale": s,
            "encoding": "colour (linear, after sRGB decode) x radiance_scale = radiance",
            "layered": bool(layered),
            "policy": baked.policy.to_dict(),
            "memory": baked.memory.to_dict(),
        }
    }
    if scene is not None:  # the model's viewpoints and walkthrough paths come along
        for cam in scene.cameras:
            g.add_camera_node(cam, name=cam.name or None)
        if scene.camera_paths:
            g.extras["iat_camera_paths"] = {
                k: [c.to_dict() for c in v] for k, v in scene.camera_paths.items()
            }
    wrote = False
    if len(baked.mesh_indices):
        mat = g.add_material("iat_mesh", unlit=True)
        g.set_material_extras(mat, common)
        col = np.clip(np.asarray(baked.mesh_radiance, np.float64) / s, 0.0, 1.0).astype(np.float32)
        mesh = g.add_mesh("iat_mesh", baked.mesh_positions, baked.mesh_indices, material=mat, colors=col)
        g.add_node("iat_mesh", mesh=mesh)
        wrote = True

    if len(baked.tex_indices):
        tri = np.asarray(baked.tex_indices, dtype=np.int64)
        layer = np.asarray(baked.tex_layer, dtype=np.int64)
        tri_page = layer[tri[:, 0]]
        det = (
            np.asarray(baked.tex_detail, dtype=np.float32) > 0
            if len(baked.tex_detail)
            else np.zeros(len(layer), bool)
        )
        tri_det = det[tri[:, 0]]
        tri_mat = np.asarray(baked.tex_material, dtype=np.int64)[tri[:, 0]]
        page_tex = {}
        for p in np.unique(tri_page).tolist():
            page_tex[p] = g.add_texture(_png(baked.pages[p] / s), f"iat_page{p}", clamp=True)
        detail_tex = {}
        for p in np.unique(tri_page).tolist():
            # plain textured patches (radiance)
            sel = (tri_page == p) & ~tri_det
            if sel.any():
                pos, idx, uv = _sub_mesh(baked.tex_positions, tri[sel], baked.tex_uv)
                mat = g.add_material(f"iat_page{p}", unlit=True)
                g.set_base_texture(mat, page_tex[p], 0)
                g.set_material_extras(mat, common)
                g.add_node(f"iat_page{p}", mesh=g.add_mesh(f"iat_page{p}", pos, idx, material=mat, uv0=uv))
            if not (tri_page == p).any() or not ((tri_page == p) & tri_det).any():
                continue
            if not layered:
                sel = (tri_page == p) & tri_det
                albedo = _albedo_per_vertex(baked, scene)
                pos, idx, uv, col = _sub_mesh(baked.tex_positions, tri[sel], baked.tex_uv, albedo)
                mat = g.add_material(f"iat_page{p}_detail", unlit=True)
                g.set_base_texture(mat, page_tex[p], 0)
                g.set_material_extras(mat, dict(common, contains="incoming light; COLOR_0 = albedo"))
                mesh = g.add_mesh(f"iat_page{p}_detail", pos, idx, material=mat, uv0=uv, colors=col)
                g.add_node(f"iat_page{p}_detail", mesh=mesh)
                continue
            for m in np.unique(tri_mat[(tri_page == p) & tri_det]).tolist():
                sel = (tri_page == p) & tri_det & (tri_mat == m)
                if m not in detail_tex:
                    d = baked.detail_textures.get(m)
                    if d is None:
                        raise BakeError(
                            f"layered export: no detail texture for material {m} in the baked model"
                        )
                    detail_tex[m] = g.add_texture(_png(d), f"iat_detail_mat{m}")
                pos, idx, uv0, uv1 = _sub_mesh(
                    baked.tex_positions, tri[sel], baked.tex_detail_uv, baked.tex_uv
                )
                name = f"iat_page{p}_mat{m}"
                mat = g.add_material(name, unlit=True)
                g.set_base_texture(mat, detail_tex[m], 0)
                g.set_material_extras(
                    mat,
                    dict(
                        common,
                        iat_illumination={
                            "index": page_tex[p],
                            "texCoord": 1,
                            "radiance_scale": s,
                            "contains": "incoming light (radiance / albedo)",
                            "combine": "multiply",
                        },
                    ),
                )
                g.add_node(name, mesh=g.add_mesh(name, pos, idx, material=mat, uv0=uv0, uv1=uv1))
        wrote = True
    if not wrote:
        raise BakeError("nothing to export: the baked model has no triangles", path)
    return g.write(path)


def _albedo_per_vertex(baked, scene) -> np.ndarray:
    """(K, 3) float32 albedo of each textured vertex's material (for COLOR_0 on detail patches)."""
    mats = np.asarray(baked.tex_material, dtype=np.int64)
    out = np.ones((len(mats), 3), dtype=np.float32)
    for m in np.unique(mats).tolist():
        if scene is not None and m < len(scene.materials):
            a = np.asarray(scene.materials[m].albedo, dtype=np.float64)
        elif m in baked.detail_textures:
            a = np.asarray(baked.detail_textures[m], dtype=np.float64).reshape(-1, 3).mean(axis=0)
        else:
            continue
        out[mats == m] = np.clip(a, 0.0, 1.0)
    return out
