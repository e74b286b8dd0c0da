"""Tests of iat.scene: loading model files into root patches, materials, lights and cameras.

Every model is written to ``tmp_path`` by the test itself (glTF with pygltflib,
the rest as text or with trimesh's exporters).
"""

from __future__ import annotations

import io
import json
import logging
import math
import struct
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from iat.errors import Cancelled, IATWarning, LoadError, OptionError
from iat.io.scene import (
    Light,
    Scene,
    load_scene,
    merge_quads,
    scene_digest,
    split_patches,
    srgb_to_linear,
    weld_vertices,
)

# ----------------------------------------------------------------------------
# a small glTF writer on pygltflib
# ----------------------------------------------------------------------------

FLOAT, UINT32 = 5126, 5125


class Gltf:
    """Build a glTF document by hand: meshes, materials, nodes, lights, cameras, images."""

    def __init__(self):
        self.doc = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
        self.blob = bytearray()
        self.roots: list[int] = []

    def _view(self, data: bytes) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data))
        )
        self.blob += data
        return len(self.doc.bufferViews) - 1

    def _accessor(self, arr, kind: str, ctype: int) -> int:
        arr = np.ascontiguousarray(arr, dtype=np.float32 if ctype == FLOAT else np.uint32)
        acc = pygltflib.Accessor(
            bufferView=self._view(arr.tobytes()), componentType=ctype, count=len(arr), type=kind
        )
        if kind == "VEC3" and np.isfinite(arr).all():
            acc.min = arr.min(axis=0).tolist()
            acc.max = arr.max(axis=0).tolist()
        self.doc.accessors.append(acc)
        return len(self.doc.accessors) - 1

    def mesh(self, positions, indices, material=None, uv=None, name=None) -> int:
        attrs = pygltflib.Attributes(
            POSITION=self._accessor(np.asarray(positions).reshape(-1, 3), "VEC3", FLOAT)
        )
        if uv is not None:
            attrs.TEXCOORD_0 = self._accessor(np.asarray(uv).reshape(-1, 2), "VEC2", FLOAT)
        prim = pygltflib.Primitive(
            attributes=attrs,
            indices=self._accessor(np.asarray(indices).ravel(), "SCALAR", UINT32),
            material=material,
        )
        self.doc.meshes.append(pygltflib.Mesh(primitives=[prim], name=name))
        return len(self.doc.meshes) - 1

    def material(
        self, base=(0.5, 0.5, 0.5, 1.0), emissive=None, strength=None, texture=None, name=None
    ) -> int:
        pbr = pygltflib.PbrMetallicRoughness(baseColorFactor=list(base))
        if texture is not None:
            pbr.baseColorTexture = pygltflib.TextureInfo(index=texture)
        m = pygltflib.Material(pbrMetallicRoughness=pbr, name=name)
        if emissive is not None:
            m.emissiveFactor = list(emissive)
        if strength is not None:
            m.extensions = {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}
            self._use("KHR_materials_emissive_strength")
        self.doc.materials.append(m)
        return len(self.doc.materials) - 1

    def texture_png(self, rgb_uint8, uri: str | None = None) -> int:
        """A PNG texture, embedded in the buffer (uri None) or referenced as an external file."""
        if uri is None:
            buf = io.BytesIO()
            Image.fromarray(np.asarray(rgb_uint8, dtype=np.uint8), "RGB").save(buf, format="PNG")
            img = pygltflib.Image(bufferView=self._view(buf.getvalue()), mimeType="image/png")
        else:
            img = pygltflib.Image(uri=uri)
        self.doc.images.append(img)
        self.doc.textures.append(pygltflib.Texture(source=len(self.doc.images) - 1))
        return len(self.doc.textures) - 1

    def node(self, root=True, **kw) -> int:
        self.doc.nodes.append(pygltflib.Node(**kw))
        i = len(self.doc.nodes) - 1
        if root:
            self.roots.append(i)
        return i

    def _use(self, ext):
        if ext not in self.doc.extensionsUsed:
            self.doc.extensionsUsed.append(ext)

    def light(self, light: dict) -> int:
        self._use("KHR_lights_punctual")
        ext = self.doc.extensions.setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append(light)
        return len(ext["lights"]) - 1

    def camera(self, yfov, znear, zfar=None) -> int:
        self.doc.cameras.append(
            pygltflib.Camera(
                type="perspective", perspective=pygltflib.Perspective(yfov=yfov, znear=znear, zfar=zfar)
            )
        )
        return len(self.doc.cameras) - 1

    def save(self, path):
        path = str(path)
        self.doc.scenes = [pygltflib.Scene(nodes=self.roots)]
        self.doc.scene = 0
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        self.doc.buffers = [pygltflib.Buffer(byteLength=len(blob))]
        if path.endswith(".glb"):
            self.doc.set_binary_blob(blob)
            self.doc.save_binary(path)
        else:
            bin_name = path.rsplit("/", 1)[-1].replace(".gltf", ".bin")
            with open(path.replace(".gltf", ".bin"), "wb") as f:
                f.write(blob)
            self.doc.buffers[0].uri = bin_name
            self.doc.save_json(path)
        return Path(path)


ROOT = Path(__file__).resolve().parents[1]
QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)  # faces +Z
QUAD_TRIS = [[0, 1, 2], [2, 3, 0]]  # trimesh's own split of a quad


def quad_gltf(path, **material):
    g = Gltf()
    mat = g.material(**material) if material else None
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat))
    return g.save(path)


def write(path, text):
    path.write_text(text)
    return path


def assert_load_error(path, *words, **kw):
    with pytest.raises(LoadError) as ei:
        load_scene(path, **kw)
    msg = str(ei.value)
    assert "\n" not in msg
    assert path.name in msg
    for w in words:
        assert w in msg, msg
    return ei.value


# ----------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------


def test_obj_unit_quad_is_one_quad_patch(tmp_path):
    p = write(tmp_path / "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    s = load_scene(p)
    assert isinstance(s, Scene)
    assert s.n_patches == 1 and s.patch_is_quad.all()
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)
    assert s.patch_area[0] == pytest.approx(1.0)
    # corners go around the polygon (consecutive corners share a side of length 1)
    c = s.corner_positions[0]
    np.testing.assert_allclose(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1), 1.0)
    assert s.path == str(p)
    assert len(s.materials) == 1 and np.allclose(s.materials[0].albedo, 0.5)


def test_gltf_quad_keeps_corner_order(tmp_path):
    s = load_scene(quad_gltf(tmp_path / "q.glb"))
    assert s.n_patches == 1 and s.patch_is_quad[0]
    np.testing.assert_allclose(s.corner_positions[0], QUAD)


def test_gltf_two_nodes_with_transforms_in_world_space(tmp_path):
    g = Gltf()
    m = g.mesh(QUAD, QUAD_TRIS)
    g.node(mesh=m, translation=[10.0, 0.0, 0.0])
    # child of a scaled parent, rotated 90 degrees about X: the +Z quad faces -Y... then +Y
    c, s_ = math.cos(math.pi / 4), math.sin(math.pi / 4)
    child = g.node(root=False, mesh=m, rotation=[-s_, 0.0, 0.0, c])  # -90 deg about X: +Z -> +Y
    g.node(children=[child], scale=[2.0, 2.0, 2.0], translation=[0.0, 5.0, 0.0])
    s = load_scene(g.save(tmp_path / "nodes.glb"))
    assert s.n_patches == 2 and s.patch_is_quad.all()
    areas = sorted(s.patch_area)
    assert areas == pytest.approx([1.0, 4.0])
    a = int(np.argmin(s.patch_area))
    b = 1 - a
    np.testing.assert_allclose(s.corner_positions[a], QUAD + [10, 0, 0], atol=1e-12)
    np.testing.assert_allclose(s.patch_normal[a], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(s.patch_normal[b], [0, 1, 0], atol=1e-12)
    lo, hi = s.corner_positions[b].min(axis=0), s.corner_positions[b].max(axis=0)
    np.testing.assert_allclose(lo, [0, 5, -2], atol=1e-12)
    np.testing.assert_allclose(hi, [2, 5, 0], atol=1e-12)


def test_mirroring_transform_flips_winding(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS), scale=[-1.0, 1.0, 1.0])
    s = load_scene(g.save(tmp_path / "mirror.glb"))
    # the surface still faces +Z: mirrored positions with the winding flipped back
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)
    assert s.bounds[0][0] == pytest.approx(-1.0)


@pytest.mark.parametrize("ext", ["ply", "stl", "off", "glb", "obj"])
def test_cube_12_triangles_become_6_quads(tmp_path, ext):
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    assert len(box.faces) == 12
    p = tmp_path / f"box.{ext}"
    box.export(p)
    s = load_scene(p)
    assert s.n_patches == 6 and s.patch_is_quad.all()
    assert s.patch_area == pytest.approx(np.full(6, 4.0))
    centres = s.corner_positions.mean(axis=1)
    # outward normals: each normal points from the origin to its face centre
    np.testing.assert_allclose(s.patch_normal, centres, atol=1e-12)
    assert len(s.vertices) == 8


def test_non_planar_pair_stays_two_triangles(tmp_path):
    p = write(tmp_path / "bent.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0.01\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    s = load_scene(p)
    assert s.n_patches == 2 and not s.patch_is_quad.any()
    assert (s.patch_corners[:, 3] == -1).all()


def test_non_convex_pair_stays_two_triangles(tmp_path):
    # a dart: coplanar but concave at vertex 3
    p = write(tmp_path / "dart.obj", "v 0 0 0\nv 2 0 0\nv 1 2 0\nv 1 0.5 0\nf 1 2 4\nf 2 3 4\n")
    s = load_scene(p)
    assert s.n_patches == 2 and not s.patch_is_quad.any()


def test_pair_with_different_materials_stays_two_triangles(tmp_path):
    write(tmp_path / "m.mtl", "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 3 4 1\n"
    s = load_scene(write(tmp_path / "two.obj", obj))
    assert s.n_patches == 2 and not s.patch_is_quad.any()
    assert sorted(tuple(m.albedo) for m in s.materials) == [(0, 1, 0), (1, 0, 0)]


def test_duplicated_vertices_are_welded_before_pairing(tmp_path):
    g = Gltf()
    pos = QUAD[np.array(QUAD_TRIS).ravel()]  # six vertices, one per corner of each triangle
    g.node(mesh=g.mesh(pos, np.arange(6)))
    s = load_scene(g.save(tmp_path / "soup.glb"))
    assert s.n_patches == 1 and s.patch_is_quad[0]
    assert len(s.vertices) == 4


def test_grid_of_quads_pairs_along_diagonals(tmp_path):
    # 3 x 3 grid of unit squares, each split along its diagonal, shuffled
    n = 3
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = (i * (n + 1) + j).ravel(), ((i + 1) * (n + 1) + j).ravel()
    faces = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([b + 1, a + 1, a], 1)])
    faces = faces[np.random.default_rng(3).permutation(len(faces))]
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    c, m, uv = merge_quads(verts, faces, np.zeros(len(faces), dtype=np.int64))
    assert len(c) == n * n and (c[:, 3] >= 0).all()
    s = Scene(verts, c, m, [])
    assert s.patch_area == pytest.approx(np.ones(n * n))  # unit squares, not parallelograms
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (n * n, 1)))


def test_degenerate_faces_dropped_when_others_remain(tmp_path, caplog):
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 1 2 5\nf 1 1 3\n"
    with caplog.at_level(logging.INFO, logger="iat.io.scene"):
        s = load_scene(write(tmp_path / "degen.obj", obj))
    assert s.n_patches == 1 and s.patch_area[0] == pytest.approx(1.0)
    assert "dropped 2 zero-area faces" in caplog.text


def test_weld_vertices_merges_close_positions():
    v = np.array([[0, 0, 0], [1, 0, 0], [1 + 1e-13, 0, 0], [0, 1, 0], [5, 5, 5]], dtype=float)
    f = np.array([[0, 1, 3], [0, 2, 3]])
    wv, wf = weld_vertices(v, f)
    assert len(wv) == 3  # the unused vertex goes too
    assert (wf[0] == wf[1]).all()


# ----------------------------------------------------------------------------
# materials
# ----------------------------------------------------------------------------


def test_base_color_factor_is_exact(tmp_path):
    s = load_scene(quad_gltf(tmp_path / "c.glb", base=(0.123456, 0.654321, 0.0101, 1.0)))
    assert len(s.materials) == 1
    np.testing.assert_allclose(s.materials[0].albedo, [0.123456, 0.654321, 0.0101], rtol=1e-12)
    assert s.materials[0].detail is None


def test_emissive_strength_multiplies_emissive_factor(tmp_path):
    s = load_scene(
        quad_gltf(tmp_path / "e.glb", base=(0.2, 0.2, 0.2, 1), emissive=(1.0, 0.5, 0.25), strength=8.0)
    )
    np.testing.assert_allclose(s.materials[0].emission, [8.0, 4.0, 2.0])
    np.testing.assert_allclose(s.patch_emission[0], [8.0, 4.0, 2.0])
    s = load_scene(quad_gltf(tmp_path / "e1.glb", emissive=(1.0, 0.5, 0.25)))
    np.testing.assert_allclose(s.materials[0].emission, [1.0, 0.5, 0.25])  # strength defaults to 1


def test_base_color_texture_mean_and_uvs(tmp_path):
    g = Gltf()
    tex = np.zeros((2, 2, 3), dtype=np.uint8)
    tex[0, 0] = [255, 255, 255]
    tex[1, 1] = [188, 188, 188]  # sRGB 188 ~ linear 0.5029
    mat = g.material(base=(0.5, 1.0, 1.0, 1.0), texture=g.texture_png(tex))
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=float)  # glTF: v = 0 is the image top
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat, uv=uv))
    s = load_scene(g.save(tmp_path / "tex.glb"))
    m = s.materials[0]
    lin188 = float(srgb_to_linear(np.float32(188 / 255)))
    mean = (1.0 + lin188) / 4
    np.testing.assert_allclose(m.albedo, [0.5 * mean, mean, mean], rtol=1e-5)
    assert m.detail is not None and m.detail.shape == (2, 2, 3) and m.detail.dtype == np.float32
    np.testing.assert_allclose(m.detail.reshape(-1, 3).mean(axis=0), m.albedo, rtol=1e-5)
    np.testing.assert_allclose(m.detail[0, 0], [0.5, 1.0, 1.0], rtol=1e-6)  # top-left texel stays top-left
    np.testing.assert_allclose(s.patch_uv[0], uv, atol=1e-7)


def test_external_texture_in_gltf(tmp_path):
    Image.fromarray(np.full((4, 4, 3), 255, dtype=np.uint8)).save(tmp_path / "white.png")
    g = Gltf()
    mat = g.material(base=(0.25, 0.5, 0.75, 1.0), texture=g.texture_png(None, uri="white.png"))
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat, uv=QUAD[:, :2]))
    s = load_scene(g.save(tmp_path / "ext.gltf"))
    np.testing.assert_allclose(s.materials[0].albedo, [0.25, 0.5, 0.75], rtol=1e-6)
    assert s.materials[0].detail.shape == (4, 4, 3)


def test_albedo_above_one_is_clamped_with_a_warning(tmp_path):
    """G6: an albedo outside [0, 1] in a file is clamped, and a warning names the file and materials."""
    write(tmp_path / "bright.mtl", "newmtl bright\nKd 1.5 0.5 0.25\nnewmtl fine\nKd 0.5 0.5 0.5\n")
    obj = write(
        tmp_path / "bright.obj",
        "mtllib bright.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "usemtl bright\nf 1 2 3\nusemtl fine\nf 1 3 4\n",
    )
    with pytest.warns(IATWarning) as rec:
        s = load_scene(obj)
    assert [str(w.message) for w in rec] == [
        f"{obj}: albedo outside [0, 1] clamped in 1 material: 'bright' (1.5, 0.5, 0.25)"
    ]
    assert rec[0].filename == __file__  # reported at the caller of load_scene
    by_name = {m.name: m for m in s.materials}
    np.testing.assert_array_equal(by_name["bright"].albedo, [1.0, 0.5, 0.25])
    np.testing.assert_array_equal(by_name["fine"].albedo, [0.5, 0.5, 0.5])

    # glTF: baseColorFactor above 1, with a texture: the detail texture keeps mean == albedo
    g = Gltf()
    white = g.texture_png(np.full((2, 2, 3), 255, dtype=np.uint8))
    a = g.material(base=(2.0, 0.5, 3.0, 1.0), texture=white, name="hot")
    b = g.material(base=(1.25, 1.0, 1.0, 1.0), name="warm")
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=a, uv=QUAD[:, :2]))
    g.node(mesh=g.mesh(QUAD + [0, 0, 1], QUAD_TRIS, material=b))
    path = g.save(tmp_path / "hot.glb")
    with pytest.warns(IATWarning) as rec:
        s = load_scene(path)
    assert [str(w.message) for w in rec] == [
        f"{path}: albedo outside [0, 1] clamped in 2 materials: 'hot' (2, 0.5, 3), 'warm' (1.25, 1, 1)"
    ]
    hot = {m.name: m for m in s.materials}["hot"]
    np.testing.assert_allclose(hot.albedo, [1.0, 0.5, 1.0])
    np.testing.assert_allclose(hot.detail.reshape(-1, 3).mean(axis=0), hot.albedo, rtol=1e-6)


def test_albedo_in_range_gives_no_warning(tmp_path):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", IATWarning)
        s = load_scene(quad_gltf(tmp_path / "one.glb", base=(1.0, 0.0, 1.0, 1.0)))
    np.testing.assert_array_equal(s.materials[0].albedo, [1.0, 0.0, 1.0])


def test_load_progress_is_monotone_and_ends_at_one(tmp_path):
    """G2: progress(fraction, message) at every stage, non-decreasing from 0 to 1; None continues."""
    calls = []
    path = ROOT / "sample_models" / "cornell_box.glb"
    s = load_scene(path, progress=lambda f, m: calls.append((f, m)))
    f = [c[0] for c in calls]
    assert f[0] == 0.0 and f[-1] == 1.0 and all(b >= a for a, b in zip(f, f[1:], strict=False))
    assert [m for _, m in calls] == [
        "reading cornell_box.glb",
        "placing geometry",
        "welding vertices",
        "merging quads",
        "reading lights and cameras",
        "loaded",
    ]
    calls.clear()
    split = load_scene(path, max_edge=0.5, progress=lambda f, m: calls.append((f, m)) or True)
    assert "splitting patches" in [m for _, m in calls] and calls[-1] == (1.0, "loaded")
    assert split.n_patches > s.n_patches


@pytest.mark.parametrize("stop_at", ["reading cornell_box.glb", "welding vertices", "loaded"])
def test_load_progress_returning_false_cancels(stop_at):
    path = ROOT / "sample_models" / "cornell_box.glb"
    seen = []

    def progress(f, m):
        seen.append(m)
        return m != stop_at

    with pytest.raises(Cancelled) as e:
        load_scene(path, progress=progress)
    assert str(e.value) == f"{path}: load cancelled"
    assert seen[-1] == stop_at


def test_obj_materials_kd_ke(tmp_path):
    write(tmp_path / "m.mtl", "newmtl lamp\nKd 0.25 0.5 0.75\nKe 3 2 1\nnewmtl wall\nKd 0.7 0.7 0.7\n")
    obj = (
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
        "usemtl lamp\nf 1 2 3 4\nusemtl wall\nf 8 7 6 5\n"
    )
    s = load_scene(write(tmp_path / "mm.obj", obj))
    assert s.n_patches == 2 and s.patch_is_quad.all()
    by_name = {m.name: m for m in s.materials}
    np.testing.assert_allclose(by_name["lamp"].albedo, [0.25, 0.5, 0.75])
    np.testing.assert_allclose(by_name["lamp"].emission, [3, 2, 1])
    np.testing.assert_allclose(by_name["wall"].emission, 0)
    lamp = [i for i, m in enumerate(s.materials) if m.name == "lamp"][0]
    z0 = s.corner_positions[:, :, 2].max(axis=1) == 0
    assert (s.patch_material[z0] == lamp).all()
    np.testing.assert_allclose(s.patch_normal[~z0][0], [0, 0, -1])


# ----------------------------------------------------------------------------
# lights, cameras, camera paths
# ----------------------------------------------------------------------------


def test_point_and_spot_lights(tmp_path, caplog):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS))
    pl = g.light({"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 40.0, "name": "bulb"})
    sl = g.light({"type": "spot", "intensity": 10.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}})
    dl = g.light({"type": "directional", "intensity": 3.0, "name": "sun"})
    g.node(translation=[1.0, 2.0, 3.0], extensions={"KHR_lights_punctual": {"light": pl}})
    # rotated -90 degrees about X: local -Z points along world -Y
    c, s_ = math.cos(math.pi / 4), math.sin(math.pi / 4)
    spot = g.node(
        root=False,
        rotation=[-s_, 0.0, 0.0, c],
        extensions={"KHR_lights_punctual": {"light": sl}},
        name="spotnode",
    )
    g.node(translation=[0.0, 4.0, 0.0], children=[spot])
    g.node(extensions={"KHR_lights_punctual": {"light": dl}})
    with caplog.at_level(logging.WARNING, logger="iat.io.scene"):
        s = load_scene(g.save(tmp_path / "lights.glb"))
    assert "directional light 'sun' skipped" in caplog.text
    assert [lt.kind for lt in s.lights] == ["point", "spot"]
    p, sp = s.lights
    np.testing.assert_allclose(p.position, [1, 2, 3])
    np.testing.assert_allclose(p.color, [1.0, 0.5, 0.25])
    assert p.intensity == 40.0 and p.name == "bulb"
    np.testing.assert_allclose(p.radiant_intensity, [40, 20, 10])
    np.testing.assert_allclose(sp.position, [0, 4, 0], atol=1e-12)
    np.testing.assert_allclose(sp.direction, [0, -1, 0], atol=1e-12)
    assert sp.inner_cone == pytest.approx(0.2) and sp.outer_cone == pytest.approx(0.5)
    assert sp.name == "spotnode"


def test_camera_from_node(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS))
    cam = g.camera(yfov=math.radians(50.0), znear=0.05, zfar=40.0)
    # yaw 90 degrees about +Y: local -Z looks along world -X
    c, s_ = math.cos(math.pi / 4), math.sin(math.pi / 4)
    g.node(camera=cam, translation=[3.0, 1.0, 0.5], rotation=[0.0, s_, 0.0, c], name="door")
    cam2 = g.camera(yfov=1.0, znear=0.1)  # no zfar: infinite projection in glTF
    g.node(camera=cam2, translation=[0.0, 0.0, 5.0])
    s = load_scene(g.save(tmp_path / "cam.glb"))
    assert len(s.cameras) == 2
    k = s.cameras[0]
    assert k.name == "door"
    assert k.yfov == pytest.approx(50.0)
    assert (k.znear, k.zfar) == pytest.approx((0.05, 40.0))
    np.testing.assert_allclose(k.eye, [3, 1, 0.5])
    np.testing.assert_allclose(k.forward, [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(k.up, [0, 1, 0], atol=1e-12)
    k2 = s.cameras[1]
    assert k2.yfov == pytest.approx(math.degrees(1.0))
    assert k2.zfar >= 100.0 and k2.zfar > np.linalg.norm(k2.eye - s.bounds.mean(axis=0))
    assert s.default_camera() is k


def test_camera_paths_from_root_extras(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS))
    poses = [
        {"eye": [0, 1, 5], "target": [0, 0, 0], "up": [0, 1, 0], "yfov": 55.0},
        {"eye": [1, 1, 5], "target": [0, 0, 0], "up": [0, 1, 0], "yfov": 60.0},
    ]
    g.doc.extras = {"iat_camera_paths": {"tour": poses}}
    s = load_scene(g.save(tmp_path / "paths.glb"))
    assert list(s.camera_paths) == ["tour"]
    tour = s.camera_paths["tour"]
    assert len(tour) == 2
    np.testing.assert_allclose(tour[1].eye, [1, 1, 5])
    assert tour[1].yfov == 60.0


# ----------------------------------------------------------------------------
# pre-split
# ----------------------------------------------------------------------------


def test_max_edge_splits_quads_into_grids(tmp_path):
    p = write(tmp_path / "floor.obj", "v 0 0 0\nv 4 0 0\nv 4 1.5 0\nv 0 1.5 0\nf 1 2 3 4\n")
    s = load_scene(p, max_edge=1.0)
    assert s.n_patches == 4 * 2 and s.patch_is_quad.all()
    assert s.patch_area.sum() == pytest.approx(6.0)
    np.testing.assert_allclose(s.patch_area, 0.75)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (8, 1)))
    assert len(s.vertices) == 5 * 3  # shared lattice points are welded


def test_max_edge_splits_triangles_regularly(tmp_path):
    p = write(tmp_path / "tri.obj", "v 0 0 0\nv 3 0 0\nv 0 3 0\nf 1 2 3\n")
    s = load_scene(p, max_edge=1.0)  # longest edge 3*sqrt(2): k = ceil(log2(4.24)) = 3
    assert s.n_patches == 4**3 and not s.patch_is_quad.any()
    assert s.patch_area.sum() == pytest.approx(4.5)
    np.testing.assert_allclose(s.patch_area, 4.5 / 64)
    np.testing.assert_allclose(s.patch_normal, np.tile([0, 0, 1.0], (64, 1)))
    assert len(s.vertices) == 9 * 10 // 2


def test_max_edge_mixed_scene_keeps_area_materials_and_uvs(tmp_path):
    box = trimesh.creation.box(extents=(3.0, 1.0, 2.0))
    box.export(tmp_path / "box.ply")
    s0 = load_scene(tmp_path / "box.ply")
    s = load_scene(tmp_path / "box.ply", max_edge=0.5)
    # faces 3x1 -> 6x2, 3x2 -> 6x4, 1x2 -> 2x4: two of each
    assert s.n_patches == 2 * (12 + 24 + 8)
    assert s.patch_area.sum() == pytest.approx(s0.patch_area.sum())
    assert s.corner_positions.max() <= 1.5 + 1e-12

    verts = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [3, 0, 0]], dtype=float)
    corners = np.array([[0, 1, 2, 3], [1, 4, 2, -1]])
    uv = np.array([[[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 0], [1, 0], [0, 1], [0, 1]]], dtype=float)
    v, c, m, u = split_patches(verts, corners, np.array([3, 7]), uv, max_edge=1.0)
    assert (m == 3).sum() == 4 and (m == 7).sum() == 16
    sc = Scene(v, c, m, [], patch_uv=u)
    # UVs follow the bilinear / barycentric parametrisation
    quads = sc.patch_is_quad
    np.testing.assert_allclose(u[quads][..., 0], sc.corner_positions[quads][..., 0] / 2)
    np.testing.assert_allclose(u[quads][..., 1], sc.corner_positions[quads][..., 1] / 2)
    np.testing.assert_allclose(u[~quads][..., 0], sc.corner_positions[~quads][..., 0] - 2)
    assert sc.patch_normal[:, 2] == pytest.approx(np.ones(len(c)))


def test_scene_digest_tracks_geometry_and_materials(tmp_path):
    d1 = scene_digest(load_scene(quad_gltf(tmp_path / "a.glb", base=(0.5, 0.5, 0.5, 1))))
    d2 = scene_digest(load_scene(quad_gltf(tmp_path / "b.glb", base=(0.5, 0.5, 0.5, 1))))
    d3 = scene_digest(load_scene(quad_gltf(tmp_path / "c.glb", base=(0.5, 0.5, 0.6, 1))))
    assert d1 == d2 != d3
    assert len(d1) == 40
    s = load_scene(tmp_path / "a.glb")
    s.lights.append(Light(kind="point", position=[0, 0, 1], intensity=5.0))
    d4 = scene_digest(s)
    s.lights[0].intensity = 6.0
    assert len({d1, d4, scene_digest(s)}) == 3


def test_max_edge_must_be_positive(tmp_path):
    p = quad_gltf(tmp_path / "q.glb")
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(OptionError):
            load_scene(p, max_edge=bad)


# ----------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------


def test_missing_file(tmp_path):
    assert_load_error(tmp_path / "nothere.glb", "file not found")


def test_empty_file(tmp_path):
    for ext in ("glb", "obj", "ply"):
        p = tmp_path / f"empty.{ext}"
        p.write_bytes(b"")
        assert_load_error(p, "empty file")


def test_unsupported_extension(tmp_path):
    p = write(tmp_path / "model.fbx", "Kaydara FBX Binary")
    err = assert_load_error(
        p, "unsupported file type '.fbx'", "supported: .glb, .gltf, .obj, .off, .ply, .stl"
    )
    assert err.path == str(p)


@pytest.mark.parametrize(
    "name, data",
    [
        ("garbage.glb", bytes(range(256)) * 3),
        ("header.glb", b"glTF\x02\x00\x00\x00garbage"),
        ("garbage.gltf", b'{"asset": {"version": "2.0"}, "meshes": ['),
        ("garbage.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty flo"),
        ("garbage.stl", b"\x00\x01\x02garbage that is not an stl file at all"),
    ],
)
def test_garbage_files(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    err = assert_load_error(p)
    assert "truncated or corrupt" in str(err) or "no triangles" in str(err)


def test_truncated_glb(tmp_path):
    full = quad_gltf(tmp_path / "full.glb")
    data = open(full, "rb").read()
    p = tmp_path / "cut.glb"
    p.write_bytes(data[: len(data) // 2])
    err = assert_load_error(p, "truncated or corrupt")
    assert err.__cause__ is not None  # the original exception is chained


def test_point_cloud_only(tmp_path):
    pts = np.random.default_rng(0).random((20, 3))
    p = tmp_path / "cloud.ply"
    trimesh.PointCloud(pts).export(p)
    assert_load_error(p, "no triangles (point cloud only)")


def test_header_only_ply(tmp_path):
    p = write(
        tmp_path / "hdr.ply",
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
        "property float y\nproperty float z\nelement face 0\n"
        "property list uchar int vertex_indices\nend_header\n",
    )
    assert_load_error(p, "no triangles")


def test_empty_obj(tmp_path):
    assert_load_error(write(tmp_path / "blank.obj", "# nothing here\n\n"), "no triangles")


def test_non_finite_vertices(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n"
    assert_load_error(write(tmp_path / "nan.obj", obj), "non-finite vertex coordinates")
    g = Gltf()
    pos = QUAD.copy()
    pos[2, 2] = np.inf
    g.node(mesh=g.mesh(pos, QUAD_TRIS))
    assert_load_error(g.save(tmp_path / "inf.glb"), "non-finite vertex coordinates")


def test_face_index_out_of_range(tmp_path):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, [[0, 1, 2], [2, 3, 7]]))
    assert_load_error(g.save(tmp_path / "range.glb"), "face index out of range")


def test_only_degenerate_faces(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n"
    assert_load_error(write(tmp_path / "flat.obj", obj), "only degenerate faces")


def test_missing_texture_gltf(tmp_path):
    g = Gltf()
    mat = g.material(texture=g.texture_png(None, uri="gone.png"))
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat, uv=QUAD[:, :2]))
    assert_load_error(g.save(tmp_path / "tex.gltf"), "missing texture file gone.png")


def test_missing_buffer_gltf(tmp_path):
    quad_gltf(tmp_path / "buf.gltf")
    (tmp_path / "buf.bin").unlink()
    assert_load_error(tmp_path / "buf.gltf", "missing buffer file buf.bin")


def test_missing_texture_obj(tmp_path):
    write(tmp_path / "t.mtl", "newmtl wood\nKd 1 1 1\nmap_Kd wood.png\n")
    obj = "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl wood\nf 1/1 2/2 3/3\n"
    assert_load_error(write(tmp_path / "t.obj", obj), "missing texture file wood.png")


def test_corrupt_texture(tmp_path):
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    g = Gltf()
    mat = g.material(texture=g.texture_png(None, uri="bad.png"))
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat, uv=QUAD[:, :2]))
    assert_load_error(g.save(tmp_path / "badtex.gltf"), "cannot decode texture bad.png")


def test_glb_json_chunk_garbage(tmp_path):
    js = b"{not json"
    js += b" " * (-len(js) % 4)
    data = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js)) + struct.pack("<I", len(js)) + b"JSON" + js
    p = tmp_path / "badjson.glb"
    p.write_bytes(data)
    assert_load_error(p, "cannot parse glTF", "truncated or corrupt")


def test_gltf_with_unknown_json_keys_still_loads(tmp_path):
    p = quad_gltf(tmp_path / "ok.gltf")
    doc = json.loads(open(p).read())
    doc["extras"] = {"note": "hello"}
    open(p, "w").write(json.dumps(doc))
    assert load_scene(p).n_patches == 1


def test_obj_face_index_out_of_range(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"
    assert_load_error(write(tmp_path / "idx.obj", obj), "face index out of range")


def test_binary_garbage_in_text_formats(tmp_path):
    p = tmp_path / "bin.obj"
    p.write_bytes(b"\x00\x01\x02\xff\xfe garbage")
    assert_load_error(p, "truncated or corrupt")
    box = trimesh.creation.box()
    box.export(tmp_path / "b.stl")
    data = (tmp_path / "b.stl").read_bytes()
    p = tmp_path / "cut.stl"
    p.write_bytes(data[:-40])
    assert_load_error(p, "truncated or corrupt")


def test_latin1_obj_loads(tmp_path):
    p = tmp_path / "latin.obj"
    p.write_bytes(b"# caf\xe9\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert load_scene(p).n_patches == 1


# ----------------------------------------------------------------------------
# glTF structure: primitives, names, camera nodes
# ----------------------------------------------------------------------------


def test_gltf_primitives_and_repeated_mesh_names_keep_their_materials(tmp_path, caplog):
    g = Gltf()
    red = g.material(base=(0.9, 0.01, 0.02, 1.0), name="red")
    green = g.material(base=(0.03, 0.8, 0.04, 1.0), name="green")
    blue = g.material(base=(0.05, 0.06, 0.7, 1.0), name="blue")
    m1 = g.mesh(QUAD, QUAD_TRIS, material=red, name="thing")
    # a second primitive on the same mesh, moved up by 1, green
    attrs = pygltflib.Attributes(POSITION=g._accessor((QUAD + [0, 0, 1]).astype(np.float32), "VEC3", FLOAT))
    idx = g._accessor(np.array(QUAD_TRIS).ravel(), "SCALAR", UINT32)
    g.doc.meshes[m1].primitives.append(pygltflib.Primitive(attributes=attrs, indices=idx, material=green))
    m2 = g.mesh(QUAD + [0, 0, 2], QUAD_TRIS, material=blue, name="thing")  # same mesh name
    m3 = g.mesh(QUAD + [0, 0, 3], QUAD_TRIS, name="thing")  # no material: the default one
    for m in (m1, m2, m3):
        g.node(mesh=m)
    with caplog.at_level(logging.WARNING, logger="iat.io.scene"):
        s = load_scene(g.save(tmp_path / "prims.glb"))
    assert caplog.text == ""
    assert s.n_patches == 4
    z = s.corner_positions[:, 0, 2]
    albedo = s.patch_albedo[np.argsort(z)]
    np.testing.assert_allclose(
        albedo, [[0.9, 0.01, 0.02], [0.03, 0.8, 0.04], [0.05, 0.06, 0.7], [0.5, 0.5, 0.5]]
    )


def test_camera_node_with_mesh_and_children(tmp_path):
    # trimesh's own graph drops a (first) camera node's mesh and cuts off its children
    g = Gltf()
    m = g.mesh(QUAD, QUAD_TRIS)
    cam = g.camera(1.0, 0.1, 100.0)
    child = g.node(root=False, mesh=m, translation=[0.0, 0.0, -1.0])
    g.node(camera=cam, translation=[0.0, 0.0, 5.0], children=[child])
    g.node(camera=cam, mesh=m, translation=[0.0, 3.0, 0.0])
    s = load_scene(g.save(tmp_path / "camchild.glb"))
    assert s.n_patches == 2 and len(s.cameras) == 2
    centres = sorted(map(tuple, s.corner_positions.mean(axis=1).round(9)))
    assert centres == [(0.5, 0.5, 4.0), (0.5, 3.5, 0.0)]


def test_trimesh_exported_glb_materials(tmp_path):
    from trimesh.visual.material import PBRMaterial

    a = trimesh.creation.box(extents=(1, 1, 1))
    a.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(baseColorFactor=[0.2, 0.4, 0.6, 1.0]))
    b = trimesh.creation.box(extents=(1, 1, 1))
    b.apply_translation([3, 0, 0])
    b.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(baseColorFactor=[0.8, 0.1, 0.1, 1.0]))
    p = tmp_path / "two.glb"
    trimesh.Scene([a, b]).export(p)
    s = load_scene(p)
    assert s.n_patches == 12 and s.patch_is_quad.all()
    left = s.corner_positions[:, :, 0].mean(axis=1) < 1.5
    # trimesh writes factors quantised to 8 bits; we read what the file holds
    np.testing.assert_allclose(s.patch_albedo[left], np.tile([0.2, 0.4, 0.6], (6, 1)), atol=1 / 255)
    np.testing.assert_allclose(s.patch_albedo[~left], np.tile([0.8, 0.1, 0.1], (6, 1)), atol=1 / 255)


def test_obj_texture_detail_and_uv_convention(tmp_path):
    tex = np.zeros((2, 2, 3), dtype=np.uint8)
    tex[0, 0] = 255  # top-left texel white
    Image.fromarray(tex).save(tmp_path / "tex.png")
    write(tmp_path / "t.mtl", "newmtl wood\nKd 0.5 0.5 0.5\nmap_Kd tex.png\n")
    obj = (
        "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl wood\nf 1/1 2/2 3/3 4/4\n"
    )
    s = load_scene(write(tmp_path / "t.obj", obj))
    m = s.materials[0]
    np.testing.assert_allclose(m.albedo, [0.125, 0.125, 0.125], rtol=1e-6)  # Kd x mean(texture)
    assert m.detail.shape == (2, 2, 3)
    np.testing.assert_allclose(m.detail[0, 0], 0.5, rtol=1e-6)
    # OBJ's vt (0, 1) is the image's top-left: (0, 0) in the glTF convention of patch_uv
    c = s.corner_positions[0]
    uv = s.patch_uv[0]
    np.testing.assert_allclose(uv[:, 0], c[:, 0], atol=1e-12)
    np.testing.assert_allclose(uv[:, 1], 1 - c[:, 1], atol=1e-12)


def test_double_sided_quad_gives_two_quads(tmp_path):
    # front and back of one wall share welded vertices: the diagonal is used by four triangles
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 3 4 1\nf 1 3 2\nf 3 1 4\n"
    s = load_scene(write(tmp_path / "wall.obj", obj))
    assert s.n_patches == 2 and s.patch_is_quad.all()
    np.testing.assert_allclose(sorted(s.patch_normal[:, 2]), [-1.0, 1.0])
    assert s.patch_area == pytest.approx([1.0, 1.0])


@settings(max_examples=25, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.integers(min_value=4, max_value=60))
def test_merge_quads_covers_each_triangle_once(seed, n_points):
    """Random planar triangulations (rotated into 3D): every triangle ends up in exactly one patch,
    the area is kept, quads are convex and face the triangles' way."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    pts2 = np.round(rng.random((n_points, 2)) * 8) / 8 + rng.random((n_points, 2)) * 1e-3 * (seed % 2)
    pts2 = np.unique(pts2, axis=0)
    try:
        tri = Delaunay(pts2)
    except Exception:  # noqa: BLE001 - collinear draws
        return
    faces = tri.simplices.astype(np.int64)
    v = np.c_[pts2, np.zeros(len(pts2))]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    v = v @ q.T
    keep = ~(
        np.abs(np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])).sum(1) < 1e-12
    )
    faces = faces[keep]
    normal = np.cross(v[faces[0, 1]] - v[faces[0, 0]], v[faces[0, 2]] - v[faces[0, 0]])
    normal /= np.linalg.norm(normal)
    mat = rng.integers(0, 2, len(faces))
    c, m, _ = merge_quads(v, faces, mat)
    s = Scene(v, c, m, [])
    assert s.patch_area.sum() == pytest.approx(
        np.linalg.norm(
            np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]]), axis=1
        ).sum()
        / 2
    )
    assert s.patch_is_quad.sum() * 2 + (~s.patch_is_quad).sum() == len(faces)
    np.testing.assert_allclose(s.patch_normal, np.tile(normal, (len(c), 1)), atol=1e-6)
    # quads: both triangles of each diagonal have the same orientation (strictly convex)
    cp = s.corner_positions[s.patch_is_quad]
    for a, b, d in ((0, 1, 2), (1, 2, 3), (2, 3, 0), (3, 0, 1)):
        turn = np.cross(cp[:, b] - cp[:, a], cp[:, d] - cp[:, b]) @ normal
        assert (turn > 0).all()
    # the patches are exactly the input triangles: quads split back along their diagonal c0-c2
    tri_mat = {tuple(sorted(f)): mm for f, mm in zip(faces.tolist(), mat.tolist(), strict=True)}
    got = {}
    for (c0, c1, c2, c3), mm in zip(c.tolist(), m.tolist(), strict=True):
        parts = [(c0, c1, c2)] if c3 < 0 else [(c0, c1, c2), (c2, c3, c0)]
        for t in parts:
            got[tuple(sorted(t))] = mm
    assert got == tri_mat
