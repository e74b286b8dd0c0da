"""Tests of iat.io.load: load progress and cancelling, and bad input (missing, empty, corrupt or
truncated files, missing textures and buffers), each a one-line LoadError naming the file.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import trimesh

from iat.errors import Cancelled
from iat.io.load import load_scene
from tests.support.scene_files import (
    QUAD,
    QUAD_TRIS,
    ROOT,
    Gltf,
    assert_load_error,
    quad_gltf,
    write,
)


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
        "making panels",
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
