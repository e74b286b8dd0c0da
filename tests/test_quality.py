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
        convergence=0.005, tolerance=0.05, samples=32, ambient_rays=1024, sky_samples=4096, seed=3
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
    args = [
        "solve",
        str(MODEL),
        "--quality",
        "draft",
        "--ambient-rays",
        "100",
        "--sky-samples",
        "256",
        "-o",
        str(out),
    ]
    assert main(args) == 0
    assert {k: Solution.load(out).options[k] for k in ("ambient_rays", "sky_samples")} == {
        "ambient_rays": 100,
        "sky_samples": 256,
    }


def test_error_falls_from_draft_to_final(egl_ctx):
    """Measured, box-filtered as the reference's pixels: draft 0.0239, default 0.0119, final 0.0115
    (before issue 37's sampling and penumbra meshing 0.0248, 0.0120, 0.0116; the issue's goal: <= 1.5 %
    at some preset)."""
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


def wall_noise_of(egl_ctx, quality: str) -> dict:
    """{wall: :func:`iat.measure.noise.wall_noise` row} of the Cornell box solved at ``quality``: on its
    walls (12 x 12-pixel windows wholly on one wall, away from edges, 96 x 96), what the render has
    beyond a quadratic and beyond the light's real structure (the :data:`NOISE_SPP` reference's, its own
    noise estimated against one of an eighth the samples)."""
    pytest.importorskip("mitsuba")
    from iat.io.load import load_scene
    from iat.measure.metrics import smooth_lit_mask
    from iat.measure.noise import NOISE_SPP, patch_image, wall_noise
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer

    scene = load_scene(MODEL)
    camera = scene.default_camera()
    ref = render_reference_cached(scene, camera, (96, 96), spp=NOISE_SPP, cache_dir=REFS, seed=3)
    other = render_reference_cached(scene, camera, (96, 96), spp=NOISE_SPP // 8, cache_dir=REFS, seed=1)
    walls = {"ceiling": 1, "back": 2, "red": 3, "green": 4}
    assert all(scene.patch_area[p] > 0.3 for p in walls.values())  # the box's five big patches
    r = Renderer(egl_ctx)
    try:
        r.set_solution(solve(scene, SolveOptions.preset(quality)))
        img = box_filtered_render(r, camera, (96, 96), "mesh")
    finally:
        r.release()
    noise = wall_noise(img, ref, other, patch_image(scene, camera, (96, 96)), walls, smooth_lit_mask(ref))
    print(quality, {k: round(100 * v["excess"], 3) for k, v in noise.items()})
    assert set(noise) == set(walls) and all(v["windows"] >= 8 for v in noise.values())
    return noise


def test_smooth_walls_carry_no_noise_at_final(egl_ctx):
    """The walls' noise (:func:`wall_noise_of`) is at most 0.5 % at ``final``. Measured: ceiling
    0.31 %, back 0.35 %, red 0.47 %, green 0.08 % (before issue 37's sampling and penumbra meshing)."""
    noise = wall_noise_of(egl_ctx, "final")
    assert max(v["excess"] for v in noise.values()) <= 0.005


def test_smooth_walls_carry_no_noise_at_default(egl_ctx):
    """... and at the defaults (issue 37), where it was ceiling 0.57 %, back 0.36 %, red 0.56 %, green
    0.23 %: the area light's direct pass with 4 x the samples per side (its noise in the tall block's
    penumbra split elements on nothing), elements in that penumbra split on 0.35 of the tolerance (the
    red wall's soft shadow was creased), the strongest shots with 2.5 x (the ceiling, lit by them alone,
    was mottled), stage C's gathers at 3 x the shots' samples a side (its new vertices stood out of the
    old ones). Measured against the 65 536-spp reference: ceiling 0.36 %, back 0.25 %, red 0.41 %,
    green 0.26 % (over seeds 0-9 at most 0.46 %; docs/benchmarks.md, "The Cornell box's walls")."""
    noise = wall_noise_of(egl_ctx, "default")
    assert max(v["excess"] for v in noise.values()) <= 0.005
