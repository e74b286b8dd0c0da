"""Tests of iat.io.load and iat.io.gltf: materials (glTF and OBJ, textures, albedo clamping),
lights, cameras, camera paths and the glTF node and primitive structure.

Every model is written to ``tmp_path`` by the test itself (glTF with pygltflib,
the rest as text or with trimesh's exporters).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pygltflib
import pytest
import trimesh
from PIL import Image

from iat.color import srgb_decode
from iat.errors import IATWarning
from iat.io.load import load_scene
from tests.support.scene_files import (
    FLOAT,
    QUAD,
    QUAD_TRIS,
    UINT32,
    Gltf,
    quad_gltf,
    write,
)

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
    lin188 = float(srgb_decode(np.float32(188 / 255)))
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


def test_point_spot_and_directional_lights(tmp_path, caplog):
    g = Gltf()
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS))
    pl = g.light({"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 40.0, "name": "bulb"})
    sl = g.light({"type": "spot", "intensity": 10.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}})
    dl = g.light(
        {"type": "directional", "intensity": 3.0, "name": "sun", "extras": {"angular_diameter": 1.0}}
    )
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
    with caplog.at_level(logging.WARNING, logger="iat.io.gltf"):
        s = load_scene(g.save(tmp_path / "lights.glb"))
    assert "skipped" not in caplog.text
    assert [lt.kind for lt in s.lights] == ["point", "spot", "directional"]
    p, sp, sun = s.lights
    np.testing.assert_allclose(sun.direction, [0, 0, -1])  # a node's -Z: where the light travels
    assert sun.intensity == 3.0 and sun.angular_diameter == pytest.approx(math.radians(1.0))
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
# glTF structure: primitives, names, camera nodes
# ----------------------------------------------------------------------------


def test_gltf_primitives_and_repeated_mesh_names_keep_their_materials(tmp_path, caplog):
    g = Gltf()
    red = g.material(base=(0.9, 0.01, 0.02, 1.0), name="red")
    green = g.material(base=(0.03, 0.8, 0.04, 1.0), name="green")
    blue = g.material(base=(0.05, 0.06, 0.7, 1.0), name="blue")
    m1 = g.mesh(QUAD, QUAD_TRIS, material=red, name="thing")
    # a second primitive on the same mesh, moved up by 1, green
    attrs = pygltflib.Attributes(POSITION=g.accessor((QUAD + [0, 0, 1]).astype(np.float32), "VEC3", FLOAT))
    idx = g.accessor(np.array(QUAD_TRIS).ravel(), "SCALAR", UINT32)
    g.doc.meshes[m1].primitives.append(pygltflib.Primitive(attributes=attrs, indices=idx, material=green))
    m2 = g.mesh(QUAD + [0, 0, 2], QUAD_TRIS, material=blue, name="thing")  # same mesh name
    m3 = g.mesh(QUAD + [0, 0, 3], QUAD_TRIS, name="thing")  # no material: the default one
    for m in (m1, m2, m3):
        g.node(mesh=m)
    with caplog.at_level(logging.WARNING, logger="iat.io"):
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
