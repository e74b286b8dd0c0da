"""iat.export.gltf: Baked -> GLB, read back with pygltflib (and the Khronos validator when present)."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pygltflib import GLTF2

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.color import srgb_encode
from iat.errors import BakeError
from iat.export.gltf import export_glb, radiance_scale
from tests.test_bake import detail_scene, grid_scene_solution
from tests.test_flatten import wavy_field

ROOT = Path(__file__).resolve().parent.parent
VALIDATE_JS = ROOT / "tests" / "gltf_validate.js"
NODE_MODULE_DIRS = [os.environ.get("IAT_GLTF_VALIDATOR_NODE_PATH", ""), str(ROOT / ".node" / "node_modules")]


def read_accessor(gltf: GLTF2, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type]
    dtype = {5126: "<f4", 5125: "<u4"}[acc.componentType]
    a = np.frombuffer(
        gltf.binary_blob(),
        dtype=dtype,
        count=acc.count * width,
        offset=view.byteOffset + (acc.byteOffset or 0),
    )
    return a.reshape(acc.count, width) if width > 1 else a


def read_image(gltf: GLTF2, texture: int) -> np.ndarray:
    img = gltf.images[gltf.textures[texture].source]
    view = gltf.bufferViews[img.bufferView]
    data = gltf.binary_blob()[view.byteOffset : view.byteOffset + view.byteLength]
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def srgb8(linear01):
    x = np.clip(np.asarray(linear01, dtype=np.float64), 0, 1)
    return np.round(srgb_encode(x) * 255).astype(int)


def node_by_name(gltf: GLTF2, name: str):
    hits = [n for n in gltf.nodes if n.name == name]
    assert len(hits) == 1, [n.name for n in gltf.nodes]
    return hits[0]


def validator_env():
    node = shutil.which("node")
    if node is None or not VALIDATE_JS.is_file():
        pytest.skip("node or tests/gltf_validate.js missing: Khronos validation skipped")
    env = dict(os.environ, NODE_PATH=os.pathsep.join(d for d in NODE_MODULE_DIRS if d))
    if subprocess.run(
        [node, "-e", "require.resolve('gltf-validator')"], env=env, capture_output=True
    ).returncode:
        pytest.skip("npm package gltf-validator not found (make setup installs it)")
    return env


@pytest.fixture(scope="module")
def mixed():
    sol = grid_scene_solution(wavy_field, seed=2)
    return sol, Baker(sol).bake(BakePolicy(threshold=4))


def test_round_trip_mesh_and_textured_parts(mixed, tmp_path):
    sol, bk = mixed
    assert bk.patch_textured.any() and not bk.patch_textured.all()
    path = export_glb(bk, tmp_path / "out.glb", watertight=False, match_clip=False)  # the bake as it is
    assert path == tmp_path / "out.glb"
    g = GLTF2().load(str(path))
    s = radiance_scale(bk)
    assert g.extras["iat"]["radiance_scale"] == pytest.approx(s)
    assert g.extras["iat"]["memory"]["texture_bytes"] == bk.memory.texture_bytes
    assert "KHR_materials_unlit" in g.extensionsUsed
    # mesh part: positions, linear COLOR_0 = radiance / scale, indices
    prim = g.meshes[node_by_name(g, "iat_mesh").mesh].primitives[0]
    np.testing.assert_array_equal(read_accessor(g, prim.attributes.POSITION), bk.mesh_positions)
    np.testing.assert_allclose(
        read_accessor(g, prim.attributes.COLOR_0), np.clip(bk.mesh_radiance / s, 0, 1), rtol=1e-6
    )
    np.testing.assert_array_equal(read_accessor(g, prim.indices).reshape(-1, 3), bk.mesh_indices)
    assert g.materials[prim.material].extensions == {"KHR_materials_unlit": {}}
    # textured part: one node per page, TEXCOORD_0 = atlas uv, the page as an sRGB PNG
    assert bk.memory.pages == 1
    prim = g.meshes[node_by_name(g, "iat_page0").mesh].primitives[0]
    pos = read_accessor(g, prim.attributes.POSITION)
    uv = read_accessor(g, prim.attributes.TEXCOORD_0)
    tri = read_accessor(g, prim.indices).reshape(-1, 3)
    assert len(tri) == len(bk.tex_indices)
    np.testing.assert_array_equal(pos[tri], bk.tex_positions[bk.tex_indices.astype(int)])
    np.testing.assert_array_equal(uv[tri], bk.tex_uv[bk.tex_indices.astype(int)])
    mat = g.materials[prim.material]
    tex = mat.pbrMetallicRoughness.baseColorTexture.index
    img = read_image(g, tex)
    assert img.shape == bk.pages.shape[1:]
    assert np.abs(img.astype(int) - srgb8(bk.pages[0] / s)).max() <= 1
    sampler = g.samplers[g.textures[tex].sampler]
    assert (sampler.minFilter, sampler.magFilter, sampler.wrapS, sampler.wrapT) == (9729, 9729, 33071, 33071)


def test_layered_export_writes_detail_on_uv0_and_illumination_on_uv1(tmp_path):
    sol, sc, brick = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=0))
    g = GLTF2().load(str(export_glb(bk, tmp_path / "layered.glb", sc, layered=True)))
    assert g.extras["iat"]["layered"] is True
    node = node_by_name(g, "iat_page0_mat1")
    prim = g.meshes[node.mesh].primitives[0]
    k = np.flatnonzero(bk.tex_patch == 0)
    np.testing.assert_array_equal(read_accessor(g, prim.attributes.TEXCOORD_0), bk.tex_detail_uv[k])
    np.testing.assert_array_equal(read_accessor(g, prim.attributes.TEXCOORD_1), bk.tex_uv[k])
    mat = g.materials[prim.material]
    detail = read_image(g, mat.pbrMetallicRoughness.baseColorTexture.index)
    assert np.abs(detail.astype(int) - srgb8(brick)).max() <= 1
    ill = mat.extras["iat_illumination"]
    assert ill["texCoord"] == 1 and ill["combine"] == "multiply"
    page = read_image(g, ill["index"])
    assert np.abs(page.astype(int) - srgb8(bk.pages[0] / ill["radiance_scale"])).max() <= 1
    # the triangle without detail is written as usual
    plain = g.meshes[node_by_name(g, "iat_page0").mesh].primitives[0]
    assert plain.attributes.TEXCOORD_1 is None


def test_plain_export_of_detail_patches_multiplies_by_albedo(tmp_path):
    sol, sc, _ = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=0))
    g = GLTF2().load(str(export_glb(bk, tmp_path / "plain.glb", sc, watertight=False, match_clip=False)))
    prim = g.meshes[node_by_name(g, "iat_page0_detail").mesh].primitives[0]
    np.testing.assert_allclose(read_accessor(g, prim.attributes.COLOR_0), np.tile([0.25, 0.5, 0.8], (4, 1)))
    assert prim.attributes.TEXCOORD_1 is None


def test_write_is_atomic_and_replaces(mixed, tmp_path):
    _, bk = mixed
    path = tmp_path / "x.glb"
    path.write_bytes(b"old")
    export_glb(bk, path)
    assert path.read_bytes()[:4] == b"glTF"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.glb"]  # no temporary file left
    with pytest.raises((OSError, BakeError)):
        export_glb(bk, tmp_path / "missing_dir" / "y.glb")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.glb"]


@pytest.mark.parametrize("layered", [False, True])
def test_khronos_validator_finds_no_errors(tmp_path, layered):
    env = validator_env()
    sol, sc, _ = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=2))
    path = export_glb(bk, tmp_path / "v.glb", sc, layered=layered)
    r = subprocess.run(["node", str(VALIDATE_JS), str(path)], env=env, capture_output=True, text=True)
    assert r.returncode in (0, 1), r.stderr
    report = json.loads(r.stdout)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    assert report["issues"]["numWarnings"] == 0, report["issues"]["messages"]


def test_radiance_scale_leaves_out_emitters_and_gutters(tmp_path):
    """One patch 1000x brighter and marked emissive: without that mark it decides the scale (its
    texels are many); with it, the scale is the 99.5th percentile, by surface area, of the other
    patches' own tile texels (each once: gutters and padding repeat edges; triangles' lower-left
    half; each the patch's area over its texels) and mesh vertices (a third of their triangles'
    area), recomputed here from the atlas placements and the patch corners; the emitter clips to
    white in the file."""
    import dataclasses

    sol = grid_scene_solution(wavy_field, seed=2)
    hot = int(np.argmax(sol.patch_depth()[:9]))  # a deep quad: many texels
    patch_of_vertex = sol.vert_key // (sol.n + 1) ** 2
    sol.vert_radiance[patch_of_vertex == hot] *= 1000.0
    sol.patch_material[hot] = 1  # the light's own material: its edges are not matched to the walls'
    baker = Baker(sol)
    bk = baker.bake(BakePolicy(threshold=2, gutter=4))
    assert bk.patch_textured[hot] and len(bk.mesh_radiance) and len(bk.patch_emissive) == 0
    hot_value = float(sol.vert_radiance[patch_of_vertex == hot].max(axis=1).min())
    assert radiance_scale(bk) >= hot_value  # today's behaviour without a scene: the emitter decides
    emissive = np.zeros(len(sol.patch_is_quad), bool)
    emissive[hot] = True
    marked = dataclasses.replace(bk, patch_emissive=emissive)
    # each tile read back at its atlas placement (the packer's, not the uv)
    ps = np.flatnonzero(bk.patch_textured)
    sides = (2 ** sol.patch_depth()[ps] + 1).astype(np.int64)
    packing = baker.pack(ps, sides, bk.policy, 2 ** (bk.mip_levels - 1))
    own, own_area = [], []
    for p, m, (layer, x, y) in zip(ps, sides, packing.placements.tolist(), strict=True):
        if emissive[p]:
            continue
        t = bk.pages[layer, y : y + m, x : x + m].max(axis=2)
        keep = np.ones((m, m), bool) if sol.patch_is_quad[p] else np.add.outer(np.arange(m), np.arange(m)) < m
        c = sol.patch_corners[p]
        area = 0.5 * np.linalg.norm(np.cross(c[1] - c[0], c[2] - c[0]))
        if sol.patch_is_quad[p]:
            area += 0.5 * np.linalg.norm(np.cross(c[2] - c[0], c[3] - c[0]))
        own.append(t[keep])
        own_area.append(np.full(int(keep.sum()), area / keep.sum()))
    tri = bk.mesh_indices.astype(np.int64)
    pos = bk.mesh_positions.astype(np.float64)
    tri_area = 0.5 * np.linalg.norm(
        np.cross(pos[tri[:, 1]] - pos[tri[:, 0]], pos[tri[:, 2]] - pos[tri[:, 0]]), axis=1
    )
    vert_area = np.bincount(tri.ravel(), np.repeat(tri_area / 3, 3), minlength=len(pos))
    m_keep = ~emissive[bk.mesh_patch]
    v = np.concatenate([bk.mesh_radiance.max(axis=1)[m_keep], *own])
    w = np.concatenate([vert_area[m_keep], *own_area])
    order = np.argsort(v, kind="stable")
    cw = np.cumsum(w[order])
    want = v[order][np.searchsorted(cw, 0.995 * cw[-1])]
    s = radiance_scale(marked)
    assert s == pytest.approx(want, rel=1e-6)
    assert s < hot_value / 100
    # in the file the emitter's texels are white, the others below it
    g = GLTF2().load(str(export_glb(marked, tmp_path / "hot.glb")))
    assert g.extras["iat"]["radiance_scale"] == pytest.approx(s)
    page = read_image(g, 0)
    k = np.flatnonzero(bk.tex_patch == hot)
    _, H, W, _ = bk.pages.shape
    x = int(round(bk.tex_uv[k, 0].mean() * W)), int(round(bk.tex_uv[k, 1].mean() * H))
    assert (page[x[1], x[0]] == 255).all()
