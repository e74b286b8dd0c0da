"""The Cornell box's walls (issue 37): per solver seed, the noise on its four walls
(:func:`iat.measure.noise.wall_noise`, %, what the render has beyond a quadratic and beyond the
65 536-spp Mitsuba reference's real structure, per 12 x 12-pixel window, 96 x 96, mesh mode), the mean
relative error per pixel on its smooth lit parts, elements, rays and solve time, at the defaults or
at options given as JSON. One JSON line a seed.

    .venv/bin/python benchmarks/cornell_walls.py [--seeds 0,1,2,3] [--options '{"samples": 32}']
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

WALLS = {"ceiling": 1, "back": 2, "red": 3, "green": 4}


def run(seeds: list[int], options: dict, refs: Path = ROOT / "tests" / "refs"):
    """Yield one dict a seed (see the module docstring)."""
    import moderngl

    from iat.io.load import load_scene
    from iat.measure.metrics import reference_errors, smooth_lit_mask
    from iat.measure.noise import NOISE_SPP, patch_image, wall_noise
    from iat.measure.reference import box_filtered_render, render_reference_cached
    from iat.radiosity import SolveOptions, solve
    from iat.render.renderer import Renderer

    scene = load_scene(ROOT / "sample_models" / "cornell_box.glb")
    camera = scene.default_camera()
    ref = render_reference_cached(scene, camera, (96, 96), spp=NOISE_SPP, cache_dir=refs, seed=3)
    other = render_reference_cached(scene, camera, (96, 96), spp=NOISE_SPP // 8, cache_dir=refs, seed=1)
    patches, mask = patch_image(scene, camera, (96, 96)), smooth_lit_mask(ref)
    r = Renderer(moderngl.create_standalone_context(backend="egl"))
    try:
        for seed in seeds:
            t0 = time.perf_counter()
            sol = solve(scene, SolveOptions(**{**options, "seed": seed}))
            seconds = time.perf_counter() - t0
            r.set_solution(sol)
            img = box_filtered_render(r, camera, (96, 96), "mesh")
            noise = wall_noise(img, ref, other, patches, WALLS, mask)
            yield {
                "options": options,
                "seed": seed,
                **{k: round(100 * v["excess"], 3) for k, v in noise.items()},
                "error": round(reference_errors(img, ref, mask)["rel_smooth"], 5),
                "elements": sol.stats["elements"],
                "rays_M": round(sol.stats["rays"] / 1e6, 2),
                "solve_s": round(seconds, 2),
            }
    finally:
        r.release()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--options", default="{}", help="SolveOptions fields as JSON (default: the defaults)")
    a = ap.parse_args()
    for row in run([int(s) for s in a.seeds.split(",")], json.loads(a.options)):
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
