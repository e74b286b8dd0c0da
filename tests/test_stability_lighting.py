"""Stability catalogue (docs/stability.md), Lighting: point lights against walls, no light, albedo
outside [0, 1], bright and dim emitters in each pixel format, banding."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from iat.bake.baker import Baker
from iat.bake.formats import quantise_rgb9e5, quantise_rgba8
from iat.bake.policy import BakePolicy
from iat.camera import Camera
from iat.errors import OptionError, RenderError
from iat.io.load import load_scene
from iat.radiosity import solve
from tests import stability_scenes as ss
from tests.support.stability import opts, record, vertex_patch

pytestmark = pytest.mark.usefixtures("stability_figures")


def test_lighting_point_light_almost_touching_a_wall():
    """A point light 0.1 mm from a floor: finite radiance, bounded by I rho / (pi d^2) (reached at the
    foot today, a softened peak would also hold), and the tree refined to max depth around the foot."""
    depth = 4
    scene = ss.make_scene([ss.quad_y(-1, 1, -1, 1)], [0], [ss.GREY], [ss.point_light(0.0, 1e-4, 0.0, 1.0)])
    sol = solve(scene, opts(max_depth=depth))
    rad = sol.vert_radiance.astype(np.float64)
    assert np.isfinite(rad).all()
    peak = 0.5 * scene.lights[0].intensity / (np.pi * 1e-8)
    f = sol.forest
    # the four leaves around the foot (lattice centre) are at max depth
    n = sol.n
    centre = (f.leaf_i <= n // 2) & (f.leaf_i + f.leaf_size >= n // 2)
    centre &= (f.leaf_j <= n // 2) & (f.leaf_j + f.leaf_size >= n // 2)
    record(
        "light_touching_wall",
        peak_radiance=float(rad.max()),
        analytic_peak=peak,
        leaves_at_foot_depth=sorted(set(f.leaf_level[centre].tolist())),
        elements=sol.stats["elements"],
    )
    assert 0 < rad.max() <= peak * (1 + 1e-5)
    assert (f.leaf_level[centre] == depth).all()


def test_lighting_point_light_near_a_wall_conserves_energy():
    """Physically the indirect light in a closed room barely depends on how close the light is to a
    wall (the wall catches about half the light either way). Fixed D3: an element shoots the power it
    received (intensity x its solid angle from the light x visible fraction, finite as d -> 0), not
    its interpolated vertex irradiance (gain 0.95 at depth 3; it was ~1.5e4)."""
    far_wall = {}
    for d in (0.1, 1e-4):
        sol = solve(ss.room_with_light([0.5, 0.5, d]), opts(max_depth=3))
        on = np.isclose(sol.vert_position[:, 2], 1.0) & (vertex_patch(sol) >= 0)
        far_wall[d] = float(sol.vert_radiance[on, 0].mean())
    record(
        "light_touching_wall",
        far_wall_radiance_d_0_1=far_wall[0.1],
        far_wall_radiance_d_1e_4=far_wall[1e-4],
        energy_gain=far_wall[1e-4] / far_wall[0.1],
    )
    assert far_wall[0.1] / 3 < far_wall[1e-4] < 3 * far_wall[0.1]


def test_lighting_emitter_facing_away_and_no_light():
    """An emitter that faces away from everything lights nothing and the solve ends at once; a scene
    with no light at all solves to exact zeros (no NaN) and renders black."""
    scene = ss.emitter_facing_away()
    t0 = time.perf_counter()
    sol = solve(scene, opts(max_depth=4))
    dt = time.perf_counter() - t0
    p = vertex_patch(sol)
    assert sol.vert_radiance[p == 0].max() == 0.0
    assert np.all(sol.vert_radiance[p == 1] == 10.0)
    dark = ss.make_scene(ss.box_faces([0, 0, 0], [1, 1, 1]), [0] * 6, [ss.GREY])
    sol2 = solve(dark, opts(max_depth=4))
    assert np.isfinite(sol2.vert_radiance).all() and sol2.vert_radiance.max() == 0.0
    assert sol2.stats["unshot_fraction"] == 0.0 and sol2.stats["shots"] == 0
    baked = Baker(sol2, dark).bake(BakePolicy(threshold=0))
    assert np.isfinite(baked.pages).all() and baked.pages.max() == 0.0
    record(
        "emitter_away_no_light",
        away_shots=sol.stats["shots"],
        away_time_s=round(dt, 3),
        away_floor_max=0.0,
        dark_max=0.0,
        dark_elements=sol2.stats["elements"],
    )
    assert sol.stats["shots"] == 0


def test_lighting_no_light_renders_black(renderer):
    dark = ss.make_scene(ss.box_faces([0, 0, 0], [1, 1, 1]), [0] * 6, [ss.GREY])
    sol = solve(dark, opts(max_depth=2))
    renderer.set_solution(sol)
    renderer.set_baked(Baker(sol, dark).bake(BakePolicy(threshold=0)))
    cam = Camera(eye=[0.5, 0.5, 0.9], target=[0.5, 0.5, 0.0], yfov=60.0, znear=0.01, zfar=10)
    for mode in ("mesh", "iat"):
        img = renderer.render(cam, (32, 24), mode)
        assert np.isfinite(img).all() and img.max() == 0.0
    from iat.color import auto_exposure, tonemap

    assert auto_exposure(img) == 1.0 and tonemap(img, None).max() == 0


def test_lighting_albedo_zero_and_albedo_above_one_is_clamped_at_load(tmp_path):
    """Albedo 0: non-emitters are exactly black. Albedo > 1 in a file is clamped to 1 at load
    (Kd 1.5 -> 1.0) with an IATWarning naming the file and the material; albedo 1 in a closed box
    never converges: the solve stops at max_shots and reports the unshot light instead of looping."""
    sol = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=0.0), opts(max_depth=2))
    assert sol.vert_radiance.max() == 0.0 and sol.stats["shots"] == 0
    mtl = tmp_path / "bright.mtl"
    mtl.write_text("newmtl bright\nKd 1.5 0.5 0.25\n")
    obj = ss.write_obj(
        tmp_path / "bright.obj",
        [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0, 1, 2]],
        extra="mtllib bright.mtl\nusemtl bright",
    )
    from iat.errors import IATWarning

    clamped = r"bright.obj: albedo outside \[0, 1\] clamped in 1 material: 'bright' \(1.5, 0.5, 0.25\)$"
    with pytest.warns(IATWarning, match=clamped):
        scene = load_scene(obj)
    assert np.allclose(scene.materials[0].albedo, [1.0, 0.5, 0.25])
    t0 = time.perf_counter()
    sol1 = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=1.0), opts(max_depth=2, max_shots=200))
    dt = time.perf_counter() - t0
    record(
        "albedo",
        albedo0_max=0.0,
        kd_1_5_loaded_as=scene.materials[0].albedo.tolist(),
        albedo1_shots=sol1.stats["shots"],
        albedo1_unshot_fraction=sol1.stats["unshot_fraction"],
        albedo1_time_s=round(dt, 2),
    )
    assert sol1.stats["shots"] == 200 and sol1.stats["unshot_fraction"] > 0.5
    assert np.isfinite(sol1.vert_radiance).all()


def test_lighting_albedo_above_one_in_memory_is_clamped_with_a_warning():
    """An in-memory scene with albedo 1.5 (no loader clamped it): the solve clamps it to 1 with an
    IATWarning naming the material, so the result equals the albedo-1 solve (finite, stops at
    max_shots); a negative albedo is clamped to 0 the same way; NaN stays an OptionError."""
    from iat.errors import IATWarning

    scene = ss.room_with_light([0.5, 0.5, 0.5], albedo=1.5)
    clamped = r"albedo outside \[0, 1\] clamped in 1 material: 'wall' \(1.5, 1.5, 1.5\)"
    with pytest.warns(IATWarning, match=clamped):
        sol = solve(scene, opts(max_depth=2, max_shots=300))
    one = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=1.0), opts(max_depth=2, max_shots=300))
    record("albedo", albedo1_5_max_radiance_after_300_shots=float(sol.vert_radiance.max()))
    assert np.isfinite(sol.vert_radiance).all()
    assert np.allclose(sol.patch_albedo, 1.0)
    assert np.allclose(sol.vert_radiance, one.vert_radiance)
    with pytest.warns(IATWarning, match="'wall' \\(-0.5"):
        dark = solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=-0.5), opts(max_depth=2))
    assert dark.vert_radiance.max() == 0.0
    with pytest.raises(OptionError, match="albedo"):
        solve(ss.room_with_light([0.5, 0.5, 0.5], albedo=float("nan")), opts(max_depth=2))


def _format_figures(renderer, sol, scene):
    """Bake at threshold 0 in every pixel format; relative quantisation error in the dim region, from
    the pages (what the baker stores) and from the GPU image (what is shown)."""
    figures = {}
    base = Baker(sol, scene)
    ref = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False))
    ref32 = dataclasses.replace(ref, policy=dataclasses.replace(ref.policy, pixel_format="rgba32f"))
    exact = ref.pages.astype(np.float64)
    dim = (exact > 0) & (exact < 1e-6 * exact.max())
    assert dim.sum() > 100
    renderer.set_baked(ref32)
    cam = Camera(
        eye=[10.0, 1.5, 0.0], target=[10.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], yfov=60.0, znear=0.01, zfar=10
    )
    img_ref = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    shown = img_ref > 0
    for fmt in ("rgba16f", "rgba8", "rgb9e5"):
        b = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False, pixel_format=fmt))
        stored = b.pages.astype(np.float64)
        if fmt == "rgba16f":
            stored = exact.astype(np.float16).astype(np.float64)  # what the rgba16f texture holds
        figures[f"{fmt}_pages_dim_max_rel_err"] = float((np.abs(stored - exact)[dim] / exact[dim]).max())
        try:
            renderer.set_baked(b)
            img = renderer.render(cam, (64, 64), "iat").astype(np.float64)
            figures[f"{fmt}_gpu_dim_max_rel_err"] = float(
                (np.abs(img - img_ref)[shown] / img_ref[shown]).max()
            )
        except RenderError as e:
            figures[f"{fmt}_gpu"] = str(e)
    figures["dynamic_range"] = float(exact.max() / exact[exact > 0].min())
    return figures


def test_lighting_bright_and_dim_emitters_pixel_formats(renderer):
    """A 5e4 emitter and a 1e-3 point light in one scene (8+ decades): rgba16f keeps the dim region
    within 2**-11 relative error; rgba8 (one scale for all pages) loses it entirely (banding to black);
    rgb9e5 keeps 2**-9 per texel in the baker's pages."""
    scene = ss.bright_and_dim()
    sol = solve(scene, opts(max_depth=3))
    fig = _format_figures(renderer, sol, scene)
    record("pixel_formats", **fig)
    assert fig["rgba16f_pages_dim_max_rel_err"] <= 2.0**-11
    assert fig["rgba16f_gpu_dim_max_rel_err"] <= 2.0**-10  # half-float texels, then filtering
    assert fig["rgb9e5_pages_dim_max_rel_err"] <= 2.0**-9 * 1.01
    assert fig["rgba8_pages_dim_max_rel_err"] == 1.0  # everything dim rounds to 0: documented limit
    # the quantisers themselves: rgb9e5 relative step of the largest channel <= 2**-9, rgba8 sRGB step
    x = np.geomspace(1e-4, 6e4, 4001)[:, None] * np.ones(3)
    assert (np.abs(quantise_rgb9e5(x) - x) / x).max() <= 2.0**-9 * 1.01
    q8 = quantise_rgba8(x, float(x.max()))
    assert (q8[x[:, 0] < 1e-5 * x.max()] == 0).all()


def test_lighting_banding_8_bit_vs_16_bit_on_a_smooth_ramp():
    """Banding measured: a smooth exponential ramp over 3 decades (1e-3 to 1, a light's falloff) baked
    at 1 025 texels across in rgba16f and rgba8. Per decade: distinct texel values, the widest band
    (run of equal texels where the exact value rises 0.7 % per texel), the largest step between
    neighbouring levels and the largest relative error. rgba16f: every texel its own level; rgba8
    (sRGB 8-bit, one scale for all pages): bands widen as the radiance falls below the maximum."""
    ramp = lambda p, x: (10.0 ** (-3.0 + 3.0 * x[:, 0]))[:, None] * np.ones(3)  # noqa: E731
    sol = ss.uniform_depth_solution(ss.grid_corners(1, 1), 6, ramp)
    base = Baker(sol)
    policy = dict(threshold=0, method="bilinear", mipmaps=False, scale=16.0)
    exact = base.bake(BakePolicy(**policy)).pages.astype(np.float64)  # rgba16f pages hold exact values
    stored = {
        "rgba16f": exact.astype(np.float16).astype(np.float64),  # what the rgba16f texture holds
        "rgba8": base.bake(BakePolicy(**policy, pixel_format="rgba8")).pages.astype(np.float64),
    }
    lit = exact[0, ..., 0] > 0
    ys, xs = np.nonzero(lit)
    row = ys[len(ys) // 2]
    cols = xs[ys == row]
    e = exact[0, row, cols, 0]
    rising = np.r_[np.diff(e) > 0, False] & np.r_[False, np.diff(e) > 0]  # inside the tile, no gutter
    e = e[rising]
    assert len(e) > 1000 and (e[1:] / e[:-1]).max() < 1.01
    fig = {}
    for fmt, pages in stored.items():
        q = pages[0, row, cols, 0][rising]
        for k, name in enumerate(("1e-3_1e-2", "1e-2_1e-1", "1e-1_1")):
            sel = (e >= 10.0 ** (k - 3)) & (e < 10.0 ** (k - 2))
            qq = q[sel]
            runs = np.diff(np.flatnonzero(np.r_[True, qq[1:] != qq[:-1], True]))
            levels = np.unique(qq)
            fig[f"{fmt}_{name}_texels"] = int(sel.sum())
            fig[f"{fmt}_{name}_levels"] = len(levels)
            fig[f"{fmt}_{name}_widest_band_texels"] = int(runs.max())
            fig[f"{fmt}_{name}_max_level_step"] = round(float((levels[1:] / levels[:-1] - 1).max()), 4)
            fig[f"{fmt}_{name}_max_rel_err"] = round(float((np.abs(qq - e[sel]) / e[sel]).max()), 5)
    record("banding_8_vs_16_bit", **fig)
    for name in ("1e-3_1e-2", "1e-2_1e-1", "1e-1_1"):
        assert fig[f"rgba16f_{name}_widest_band_texels"] == 1  # no band: the ramp's 0.7 % steps survive
        assert fig[f"rgba16f_{name}_max_rel_err"] <= 2.0**-11
    assert fig["rgba8_1e-1_1_max_rel_err"] < 0.02  # the top decade is fine in 8 bits
    assert fig["rgba8_1e-3_1e-2_widest_band_texels"] > 10  # 3 decades down: visible bands (documented)


def test_lighting_rgb9e5_bake_renders(renderer):
    """D4 (fixed): an rgb9e5 bake uploads (GL_RGB9_E5) instead of raising RenderError."""
    scene = ss.bright_and_dim()
    sol = solve(scene, opts(max_depth=2))
    renderer.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0, pixel_format="rgb9e5")))


def test_lighting_rgba8_gpu_matches_the_baked_pages(renderer):
    """D5 (fixed): rgba8 pages are drawn as the baker stored them (sRGB8 texture), not 29 % off."""
    scene = ss.floor_under_light(height=0.3)
    sol = solve(scene, opts(max_depth=4))
    base = Baker(sol, scene)
    b8 = base.bake(BakePolicy(threshold=0, method="scan", mipmaps=False, pixel_format="rgba8"))
    ref = dataclasses.replace(
        b8, policy=dataclasses.replace(b8.policy, pixel_format="rgba32f"), page_scale=1.0
    )
    cam = Camera(
        eye=[0.0, 2.0, 0.0], target=[0.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], yfov=60.0, znear=0.01, zfar=10
    )
    renderer.set_baked(ref)  # the stored (already sRGB8-quantised) values, uploaded exactly
    want = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    renderer.set_baked(b8)
    got = renderer.render(cam, (64, 64), "iat").astype(np.float64)
    m = want > 1e-3 * want.max()
    err = float((np.abs(got - want)[m] / want[m]).max())
    record("pixel_formats", rgba8_gpu_vs_pages_max_rel_err=err)
    assert err < 0.05


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
def test_lighting_very_bright_texel_stays_finite_in_rgba16f(renderer):
    """D6 (fixed): a 1e5 texel is clamped to 65504 before the float16 cast, never inf on screen."""
    scene = ss.bright_and_dim(bright=1.0e5)
    sol = solve(scene, opts(max_depth=2))
    renderer.set_baked(Baker(sol, scene).bake(BakePolicy(threshold=0)))
    cam = Camera(
        eye=[0.0, 4.0, 0.0], target=[0.0, 3.0, 0.0], up=[0.0, 0.0, -1.0], yfov=30.0, znear=0.01, zfar=10
    )
    img = renderer.render(cam, (32, 32), "iat")
    record("pixel_formats", rgba16f_1e5_emitter_pixels_not_finite=int((~np.isfinite(img)).any(axis=2).sum()))
    assert np.isfinite(img).all()
