"""The radiosity solution against a Mitsuba 3 path-traced reference of the Cornell box.

The reference (4096 spp, 96 x 96) is cached under ``tests/refs/`` (``pytest
--regen-refs`` renders it again, ~8 min on 2 cores); the radiosity image is the renderer's
``mesh`` mode. Edges are left out of the comparison: a one-pixel difference in
where an edge falls says nothing about the light.

The 512-spp reference used before carried 2.1 % of noise per pixel (two of them with other seeds
differ by 2.8 %; each is 2.1 % from the 4096-spp one): against it the defaults measured 4.08 %,
against this one 3.25 %. Mitsuba's pixels average their footprint (a box filter); the renderer's
image is box-filtered the same way (:func:`iat.measure.reference.box_filtered_render`, 8 x 8 samples
a pixel): sampled at pixel centres it differed from the reference at every edge and along curved
gradients, which read as 3.25 % per pixel and 7.2 % on 8 x 8 blocks at the defaults, where the
light is 1.9 % and 1.25 % off.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from iat.measure.metrics import reference_errors, smooth_lit_mask
from iat.radiosity import SolveOptions, solve

MODEL = Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb"
REFS = Path(__file__).parent / "refs"
SIZE = (96, 96)


def test_cornell_box_against_mitsuba(egl_ctx):
    pytest.importorskip("mitsuba")
    from iat.io.load import load_scene
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.render.renderer import Renderer

    scene = load_scene(MODEL)
    camera = scene.default_camera()
    ref = render_reference_cached(scene, camera, SIZE, spp=4096, cache_dir=REFS, seed=3)
    sol = solve(scene, SolveOptions())  # the defaults: issue 4 asks for 5 % within 5 s on 2 cores
    renderer = Renderer(egl_ctx)
    try:
        renderer.set_solution(sol)
        img = box_filtered_render(renderer, camera, SIZE, "mesh")
    finally:
        renderer.release()
    lit = ref.mean(axis=2) > 0.05
    mask = smooth_lit_mask(ref)
    assert mask.sum() > 0.2 * lit.sum()
    e = reference_errors(img, ref, mask)  # 8 x 8 blocks: robust to edges, sensitive to any bias
    rel_smooth, rel_blocks = e["rel_smooth"], e["rel_blocks"]
    print(f"relative error: smooth lit pixels {rel_smooth:.4f}, 8x8 blocks {rel_blocks:.4f}")
    # measured 0.0190 box-filtered (0.0325 sampled at pixel centres; 0.0408 against the 512-spp
    # reference; 0.0418 before the open-scene convergence, 0.0446 before stage C's gathers took the
    # strongest shots' samples and patches shot their light's quadratic integral, 0.0524 before large
    # elements split at a finer tolerance)
    assert rel_smooth < 0.03
    assert rel_blocks < 0.025  # measured 0.0125 (0.0723 at pixel centres: the silhouettes' pixels)
    # no overall bias in the light: mean over the smooth pixels within 3 %
    assert img[mask].mean() == pytest.approx(ref[mask].mean(), rel=0.03)  # measured -1.2 %
