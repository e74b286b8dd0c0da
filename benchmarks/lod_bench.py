"""Level-of-detail benchmark: frame time and resident texture memory along the sample models'
camera paths, without LOD, with LOD (every level resident) and with LOD streaming.

For each model (``sample_models/*.glb``; solved once with the tests' quick options, cached under
``out/acceptance``) and its ``scene.camera_paths["default"]`` (poses interpolated linearly,
``--steps`` frames between two poses), three renderers draw every frame in IAT mode:

- ``full``: ``BakePolicy()`` (the finest textures, the mip levels the gutter allows)
- ``lod``: ``BakePolicy(lod=True)`` (every level resident, two blended per fragment)
- ``stream``: ``BakePolicy(lod_stream=True)`` (only the levels the view needs resident, by
  distance; the streaming update, i.e. re-packing and uploading when the resident set changes, is
  in the frame)
- ``cull``: as ``stream``, and patches outside the frustum (widened by a quarter) keep only their
  coarsest level (``Renderer.set_lod(cull=0.25)``)

The three draw each frame in turn (interleaved, so the shared machine's load drifts alike for
all). Per mode: frame time (``Renderer.render``: draw + finish + read-back, p50 / p95 in ms), texture bytes
on the GPU (the bake's memory report; for streaming the resident pages per frame: mean and max,
and the resident boxes without the pages' power-of-two rounding), page uploads, and the PSNR of
the LOD frames against the full-resolution ones (sRGB at the full frame's auto exposure, peak 1:
the worst frame and the mean). Not a test: timings depend on the machine (llvmpipe here, shared).

    python benchmarks/lod_bench.py                       # all five models, 320 x 240
    python benchmarks/lod_bench.py cornell_box house --steps 4 --size 160x120 --json out/lod.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MODELS = ["cornell_box", "house", "cave", "lavapit", "pool"]
#: the "cull" mode's frustum margin (:func:`iat.bake.lod.needed_levels`)
CULL_MARGIN = 0.25


def path_frames(poses: list, steps: int) -> list:
    """Cameras along ``poses``: ``steps`` frames from each pose to the next (eye, target, yfov
    linear), then the last pose."""
    from iat.camera import Camera

    out = []
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        for k in range(steps):
            t = k / steps
            out.append(
                Camera(
                    eye=(1 - t) * a.eye + t * b.eye,
                    target=(1 - t) * a.target + t * b.target,
                    up=a.up,
                    yfov=(1 - t) * a.yfov + t * b.yfov,
                    znear=a.znear,
                    zfar=a.zfar,
                )
            )
    return out + [poses[-1]]


def run_model(name: str, renderers: dict, steps: int, size: tuple[int, int]) -> dict:
    """The figures of one model: ``renderers`` {"full", "lod", "stream", "cull": Renderer} (one per
    mode, so each keeps its own pages)."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.color import auto_exposure
    from iat.measure.metrics import psnr, srgb_tonemap
    from iat.radiosity.cache import cached_solve
    from iat.radiosity.options import SolveOptions

    quick = SolveOptions(
        max_depth=4, samples=1, max_shots=30, convergence=0.2, refine_indirect=False, tolerance=0.1
    )
    scene, sol, _ = cached_solve(ROOT / "sample_models" / f"{name}.glb", quick, ROOT / "out" / "acceptance")
    poses = scene.camera_paths.get("default") or scene.cameras
    cams = path_frames(list(poses), steps)
    baker = Baker(sol, scene)
    bakes = {
        "full": baker.bake(BakePolicy()),
        "lod": baker.bake(BakePolicy(lod=True)),
        "stream": baker.bake(BakePolicy(lod_stream=True)),
        "cull": baker.bake(BakePolicy(lod_stream=True)),
    }
    renderers["cull"].set_lod(cull=CULL_MARGIN)
    out: dict = {"model": name, "frames": len(cams), "patches": int(len(sol.patch_is_quad))}
    modes = list(bakes)
    for mode in modes:  # warm-up (shader compile, first upload), then the real first set
        renderers[mode].set_baked(bakes[mode])
        renderers[mode].render(cams[0], size, "iat")
        renderers[mode].set_baked(bakes[mode])
    times = {m: [] for m in modes}
    resident = {m: [] for m in modes}
    texels = {m: [] for m in modes}
    images: dict[str, list] = {m: [] for m in modes}
    for cam in cams:  # the modes interleaved frame by frame: the machine's load drifts alike for all
        for mode in modes:
            r, bk = renderers[mode], bakes[mode]
            t0 = time.perf_counter()
            images[mode].append(r.render(cam, size, "iat"))
            times[mode].append(time.perf_counter() - t0)
            info = r.lod_info()
            resident[mode].append(info.get("resident_bytes", bk.memory.texture_bytes))
            texels[mode].append(info.get("resident_texel_bytes", bk.memory.texture_bytes))
    for mode in modes:
        bk = bakes[mode]
        info = renderers[mode].lod_info()
        ms = np.array(times[mode]) * 1e3
        out[mode] = {
            "frame_ms_p50": float(np.percentile(ms, 50)),
            "frame_ms_p95": float(np.percentile(ms, 95)),
            "texture_bytes": int(bk.memory.texture_bytes),
            "resident_bytes_mean": float(np.mean(resident[mode])),
            "resident_bytes_max": int(np.max(resident[mode])),
            "resident_texel_bytes_mean": float(np.mean(texels[mode])),
            "total_bytes": int(info.get("total_bytes", bk.memory.texture_bytes)),
            "total_texel_bytes": int(info.get("total_texel_bytes", bk.memory.texture_bytes)),
            "uploads": int(info.get("updates", 1)),
            "bake_s": float(bk.timings.get("total", 0.0)),
        }
    for mode in ("lod", "stream", "cull"):
        vals = []
        for a, b in zip(images["full"], images[mode], strict=True):
            e = auto_exposure(a)
            vals.append(psnr(srgb_tonemap(b, e), srgb_tonemap(a, e), peak=1.0))
        v = np.array(vals)
        fin = v[np.isfinite(v)]
        out[mode]["psnr_min"] = float(v.min())
        out[mode]["psnr_mean"] = float(fin.mean()) if len(fin) else float("inf")
    return out


def table(rows: list[dict]) -> str:
    lines = [
        "| model | frames | mode | frame p50 / p95 (ms) | texture on GPU (KiB) | PSNR min / mean (dB) "
        "| uploads |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for mode in ("full", "lod", "stream", "cull"):
            m = r[mode]
            if mode in ("stream", "cull"):
                kib = {k: v / 1024 for k, v in m.items() if "bytes" in k}
                mem = (
                    f"{kib['resident_bytes_mean']:.0f} mean, {kib['resident_bytes_max']:.0f} max "
                    f"(boxes {kib['resident_texel_bytes_mean']:.0f} of {kib['total_texel_bytes']:.0f})"
                    f" of {kib['total_bytes']:.0f}"
                )
            else:
                mem = f"{m['texture_bytes'] / 1024:.0f}"
            ps = "-" if mode == "full" else f"{m['psnr_min']:.1f} / {m['psnr_mean']:.1f}"
            ft = f"{m['frame_ms_p50']:.1f} / {m['frame_ms_p95']:.1f}"
            lines.append(f"| {r['model']} | {r['frames']} | {mode} | {ft} | {mem} | {ps} | {m['uploads']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="*", default=MODELS)
    ap.add_argument("--steps", type=int, default=8, help="frames between two poses of the path")
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--json", type=Path, help="write the figures here")
    a = ap.parse_args(argv)
    from iat.render.renderer import Renderer

    w, h = (int(x) for x in a.size.lower().split("x"))
    rows = []
    base = Renderer()
    renderers = {"full": base, **{m: Renderer(base.ctx) for m in ("lod", "stream", "cull")}}
    try:
        for name in a.models:
            rows.append(run_model(name, renderers, a.steps, (w, h)))
            print(table(rows[-1:]).split("\n", 2)[-1], flush=True)
    finally:
        for m in ("lod", "stream", "cull", "full"):
            renderers[m].release()
    print()
    print(f"{w}x{h}, {a.steps} frames between poses, load average {os.getloadavg()[0]:.1f}")
    print(table(rows))
    if a.json is not None:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"size": [w, h], "steps": a.steps, "models": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
