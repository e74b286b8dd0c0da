"""Baked → GLB that opens in any glTF viewer.

What is written (``export_glb(baked, path, scene=None, layered=False, watertight=True,
match_clip=True, hdr=False)``, as ``iat bake``, the viewer and ``iat batch`` write it; how
clients use the files: docs/export.md):

- **Watertight** (``watertight=True``): every triangle edge of either part is split at the
  vertices of either part lying inside it (:func:`watertight_parts`,
  :mod:`iat.geometry.tjunctions`), so that no client shows see-through pixels along the
  T-junctions between patches of different depth; new vertices take the colour and uvs
  interpolated along the edge they split, so the picture is unchanged.

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
  atlas uv; material ``iat_page<k>_mat<m>`` (lit: metallic 0, roughness 1) has
  baseColorTexture = the detail texture (albedo, texCoord 0, repeat + mipmaps), the
  page's illumination as ``extensions.MOZ_lightmap = {index, texCoord: 1, intensity: pi}``
  (Mozilla Hubs' form; three.js multiplies a lightmap by intensity / pi) and as its
  ``occlusionTexture`` (texCoord 1: core glTF's use of the second set, so validators
  see TEXCOORD_1 used; IBL viewers darken their ambient light with it), and, in its
  ``extras``, ``{"iat_illumination": {"index": <that texture>, "texCoord": 1,
  "radiance_scale": s, "combine": "multiply"}}``: colour = albedo(TEXCOORD_0) x
  illumination(TEXCOORD_1) x radiance_scale. The lightmap is a PNG of its own when
  plain patches use the page too (Blender's importer would make the shared image
  Non-Color). Not unlit: the validator warns of ``KHR_materials_unlit`` beside another
  extension. three.js draws it with ``iat/export/clients/three/iat_lightmap.js``, Babylon.js
  with ``iat/export/clients/babylon/iat_lightmap.js``, Blender with
  ``iat/export/clients/blender/iat_import.py``. Patches without a detail texture
  are written as in the default. ``hdr=True``: the lightmap is an RGBM PNG (alpha = multiplier,
  up to ``RGBM_RANGE`` x white; ``iat_illumination.encoding = "rgbm"``, ``rgbm_range``).
- ``match_clip=True`` (``iat bake``): mesh-part triangles cut where a channel crosses white,
  page texels placed by least squares around values above white, and tiles holding incoming
  light stored x k (the brightest albedo channel; k comes back out of COLOR_0 or the lightmap
  intensity pi / k and ``iat_illumination.radiance_scale`` s / k): clients, which clip before
  interpolating, then show what our renderer shows.
- Root ``extras.iat``: radiance_scale, layered, watertight, policy, memory report.

The file is written atomically (``GlbBuilder.write``: temp file + fsync + os.replace).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from iat.color import srgb_encode
from iat.errors import BakeError, OptionError
from iat.export.texels import RGBM_RANGE, place_texels, rgbm_encode, scale_tiles, tile_boxes
from iat.io.glb import GlbBuilder

__all__ = [
    "BABYLON_PLUGIN",
    "BLENDER_SCRIPT",
    "LIGHTMAP_EXTENSION",
    "LIGHTMAP_INTENSITY",
    "THREE_PLUGIN",
    "export_glb",
    "radiance_scale",
    "watertight_parts",
]

#: the vendor extension the layered export writes its illumination through (docs/export.md)
LIGHTMAP_EXTENSION = "MOZ_lightmap"
#: its ``intensity``: three.js multiplies a lightmap by intensity / pi, so pi shows it as stored
LIGHTMAP_INTENSITY = float(np.pi)
#: the client code shipped in the package (docs/export.md): a three.js GLTFLoader plugin, a
#: Babylon.js glTF loader extension and a Blender import script for the layered export's lightmaps
THREE_PLUGIN = Path(__file__).resolve().parent / "clients" / "three" / "iat_lightmap.js"
BABYLON_PLUGIN = Path(__file__).resolve().parent / "clients" / "babylon" / "iat_lightmap.js"
BLENDER_SCRIPT = Path(__file__).resolve().parent / "clients" / "blender" / "iat_import.py"

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
        self._iat_lightmap: dict[int, tuple[int, int, float]] = {}

    def add_texture(self, png: bytes, name: str, clamp: bool = False) -> int:
        t = self._add_png_texture(png, name)
        if clamp:
            self._iat_clamped.add(t)
        return t

    def set_base_texture(self, material: int, texture: int, texcoord: int = 0) -> None:
        self._iat_base[material] = (texture, texcoord)

    def set_material_extras(self, material: int, extras: dict) -> None:
        self._iat_material_extras[material] = extras

    def set_lightmap(self, material: int, texture: int, texcoord: int, intensity: float) -> None:
        """``MOZ_lightmap`` on the material, and the same texture as its ``occlusionTexture`` (core
        glTF's one use of a second texture coordinate set on a lit material)."""
        self._iat_lightmap[material] = (texture, texcoord, float(intensity))

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
        for m, (t, c, k) in self._iat_lightmap.items():
            mat = doc["materials"][m]
            mat.setdefault("extensions", {})[LIGHTMAP_EXTENSION] = {"index": t, "texCoord": c, "intensity": k}
            mat["occlusionTexture"] = {"index": t, "texCoord": c}
        if self._iat_lightmap:
            doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {LIGHTMAP_EXTENSION})
        return doc


def _png(rgb_linear01: np.ndarray) -> bytes:
    """sRGB 8-bit PNG of linear values in [0, 1], (h, w, 3)."""
    x = srgb_encode(np.clip(np.asarray(rgb_linear01, dtype=np.float64), 0.0, 1.0))
    return _png_bytes(np.round(x * 255.0).astype(np.uint8))


def _png_bytes(pixels: np.ndarray) -> bytes:
    """PNG file of (h, w, 3 or 4) uint8 pixels."""
    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, format="PNG")
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
    tb = tile_boxes(baked)
    ps = tb["patch"]
    ok = np.ones(len(ps), bool)
    if drop is not None:
        ok = (ps < len(drop)) & ~drop[np.minimum(ps, len(drop) - 1)]
    x0, y0, side, area = tb["x0"][ok], tb["y0"][ok], tb["side"][ok], tb["area"][ok]
    lay_t, nv = tb["layer"][ok], tb["vertices"][ok]
    vals_out, area_out = [], []
    for m in np.unique(side).tolist():  # a few distinct tile sides: one gather each
        sel = side == m
        a = np.arange(m)
        lay = lay_t[sel][:, None, None]
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


@dataclass
class Parts:
    """The arrays export writes (names and shapes as in :class:`iat.bake.baked.Baked`)."""

    mesh_positions: np.ndarray
    mesh_radiance: np.ndarray
    mesh_indices: np.ndarray
    tex_positions: np.ndarray
    tex_uv: np.ndarray
    tex_layer: np.ndarray
    tex_detail_uv: np.ndarray
    tex_material: np.ndarray
    tex_indices: np.ndarray
    tex_detail: np.ndarray
    split_edges: int = 0


def watertight_parts(baked, watertight: bool = True, clip_scale: float | None = None) -> Parts:
    """The mesh part and the textured part of ``baked``, with (``watertight``) every triangle edge
    split at the vertices of either part lying inside it (:func:`iat.geometry.tjunctions.split_tjunctions`):
    colours and uvs of the new vertices are interpolated along the edge they split, so the image is
    the same, without the see-through pixels a client shows at T-junctions. ``split_edges`` counts the
    triangle edges that had a T-junction. With ``clip_scale`` the mesh part's triangles are first cut
    where a channel of ``radiance / clip_scale`` crosses 1 (:func:`iat.export.isoclip.slice_at_one`),
    so that a client's clipping at the vertices gives our renderer's clipping of the pixels."""
    from iat.geometry.tjunctions import split_tjunctions, tjunction_edges, weld_tolerance

    k = len(baked.tex_positions)
    det = np.asarray(baked.tex_detail, np.float32) if len(baked.tex_detail) else np.zeros(k, np.float32)
    parts = Parts(
        np.asarray(baked.mesh_positions, np.float32).reshape(-1, 3),
        np.asarray(baked.mesh_radiance, np.float32).reshape(-1, 3),
        np.asarray(baked.mesh_indices, np.int64).reshape(-1, 3),
        np.asarray(baked.tex_positions, np.float32).reshape(-1, 3),
        np.asarray(baked.tex_uv, np.float32).reshape(-1, 2),
        np.asarray(baked.tex_layer, np.float32),
        np.asarray(baked.tex_detail_uv, np.float32).reshape(-1, 2),
        np.asarray(baked.tex_material, np.int64),
        np.asarray(baked.tex_indices, np.int64).reshape(-1, 3),
        det,
    )
    if clip_scale is not None and len(parts.mesh_indices):
        from iat.export.isoclip import slice_at_one

        rel = parts.mesh_radiance / clip_scale
        pos, val, tri = slice_at_one(parts.mesh_positions, rel, parts.mesh_indices)
        parts.mesh_positions, parts.mesh_indices = pos.astype(np.float32), tri
        parts.mesh_radiance = (val * clip_scale).astype(np.float32)
    if not watertight:
        return parts
    points = np.concatenate([parts.mesh_positions, parts.tex_positions]).astype(np.float64)
    tol = weld_tolerance(points)
    edges = 0
    if len(parts.mesh_indices):
        edges += tjunction_edges(parts.mesh_positions, parts.mesh_indices, points, tol)
        m = split_tjunctions(parts.mesh_positions, parts.mesh_indices, points, tol)
        parts.mesh_positions = m.positions.astype(np.float32)
        parts.mesh_radiance = m.interpolate(parts.mesh_radiance)
        parts.mesh_indices = m.triangles
    if len(parts.tex_indices):
        edges += tjunction_edges(parts.tex_positions, parts.tex_indices, points, tol)
        t = split_tjunctions(parts.tex_positions, parts.tex_indices, points, tol)
        parts.tex_positions = t.positions.astype(np.float32)
        parts.tex_uv = t.interpolate(parts.tex_uv)
        parts.tex_detail_uv = (
            t.interpolate(parts.tex_detail_uv) if len(parts.tex_detail_uv) else parts.tex_detail_uv
        )
        parts.tex_layer = t.pick(parts.tex_layer)
        parts.tex_material = t.pick(parts.tex_material)
        parts.tex_detail = t.pick(parts.tex_detail)
        parts.tex_indices = t.triangles
    parts.split_edges = edges
    return parts


def _sub_mesh(positions, tri, *attrs):
    """Compact the vertices used by ``tri`` (t, 3): returns (positions, indices, *attrs)."""
    used, inv = np.unique(tri.reshape(-1), return_inverse=True)
    return (positions[used], inv.reshape(-1, 3).astype(np.uint32)) + tuple(a[used] for a in attrs)


def export_glb(
    baked,
    path,
    scene=None,
    layered: bool = False,
    watertight: bool = True,
    match_clip: bool = True,
    hdr: bool = False,
) -> Path:
    """Write ``baked`` as a GLB at ``path`` (atomically); returns the path. See the module docstring.

    scene : the Scene (albedo of detail materials, names); optional
    layered : write detail (albedo) on TEXCOORD_0 and illumination on TEXCOORD_1 (see above)
    watertight : split triangle edges at T-junctions (:func:`watertight_parts`); False keeps the
        baked triangles as they are
    match_clip : clients clip vertex colours and texels to 1 before interpolating, our renderer after:
        cut mesh-part triangles where a colour channel crosses 1 (:mod:`iat.export.isoclip`) and place
        the 8-bit texels around values above 1 by least squares (:mod:`iat.export.texels`), so that
        clients show what our renderer shows; False writes colours and texels clipped as they are
    hdr : with ``layered``, the lightmaps as RGBM PNGs (alpha = multiplier, up to
        :data:`iat.export.texels.RGBM_RANGE` x white), decoded by the shipped three.js plugin and
        Blender script; ``extras.iat_illumination.encoding = "rgbm"``
    """
    if hdr and not layered:
        raise OptionError("HDR lightmaps go with the layered export (layered=True, iat bake --layered --hdr)")
    path = Path(path)
    s = radiance_scale(baked, scene)
    parts = watertight_parts(baked, watertight, s if match_clip else None)
    g = _IatGlb()
    common = {"radiance_scale": s}
    g.extras = {
        "iat": {
            "radiance_scale": s,
            "encoding": "colour (linear, after sRGB decode) x radiance_scale = radiance",
            "layered": bool(layered),
            "watertight": bool(watertight),
            "match_clip": bool(match_clip),
            "hdr": bool(hdr),
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
    if len(parts.mesh_indices):
        mat = g.add_material("iat_mesh", unlit=True)
        g.set_material_extras(mat, common)
        col = np.clip(np.asarray(parts.mesh_radiance, np.float64) / s, 0.0, 1.0).astype(np.float32)
        mesh = g.add_mesh("iat_mesh", parts.mesh_positions, parts.mesh_indices, material=mat, colors=col)
        g.add_node("iat_mesh", mesh=mesh)
        wrote = True

    if len(parts.tex_indices):
        tri = parts.tex_indices
        layer = np.asarray(parts.tex_layer, dtype=np.int64)
        tri_page = layer[tri[:, 0]]
        det = parts.tex_detail > 0
        tri_det = det[tri[:, 0]]
        tri_mat = parts.tex_material[tri[:, 0]]
        page_tex, page_png, page_hdr = {}, {}, {}
        boxes = tile_boxes(baked) if match_clip and len(baked.tex_patch) else None
        headroom = _detail_headroom(baked, scene, layered) if boxes is not None else {}
        for p in np.unique(tri_page).tolist():
            texels = baked.pages[p] / s
            if boxes is not None:
                on = boxes["layer"] == p
                texels = _with_headroom(texels, baked, {k: v[on] for k, v in boxes.items()}, headroom)
            page_hdr[p] = texels
            if boxes is not None:
                texels, _ = place_texels(
                    texels,
                    {k: v[on] for k, v in boxes.items()},
                    baked.policy.gutter,
                    1 << (baked.mip_levels - 1),
                )
            page_png[p] = _png(texels)

        def page_texture(p: int) -> int:
            """The 8-bit page's texture, added when a material first uses it."""
            if p not in page_tex:
                page_tex[p] = g.add_texture(page_png[p], f"iat_page{p}", clamp=True)
            return page_tex[p]

        detail_tex = {}
        for p in np.unique(tri_page).tolist():
            # plain textured patches (radiance)
            sel = (tri_page == p) & ~tri_det
            light_tex = None
            if sel.any():
                pos, idx, uv = _sub_mesh(parts.tex_positions, tri[sel], parts.tex_uv)
                mat = g.add_material(f"iat_page{p}", unlit=True)
                g.set_base_texture(mat, page_texture(p), 0)
                g.set_material_extras(mat, common)
                g.add_node(f"iat_page{p}", mesh=g.add_mesh(f"iat_page{p}", pos, idx, material=mat, uv0=uv))
                if layered and not hdr and ((tri_page == p) & tri_det).any():
                    # the lightmap as an image of its own: Blender's importer gives an image one colour
                    # space, and makes an occlusion texture's Non-Color (the base colour's would go too)
                    light_tex = g.add_texture(page_png[p], f"iat_page{p}_lightmap", clamp=True)
            if not (tri_page == p).any() or not ((tri_page == p) & tri_det).any():
                continue
            if layered and hdr:
                rgbm = _png_bytes(rgbm_encode(page_hdr[p]))
                light_tex = g.add_texture(rgbm, f"iat_page{p}_lightmap_rgbm", clamp=True)
            elif light_tex is None:
                light_tex = page_texture(p)
            if not layered:
                sel = (tri_page == p) & tri_det
                albedo = _albedo_per_vertex(baked, parts.tex_material, scene)
                for m, k in headroom.items():  # the page holds incoming light x k (see _detail_headroom)
                    albedo[parts.tex_material == m] /= k
                pos, idx, uv, col = _sub_mesh(parts.tex_positions, tri[sel], parts.tex_uv, albedo)
                mat = g.add_material(f"iat_page{p}_detail", unlit=True)
                g.set_base_texture(mat, page_texture(p), 0)
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
                    parts.tex_positions, tri[sel], parts.tex_detail_uv, parts.tex_uv
                )
                name = f"iat_page{p}_mat{m}"
                mat = g.add_material(name)  # lit: KHR_materials_unlit beside MOZ_lightmap is a warning
                g.set_base_texture(mat, detail_tex[m], 0)
                k = headroom.get(m, 1.0)
                g.set_lightmap(mat, light_tex, 1, LIGHTMAP_INTENSITY / k)
                g.set_material_extras(
                    mat,
                    dict(
                        common,
                        iat_illumination={
                            "index": light_tex,
                            "texCoord": 1,
                            "radiance_scale": s / k,
                            "contains": "incoming light (radiance / albedo)",
                            "combine": "multiply",
                            **({"encoding": "rgbm", "rgbm_range": RGBM_RANGE} if hdr else {}),
                        },
                    ),
                )
                g.add_node(name, mesh=g.add_mesh(name, pos, idx, material=mat, uv0=uv0, uv1=uv1))
        wrote = True
    if not wrote:
        raise BakeError("nothing to export: the baked model has no triangles", path)
    return g.write(path)


def _detail_headroom(baked, scene, layered: bool) -> dict[int, float]:
    """{material: k} for the materials whose textured patches store incoming light: their tiles are
    written as incoming light x k / radiance_scale, and k comes back out of COLOR_0 (albedo / k) or
    the lightmap's intensity (pi / k). k = the brightest albedo channel (of the detail texture in
    the layered export): incoming light then clips in the file where radiance does, not before."""
    out = {}
    det = np.asarray(baked.tex_detail, np.float32) > 0 if len(baked.tex_detail) else None
    if det is None or not det.any():
        return out
    mats = np.asarray(baked.tex_material, np.int64)
    for m in np.unique(mats[det]).tolist():
        d = baked.detail_textures.get(m)
        if layered and d is not None:
            a = float(np.asarray(d).max())
        else:
            a = float(_albedo_per_vertex(baked, np.array([m]), scene).max())
        out[m] = float(np.clip(a, 1e-3, 1.0))
    return out


def _with_headroom(texels: np.ndarray, baked, boxes: dict, headroom: dict) -> np.ndarray:
    """The page's detail tiles multiplied by their material's headroom ``k``."""
    if not headroom or not len(boxes["first"]):
        return texels
    mat = np.asarray(baked.tex_material, np.int64)[boxes["first"]]
    det = np.asarray(baked.tex_detail, np.float32)[boxes["first"]] > 0
    k = np.array([headroom.get(m, 1.0) for m in mat.tolist()])
    k = np.where(det, k, 1.0)
    if (k == 1.0).all():
        return texels
    return scale_tiles(texels, boxes, k, baked.policy.gutter, 1 << (baked.mip_levels - 1))


def _albedo_per_vertex(baked, tex_material: np.ndarray, scene) -> np.ndarray:
    """(K, 3) float32 albedo of each textured vertex's material (for COLOR_0 on detail patches)."""
    mats = np.asarray(tex_material, dtype=np.int64)
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
