"""Panels (report §6.1): coplanar patches holding triangles become rectangle roots cut to the
surface by clip triangles. Clipping helpers, the loader's panels, and a solve on them against
the same model without panels (areas, holes, energy, IAT against mesh)."""

from __future__ import annotations

import numpy as np
import pytest

from iat.bake.baker import bake
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.color import LUMINANCE_WEIGHTS
from iat.geometry.clip import clamp_into, clip_mesh, clip_to_boxes, coverage_grid, fan, triangle_area
from iat.geometry.panels import find_panels
from iat.io.load import load_scene
from iat.radiosity import SolveOptions, solve
from tests.support.scene_files import write

# a 4 x 2.5 wall (z = 0, facing +z) with a round window of radius 0.6, triangulated by earcut
# as CAD kernels do it: long thin triangles from the wall's corners to the window's 24 points
_K = 24


def _wall_obj(tmp_path, with_room: bool = True):
    import mapbox_earcut

    ang = np.linspace(0, 2 * np.pi, _K, endpoint=False)
    hole = np.stack([2.0 + 0.6 * np.cos(ang), 1.25 + 0.6 * np.sin(ang), np.zeros(_K)], axis=1)[::-1]
    corners = np.array([[0, 0, 0], [4, 0, 0], [4, 2.5, 0], [0, 2.5, 0]], dtype=float)
    V = np.concatenate([corners, hole])
    faces = mapbox_earcut.triangulate_float64(V[:, :2], np.array([4, 4 + _K], dtype=np.uint32)).reshape(-1, 3)
    e1, e2 = V[faces[:, 1]] - V[faces[:, 0]], V[faces[:, 2]] - V[faces[:, 0]]
    flip = np.cross(e1, e2)[:, 2] < 0
    faces[flip] = faces[flip][:, ::-1]
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in V]
    lines.append("usemtl wall")
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    if with_room:  # a floor in front of the wall and an emissive panel above it
        n = len(V)
        lines += [
            "v 0 0 0",
            "v 0 0 3",
            "v 4 0 3",
            "v 4 0 0",
            "usemtl floor",
            f"f {n + 1} {n + 2} {n + 3} {n + 4}",
        ]
        lines += ["v 1.5 2.4 1.0", "v 2.5 2.4 1.0", "v 2.5 2.4 2.0", "v 1.5 2.4 2.0", "usemtl lamp"]
        lines += [f"f {n + 5} {n + 6} {n + 7} {n + 8}"]
    mtl = write(
        tmp_path / "wall.mtl",
        "newmtl wall\nKd 0.7 0.7 0.7\nnewmtl floor\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n",
    )
    return write(tmp_path / "wall.obj", f"mtllib {mtl.name}\n" + "\n".join(lines) + "\n")


WALL_AREA = 4 * 2.5 - 0.5 * _K * 0.6**2 * np.sin(2 * np.pi / _K)  # minus the 24-gon


def test_clip_to_boxes_and_fan_keep_the_area():
    tri = np.array([[[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]]])
    P, A, count = clip_to_boxes(
        np.repeat(tri, 2, 0), np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[1.0, 1.0], [2.0, 2.0]])
    )
    T, TA, src = fan(P, A, count)
    area = np.bincount(src, weights=triangle_area(T), minlength=2)
    np.testing.assert_allclose(area, [1.0, 0.5], atol=1e-12)
    # the attributes are barycentric weights of the source corners: they rebuild the positions
    np.testing.assert_allclose(np.einsum("tkj,tjc->tkc", TA, tri[[0] * len(T)]), T, atol=1e-12)


def test_clamp_into_moves_outside_points_to_the_surface():
    clip = np.array([[[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]]])
    start = np.array([0, 1])
    pts = np.array([[0.1, 0.1], [0.9, 0.9], [-0.5, 0.2]])
    out = clamp_into(pts, np.zeros(3, dtype=np.int64), clip, start, np.full(3, 0.01))
    np.testing.assert_array_equal(out[0], pts[0])  # inside: unchanged
    assert out[1, 0] + out[1, 1] < 0.5 and np.hypot(*(out[1] - [0.25, 0.25])) < 0.02
    assert out[2, 0] > 0 and out[2, 1] == pytest.approx(0.2, abs=0.02)


def test_coverage_grid_marks_the_cell_centres_inside_its_triangles():
    """Every cell centre of a 64 x 64 grid tested against the clip triangles (either winding), those
    on an edge included; the covered share is the triangles' area to a cell's rim."""
    clip = np.array([[[0.0, 0.0], [0.75, 0.0], [0.0, 0.5]], [[1.0, 1.0], [0.25, 1.0], [1.0, 0.5]]])
    res = 64
    c = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(c, c)  # grid[b, a]: u = c[a], v = c[b]
    want = np.zeros((res, res), dtype=bool)
    for t in clip:
        d = [
            (t[k1, 0] - t[k, 0]) * (v - t[k, 1]) - (t[k1, 1] - t[k, 1]) * (u - t[k, 0])
            for k, k1 in ((0, 1), (1, 2), (2, 0))
        ]
        want |= (np.min(d, axis=0) >= 0) | (np.max(d, axis=0) <= 0)
    got = coverage_grid(clip, res)
    np.testing.assert_array_equal(got, want)
    assert got[0, 0] and got[-1, -1] and not got[0, -1] and not got[-1, 0]
    assert abs(got.mean() - triangle_area(clip).sum()) < 4 / res


def test_clip_mesh_interpolates_a_linear_field_exactly():
    rng = np.random.default_rng(1)
    tri = rng.random((20, 3, 2))
    clip = np.array([[[0.2, 0.2], [0.9, 0.3], [0.3, 0.8]]])
    uv, w, src = clip_mesh(tri, np.zeros(20, dtype=np.int64), clip, np.array([0, 1]))
    f = tri @ [2.0, -3.0] + 1.0  # (20, 3) a linear field at the source corners
    np.testing.assert_allclose(np.einsum("tkj,tj->tk", w, f[src]), uv @ [2.0, -3.0] + 1.0, atol=1e-12)
    piece = np.bincount(src, weights=triangle_area(uv), minlength=20)
    assert (piece <= np.minimum(triangle_area(tri), triangle_area(clip)) * (1 + 1e-9)).all()


def test_a_fan_triangulated_wall_becomes_one_panel_with_its_hole(tmp_path):
    p = _wall_obj(tmp_path, with_room=False)
    plain = load_scene(p, panels=False)
    s = load_scene(p)
    assert plain.n_patches >= 24 and find_panels(s).n_panels == 1
    assert s.patch_is_quad.all() and s.patch_clipped.any()
    assert s.patch_area.sum() == pytest.approx(WALL_AREA, rel=1e-9)
    assert plain.patch_area.sum() == pytest.approx(WALL_AREA, rel=1e-9)
    tris = s.world_triangles()
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1).sum()
    assert area == pytest.approx(WALL_AREA, rel=1e-9)
    np.testing.assert_allclose(s.patch_normal[0], [0, 0, 1], atol=1e-12)


@pytest.fixture(scope="module")
def wall_solves(tmp_path_factory):
    p = _wall_obj(tmp_path_factory.mktemp("panels"))
    opts = SolveOptions(max_depth=5)
    out = {}
    for panels in (False, True):
        scene = load_scene(p, panels=panels)
        out[panels] = (scene, solve(scene, opts))
    return out


def _render(egl_ctx, scene, sol, mode):
    from iat.render.renderer import Renderer

    r = Renderer(ctx=egl_ctx)
    r.set_solution(sol)
    r.set_baked(bake(sol, scene, BakePolicy()))
    cam = Camera(eye=[2.0, 1.3, 2.9], target=[2.0, 1.1, 0.0], yfov=60.0)
    return r.render(cam, size=(160, 120), mode=mode)


def test_panel_solve_matches_the_plain_solve_and_keeps_the_hole(egl_ctx, wall_solves):
    """Against the same wall as 40 fan triangles: the same light (the lit pixels' mean within 3 %),
    the hole in the same pixels in mesh and IAT mode, IAT within 40 dB of the mesh (peak at the
    99.5th percentile), with fewer elements."""
    (s0, sol0), (s1, sol1) = wall_solves[False], wall_solves[True]
    assert sol1.stats["elements"] < sol0.stats["elements"]
    m0 = _render(egl_ctx, s0, sol0, "mesh")
    m1, i1 = _render(egl_ctx, s1, sol1, "mesh"), _render(egl_ctx, s1, sol1, "iat")
    y0, y1, yi = (a @ LUMINANCE_WEIGHTS for a in (m0, m1, i1))
    hole0, hole1, holei = y0 == 0, y1 == 0, yi == 0
    assert hole0.sum() > 500
    assert (hole0 != hole1).sum() <= 0.01 * hole0.sum() and (hole1 != holei).sum() <= 0.01 * hole0.sum()
    lit = ~hole0 & ~hole1
    assert y1[lit].mean() == pytest.approx(y0[lit].mean(), rel=0.03)
    peak = np.percentile(y1, 99.5)
    psnr = 10 * np.log10(peak**2 / np.mean((i1 - m1) ** 2))
    assert psnr >= 40.0, f"IAT vs mesh {psnr:.1f} dB"


def test_panels_through_scale_variants_and_export(egl_ctx, wall_solves, tmp_path):
    """What works on roots works on panel cells: a light-only variant on the same mesh, a bake at
    scale 0.5 (clamped scaling keeps the cells' edges), and the exported GLB drawn by our GLB
    drawer shows the same lit pixels (the window a hole) as IAT mode."""
    from iat.export.gltf import export_glb
    from iat.render.glb_view import GlbView
    from iat.render.renderer import Renderer

    scene, sol = wall_solves[True]
    dim = solve(
        _scaled_emission(scene, 0.5), SolveOptions(max_depth=5), mesh=sol
    )  # same leaves, half the light
    np.testing.assert_array_equal(dim.vert_key, sol.vert_key)
    lit = sol.vert_radiance.sum(axis=1) > 0
    ratio = dim.vert_radiance[lit].sum(axis=1) / sol.vert_radiance[lit].sum(axis=1)
    assert np.median(ratio) == pytest.approx(0.5, rel=0.05)
    cam = Camera(eye=[2.0, 1.3, 2.9], target=[2.0, 1.1, 0.0], yfov=60.0)
    r = Renderer(ctx=egl_ctx)
    r.set_solution(sol)
    mesh = r.render(cam, size=(160, 120), mode="mesh")
    half = bake(sol, scene, BakePolicy(scale=0.5))
    r.set_baked(half)
    iat = r.render(cam, size=(160, 120), mode="iat")
    y, yi = mesh @ LUMINANCE_WEIGHTS, iat @ LUMINANCE_WEIGHTS
    peak = np.percentile(y, 99.5)
    assert 10 * np.log10(peak**2 / np.mean((iat - mesh) ** 2)) >= 30.0
    assert ((y == 0) != (yi == 0)).sum() <= 0.01 * (y == 0).sum()
    path = export_glb(half, tmp_path / "wall.glb")
    with GlbView(path, egl_ctx) as view:
        img = view.render(cam, (160, 120))
    assert ((img.max(axis=-1) > 0) != (iat.max(axis=-1) > 0)).sum() <= 0.01 * (y == 0).sum()


def _scaled_emission(scene, k: float):
    import dataclasses

    mats = [dataclasses.replace(m, emission=m.emission * k) for m in scene.materials]
    return dataclasses.replace(scene, materials=mats)
