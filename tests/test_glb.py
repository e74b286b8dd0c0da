"""iat.io.glb (GlbBuilder) and the Cornell box sample script."""

from __future__ import annotations

import io
import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pygltflib import GLTF2

from iat.camera import Camera
from iat.io.glb import GlbBuilder, look_rotation, quat_from_matrix
from sample_models import cornell_box

ROOT = Path(__file__).resolve().parent.parent
VALIDATE_JS = ROOT / "tests" / "gltf_validate.js"
# where `make setup` installs the npm package gltf-validator (and an override for other places)
NODE_MODULE_DIRS = [os.environ.get("IAT_GLTF_VALIDATOR_NODE_PATH", ""), str(ROOT / ".node" / "node_modules")]


# -- helpers --------------------------------------------------------------------------------------


def quat_to_matrix(q) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def read_accessor(gltf: GLTF2, index: int) -> np.ndarray:
    """Decode a float32/uint32 accessor of a loaded GLB."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type]
    dtype = {5126: "<f4", 5125: "<u4"}[acc.componentType]
    blob = gltf.binary_blob()
    start = view.byteOffset + (acc.byteOffset or 0)
    a = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
    return a.reshape(acc.count, width) if width > 1 else a


def png_bytes(w=4, h=2) -> bytes:
    img = Image.fromarray((np.arange(w * h * 3).reshape(h, w, 3) * 9 % 256).astype(np.uint8))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def quad_mesh():
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 0, -1], [0, 0, -1]], dtype=np.float32)
    idx = np.array([[0, 1, 2], [2, 3, 0]], dtype=np.uint32)
    return pos, idx


def kitchen_sink() -> GlbBuilder:
    """A builder using every feature once."""
    b = GlbBuilder()
    white = b.add_material("white", (0.73, 0.73, 0.73, 1.0))
    lamp = b.add_material("lamp", (0.78, 0.78, 0.78), emissive=(17.0, 12.0, 4.0))
    dim = b.add_material("dim", (0.5, 0.25, 0.125, 1.0), emissive=(0.5, 0.25, 0.0), double_sided=True)
    tex = b.add_material("tex", (1.0, 1.0, 1.0, 1.0), base_color_png=png_bytes(), base_color_texcoord=1)
    flat = b.add_material("flat", (0.2, 0.3, 0.4, 1.0), unlit=True)
    pos, idx = quad_mesh()
    nrm = np.tile([0.0, 2.0, 0.0], (4, 1))  # normalised by the writer
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)
    col = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=np.float32)
    meshes = [
        b.add_mesh("m_white", pos, idx, white, normals=nrm),
        b.add_mesh("m_lamp", pos + [0, 2, 0], idx[:, ::-1], lamp),
        b.add_mesh("m_dim", pos, idx, dim, uv0=uv),
        b.add_mesh("m_tex", pos, idx, tex, normals=nrm, uv0=uv, uv1=uv * 0.5),
        b.add_mesh("m_flat", pos, idx, flat, colors=np.c_[col, np.ones(4, np.float32)]),
        b.add_mesh("m_colors", pos, idx, None, colors=col),
    ]
    kids = [b.add_node(f"n{i}", mesh=m) for i, m in enumerate(meshes[1:])]
    b.add_node("group", mesh=meshes[0], translation=(1, 2, 3), rotation=(0, 0, 0, 2), children=kids)
    b.add_node(
        "moved", mesh=meshes[0], matrix=np.array([[1, 0, 0, 5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    )
    b.add_point_light("bulb", (1.0, 0.9, 0.8), 3.5, (0.1, 0.5, 0.2))
    b.add_spot_light("spot", (1.0, 1.0, 1.0), 10.0, (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), 0.2, 0.5)
    b.add_camera_node(Camera(eye=(0, 1, 3), target=(0.5, 0, 0), name="view"), aspect=16 / 9)
    b.extras["iat_camera_paths"] = {"default": [Camera().to_dict()]}
    return b


@pytest.fixture
def sink(tmp_path) -> tuple[GlbBuilder, GLTF2]:
    b = kitchen_sink()
    path = b.write(tmp_path / "sink.glb")
    return b, GLTF2().load_binary(str(path))


# -- round trip -----------------------------------------------------------------------------------


def test_glb_header_and_chunks(tmp_path):
    data = kitchen_sink().to_bytes()
    magic, version, length = struct.unpack_from("<III", data)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A and jlen % 4 == 0
    doc = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942 and blen % 4 == 0 and blen == doc["buffers"][0]["byteLength"]
    assert 28 + jlen + blen == len(data)
    assert all(v["byteOffset"] % 4 == 0 for v in doc["bufferViews"])


def test_materials_round_trip(sink):
    _, g = sink
    by_name = {m.name: m for m in g.materials}
    assert by_name["white"].pbrMetallicRoughness.baseColorFactor == [0.73, 0.73, 0.73, 1.0]
    assert by_name["dim"].pbrMetallicRoughness.baseColorFactor == [0.5, 0.25, 0.125, 1.0]
    assert by_name["lamp"].pbrMetallicRoughness.baseColorFactor == [0.78, 0.78, 0.78, 1.0]
    for m in g.materials:
        assert m.pbrMetallicRoughness.metallicFactor == 0.0
        assert m.pbrMetallicRoughness.roughnessFactor == 1.0

    lamp = by_name["lamp"]
    strength = lamp.extensions["KHR_materials_emissive_strength"]["emissiveStrength"]
    assert strength == 17.0
    assert max(lamp.emissiveFactor) == 1.0
    assert np.allclose(np.array(lamp.emissiveFactor) * strength, [17.0, 12.0, 4.0], rtol=1e-15)

    dim = by_name["dim"]
    assert dim.emissiveFactor == [0.5, 0.25, 0.0]
    assert not dim.extensions and dim.doubleSided
    assert by_name["white"].emissiveFactor in (None, [0.0, 0.0, 0.0])
    assert "KHR_materials_unlit" in by_name["flat"].extensions
    assert set(g.extensionsUsed) == {
        "KHR_materials_emissive_strength",
        "KHR_materials_unlit",
        "KHR_lights_punctual",
    }
    assert not g.extensionsRequired

    tex = by_name["tex"].pbrMetallicRoughness.baseColorTexture
    assert tex.texCoord == 1
    texture = g.textures[tex.index]
    sampler = g.samplers[texture.sampler]
    assert (sampler.wrapS, sampler.wrapT, sampler.magFilter, sampler.minFilter) == (10497, 10497, 9729, 9987)
    image = g.images[texture.source]
    assert image.mimeType == "image/png"
    view = g.bufferViews[image.bufferView]
    assert g.binary_blob()[view.byteOffset : view.byteOffset + view.byteLength] == png_bytes()


def test_meshes_round_trip(sink):
    _, g = sink
    pos, idx = quad_mesh()
    meshes = {m.name: m for m in g.meshes}
    prim = meshes["m_tex"].primitives[0]
    a = prim.attributes
    assert np.array_equal(read_accessor(g, a.POSITION), pos)
    assert np.array_equal(read_accessor(g, prim.indices).reshape(-1, 3), idx)
    assert np.allclose(read_accessor(g, a.NORMAL), [0, 1, 0])
    assert np.array_equal(read_accessor(g, a.TEXCOORD_1), read_accessor(g, a.TEXCOORD_0) * 0.5)
    acc = g.accessors[a.POSITION]
    assert acc.min == [0.0, 0.0, -1.0] and acc.max == [1.0, 0.0, 0.0]
    assert g.accessors[meshes["m_colors"].primitives[0].attributes.COLOR_0].type == "VEC3"
    assert g.accessors[meshes["m_flat"].primitives[0].attributes.COLOR_0].type == "VEC4"
    assert meshes["m_colors"].primitives[0].material is None


def test_nodes_lights_camera_extras(sink):
    _, g = sink
    nodes = {n.name: n for n in g.nodes}
    assert nodes["group"].rotation == [0.0, 0.0, 0.0, 1.0]
    assert len(nodes["group"].children) == 5
    roots = g.scenes[g.scene].nodes
    assert all(g.nodes[i].name not in ("n0", "n1") for i in roots)
    assert nodes["moved"].matrix[12:15] == [5.0, 0.0, 0.0]  # column-major: translation last

    lights = g.extensions["KHR_lights_punctual"]["lights"]
    assert [lt["type"] for lt in lights] == ["point", "spot"]
    assert lights[0]["intensity"] == 3.5 and lights[0]["color"] == [1.0, 0.9, 0.8]
    assert lights[1]["spot"] == {"innerConeAngle": 0.2, "outerConeAngle": 0.5}
    bulb = nodes["bulb"]
    assert bulb.extensions["KHR_lights_punctual"]["light"] == 0 and bulb.translation == [0.1, 0.5, 0.2]
    spot = nodes["spot"]
    assert np.allclose(quat_to_matrix(spot.rotation) @ [0, 0, -1], [0, -1, 0], atol=1e-12)

    cam = g.cameras[nodes["view"].camera]
    assert cam.type == "perspective"
    assert cam.perspective.yfov == pytest.approx(np.radians(60.0))
    assert cam.perspective.aspectRatio == pytest.approx(16 / 9)
    assert (cam.perspective.znear, cam.perspective.zfar) == (0.01, 1000.0)
    assert g.extras["iat_camera_paths"]["default"][0]["yfov"] == 60.0


@pytest.mark.parametrize(
    "eye, target, up",
    [
        ((0, 1, 3), (0.5, 0, 0), (0, 1, 0)),
        ((0.278, 0.273, -0.8), (0.278, 0.273, 0), (0, 1, 0)),
        ((1, 2, 3), (-4, 0.5, 2), (0, 0, 1)),
        ((0, 5, 0), (0, 0, 0), (0, 1, 0)),  # looking straight down: up is parallel
        ((0, 0, 0), (0, 0, 1), (0, 1, 0)),  # looking down +Z: 180 degree turn
    ],
)
def test_camera_node_orientation(tmp_path, eye, target, up):
    b = GlbBuilder()
    cam = Camera(eye=eye, target=target, up=up, yfov=39.3, znear=0.01, zfar=10.0)
    node = b.add_camera_node(cam, aspect=1.0)
    g = GLTF2().load_binary(str(b.write(tmp_path / "cam.glb")))
    n = g.nodes[node]
    assert n.translation == list(map(float, eye))
    assert np.linalg.norm(n.rotation) == pytest.approx(1.0)
    r = quat_to_matrix(n.rotation)
    assert np.allclose(r @ [0, 0, -1], cam.forward, atol=1e-12)
    # local +Y is the camera's up made orthogonal (when up is not parallel to the view)
    if np.linalg.norm(np.cross(cam.forward, cam.up)) > 1e-6:
        view = cam.view_from_world()
        assert np.allclose(r, view[:3, :3].T, atol=1e-12)


def test_quaternion_helpers():
    rng = np.random.default_rng(1)
    for _ in range(200):
        r = look_rotation(rng.normal(size=3), rng.normal(size=3))
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-12) and np.linalg.det(r) == pytest.approx(1.0)
        q = quat_from_matrix(r)
        assert q[3] >= 0 and np.allclose(quat_to_matrix(q), r, atol=1e-12)


def test_bad_inputs_raise():
    b = GlbBuilder()
    pos, idx = quad_mesh()
    m = b.add_material("m", (0.5, 0.5, 0.5))
    with pytest.raises(ValueError):
        b.add_mesh("x", pos, idx + 4, m)  # index out of range
    with pytest.raises(ValueError):
        b.add_mesh("x", pos[:, :2], idx, m)
    with pytest.raises(ValueError):
        b.add_mesh("x", np.where(pos == 1, np.nan, pos), idx, m)
    with pytest.raises(ValueError):
        b.add_mesh("x", pos, idx, m, normals=np.zeros((4, 3)))
    with pytest.raises(ValueError):
        b.add_material("bad", (1.5, 0, 0))
    with pytest.raises(ValueError):
        b.add_material("bad", (1, 1, 1), emissive=(-1, 0, 0))
    with pytest.raises(ValueError):
        b.add_material("bad", (1, 1, 1), base_color_png=b"not a png")
    t = b.add_material("t", (1, 1, 1), base_color_png=png_bytes(), base_color_texcoord=1)
    with pytest.raises(ValueError, match="TEXCOORD_1"):
        b.add_mesh("x", pos, idx, t, uv0=np.zeros((4, 2)))
    with pytest.raises(ValueError):
        b.add_spot_light("s", (1, 1, 1), 1.0, (0, 0, 0), (0, -1, 0), 0.6, 0.5)
    with pytest.raises(ValueError):
        b.add_node("n", translation=(0, 0, 0), matrix=np.eye(4))
    with pytest.raises(ValueError):
        b.add_node("n", mesh=7)


# -- atomic write ---------------------------------------------------------------------------------


def _old_file(tmp_path) -> tuple[Path, bytes]:
    path = tmp_path / "scene.glb"
    old = GlbBuilder().to_bytes()
    path.write_bytes(old)
    return path, old


def test_write_is_atomic_when_replace_fails(tmp_path, monkeypatch):
    path, old = _old_file(tmp_path)

    def boom(src, dst):
        assert Path(src).exists() and Path(src).parent == path.parent  # the temp sits next to the target
        raise OSError("disk on fire")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk on fire"):
        kitchen_sink().write(path)
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.glb"]


def test_write_is_atomic_when_writing_fails(tmp_path, monkeypatch):
    path, old = _old_file(tmp_path)

    def boom(fd):
        raise OSError("no space left")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="no space"):
        kitchen_sink().write(path)
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.glb"]


@pytest.mark.parametrize("bad", [float("nan"), np.array([1.0, np.inf]), object()])
def test_write_is_atomic_when_serialising_fails(tmp_path, bad):
    path, old = _old_file(tmp_path)
    b = kitchen_sink()
    b.extras["broken"] = bad
    with pytest.raises(ValueError):
        b.write(path)
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.glb"]


def test_write_replaces_and_is_deterministic(tmp_path):
    path, _ = _old_file(tmp_path)
    kitchen_sink().write(path)
    assert path.read_bytes() == kitchen_sink().to_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.glb"]


def test_write_removes_stale_temporaries_of_killed_writers(tmp_path, monkeypatch):
    """The temporary is `.scene.glb.<random>.tmp` (the one scheme of iat.fsutil.atomic_write); one a
    killed writer left more than an hour ago goes with the next successful write, a young one (a write
    in progress elsewhere) and other names stay (docs/stability.md, G4)."""
    import time

    from iat.fsutil import STALE_TEMPORARY_S, temporary_pattern

    path, _ = _old_file(tmp_path)
    names = []
    real_replace = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (names.append(Path(a).name), real_replace(a, b)))
    kept = [".scene.glb.w0rk1ng.tmp", "x.tmp"]
    stale, young, other = (tmp_path / n for n in [".scene.glb.k1ll3d_1.tmp", *kept])
    old = time.time() - 2 * STALE_TEMPORARY_S
    for f in (stale, young, other):
        f.write_bytes(b"half")
        os.utime(f, (old, old))
    os.utime(young)  # now
    kitchen_sink().write(path)
    assert len(names) == 1 and temporary_pattern(path).fullmatch(names[0]), names
    assert path.read_bytes() == kitchen_sink().to_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*kept, "scene.glb"])


# -- the Cornell box sample -----------------------------------------------------------------------


def test_cornell_box_script_is_deterministic(tmp_path):
    outs = []
    for k in range(2):
        out = tmp_path / f"cb{k}.glb"
        r = subprocess.run(
            [sys.executable, str(ROOT / "sample_models" / "cornell_box.py"), "-o", str(out)],
            capture_output=True,
            text=True,
            check=True,
        )
        assert str(out) in r.stdout
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert cornell_box.build(tmp_path / "cb_in_process.glb").read_bytes() == outs[0]
    committed = ROOT / "sample_models" / "cornell_box.glb"
    assert committed.read_bytes() == outs[0], "stale: run python sample_models/cornell_box.py"


def test_cornell_box_content(tmp_path):
    g = GLTF2().load_binary(str(cornell_box.build(tmp_path / "cb.glb")))
    mats = {m.name: m for m in g.materials}
    assert mats["white"].pbrMetallicRoughness.baseColorFactor[:3] == [0.73, 0.73, 0.73]
    assert mats["red"].pbrMetallicRoughness.baseColorFactor[:3] == [0.63, 0.065, 0.05]
    assert mats["green"].pbrMetallicRoughness.baseColorFactor[:3] == [0.14, 0.45, 0.09]
    light = mats["light"]
    strength = light.extensions["KHR_materials_emissive_strength"]["emissiveStrength"]
    assert np.allclose(np.array(light.emissiveFactor) * strength, cornell_box.LIGHT_RADIANCE)
    assert 1.0 < strength < 1000.0

    centre = np.array([cornell_box.W, cornell_box.H, cornell_box.D]) / 2
    n_quads = 0
    for node in g.nodes:
        if node.mesh is None:
            continue
        assert node.matrix is None and node.translation is None and node.rotation is None
        prim = g.meshes[node.mesh].primitives[0]
        pos = read_accessor(g, prim.attributes.POSITION).astype(np.float64)
        nrm = read_accessor(g, prim.attributes.NORMAL).astype(np.float64)
        tri = read_accessor(g, prim.indices).reshape(-1, 2, 3).astype(np.int64)
        for pair in tri:
            q = pair[0, 0]
            # the loader's contract: a quad [q, q+1, q+2, q+3] is written as [0,1,2],[2,3,0]
            assert pair.tolist() == [[q, q + 1, q + 2], [q + 2, q + 3, q]]
            c = pos[q : q + 4]
            n = np.cross(c[2] - c[0], c[3] - c[1])
            n /= np.linalg.norm(n)
            assert np.allclose(nrm[q : q + 4], n, atol=1e-6)  # stored normals agree with winding
            assert abs(np.dot(c[3] - c[0], n)) < 1e-9  # planar
            to_centre = centre - c.mean(axis=0)
            if node.name in ("floor", "ceiling", "back_wall", "red_wall", "green_wall", "light"):
                assert np.dot(n, to_centre) > 0, node.name  # faces into the room
            n_quads += 1
    assert n_quads == 16

    cam_node = next(n for n in g.nodes if n.camera is not None)
    cam = g.cameras[cam_node.camera].perspective
    assert np.degrees(cam.yfov) == pytest.approx(39.3, abs=0.05)
    assert np.allclose(quat_to_matrix(cam_node.rotation) @ [0, 0, -1], [0, 0, 1])
    poses = g.extras["iat_camera_paths"]["default"]
    assert len(poses) == 8
    for p in poses:
        c = Camera.from_dict(p)
        assert set(p) == {"eye", "target", "up", "yfov"}
        assert c.eye[2] < 0 and 0 < c.target[2] < cornell_box.D


# -- Khronos validator ----------------------------------------------------------------------------


def _validator_env() -> dict:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (the Khronos glTF validator runs on Node.js)")
    env = dict(os.environ, NODE_PATH=os.pathsep.join(d for d in NODE_MODULE_DIRS if d))
    r = subprocess.run([node, "-e", "require.resolve('gltf-validator')"], env=env, capture_output=True)
    if r.returncode != 0:
        pytest.skip("npm package gltf-validator not found in .node/node_modules (make setup installs it)")
    return env


@pytest.mark.parametrize("which", ["cornell_box", "kitchen_sink", "empty"])
def test_khronos_validator(tmp_path, which):
    env = _validator_env()
    b = {"cornell_box": cornell_box.make_builder, "kitchen_sink": kitchen_sink, "empty": GlbBuilder}[which]()
    path = b.write(tmp_path / f"{which}.glb")
    r = subprocess.run(["node", str(VALIDATE_JS), str(path)], env=env, capture_output=True, text=True)
    assert r.returncode in (0, 1), r.stderr
    report = json.loads(r.stdout)
    messages = report["issues"]["messages"]
    assert report["issues"]["numErrors"] == 0, messages
    assert report["issues"]["numWarnings"] == 0, messages
