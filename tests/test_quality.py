"""Quality presets (``SolveOptions.preset``, ``--quality``): the error against a 4096-spp Mitsuba
reference of the Cornell box falls from draft to final, and flags given override a preset."""

from __future__ import annotations

from pathlib import Path

import pytest

from iat.cli.commands import main
from iat.errors import OptionError
from iat.radiosity import Solution, SolveOptions, solve
from iat.radiosity.options import QUALITY_PRESETS

MODEL = Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb"
REFS = Path(__file__).parent / "refs"


def test_presets_and_overrides(tmp_path):
    assert SolveOptions.preset() == SolveOptions()
    assert SolveOptions.preset("final", seed=3) == SolveOptions(
        convergence=0.005, tolerance=0.05, samples=32, ambient_rays=1024, seed=3
    )
    with pytest.raises(
        OptionError, match=r"unknown quality 'best' \(choose from draft, default, fine, final\)"
    ):
        SolveOptions.preset("best")
    with pytest.raises(OptionError, match=r"^solve option ambient_rays=0: must be between 1 and 4096$"):
        SolveOptions(ambient_rays=0).validate()
    from iat.cli.commands import build_parser

    for name in QUALITY_PRESETS:  # the CLI takes every preset the library has
        assert build_parser().parse_args(["solve", "m.glb", "-o", "s.npz", "--quality", name]).quality == name
    out = tmp_path / "d.npz"
    assert (
        main(["solve", str(MODEL), "--quality", "draft", "--max-depth", "3", "-o", str(out), "--json"]) == 0
    )
    opts = Solution.load(out).options
    assert (opts["max_depth"], opts["samples"]) == (3, QUALITY_PRESETS["draft"]["samples"])
    assert opts["ambient_rays"] == 64
    out = tmp_path / "r.npz"
    assert main(["solve", str(MODEL), "--quality", "draft", "--ambient-rays", "100", "-o", str(out)]) == 0
    assert Solution.load(out).options["ambient_rays"] == 100


def test_error_falls_from_draft_to_final(egl_ctx):
    """Measured, box-filtered as the reference's pixels: draft 0.0281, default 0.0190, final 0.0117 (the
    issue's goal: <= 1.5 % at some preset; at pixel centres they read 0.041, 0.0325, 0.0254)."""
    pytest.importorskip("mitsuba")
    from iat.io.load import load_scene
    from iat.measure.metrics import reference_errors, smooth_lit_mask
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer

    scene = load_scene(MODEL)
    camera = scene.default_camera()
    ref = render_reference_cached(scene, camera, (96, 96), spp=4096, cache_dir=REFS, seed=3)
    mask = smooth_lit_mask(ref)
    errors = {}
    r = Renderer(egl_ctx)
    try:
        for quality in ("draft", "default", "final"):
            r.set_solution(solve(scene, SolveOptions.preset(quality)))
            img = box_filtered_render(r, camera, (96, 96), "mesh")
            errors[quality] = reference_errors(img, ref, mask)["rel_smooth"]
    finally:
        r.release()
    print(errors)
    assert errors["draft"] < 0.04 and errors["final"] <= 0.015
    assert errors["draft"] > errors["default"] > errors["final"]


def test_smooth_walls_carry_no_noise_at_final(egl_ctx):
    """On the Cornell box's walls (12 x 12-pixel windows wholly on one wall, away from edges, 96 x 96),
    what the render has beyond a quadratic and beyond the light's real structure (the 4096-spp
    reference's, its own noise estimated against the 512-spp one) is at most 0.5 % at ``final``.
    Measured: final ceiling 0.31 %, back 0.35 %, red 0.47 %, green 0.08 %; default 0.57, 0.37,
    1.03, 0.35 % (the red wall's and ceiling's are over the goal)."""
    pytest.importorskip("mitsuba")
    from iat.io.load import load_scene
    from iat.measure.metrics import smooth_lit_mask
    from iat.measure.noise import patch_image, wall_noise
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer

    scene = load_scene(MODEL)
    camera = scene.default_camera()
    ref = render_reference_cached(scene, camera, (96, 96), spp=4096, cache_dir=REFS, seed=3)
    other = render_reference_cached(scene, camera, (96, 96), spp=512, cache_dir=REFS, seed=1)
    walls = {"ceiling": 1, "back": 2, "red": 3, "green": 4}
    assert all(scene.patch_area[p] > 0.3 for p in walls.values())  # the box's five big patches
    r = Renderer(egl_ctx)
    try:
        r.set_solution(solve(scene, SolveOptions.preset("final")))
        img = box_filtered_render(r, camera, (96, 96), "mesh")
    finally:
        r.release()
    noise = wall_noise(img, ref, other, patch_image(scene, camera, (96, 96)), walls, smooth_lit_mask(ref))
    print(noise)
    assert set(noise) == set(walls) and all(v["windows"] >= 8 for v in noise.values())
    assert max(v["excess"] for v in noise.values()) <= 0.005
