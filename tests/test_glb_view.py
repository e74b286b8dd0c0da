"""iat.glb_view: our own drawer of exported GLB files, against the IAT renderer."""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest
from PIL import Image

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.color import srgb_decode, srgb_encode
from iat.errors import LoadError
from iat.export.gltf import export_glb, radiance_scale
from iat.io.glb import GlbBuilder
from iat.render.glb_view import GlbView, is_iat_export, load_glb, render_glb
from tests.test_bake import detail_scene, grid_scene_solution
from tests.test_flatten import linear_field, wavy_field

W, H = 160, 120
GRID_CAM = Camera(
    eye=np.array([2.0, 1.5, 4.0]), target=np.array([2.0, 1.5, 0.0]), yfov=50.0, znear=0.1, zfar=20
)


def png(rgb8: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.asarray(rgb8, dtype=np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def srgb_encode01(x):
    """sRGB-encoded values of linear ``x`` clamped to [0, 1]."""
    return srgb_encode(np.clip(np.asarray(x, dtype=np.float64), 0, 1))


def srgb_decode8(c8):
    """Linear values of 8-bit sRGB codes."""
    return srgb_decode(np.asarray(c8, dtype=np.float64) / 255.0)


@pytest.fixture(scope="module")
def mixed():
    sol = grid_scene_solution(wavy_field, seed=2)
    return sol, Baker(sol).bake(BakePolicy(threshold=4, mipmaps=False))


def test_load_reads_what_export_wrote(mixed, tmp_path):
    _, bk = mixed
    path = export_glb(bk, tmp_path / "m.glb", watertight=False, match_clip=False)
    doc = load_glb(path)
    assert is_iat_export(path)
    assert doc.triangles == bk.memory.triangles
    s = radiance_scale(bk)
    assert [p.radiance_scale for p in doc.primitives] == pytest.approx([s] * len(doc.primitives))
    names = sorted(p.node for p in doc.primitives)
    assert names == ["iat_mesh", "iat_page0"]
    mesh = next(p for p in doc.primitives if p.node == "iat_mesh")
    np.testing.assert_array_equal(mesh.positions, bk.mesh_positions)
    np.testing.assert_allclose(mesh.colors[:, :3], np.clip(bk.mesh_radiance / s, 0, 1), rtol=1e-6)
    page = next(p for p in doc.primitives if p.node == "iat_page0")
    assert page.base_texture is not None and page.ill_texture is None
    t = doc.textures[page.base_texture]
    assert (t["min"], t["mag"], t["wrap_s"], t["wrap_t"]) == (9729, 9729, 33071, 33071)
    assert t["image"].shape[:2] == bk.pages.shape[1:3]
    allpos = np.concatenate([bk.mesh_positions, bk.tex_positions])
    np.testing.assert_allclose(doc.bounds, [allpos.min(0), allpos.max(0)], atol=1e-6)


def test_draws_an_export_like_iat_mode(mixed, egl_ctx, tmp_path):
    """Same pixels as the IAT renderer up to the 8-bit sRGB PNG of the pages (and COLOR_0 in f32)."""
    from iat.render.renderer import Renderer

    _, bk = mixed
    path = export_glb(bk, tmp_path / "m.glb", watertight=False, match_clip=False)
    s = radiance_scale(bk)
    r = Renderer(egl_ctx)
    try:
        r.set_baked(bk)
        ref = r.render(GRID_CAM, (W, H), mode="iat")
    finally:
        r.release()
    with GlbView(path, egl_ctx) as view:
        img = view.render(GRID_CAM, (W, H))
        assert view.draw_calls == 2 and view.triangles == bk.memory.triangles
    lit = ref.max(axis=-1) > 0
    np.testing.assert_array_equal(img.max(axis=-1) > 0, lit)
    # below the scale the two differ by the 8-bit sRGB rounding of the page texels (and of
    # COLOR_0's f32): compare in sRGB codes of radiance / scale
    below = lit & (ref < 0.98 * s).all(axis=-1)
    codes = np.abs(srgb_encode01(img / s) - srgb_encode01(ref / s))[below] * 255
    assert codes.max() <= 1.5, codes.max()
    # above the scale both clip: the file shows radiance_scale, at most
    assert img.max() <= s * (1 + 1e-5)
    assert egl_ctx.error == "GL_NO_ERROR"


def test_layered_export_multiplies_detail_and_illumination(egl_ctx, tmp_path):
    from iat.render.renderer import Renderer

    sol, sc, _ = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=0, mipmaps=False))
    cam = Camera(
        eye=np.array([3.5, 0.5, 2.0]), target=np.array([3.5, 0.5, 0.0]), yfov=45.0, znear=0.1, zfar=20
    )
    r = Renderer(egl_ctx)
    try:
        r.set_baked(bk)
        ref = r.render(cam, (W, H), mode="iat")
    finally:
        r.release()
    doc = load_glb(export_glb(bk, tmp_path / "layered.glb", sc, layered=True))
    layered = next(p for p in doc.primitives if p.ill_texture is not None)
    assert layered.base_set == 0 and layered.ill_set == 1
    with GlbView(doc, egl_ctx) as view:
        img = view.render(cam, (W, H))
    lit = ref.max(axis=-1) > 0
    assert lit.mean() > 0.2
    np.testing.assert_array_equal(img.max(axis=-1) > 0, lit)
    # both images show albedo(detail) x incoming light; the file stores both in 8-bit sRGB,
    # and its detail texture is mipmapped from the PNG (the renderer's from float32)
    rel = np.abs(img - ref)[lit] / np.maximum(ref[lit], 1e-3)
    assert np.median(rel) < 0.01 and np.percentile(rel, 99) < 0.05


def test_hdr_layered_export_draws_like_the_plain_one(egl_ctx, tmp_path):
    """``--hdr`` (RGBM lightmaps): the drawer decodes rgb x alpha x range, so where nothing clips the
    image is the plain layered one's (within the two 8-bit encodings)."""
    sol, sc, _ = detail_scene()
    bk = Baker(sol, sc).bake(BakePolicy(threshold=0, mipmaps=False))
    cam = Camera(
        eye=np.array([3.5, 0.5, 2.0]), target=np.array([3.5, 0.5, 0.0]), yfov=45.0, znear=0.1, zfar=20
    )
    images = []
    for hdr in (False, True):
        doc = load_glb(export_glb(bk, tmp_path / f"layered-{hdr}.glb", sc, layered=True, hdr=hdr))
        assert any(p.ill_rgbm > 0 for p in doc.primitives) == hdr
        with GlbView(doc, egl_ctx) as view:
            images.append(view.render(cam, (W, H)))
    plain, rgbm = images
    lit = plain.max(axis=-1) > 0
    assert lit.mean() > 0.2
    rel = np.abs(rgbm - plain)[lit] / np.maximum(plain[lit], 1e-3)
    assert np.median(rel) < 0.02 and np.percentile(rel, 99) < 0.08


def _quad_glb(path, sampler: dict, texel_rgb8, node_kwargs=None, factor=(1.0, 1.0, 1.0, 1.0), colors=None):
    """A unit quad in z = 0 with a 2 x 2 texture, uv = (x, y), drawn through a node."""

    class B(GlbBuilder):
        def to_json(self):
            doc = super().to_json()
            doc["samplers"] = [sampler]
            return doc

    g = B()
    m = g.add_material("q", base_color=factor, base_color_png=png(texel_rgb8), unlit=True)
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    mesh = g.add_mesh("q", pos, [[0, 1, 2], [0, 2, 3]], material=m, uv0=pos[:, :2], colors=colors)
    g.add_node("q", mesh=mesh, **(node_kwargs or {}))
    return g.write(path)


HEAD_ON = Camera(
    eye=np.array([0.5, 0.5, 1.5]), target=np.array([0.5, 0.5, 0.0]), yfov=40.0, znear=0.1, zfar=10
)


def test_sampler_filters_srgb_decode_factor_and_colour(egl_ctx, tmp_path):
    tex = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [128, 128, 128]]], np.uint8)
    lin = srgb_decode8(tex)
    nearest = {"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}
    p = _quad_glb(tmp_path / "n.glb", nearest, tex, factor=(0.5, 1.0, 1.0, 1.0), colors=np.full((4, 3), 0.8))
    assert not is_iat_export(p)
    img = render_glb(p, HEAD_ON, (64, 64), egl_ctx)
    # NEAREST: four flat quadrants; texture row 0 is v = 0, the bottom of the quad on screen
    want = lin * [0.5, 1.0, 1.0] * 0.8
    ys, xs = np.nonzero(img.max(axis=-1) > 0)
    cy, cx = (ys.min() + ys.max()) / 2, (xs.min() + xs.max()) / 2
    quadrants = {
        (0, 0): (ys > cy + 2) & (xs < cx - 2),
        (0, 1): (ys > cy + 2) & (xs > cx + 2),
        (1, 0): (ys < cy - 2) & (xs < cx - 2),
        (1, 1): (ys < cy - 2) & (xs > cx + 2),
    }
    for (row, col), sel in quadrants.items():
        assert sel.sum() > 50
        px = img[ys[sel], xs[sel]]
        np.testing.assert_allclose(px, np.broadcast_to(want[row, col], px.shape), rtol=5e-3, atol=1e-4)
    # LINEAR: the centre of the quad is the mean of the four (decoded) texels
    linear = {"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071}
    img = render_glb(_quad_glb(tmp_path / "l.glb", linear, tex), HEAD_ON, (64, 64), egl_ctx)
    centre = img[31:33, 31:33].reshape(-1, 3).mean(axis=0)  # symmetric about the quad's centre
    np.testing.assert_allclose(centre, lin.reshape(-1, 3).mean(axis=0), rtol=5e-3)


def test_node_transforms_are_applied(egl_ctx, tmp_path):
    tex = np.full((2, 2, 3), 200, np.uint8)
    s = {"magFilter": 9729, "minFilter": 9729}
    p = _quad_glb(tmp_path / "t.glb", s, tex, node_kwargs={"translation": [10.0, 0.0, 0.0]})
    doc = load_glb(p)
    np.testing.assert_allclose(doc.bounds, [[10, 0, 0], [11, 1, 0]], atol=1e-6)
    assert render_glb(p, HEAD_ON, (32, 32), egl_ctx).max() == 0  # moved out of view
    cam = doc.default_camera()
    img = render_glb(p, cam, (32, 32), egl_ctx)
    np.testing.assert_allclose(img[16, 16], srgb_decode8([200, 200, 200]), rtol=2e-3)


def test_own_context_and_errors(tmp_path):
    tex = np.full((2, 2, 3), 255, np.uint8)
    p = _quad_glb(tmp_path / "w.glb", {"magFilter": 9729, "minFilter": 9729}, tex)
    try:
        img = render_glb(p, HEAD_ON, (32, 24))  # a temporary EGL context of its own
    except Exception as e:  # pragma: no cover - no EGL here
        pytest.skip(f"no EGL context: {e}")
    assert img.shape == (24, 32, 3) and img.dtype == np.float32
    np.testing.assert_allclose(img[12, 16], [1, 1, 1], rtol=1e-6)
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"not a glb at all, but long enough")
    with pytest.raises(LoadError, match="not a GLB"):
        load_glb(bad)
    assert not is_iat_export(bad)
    with pytest.raises(LoadError):
        load_glb(tmp_path / "missing.glb")
    trunc = tmp_path / "trunc.glb"
    trunc.write_bytes(struct.pack("<III", 0x46546C67, 2, 28) + struct.pack("<II", 4, 0x4E4F534A) + b"{}  ")
    assert load_glb(trunc).primitives == []


def test_linear_field_round_trip_is_within_8_bit(egl_ctx, tmp_path):
    """Threshold 0 on a linear field: the GLB drawn here is the IAT image to 8-bit sRGB precision."""
    from iat.render.renderer import Renderer

    sol = grid_scene_solution(linear_field, seed=3)
    bk = Baker(sol).bake(BakePolicy(threshold=0, mipmaps=False))
    s = radiance_scale(bk)
    r = Renderer(egl_ctx)
    try:
        r.set_baked(bk)
        ref = r.render(GRID_CAM, (W, H), mode="iat")
    finally:
        r.release()
    img = render_glb(export_glb(bk, tmp_path / "lin.glb"), GRID_CAM, (W, H), egl_ctx)
    lit = ref.max(axis=-1) > 0
    ok = lit & (ref < 0.98 * s).all(axis=-1)
    assert ok.mean() > 0.3
    codes = np.abs(srgb_encode01(img / s) - srgb_encode01(ref / s))[ok] * 255
    assert codes.max() <= 1.5, codes.max()
