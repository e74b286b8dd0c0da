"""Renderer (real EGL context, no mocks) and image output.

Scene of most tests: the unit square quad (-1..1)^2 in the z = 0 plane, seen
head-on from (0, 0, 3) with a 60 degree vertical field of view, so screen
position is an affine function of (u, v) and a field linear in (u, v) is
reproduced exactly by both Gouraud shading and bilinear texture filtering.
"""

from __future__ import annotations

import os
import types

import numpy as np
import pytest

from iat.camera import Camera
from iat.color import auto_exposure, srgb_encode, tonemap
from iat.errors import RenderError
from iat.geometry.quadtree import lattice_to_world
from iat.io.images import load_png, save_npy, save_png
from iat.io.scene import Material, Scene
from iat.render.gl import shader_dir, shader_source
from iat.render.renderer import PREVIEW_AMBIENT, Renderer

W, H = 64, 48
CAM = Camera(eye=[0.0, 0.0, 3.0], target=[0.0, 0.0, 0.0], yfov=60.0, znear=0.1, zfar=10.0)
QUAD = np.array([[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]])
# lattice points of a depth-0 patch, in vertex-key order: key = i * 2 + j
UV4 = np.array([[0, 0], [0, 1], [1, 0], [1, 1]])
TRIS = np.array([[0, 2, 3], [0, 3, 1]])  # (0,0) (1,0) (1,1) and (0,0) (1,1) (0,1)
LINEAR = (np.array([0.25, 0.5, 0.125]), np.array([0.5, 0.25, 0.25]), np.array([0.125, 0.125, 0.5]))


@pytest.fixture
def renderer(egl_ctx):
    r = Renderer(egl_ctx)
    yield r
    r.release()
    assert egl_ctx.error == "GL_NO_ERROR"


# -- synthetic inputs ------------------------------------------------------------------------
def linear_field(u, v, coeffs=LINEAR):
    """(k, 3) a + b u + c v."""
    a, b, c = coeffs
    u, v = np.asarray(u, float)[..., None], np.asarray(v, float)[..., None]
    return a + b * u + c * v


def solution_of(radiance, corners=QUAD):
    """A 1-patch depth-0 solution; radiance (4, 3) at the lattice points in key order."""
    return types.SimpleNamespace(
        max_depth=0,
        patch_corners=corners,
        patch_is_quad=np.array([True]),
        vert_key=np.arange(4, dtype=np.int64),
        vert_radiance=np.asarray(radiance, dtype=np.float32),
        tri_vertices=TRIS.astype(np.int32),
    )


def baked_of(page, pixel_format="rgba32f", mipmaps=False, corners=QUAD, material=0, details=None, **extra):
    """A Baked with no mesh part and one textured quad whose texel centres sit on its corners.

    page : (h, w, 3) texels; texel (x, y) = lattice point (u, v) = (x / (w-1), y / (h-1)).
    """
    page = np.asarray(page, dtype=np.float32)
    h, w = page.shape[:2]
    pos = lattice_to_world(corners, np.array([True]), np.zeros(4, int), UV4[:, 0], UV4[:, 1], 1)
    uv = np.stack([(0.5 + UV4[:, 0] * (w - 1)) / w, (0.5 + UV4[:, 1] * (h - 1)) / h], axis=1)
    ns = dict(
        mesh_positions=np.zeros((0, 3), np.float32),
        mesh_radiance=np.zeros((0, 3), np.float32),
        mesh_indices=np.zeros((0, 3), np.uint32),
        tex_positions=pos.astype(np.float32),
        tex_uv=uv.astype(np.float32),
        tex_layer=np.zeros(4, np.float32),
        tex_detail_uv=UV4.astype(np.float32),
        tex_material=np.full(4, material, np.int32),
        tex_indices=TRIS.astype(np.uint32),
        pages=page[None],
        policy=types.SimpleNamespace(pixel_format=pixel_format, mipmaps=mipmaps),
        detail_textures=details or {},
    )
    ns.update(extra)
    return types.SimpleNamespace(**ns)


def page_from_field(h, w, coeffs=LINEAR):
    x, y = np.meshgrid(np.arange(w) / (w - 1), np.arange(h) / (h - 1))
    return linear_field(x, y, coeffs).astype(np.float32)


def pixel_uv(w=W, h=H):
    """(h, w) u and v of the quad under each pixel centre (row 0 at the top)."""
    t = np.tan(np.radians(CAM.yfov) / 2) * 3.0
    col, row = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    x = (col / w * 2 - 1) * t * (w / h)
    y = (1 - row / h * 2) * t
    return (x + 1) / 2, (y + 1) / 2


def project(p, w=W, h=H):
    """(col, row) float pixel coordinates of world point p (row 0 at the top)."""
    c = CAM.clip_from_world(w / h) @ np.append(p, 1.0)
    ndc = c[:3] / c[3]
    return (ndc[0] + 1) / 2 * w, (1 - ndc[1]) / 2 * h


# -- shader lookup ---------------------------------------------------------------------------
def test_shaders_found_with_version_and_stage_define():
    d = shader_dir()
    for name in ("mesh", "iat", "preview", "composite"):
        assert (d / f"{name}.glsl").is_file()
    src = shader_source("mesh", "FRAGMENT_SHADER")
    assert src.startswith("#version 330 core\n#define FRAGMENT_SHADER\n")


def test_lattice_to_world_quad_and_triangle():
    corners = np.array([QUAD[0], [[0, 0, 0], [2, 0, 0], [0, 4, 0], [0, 4, 0]]], float)
    p = lattice_to_world(
        corners,
        np.array([True, False]),
        np.array([0, 0, 1, 1]),
        np.array([2, 1, 1, 0]),
        np.array([2, 3, 2, 4]),
        4,
    )
    np.testing.assert_allclose(p, [[0, 0, 0], [-0.5, 0.5, 0], [0.5, 2, 0], [0, 4, 0]])


# -- mesh mode -------------------------------------------------------------------------------
def test_constant_quad_renders_exact_value(renderer):
    value = np.array([0.3, 0.6, 0.9], np.float32)
    renderer.set_solution(solution_of(np.tile(value, (4, 1))))
    img = renderer.render(CAM, (W, H), "mesh")
    assert img.shape == (H, W, 3) and img.dtype == np.float32
    # the read-back is exact; interpolating a constant may cost one ulp
    np.testing.assert_array_max_ulp(img[H // 2, W // 2], value, maxulp=1)
    assert np.all(img[0, 0] == 0) and np.all(img[-1, -1] == 0)  # background black
    s = renderer.stats()
    assert (s["mode"], s["triangles"], s["draw_calls"]) == ("mesh", 2, 1)


def test_mesh_linear_gradient_matches_analytic_field(renderer):
    renderer.set_solution(solution_of(linear_field(UV4[:, 0], UV4[:, 1])))
    img = renderer.render(CAM, (W, H), "mesh")
    u, v = pixel_uv()
    inside = (u > 0.02) & (u < 0.98) & (v > 0.02) & (v < 0.98)
    assert inside.sum() > 500
    np.testing.assert_allclose(img[inside], linear_field(u[inside], v[inside]), atol=2e-5)
    assert np.all(img[(u < -0.02) | (u > 1.02)] == 0)


def test_mesh_corner_pixels_near_vertex_values(renderer):
    # at lattice points (0,0) (0,1) (1,0) (1,1), the key order
    rad = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 1.0, 1.0]], np.float32)
    renderer.set_solution(solution_of(rad))
    img = renderer.render(CAM, (W, H), "mesh")
    for k, (i, j) in enumerate(UV4):
        corner = QUAD[0][[0, 3, 1, 2][2 * i + j]]
        col, row = project(corner)
        # one pixel inside the corner: the value moves by at most ~2 pixels' worth of gradient
        c = int(col + (1.5 if i == 0 else -1.5))
        r = int(row + (-1.5 if j == 0 else 1.5))
        np.testing.assert_allclose(img[r, c], rad[k], atol=0.1)
    # the centre lies on the diagonal (0,0)-(1,1) that splits the quad: the mean of those two vertices
    np.testing.assert_allclose(img[H // 2, W // 2], (rad[0] + rad[3]) / 2, atol=0.05)


# -- IAT mode --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "pixel_format, mipmaps, atol",
    [("rgba32f", False, 1e-4), ("rgba32f", True, 1e-4), ("rgba16f", False, 1e-3), ("rgba8", True, 2.5 / 255)],
)
def test_iat_texture_equals_gouraud_mesh_on_linear_field(renderer, pixel_format, mipmaps, atol):
    """The project's core claim: one texel per mesh vertex, texel centres on the corners ==
    the vertex-coloured mesh (exact for a field linear in u and v)."""
    renderer.set_solution(solution_of(linear_field(UV4[:, 0], UV4[:, 1])))
    mesh = renderer.render(CAM, (W, H), "mesh")
    renderer.set_baked(baked_of(page_from_field(2, 2), pixel_format, mipmaps))
    iat = renderer.render(CAM, (W, H), "iat")
    assert (mesh > 0).any(axis=2).sum() > 500
    np.testing.assert_array_equal((mesh > 0).any(axis=2), (iat > 0).any(axis=2))  # same coverage
    assert np.abs(iat - mesh).max() < atol
    s = renderer.stats()
    assert (s["triangles"], s["draw_calls"]) == (2, 1)


def test_iat_rgba8_pages_scaled_by_page_scale(renderer):
    renderer.set_solution(solution_of(4.0 * linear_field(UV4[:, 0], UV4[:, 1])))
    mesh = renderer.render(CAM, (W, H), "mesh")
    renderer.set_baked(baked_of(4.0 * page_from_field(2, 2), "rgba8", page_scale=4.0))
    err = np.abs(renderer.render(CAM, (W, H), "iat") - mesh).max()
    assert 0 < err < 4.0 * 1.5 / 255  # 8-bit steps of page_scale / 255, filtered


def test_iat_larger_page_still_matches_mesh(renderer):
    """A 5x5-texel page (depth 2) of the same linear field: bilinear texture == the field."""
    renderer.set_solution(solution_of(linear_field(UV4[:, 0], UV4[:, 1])))
    mesh = renderer.render(CAM, (W, H), "mesh")
    renderer.set_baked(baked_of(page_from_field(5, 5), "rgba32f"))
    assert np.abs(renderer.render(CAM, (W, H), "iat") - mesh).max() < 1e-4


def test_iat_mesh_part_and_layers(renderer):
    """Mesh part drawn vertex-coloured next to a textured quad on page 1 of 2."""
    left = QUAD.copy()
    left[0, :, 0] = left[0, :, 0] * 0.5 - 0.5  # x in [-1, 0]
    right = QUAD.copy()
    right[0, :, 0] = right[0, :, 0] * 0.5 + 0.5  # x in [0, 1]
    pages = np.zeros((2, 2, 2, 3), np.float32)
    pages[1] = [0.7, 0.2, 0.1]
    b = baked_of(pages[1], corners=right, tex_layer=np.ones(4, np.float32), pages=pages)
    b.mesh_positions = left[0].astype(np.float32)
    b.mesh_radiance = np.tile(np.float32([0.1, 0.4, 0.9]), (4, 1))
    b.mesh_indices = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    renderer.set_baked(b)
    img = renderer.render(CAM, (W, H), "iat")
    cl, r = project([-0.5, 0, 0])
    cr, _ = project([0.5, 0, 0])
    np.testing.assert_allclose(img[int(r), int(cl)], [0.1, 0.4, 0.9], atol=1e-6)
    np.testing.assert_allclose(img[int(r), int(cr)], [0.7, 0.2, 0.1], atol=1e-6)
    s = renderer.stats()
    assert (s["triangles"], s["draw_calls"]) == (4, 2)


def test_iat_detail_texture_multiplies_incoming_light(renderer):
    """Two quads: plain material 0, detail material 1 -> one draw call each for the textured part."""
    left = QUAD.copy()
    left[0, :, 0] = left[0, :, 0] * 0.5 - 0.5
    right = QUAD.copy()
    right[0, :, 0] = right[0, :, 0] * 0.5 + 0.5
    a = baked_of(np.full((2, 2, 3), 0.5, np.float32), corners=left, material=0)
    b = baked_of(np.full((2, 2, 3), 0.5, np.float32), corners=right, material=1)
    detail = np.zeros((4, 4, 3), np.float32)
    detail[:] = [1.0, 0.5, 0.25]
    merged = baked_of(
        np.full((2, 2, 3), 0.5, np.float32),
        "rgba16f",
        True,
        tex_positions=np.concatenate([a.tex_positions, b.tex_positions]),
        tex_uv=np.concatenate([a.tex_uv, b.tex_uv]),
        tex_layer=np.zeros(8, np.float32),
        tex_detail_uv=np.concatenate([a.tex_detail_uv, b.tex_detail_uv]) * 3,
        tex_material=np.concatenate([a.tex_material, b.tex_material]),
        tex_indices=np.concatenate([TRIS, TRIS + 4]).astype(np.uint32),
        tex_detail=np.repeat(np.float32([0, 1]), 4),
        detail_textures={1: detail},
    )
    renderer.set_baked(merged)
    img = renderer.render(CAM, (W, H), "iat")
    cl, r = project([-0.5, 0, 0])
    cr, _ = project([0.5, 0, 0])
    np.testing.assert_allclose(img[int(r), int(cl)], [0.5, 0.5, 0.5], atol=1e-3)
    np.testing.assert_allclose(img[int(r), int(cr)], [0.5, 0.25, 0.125], atol=1e-3)
    s = renderer.stats()
    assert (s["triangles"], s["draw_calls"]) == (4, 2)


# -- preview ---------------------------------------------------------------------------------
def two_patch_scene(detail=None):
    vertices = np.array(
        [[-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0], [0.1, -1, 0], [1, -1, 0], [0.1, 1, 0]], float
    )
    materials = [
        Material("lamp", albedo=[0.4, 0.6, 0.8], emission=[0.1, 0.0, 0.0]),
        Material("wall", albedo=[0.2, 0.3, 0.4], detail=detail),
    ]
    return Scene(
        vertices=vertices,
        patch_corners=[[0, 1, 2, 3], [4, 5, 6, -1]],
        patch_material=[0, 1],
        materials=materials,
        patch_uv=np.array([[[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 0], [2, 0], [0, 2], [0, 2]]], float),
    )


def test_preview_quad_and_triangle(renderer):
    renderer.set_scene(two_patch_scene())
    img = renderer.render(CAM, (W, H), "preview")
    cq, r = project([-0.5, 0, 0])
    ct, rt = project([0.3, -0.5, 0])
    np.testing.assert_allclose(img[int(r), int(cq)], [0.1 + 0.2, 0.3, 0.4], atol=1e-6)
    np.testing.assert_allclose(img[int(rt), int(ct)], PREVIEW_AMBIENT * np.array([0.2, 0.3, 0.4]), atol=1e-6)
    cx, ry = project([0.9, 0.9, 0])  # above the triangle's hypotenuse: background
    assert np.all(img[int(ry), int(cx)] == 0)
    s = renderer.stats()
    assert (s["triangles"], s["draw_calls"]) == (3, 1)


def test_preview_detail_texture(renderer):
    renderer.set_scene(two_patch_scene(detail=np.full((8, 8, 3), [0.9, 0.5, 0.1], np.float32)))
    img = renderer.render(CAM, (W, H), "preview")
    ct, rt = project([0.3, -0.5, 0])
    np.testing.assert_allclose(img[int(rt), int(ct)], PREVIEW_AMBIENT * np.array([0.9, 0.5, 0.1]), atol=1e-6)
    assert renderer.stats()["draw_calls"] == 2


def test_preview_reference_image(renderer, reference_image):
    renderer.set_scene(two_patch_scene())
    reference_image("preview_two_patches", renderer.render(CAM, (32, 24), "preview"), atol=1e-5)


# -- split, diff, draw -----------------------------------------------------------------------
@pytest.fixture
def mesh_and_iat(renderer):
    """Mesh: the linear field; IAT: a different linear field, so they differ everywhere."""
    renderer.set_solution(solution_of(linear_field(UV4[:, 0], UV4[:, 1])))
    other = (LINEAR[0] + 0.1, LINEAR[1] * 0.5, LINEAR[2])
    renderer.set_baked(baked_of(page_from_field(2, 2, other)))
    mesh = renderer.render(CAM, (W, H), "mesh")
    iat = renderer.render(CAM, (W, H), "iat")
    return renderer, mesh, iat


def test_split_left_mesh_right_iat(mesh_and_iat):
    r, mesh, iat = mesh_and_iat
    img = r.render(CAM, (W, H), "split", split=0.25)
    np.testing.assert_array_equal(img[:, :16], mesh[:, :16])
    np.testing.assert_array_equal(img[:, 16:], iat[:, 16:])
    s = r.stats()
    assert s["modes"]["mesh"]["draw_calls"] == 1 and s["modes"]["iat"]["draw_calls"] == 1


def test_diff_is_gain_times_abs_difference(mesh_and_iat):
    r, mesh, iat = mesh_and_iat
    img = r.render(CAM, (W, H), "diff", diff_gain=4.0)
    np.testing.assert_allclose(img, 4.0 * np.abs(mesh - iat), atol=1e-6)
    assert img.max() > 0.1


def test_draw_tonemaps_into_bound_framebuffer(egl_ctx, mesh_and_iat):
    r, mesh, iat = mesh_and_iat
    ldr = egl_ctx.simple_framebuffer((W + 10, H + 6), components=4)  # RGBA8, not sRGB
    ldr.use()
    ldr.clear(1.0, 1.0, 1.0, 1.0)
    split = np.concatenate([mesh[:, : W // 2], iat[:, W // 2 :]], axis=1)
    for mode, expected in (("mesh", mesh), ("diff", 3.0 * np.abs(mesh - iat)), ("split", split)):
        r.draw(CAM, mode, viewport=(10, 6, W, H), exposure=1.5, diff_gain=3.0)
        egl_ctx.finish()
        raw = np.frombuffer(ldr.read(components=3), np.uint8).reshape(H + 6, W + 10, 3)[::-1]
        got = raw[:H, 10:].astype(int)  # the viewport; row 0 at the top
        assert np.abs(got - tonemap(expected, 1.5).astype(int)).max() <= 1
        assert np.all(raw[H:, :] == 255) and np.all(raw[:, :10] == 255)  # outside the viewport untouched
    egl_ctx.detect_framebuffer(0).use()  # never leave a released framebuffer bound
    ldr.release()


# -- errors, lifetime, memory ---------------------------------------------------------------
def test_errors_name_the_cause(renderer):
    with pytest.raises(RenderError, match="needs set_baked"):
        renderer.set_solution(solution_of(np.zeros((4, 3))))
        renderer.render(CAM, (8, 8), "iat")
    with pytest.raises(RenderError, match="unknown render mode 'wire'"):
        renderer.render(CAM, (8, 8), "wire")
    bad = solution_of(np.zeros((4, 3)))
    bad.tri_vertices = np.array([[0, 1, 7]])
    with pytest.raises(RenderError, match="refer to vertex 7"):
        renderer.set_solution(bad)
    with pytest.raises(RenderError, match="unknown pixel format 'bc7'"):
        renderer.set_baked(baked_of(np.zeros((2, 2, 3)), "bc7"))


def test_own_context_and_release():
    r = Renderer()  # creates and owns an EGL context
    r.set_solution(solution_of(np.full((4, 3), 0.5)))
    assert r.render(CAM, (16, 12), "mesh")[6, 8, 0] == np.float32(0.5)
    assert r.gl_object_count() > 0
    r.release()
    assert r.gl_object_count() == 0
    with pytest.raises(RenderError, match="released"):
        r.render(CAM, (16, 12), "mesh")


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_resetting_baked_does_not_grow_gl_objects_or_memory(renderer):
    big = np.random.default_rng(0).random((256, 256, 3), dtype=np.float32)  # 1 MiB as RGBA32F
    renderer.set_baked(baked_of(big, "rgba32f", True))
    renderer.render(CAM, (W, H), "iat")
    n_objects = renderer.gl_object_count()
    pages_glo = renderer.page_array.glo
    for _ in range(20):  # warm up the allocator
        renderer.set_baked(baked_of(big, "rgba32f", True))
    rss = _rss_bytes()
    for k in range(200):
        if k % 20 == 10:  # a different page shape: the texture is reallocated, not leaked
            renderer.set_baked(baked_of(big[:128], "rgba32f", True))
        else:
            renderer.set_baked(baked_of(big, "rgba32f", True))
        assert renderer.gl_object_count() == n_objects
    glo = renderer.page_array.glo
    assert glo != pages_glo  # the shape changes reallocated the page texture
    renderer.set_baked(baked_of(big, "rgba32f", True))
    assert renderer.page_array.glo == glo  # same shape: written in place
    growth = _rss_bytes() - rss
    assert growth < 64 * 2**20, f"RSS grew by {growth / 2**20:.0f} MiB over 200 re-sets"
    renderer.render(CAM, (W, H), "iat")
    assert renderer.gl_object_count() == n_objects


def test_geometry_buffers_keep_their_names_when_data_grows(renderer):
    renderer.set_solution(solution_of(np.full((4, 3), 0.5)))
    names = {k: b.glo for k, b in renderer.solution_geometry.buffers.items()}
    n = renderer.gl_object_count()
    bigger = solution_of(np.full((4, 3), 0.25))
    bigger.tri_vertices = np.tile(TRIS, (500, 1)).astype(np.int32)  # grows the index buffer
    renderer.set_solution(bigger)
    assert {k: b.glo for k, b in renderer.solution_geometry.buffers.items()} == names
    assert renderer.gl_object_count() == n
    assert renderer.render(CAM, (16, 12), "mesh")[6, 8, 0] == np.float32(0.25)
    assert renderer.stats()["triangles"] == 1000


# -- image output ----------------------------------------------------------------------------
def test_tonemap_exact_values():
    lin = np.array([[[0.0, 1.0, 0.5], [0.18, 0.001, 2.0], [-1.0, np.nan, 0.0031308]]], np.float32)
    np.testing.assert_array_equal(tonemap(lin), [[[0, 255, 188], [118, 3, 255], [0, 0, 10]]])
    np.testing.assert_array_equal(tonemap(np.full((1, 1, 3), 0.25, np.float32), exposure=2.0), [[[188] * 3]])
    assert srgb_encode(np.array([1.0]))[0] == pytest.approx(1.0)


def test_auto_exposure():
    img = np.zeros((10, 10, 3), np.float32)
    assert auto_exposure(img) == 1.0
    img[:] = 2.0
    assert auto_exposure(img) == pytest.approx(0.4)
    assert tonemap(img, exposure=None)[0, 0, 0] == tonemap(np.full((1, 1, 3), 0.8), 1.0)[0, 0, 0]


def test_png_and_npy_round_trip(tmp_path):
    lin = np.random.default_rng(1).random((6, 7, 3), dtype=np.float32)
    p = save_png(tmp_path / "a" / "b" / "img.png", lin, exposure=0.7)
    np.testing.assert_array_equal(load_png(p), tonemap(lin, 0.7))
    q = save_npy(tmp_path / "c" / "img.npy", lin)
    back = np.load(q)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, lin)


def test_failed_write_leaves_old_file(tmp_path, monkeypatch):
    from PIL import Image

    target = tmp_path / "img.png"
    save_png(target, np.zeros((2, 2, 3), np.float32))
    before = target.read_bytes()

    def broken_save(self, *a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(Image.Image, "save", broken_save)
    with pytest.raises(OSError, match="disk full"):
        save_png(target, np.ones((2, 2, 3), np.float32))
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img.png"]  # no temp file left
    with pytest.raises(ValueError, match=r"\(h, w, 3\)"):
        save_png(target, np.ones((2, 2), np.float32))


# -- pixel formats on the GPU -----------------------------------------------------------------


def _internal_format(renderer) -> int:
    """GL_TEXTURE_INTERNAL_FORMAT of level 0 of the page texture (read with glGetTexLevelParameteriv)."""
    import ctypes

    from iat.render.gl import libgl

    gl = libgl()
    gl.glGetTexLevelParameteriv.argtypes = [
        ctypes.c_uint,
        ctypes.c_int,
        ctypes.c_uint,
        ctypes.POINTER(ctypes.c_int),
    ]
    renderer.page_array.use(0)
    v = ctypes.c_int()
    gl.glGetTexLevelParameteriv(0x8C1A, 0, 0x1003, ctypes.byref(v))
    return v.value


@pytest.mark.parametrize("mipmaps", [False, True])
def test_rgba8_pages_are_srgb_and_dark_texels_survive(renderer, mipmaps):
    """rgba8 texels are sRGB8 of page / page_scale in a GL_SRGB8_ALPHA8 texture: decoded to linear
    before filtering, so a texel at 0.125 % of the scale (sRGB code 4; linear UNORM8 would round it
    to 0, black) renders as the value the baker stored; mipmaps are built in linear space."""
    from iat.bake.formats import quantise_rgba8

    scale = 8.0
    page = np.empty((4, 4, 3), np.float32)
    page[:] = [0.01, 0.4, 5.0]  # 0.125 %, 5 % and 62 % of the scale
    q = quantise_rgba8(page, scale)
    assert abs(q[0, 0, 0] / 0.01 - 1) < 0.05  # the baker's own rounding is fine
    renderer.set_baked(baked_of(page, "rgba8", mipmaps, page_scale=scale, mip_levels=2))
    assert _internal_format(renderer) == 0x8C43  # GL_SRGB8_ALPHA8
    img = renderer.render(CAM, (W, H), "iat")
    lit = img[(img > 0).any(axis=2)]
    assert len(lit) > 500
    # llvmpipe's sRGB decode is approximate (2.5 % at code 4, 0.4 % at code 89; exact on GPUs'
    # tables); the linear upload this replaces showed the dark channel as 0
    np.testing.assert_allclose(lit, np.broadcast_to(q[0, 0], lit.shape), rtol=0.03)
    assert renderer.ctx.error == "GL_NO_ERROR"


def test_rgb9e5_pages_upload_as_rgb9e5_and_render_the_stored_values(renderer):
    from iat.bake.formats import quantise_rgb9e5

    page = page_from_field(5, 5) * np.float32([3.0, 0.01, 700.0])  # channels 5 decades apart
    q = quantise_rgb9e5(page)
    renderer.set_baked(baked_of(q, "rgb9e5"))
    assert _internal_format(renderer) == 0x8C3D  # GL_RGB9_E5: 4 bytes a texel
    got = renderer.render(CAM, (W, H), "iat")
    renderer.set_baked(baked_of(q, "rgba32f"))  # the same stored values, exactly
    want = renderer.render(CAM, (W, H), "iat")
    assert (want > 0).any(axis=2).sum() > 500
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    assert renderer.ctx.error == "GL_NO_ERROR"


def test_same_baked_pages_are_not_uploaded_twice(renderer):
    """The Baker's cached pages (read-only) already on the GPU are not written again; other pages are.
    Shown with real GL: texels overwritten behind the renderer's back stay until other pages come."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from tests.test_bake import grid_scene_solution

    b = Baker(grid_scene_solution())
    cam = Camera(eye=[2.0, 1.5, 5.0], target=[2.0, 1.5, 0.0], yfov=60.0)
    bk = b.bake(BakePolicy(threshold=0, mipmaps=False))
    assert bk.gpu_form() is not None and not bk.gpu_form().flags.writeable
    renderer.set_baked(bk)
    first = renderer.render(cam, (W, H), "iat")
    assert (first > 0).any(axis=2).sum() > 500
    tex = renderer.page_array
    tex.write(
        np.zeros((tex.height, tex.width, 4), np.float16).tobytes(),
        viewport=(0, 0, 0, tex.width, tex.height, 1),
    )
    renderer.set_baked(b.bake(BakePolicy(threshold=0, mipmaps=False)))  # cache hit: the same array
    assert renderer.render(cam, (W, H), "iat").max() == 0.0
    renderer.set_baked(b.bake(BakePolicy(threshold=0, mipmaps=False, scale=0.5)))  # other pages
    renderer.set_baked(bk)
    np.testing.assert_array_equal(renderer.render(cam, (W, H), "iat"), first)


def _fresh_iat_render(ctx, baked, cam) -> np.ndarray:
    """``baked`` drawn in iat mode by a new Renderer (nothing kept from earlier uploads)."""
    fresh = Renderer(ctx)
    try:
        fresh.set_baked(baked)
        return fresh.render(cam, (W, H), "iat")
    finally:
        fresh.release()


def test_threshold_walk_on_one_renderer_matches_fresh_renderers(renderer, egl_ctx):
    """Mesh parts are prefixes of one depth-sorted mesh, written once and drawn by count; pages are
    written without conversion. A threshold walk down and up on one renderer draws, at every step,
    exactly what a fresh renderer draws for that bake."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from tests.test_bake import grid_scene_solution

    sol = grid_scene_solution()
    b = Baker(sol)
    cam = Camera(eye=[2.0, 1.5, 5.0], target=[2.0, 1.5, 0.0], yfov=60.0)
    deepest = int(sol.patch_depth().max())
    walk = list(range(deepest + 1, -1, -1)) + list(range(1, deepest + 2))
    for t in walk:
        bk = b.bake(BakePolicy(threshold=t))
        renderer.set_baked(bk)
        got = renderer.render(cam, (W, H), "iat")
        want = _fresh_iat_render(egl_ctx, bk, cam)
        assert (want > 0).any(axis=2).sum() > 500
        np.testing.assert_array_equal(got, want, err_msg=f"threshold {t}")
        assert renderer.stats()["triangles"] == len(bk.mesh_indices) + len(bk.tex_indices)


def test_scale_walk_keeps_the_page_texture_and_matches_fresh_renderers(renderer, egl_ctx):
    """Pages that fit in the page texture are written into its corner (texture coordinates scaled
    by powers of two, exactly) instead of re-creating the texture: a scale walk down and up (every
    format, mip levels on) draws, at every step, exactly what a fresh renderer draws; the texture is
    re-created only to grow or for another format, and ``page_texture`` tells allocated from used."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from tests.test_bake import grid_scene_solution

    b = Baker(grid_scene_solution())
    cam = Camera(eye=[2.0, 1.5, 5.0], target=[2.0, 1.5, 0.0], yfov=60.0)
    steps = [(0, 1.0), (0, 0.5), (0, 2.0), (0, 0.25), (1, 1.0), (0, 0.7), (2, 0.125), (0, 1.0)]
    for fmt in ("rgba16f", "rgba8", "rgb9e5"):
        created = []
        for t, s in steps:
            bk = b.bake(BakePolicy(threshold=t, scale=s, pixel_format=fmt))
            assert bk.mip_levels >= 2
            renderer.set_baked(bk)
            if renderer.page_array not in created:
                created.append(renderer.page_array)
            got = renderer.render(cam, (W, H), "iat")
            want = _fresh_iat_render(egl_ctx, bk, cam)
            assert (want > 0).any(axis=2).sum() > 300
            np.testing.assert_array_equal(got, want, err_msg=f"{fmt} threshold {t} scale {s}")
            m, pt = bk.memory, renderer.page_texture
            assert pt["used"] == (m.page_width, m.page_height, m.pages) and pt["pixel_format"] == fmt
            aw, ah, an = pt["allocated"]
            assert aw >= m.page_width and ah >= m.page_height and an >= m.pages
        # the first bake of the format, then growing once to scale 2's pages; never for smaller ones
        assert len(created) == 2, fmt
        assert renderer.page_texture["allocated"][:2] == (2 * 128, 2 * 64)
    assert renderer.ctx.error == "GL_NO_ERROR"


def test_page_texture_is_recreated_when_pages_are_much_smaller_or_not_power_of_two(renderer):
    """Pages using under 1/64 of the texture, or whose size does not divide it by a power of two (the
    texture coordinates could not scale exactly), get a texture of their own size."""
    renderer.set_solution(solution_of(linear_field(UV4[:, 0], UV4[:, 1])))
    mesh = renderer.render(CAM, (W, H), "mesh")
    renderer.set_baked(baked_of(page_from_field(64, 64), "rgba16f"))
    assert renderer.page_texture["allocated"] == (64, 64, 1)
    renderer.set_baked(baked_of(page_from_field(16, 16), "rgba16f"))  # 1/16: kept
    assert renderer.page_texture["allocated"] == (64, 64, 1)
    assert renderer.page_texture["used"] == (16, 16, 1)
    iat = renderer.render(CAM, (W, H), "iat")  # the 16 x 16 corner only, the field exactly
    assert (mesh > 0).any(axis=2).sum() > 500
    np.testing.assert_array_equal((mesh > 0).any(axis=2), (iat > 0).any(axis=2))
    assert np.abs(iat - mesh).max() < 1e-3
    renderer.set_baked(baked_of(page_from_field(12, 12), "rgba16f"))  # 64 / 12: not a power of two
    assert renderer.page_texture["allocated"] == (12, 12, 1)
    renderer.set_baked(baked_of(page_from_field(96, 96), "rgba16f"))  # grows: 96 / 12 = 8
    assert renderer.page_texture["allocated"] == (96, 96, 1)
    renderer.set_baked(baked_of(page_from_field(8, 8), "rgba16f"))  # 64 / 9216: under 1/64
    assert renderer.page_texture["allocated"] == (8, 8, 1)


# -- detail textures in mesh mode --------------------------------------------------------------
def test_mesh_mode_multiplies_incoming_light_by_the_detail_texture(renderer):
    """A detail patch's vertices carry radiance / albedo once the scene is known; mesh.glsl
    multiplies by the detail texture as iat.glsl does (one draw call for the detail material)."""
    tile = np.full((8, 8, 3), [0.9, 0.5, 0.1], np.float32)
    scene = Scene(
        vertices=QUAD[0],
        patch_corners=[[0, 1, 2, 3]],
        patch_material=[0],
        materials=[Material("tiles", albedo=[0.5, 0.5, 0.5], detail=tile)],
        patch_uv=np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float),
    )
    sol = solution_of(np.full((4, 3), 0.25, np.float32))
    sol.patch_material, sol.patch_albedo = np.array([0]), np.array([[0.5, 0.5, 0.5]])
    renderer.set_solution(sol)  # no scene yet: radiance as it is
    c, r = project([0.0, 0.0, 0.0])
    np.testing.assert_allclose(renderer.render(CAM, (W, H), "mesh")[int(r), int(c)], [0.25] * 3, atol=1e-5)
    renderer.set_scene(scene)
    renderer.set_solution(sol)
    img = renderer.render(CAM, (W, H), "mesh")
    np.testing.assert_allclose(img[int(r), int(c)], [0.45, 0.25, 0.05], atol=1e-4)  # 0.25 / 0.5 x tile
    assert renderer.stats()["draw_calls"] == 1


def test_pool_mesh_mode_shows_the_detail_textures_as_iat_mode_does(renderer):
    """The pool's tiles (detail textures): mesh mode and IAT mode at threshold 0 match closely, in
    their fine structure too (high-pass difference well below that of a mesh without detail)."""
    from pathlib import Path

    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions
    from iat.radiosity.cache import cached_solve

    root = Path(__file__).resolve().parent.parent
    quick = SolveOptions(
        max_depth=4, samples=1, max_shots=30, convergence=0.2, refine_indirect=False, tolerance=0.1
    )  # as tests/test_export_clients.py: the same cached solution
    scene, sol, _ = cached_solve(root / "sample_models" / "pool.glb", quick, root / "out" / "acceptance")
    renderer.set_scene(scene)
    renderer.set_solution(sol)
    renderer.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0)))
    cam, size = scene.default_camera(), (320, 240)
    mesh, iat = renderer.render(cam, size, "mesh"), renderer.render(cam, size, "iat")
    plain_r = Renderer(renderer.ctx)
    try:
        plain_r.set_solution(sol)  # no scene: no detail textures
        plain = plain_r.render(cam, size, "mesh")
    finally:
        plain_r.release()

    def high_pass(img, k=3):
        g = img.mean(axis=2)
        pad = np.pad(g, k, mode="edge")
        n = 2 * k + 1
        blur = sum(pad[dy : dy + g.shape[0], dx : dx + g.shape[1]] for dy in range(n) for dx in range(n))
        return g - blur / n**2

    rel = np.abs(mesh - iat).mean() / np.abs(iat).mean()
    assert rel < 0.03, rel
    hp_iat = high_pass(iat)
    with_detail = np.abs(high_pass(mesh) - hp_iat).mean()
    without = np.abs(high_pass(plain) - hp_iat).mean()
    assert with_detail < 0.5 * without, (with_detail, without)
