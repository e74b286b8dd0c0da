"""Baked → GLB that opens in any glTF viewer.

What is written (``export_glb(baked, path, scene=None, layered=False)``):

- **Exposure.** glTF colours are at most 1 and base-colour textures are sRGB 8-bit,
  so every colour is ``radiance / radiance_scale`` (clamped to [0, 1]);
  ``radiance_scale`` is the 99.5th percentile of the non-zero stored values
  (mesh vertices and page texels), recorded as ``extras.iat.radiance_scale``
  at the root and on every material: radiance = decoded colour x radiance_scale.
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

from .errors import BakeError
from .glb import GlbBuilder

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
    x = np.clip(np.asarray(rgb_linear01, dtype=np.float64), 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)
    img = Image.fromarray(np.round(x * 255.0).astype(np.uint8))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def radiance_scale(baked) -> float:
    """The exposure scale export uses: 99.5th percentile of non-zero stored values (1.0 if none)."""
    parts = []
    if len(baked.mesh_radiance):
        parts.append(np.asarray(baked.mesh_radiance, dtype=np.float32).max(axis=1))
    if baked.pages.size:
        m = baked.pages.max(axis=-1).ravel()
        parts.append(m[m > 0])
    v = np.concatenate(parts) if parts else np.zeros(0)
    v = v[np.isfinite(v) & (v > 0)]
    if not len(v):
        return 1.0
    s = float(np.percentile(v, _PERCENTILE))
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
    s = radiance_scale(baked)
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
