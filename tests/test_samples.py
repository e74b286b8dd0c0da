"""The four Figure 3 sample models (house, cave, lavapit, pool) and the house's daylight
variant (house_day): deterministic scripts,
kept files up to date, and scenes that load with the lights, cameras, paths, detail
textures and polygon budgets they promise; seen from their camera paths they are
closed rooms whose visible faces all look at the viewer."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from iat.io.load import load_scene

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "sample_models"

#: name -> (KHR lights, cameras, (min, max) camera path poses)
EXPECTED = {
    "house": (4, 3, (30, 40)),
    "cave": (4, 3, (25, 35)),
    "lavapit": (4, 3, (30, 40)),
    "pool": (8, 3, (30, 40)),
    "house_day": (5, 3, (30, 40)),
}
NAMES = sorted(EXPECTED)

#: lean input models: root patches and glTF triangles
LEAN_PATCHES = (300, 4000)
LEAN_TRIANGLES = 6000


def _build(name: str, path: Path) -> Path:
    from sample_models.make_all import build_one

    return build_one(name, path)


@pytest.fixture(scope="module")
def scenes():
    return {n: load_scene(SAMPLES / f"{n}.glb") for n in NAMES}


def _gltf_json(path: Path) -> dict:
    data = path.read_bytes()
    magic, version, _ = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2
    length, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    return json.loads(data[20 : 20 + length])


@pytest.mark.parametrize("name", NAMES)
def test_script_is_deterministic_and_kept_file_is_fresh(name, tmp_path):
    a = _build(name, tmp_path / "a.glb").read_bytes()
    b = _build(name, tmp_path / "b.glb").read_bytes()
    assert a == b, f"{name}: two builds differ"
    kept = SAMPLES / f"{name}.glb"
    assert kept.read_bytes() == a, f"{kept} is stale: run python sample_models/make_all.py"
    assert len(a) < 1_000_000


def test_scripts_run_from_the_command_line(tmp_path):
    out = tmp_path / "cave.glb"
    r = subprocess.run(
        [sys.executable, str(SAMPLES / "cave.py"), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == (SAMPLES / "cave.glb").read_bytes()
    r = subprocess.run(
        [sys.executable, str(SAMPLES / "make_all.py"), "--check", "house", "pool"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.parametrize("name", NAMES)
def test_loads_with_lights_cameras_and_path(name, scenes):
    scene = scenes[name]
    n_lights, n_cameras, (lo, hi) = EXPECTED[name]
    assert len(scene.lights) == n_lights
    assert len(scene.cameras) == n_cameras
    path = scene.camera_paths.get("default")
    assert path and lo <= len(path) <= hi
    eyes = np.array([c.eye for c in path])
    steps = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    assert np.all(np.isfinite(eyes))
    assert steps.min() > 0.2 and steps.max() < 2.0 * steps.mean()  # a smooth walk, no jumps or stops
    assert all(20.0 <= c.yfov <= 90.0 for c in path + scene.cameras)
    lo_b, hi_b = scene.bounds
    placed = [lt.position for lt in scene.lights if lt.kind != "directional"]
    inside = [(lo_b < p).all() and (p < hi_b).all() for p in [c.eye for c in path + scene.cameras] + placed]
    assert all(inside)


@pytest.mark.parametrize("name", NAMES)
def test_input_polygons_are_lean(name, scenes):
    scene = scenes[name]
    assert LEAN_PATCHES[0] <= scene.n_patches <= LEAN_PATCHES[1]
    doc = _gltf_json(SAMPLES / f"{name}.glb")
    tris = sum(doc["accessors"][p["indices"]]["count"] // 3 for m in doc["meshes"] for p in m["primitives"])
    assert tris <= LEAN_TRIANGLES
    # large surfaces come as panels: no root polygon longer than 3.2 m
    c = scene.corner_positions
    edges = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)
    assert edges.max() <= 3.2


def test_house_and_halls_are_quads_cave_is_triangles(scenes):
    for name in ("house", "lavapit", "pool"):
        assert scenes[name].patch_is_quad.all(), name
    tri_share = 1.0 - scenes["cave"].patch_is_quad.mean()
    assert tri_share > 0.9
    assert 500 <= scenes["cave"].n_patches <= 2600  # 1 944 roots, 2 528 once the rocks crossing it cut it


def test_lavapit_has_strong_emissive_lava(scenes):
    doc = _gltf_json(SAMPLES / "lavapit.glb")
    lava = [m for m in doc["materials"] if m["name"] == "lava"]
    assert lava and lava[0]["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] > 1.0
    scene = scenes["lavapit"]
    emission = np.array([m.emission for m in scene.materials])
    assert emission.max() > 1.0
    hot = emission.max(axis=1) > 1.0
    area = scene.patch_area[hot[scene.patch_material]].sum()
    assert area == pytest.approx(8.0 * 6.0)  # the whole pit floor glows
    assert emission[hot][0, 0] > emission[hot][0, 1] > emission[hot][0, 2]  # orange


def test_pool_has_repeating_detail_textures(scenes):
    scene = scenes["pool"]
    detailed = [i for i, m in enumerate(scene.materials) if m.detail is not None]
    names = {scene.materials[i].name for i in detailed}
    assert {"floor_tiles", "wall_tiles", "pool_tiles"} <= names
    for i in detailed:
        d = scene.materials[i].detail
        assert d.ndim == 3 and d.shape[2] == 3 and d.shape[0] >= 64
        uv = scene.patch_uv[scene.patch_material == i]
        assert np.ptp(uv[..., 0]) > 5.0 and np.ptp(uv[..., 1]) > 2.0  # repeats many times
    doc = _gltf_json(SAMPLES / "pool.glb")
    assert all(s["wrapS"] == 10497 and s["wrapT"] == 10497 for s in doc["samplers"])
    # most of the surface area carries a detail texture
    has = np.isin(scene.patch_material, detailed)
    assert scene.patch_area[has].sum() > 0.5 * scene.patch_area.sum()


@pytest.mark.parametrize("name", NAMES)
def test_seen_from_the_path_the_model_is_closed_and_faces_the_viewer(name, scenes):
    """Rays from every pose of the camera path hit a front face, and never escape."""
    rtcs = pytest.importorskip("embreex.rtcore_scene")
    from embreex.mesh_construction import TriangleMesh

    scene = scenes[name]
    pc = scene.patch_corners
    quad = pc[:, 3] >= 0
    tris = np.concatenate([pc[:, [0, 1, 2]], pc[quad][:, [0, 2, 3]]])
    owner = np.concatenate([np.arange(len(pc)), np.flatnonzero(quad)])
    sc = rtcs.EmbreeScene()
    TriangleMesh(sc, scene.vertices.astype(np.float32), tris.astype(np.int32))
    eyes = np.array([c.eye for c in scene.camera_paths["default"] + scene.cameras])
    k = 256  # directions: a Fibonacci sphere
    i = np.arange(k) + 0.5
    phi, cos_t = np.pi * (1 + 5**0.5) * i, 1 - 2 * i / k
    sin_t = np.sqrt(1 - cos_t**2)
    dirs = np.column_stack([np.cos(phi) * sin_t, cos_t, np.sin(phi) * sin_t])
    origins = np.repeat(eyes, k, axis=0).astype(np.float32)
    d = np.tile(dirs, (len(eyes), 1)).astype(np.float32)
    prim = np.asarray(sc.run(origins, d))
    assert np.all(prim >= 0), f"{name}: {int(np.sum(prim < 0))} rays escape the model"
    facing = np.einsum("ij,ij->i", scene.patch_normal[owner[prim]], d)
    assert np.all(facing < 0), f"{name}: {int(np.sum(facing >= 0))} rays hit the back of a face"


@pytest.mark.parametrize("name", NAMES)
def test_khronos_validator_finds_no_issue(name):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (the Khronos glTF validator runs on Node.js)")
    dirs = [os.environ.get("IAT_GLTF_VALIDATOR_NODE_PATH", ""), str(ROOT / ".node" / "node_modules")]
    env = dict(os.environ, NODE_PATH=os.pathsep.join(d for d in dirs if d))
    if subprocess.run(
        [node, "-e", "require.resolve('gltf-validator')"], env=env, capture_output=True
    ).returncode:
        pytest.skip("npm package gltf-validator not found in .node/node_modules (make setup installs it)")
    r = subprocess.run(
        [node, str(ROOT / "tests" / "gltf_validate.js"), str(SAMPLES / f"{name}.glb")],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode in (0, 1), r.stderr
    issues = json.loads(r.stdout)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
