# ruff: noqa: E501
"""Our quality presets against a Blender Cycles lightmap bake of the same Cornell box (issue 17).

    .venv/bin/python benchmarks/cycles_bench.py [--settings "64,128x16,64,256,1024,4096;256x16,64,256;512x16,64"]
        [--repeats 2] [--no-ours] [--out benchmarks/cycles.json] [--keep DIR]
    .venv/bin/python benchmarks/cycles_bench.py --rescore DIR   # score atlases kept by --keep again
    .venv/bin/python benchmarks/cycles_bench.py --report        # the tables of benchmarks/cycles.json

writes ``benchmarks/cycles.json`` (the run it replaces kept as ``previous_run``) and prints Markdown
tables (docs/benchmarks.md, "Against a Blender Cycles bake"). bpy (Blender as a Python module,
``pip install bpy==4.2.*``, the optional test extra) is needed: without it the script says so in one
line and exits 0.

* **Cycles** -- ``tests/support/cycles_bake.py`` in its own process builds the scene from our
  :class:`~iat.io.scene.Scene` (exactly the triangles Mitsuba rendered, one object, flat faces,
  Lambertian albedo + emission of radiance = colour, black from behind: single-sided as the reference),
  gives it a Smart UV Project lightmap UV (3 texels between islands) per atlas resolution and bakes
  COMBINED (direct + indirect diffuse + emission: outgoing radiance) into one float atlas per setting,
  on the CPU, no denoising, no clamping, 128 diffuse bounces, no world. Times: the bake call's wall
  clock (scene sync + BVH + path tracing) and separately importing bpy and building the scene.
* **evaluation** -- both bakes the same way against the 4096-spp Mitsuba reference of ``solver_bench
  quality`` (96 x 96, box-filtered pixels): the atlas is looked up where rays from the camera's
  8 x 8 sub-pixel centres (768 x 768, exactly the renderer's pixel centres of ``box_filtered_render``)
  hit the triangles (numpy ray casting, bilinear texel filtering with clamp-to-edge as GL does, the
  texels rounded to half floats as rgba16f pages would be), averaged 8 x 8, and scored by
  :func:`iat.measure.metrics.reference_errors` on ``smooth_lit_mask`` of the reference. Checked first:
  the ray caster's hit points projected by :meth:`Camera.clip_from_world` land on their pixel centres.
  Each atlas is also scored denoised (``oidn``): Open Image Denoise from bpy's own library (ctypes),
  filter ``RT``, HDR, colour alone, as Blender's compositor Denoise node; its time is added.
* **ours** -- each ``--quality`` preset: solve time (best of ``--repeats``), the error of the mesh
  image (as ``solver_bench quality``) and of the baked textures (``iat`` mode), the bake time and
  ``Baked.memory.texture_bytes`` (rgba16f pages with their mip chain, as the renderer uploads them).
* **equal error** -- for each preset's mesh-image error (of this run, and of the quality table of
  ``benchmarks/solver.json`` as last committed), the cheapest Cycles setting measured at or below it,
  raw and denoised, and the bake time interpolated (log time against log error along one
  resolution's sample counts, the cheapest resolution whose curve reaches it).

Texture memory of a Cycles atlas: N x N texels, rgba16f (8 B, our default format) with the mip
chain (x 4/3) to compare with ours, and RGBA8 level 0 (4 B), what a game engine would usually store.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

OUT_JSON = ROOT / "benchmarks" / "cycles.json"
BAKE_SCRIPT = ROOT / "tests" / "support" / "cycles_bake.py"
SIZE = (96, 96)
#: atlas resolutions x sample counts of the sweep
DEFAULT_SETTINGS = "64,128x16,64,256,1024,4096;256x16,64,256;512x16,64"
K = 8  # sub-pixels per pixel side (``iat.measure.reference.SUPERSAMPLE``)


# -- the scene for Blender --------------------------------------------------------------------
def scene_job(scene) -> tuple[dict, np.ndarray]:
    """The bake job's geometry: every patch's corners as its own vertices, the triangles of
    :meth:`Scene.world_triangles` in its order (so UV row t is world triangle t), and the materials.
    Returns (job, world triangles (T, 3, 3))."""
    c = scene.corner_positions
    q = scene.patch_is_quad
    if len(scene.clip_patch):
        raise SystemExit("clipped patches are not handled by this benchmark")
    n = scene.n_patches
    tris = [[4 * p, 4 * p + 1, 4 * p + 2] for p in range(n)] + [
        [4 * p, 4 * p + 2, 4 * p + 3] for p in range(n) if q[p]
    ]
    wt = scene.world_triangles()
    verts = c.reshape(-1, 3)
    assert np.allclose(verts[np.array(tris)], wt)
    tp = scene.world_triangle_patch()
    job = {
        "vertices": verts.tolist(),
        "triangles": tris,
        "triangle_material": scene.patch_material[tp].tolist(),
        "materials": [
            {"albedo": np.clip(m.albedo, 0, 1).tolist(), "emission": np.maximum(m.emission, 0).tolist()}
            for m in scene.materials
        ],
    }
    return job, wt


# -- ray casting the camera's sub-pixel centres ------------------------------------------------
def camera_rays(camera, size, k: int = K) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (h k, w k, 3) through the centres of a (w k) x (h k) grid (row 0 at the top,
    column 0 at the left, as the renderer's read-back and the reference), and the eye."""
    return camera.pixel_rays(size, k), camera.eye.copy()


def ray_cast(tris: np.ndarray, eye: np.ndarray, dirs: np.ndarray):
    """Nearest hit of each ray (Moller-Trumbore, both sides): (triangle or -1, b1, b2, t), flat."""
    d = dirs.reshape(-1, 3)
    best_t = np.full(len(d), np.inf)
    tri = np.full(len(d), -1, dtype=np.int64)
    bb1 = np.zeros(len(d))
    bb2 = np.zeros(len(d))
    for i, (a, b, c) in enumerate(tris):
        e1, e2 = b - a, c - a
        p = np.cross(d, e2)
        det = p @ e1
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = eye - a
        b1 = (p @ s) * inv
        qv = np.cross(s, e1)
        b2 = (d @ qv) * inv
        t = (qv @ e2) * inv
        hit = ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 1e-9) & (t < best_t)
        best_t[hit], tri[hit], bb1[hit], bb2[hit] = t[hit], i, b1[hit], b2[hit]
    return tri, bb1, bb2, best_t


def check_camera(camera, dirs, eye, hits) -> float:
    """Largest distance (in sub-pixels) between a hit point projected by the camera's GL matrices
    and the centre of the sub-pixel its ray went through (0 when the ray caster is the renderer's camera)."""
    tri, _, _, t = hits
    h, w = dirs.shape[:2]
    keep = np.flatnonzero(tri >= 0)[::97]
    p = eye + dirs.reshape(-1, 3)[keep] * t[keep, None]
    clip = camera.clip_from_world(w / h) @ np.c_[p, np.ones(len(p))].T
    ndc = clip[:2] / clip[3]
    col = (ndc[0] + 1.0) / 2.0 * w - 0.5
    row = (1.0 - ndc[1]) / 2.0 * h - 0.5
    return float(max(np.abs(col - keep % w).max(), np.abs(row - keep // w).max()))


def sample_bilinear(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """GL_LINEAR lookup with clamp-to-edge of ``tex`` (n, n, c), row 0 at v = 0, at uv (m, 2)."""
    n_v, n_u = tex.shape[:2]
    x = uv[:, 0] * n_u - 0.5
    y = uv[:, 1] * n_v - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    x1, y1 = np.clip(x0 + 1, 0, n_u - 1), np.clip(y0 + 1, 0, n_v - 1)
    x0, y0 = np.clip(x0, 0, n_u - 1), np.clip(y0, 0, n_v - 1)
    top = tex[y0, x0] * (1 - fx) + tex[y0, x1] * fx
    bot = tex[y1, x0] * (1 - fx) + tex[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def lightmap_image(tex: np.ndarray, tri_uv: np.ndarray, hits, shape) -> np.ndarray:
    """The (h, w, 3) box-filtered image of a lightmap: looked up at every hit, averaged K x K."""
    tri, b1, b2, _ = hits
    img = np.zeros((len(tri), 3))
    m = tri >= 0
    uvt = tri_uv[tri[m]].astype(np.float64)
    uv = uvt[:, 0] * (1 - b1[m] - b2[m])[:, None] + uvt[:, 1] * b1[m][:, None] + uvt[:, 2] * b2[m][:, None]
    img[m] = sample_bilinear(tex[..., :3].astype(np.float16).astype(np.float64), uv)
    hk, wk = shape
    return img.reshape(hk // K, K, wk // K, K, 3).mean(axis=(1, 3))


# -- Open Image Denoise (the library bpy ships) ---------------------------------------------------
_OIDN = None


def _oidn():
    """ctypes handle of bpy's ``libOpenImageDenoise.so.2`` and a committed CPU device, or None."""
    global _OIDN
    if _OIDN is None:
        import ctypes

        spec = importlib.util.find_spec("bpy")
        locs = list(spec.submodule_search_locations or []) if spec else []
        path = next(
            (
                Path(d) / "lib" / "libOpenImageDenoise.so.2"
                for d in locs
                if (Path(d) / "lib" / "libOpenImageDenoise.so.2").is_file()
            ),
            None,
        )
        if path is None:
            _OIDN = False
            return None
        lib = ctypes.CDLL(str(path))
        vp, cp, sz = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t
        lib.oidnNewDevice.restype, lib.oidnNewDevice.argtypes = vp, [ctypes.c_int]
        lib.oidnCommitDevice.argtypes = [vp]
        lib.oidnNewFilter.restype, lib.oidnNewFilter.argtypes = vp, [vp, cp]
        lib.oidnSetSharedFilterImage.argtypes = [vp, cp, vp, ctypes.c_int, sz, sz, sz, sz, sz]
        lib.oidnSetFilterBool.argtypes = [vp, cp, ctypes.c_bool]
        lib.oidnCommitFilter.argtypes = lib.oidnExecuteFilter.argtypes = lib.oidnReleaseFilter.argtypes = [vp]
        lib.oidnGetDeviceError.restype = ctypes.c_int
        lib.oidnGetDeviceError.argtypes = [vp, ctypes.POINTER(ctypes.c_char_p)]
        dev = lib.oidnNewDevice(1)  # OIDN_DEVICE_TYPE_CPU
        lib.oidnCommitDevice(dev)
        _OIDN = (lib, dev)
    return _OIDN or None


def oidn_denoise(tex: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The atlas ``tex`` (n, n, >= 3) denoised by OIDN's ``RT`` filter, HDR, colour alone (as
    Blender's compositor Denoise node with no passes; the ``RTLightmap`` weights are not in bpy's
    build), and the seconds it took; None without the library."""
    import ctypes

    h = _oidn()
    if h is None:
        return None
    lib, dev = h
    x = np.ascontiguousarray(tex[..., :3], dtype=np.float32)
    y = np.zeros_like(x)
    t0 = time.perf_counter()
    f = lib.oidnNewFilter(dev, b"RT")
    n_v, n_u = x.shape[:2]
    lib.oidnSetSharedFilterImage(f, b"color", x.ctypes.data, 3, n_u, n_v, 0, 0, 0)  # OIDN_FORMAT_FLOAT3
    lib.oidnSetSharedFilterImage(f, b"output", y.ctypes.data, 3, n_u, n_v, 0, 0, 0)
    lib.oidnSetFilterBool(f, b"hdr", True)
    lib.oidnCommitFilter(f)
    lib.oidnExecuteFilter(f)
    dt = time.perf_counter() - t0
    msg = ctypes.c_char_p()
    err = lib.oidnGetDeviceError(dev, ctypes.byref(msg))
    lib.oidnReleaseFilter(f)
    if err:
        raise RuntimeError(f"OIDN error {err}: {msg.value}")
    return y, dt


# -- runs ---------------------------------------------------------------------------------------
def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        return ""


def parse_settings(text: str) -> list[tuple[int, list[int]]]:
    """ "64,128x16,64;512x16" -> [(64, [16, 64]), (128, [16, 64]), (512, [16])] (a resolution named
    twice gets its sample counts merged, in order)."""
    out: dict[int, list[int]] = {}
    for group in text.split(";"):
        if group.strip():
            res, spp = group.split("x")
            for n in res.split(","):
                out.setdefault(int(n), [])
                out[int(n)] += [int(s) for s in spp.split(",") if int(s) not in out[int(n)]]
    return [(n, sorted(s)) for n, s in sorted(out.items())]


def run_cycles(job: dict, settings, work: Path) -> tuple[list[dict], dict]:
    job = {**job, "settings": [[n, s] for n, s in settings], "out": str(work)}
    jp = work / "job.json"
    jp.write_text(json.dumps(job))
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, str(BAKE_SCRIPT), str(jp)], capture_output=True, text=True, check=False
    )
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"cycles_bake.py failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
    rows, meta = [], {}
    for line in r.stdout.splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            (rows.append(d) if "bake_s" in d else meta.update(d))
    meta["process_wall_s"] = wall
    return rows, meta


def run_ours(cb, repeats: int) -> list[dict]:
    from solver_bench import preset_solves

    from iat.bake.baker import Baker
    from iat.measure.metrics import reference_errors
    from iat.measure.reference import box_filtered_render

    rows = []
    for level, sol, best in preset_solves(cb.scene, repeats):
        t0 = time.perf_counter()
        baked = Baker(sol, cb.scene).bake()
        bake_s = time.perf_counter() - t0
        mesh_err = cb.errors(sol)
        cb.renderer.set_baked(baked)
        tex_err = reference_errors(box_filtered_render(cb.renderer, cb.camera, SIZE, "iat"), cb.ref, cb.mask)
        mem = baked.memory
        rows.append(
            {
                "quality": level,
                "solve_s": best,
                "bake_s": bake_s,
                "texture_bytes": int(mem.texture_bytes),
                "pixel_format": baked.policy.pixel_format if hasattr(baked, "policy") else None,
                "pages": int(mem.pages),
                **mesh_err,
                **{f"tex_{k}": v for k, v in tex_err.items()},
            }
        )
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    return rows


# -- equal error -----------------------------------------------------------------------------------
def equal_error(target: float, cyc: list[dict]) -> dict:
    """The cheapest measured Cycles setting with rel_smooth <= target, and the bake time interpolated
    (log-log between two sample counts of one resolution that bracket it; the cheapest resolution)."""
    ok = [r for r in cyc if r["rel_smooth"] <= target]
    best = min(ok, key=lambda r: r["bake_s"]) if ok else None
    interp = None
    for n in sorted({r["resolution"] for r in cyc}):
        pts = sorted((r for r in cyc if r["resolution"] == n), key=lambda r: r["samples"])
        for a, b in zip(pts, pts[1:], strict=False):
            if a["rel_smooth"] >= target >= b["rel_smooth"] and a["rel_smooth"] > b["rel_smooth"]:
                w = math.log(a["rel_smooth"] / target) / math.log(a["rel_smooth"] / b["rel_smooth"])
                t = math.exp(math.log(a["bake_s"]) + w * math.log(b["bake_s"] / a["bake_s"]))
                spp = math.exp(math.log(a["samples"]) + w * math.log(b["samples"] / a["samples"]))
                if interp is None or t < interp["bake_s"]:
                    interp = {
                        "resolution": n,
                        "samples": spp,
                        "bake_s": t,
                        "texture_bytes_rgba16f_mips": a["texture_bytes_rgba16f_mips"],
                    }
                break
        if pts and pts[0]["rel_smooth"] <= target:  # already below at the fewest samples
            c = {
                "resolution": n,
                "samples": pts[0]["samples"],
                "bake_s": pts[0]["bake_s"],
                "texture_bytes_rgba16f_mips": pts[0]["texture_bytes_rgba16f_mips"],
                "at_fewest": True,
            }
            if interp is None or c["bake_s"] < interp["bake_s"]:
                interp = c
    return {"measured": best, "interpolated": interp}


def _mib(b):
    return f"{b / (1 << 20):.2f}"


def committed_quality() -> dict | None:
    """The ``quality`` table of ``benchmarks/solver.json`` (``solver_bench.py quality``) as committed
    at git HEAD (the working tree's file when git cannot say), with ``commit`` added; or None."""
    try:
        r = subprocess.run(
            ["git", "-C", str(ROOT), "log", "-1", "--format=%h", "--", "benchmarks/solver.json"],
            capture_output=True,
            text=True,
            check=True,
        )
        commit = r.stdout.strip()
        text = subprocess.run(
            ["git", "-C", str(ROOT), "show", f"{commit}:benchmarks/solver.json"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        commit, text = "working tree", None
    try:
        q = json.loads(text if text else (ROOT / "benchmarks" / "solver.json").read_text()).get("quality")
    except (OSError, ValueError):
        return None
    if isinstance(q, dict) and q.get("rows"):
        return {**q, "commit": commit}
    return None


def comparisons(res: dict) -> None:
    """``res["equal_error"]``: for each preset of this run (``ours``) and of ``solver.json``
    (``ours_solver_json``), the Cycles settings at that error."""
    res["equal_error"] = {}
    variants = {
        "raw": res["cycles"],
        "oidn": [
            {**r, "rel_smooth": r["oidn"]["rel_smooth"], "bake_s": r["bake_s"] + r["oidn"]["denoise_s"]}
            for r in res["cycles"]
            if "oidn" in r
        ],
    }
    for key in ("ours_solver_json", "ours"):
        for v, cyc in variants.items():
            if cyc and res.get(key):
                res["equal_error"][f"{key}/{v}"] = [
                    {
                        "quality": r["quality"],
                        "rel_smooth": r["rel_smooth"],
                        **equal_error(r["rel_smooth"], cyc),
                    }
                    for r in res[key]
                ]


def format_md(res: dict) -> str:
    m = res["meta"]
    lines = [
        f"Run {m['date']}, {m['cpus']} CPUs, Blender {m.get('blender', '?')} (Cycles CPU, {m.get('threads')} threads), "
        f"load: `{m['uptime_before']}` before, `{m['uptime_after']}` after. Blender start (import bpy) {m.get('import_bpy_s', 0):.2f} s, "
        f"scene build {m.get('setup_s', 0):.2f} s; camera check: hits project {m['camera_check_subpixels']:.2e} sub-pixels from their centres.",
        "",
        "| Cycles atlas | samples | bake s | rgba16f + mips MiB | RGBA8 MiB | rel_smooth % | rel_blocks % | bias % | OIDN s | denoised: rel_smooth % | rel_blocks % | bias % |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["cycles"]:
        o = r.get("oidn")
        dn = (
            f"{o['denoise_s']:.2f} | {100 * o['rel_smooth']:.2f} | {100 * o['rel_blocks']:.2f} | {100 * o['bias']:+.2f}"
            if o
            else "- | - | - | -"
        )
        lines.append(
            f"| {r['resolution']}² | {r['samples']} | {r['bake_s']:.2f} | {_mib(r['texture_bytes_rgba16f_mips'])} | "
            f"{_mib(r['texture_bytes_rgba8'])} | {100 * r['rel_smooth']:.2f} | {100 * r['rel_blocks']:.2f} | {100 * r['bias']:+.2f} | {dn} |"
        )
    ours = {r["quality"]: r for r in res.get("ours") or []}
    if ours:
        lines += [
            "",
            "Ours in this run (same load):",
            "",
            "| preset | solve s | bake s | texture MiB (rgba16f + mips) | mesh image rel_smooth % | rel_blocks % | bias % | baked textures (iat mode) rel_smooth % |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in ours.values():
            lines.append(
                f"| {r['quality']} | {r['solve_s']:.2f} | {r['bake_s']:.3f} | {_mib(r['texture_bytes'])} | {100 * r['rel_smooth']:.2f} | "
                f"{100 * r['rel_blocks']:.2f} | {100 * r['bias']:+.2f} | {100 * r['tex_rel_smooth']:.2f} |"
            )
    eq = res.get("equal_error") or {}
    for ek in eq:
        key, variant = ek.split("/")
        sq = res["meta"].get("solver_json_quality") or {}
        title = (
            f"solver.json's quality table at {sq.get('commit')} ({sq.get('date')}, load {sq.get('load')})"
            if key == "ours_solver_json"
            else "this run"
        )
        rows = {r["quality"]: r for r in res.get(key) or []}
        what = "Cycles raw" if variant == "raw" else "Cycles + OIDN (time: bake + denoise)"
        lines += [
            "",
            f"At equal error, {what} (our errors and times from {title}; our bake time and texture memory from this run):",
            "",
            "| preset | ours: s | rel_smooth % | MiB | Cycles cheapest measured at or below: atlas x samples | bake s | x ours | rel_smooth % | MiB | x ours | Cycles interpolated: atlas, samples, bake s | x ours |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for c in eq[ek]:
            r = rows[c["quality"]]
            t = r.get("solve_s", r.get("time_s")) + (ours.get(c["quality"], {}).get("bake_s") or 0.0)
            mem = ours.get(c["quality"], {}).get("texture_bytes")
            me, it = c["measured"], c["interpolated"]
            cells = [c["quality"], f"{t:.2f}", f"{100 * c['rel_smooth']:.2f}", _mib(mem) if mem else "-"]
            if me:
                cells += [
                    f"{me['resolution']}² x {me['samples']}",
                    f"{me['bake_s']:.2f}",
                    f"{me['bake_s'] / t:.0f}",
                    f"{100 * me['rel_smooth']:.2f}",
                    _mib(me["texture_bytes_rgba16f_mips"]),
                    f"{me['texture_bytes_rgba16f_mips'] / mem:.2f}" if mem else "-",
                ]
            else:
                cells += ["not reached", "-", "-", "-", "-", "-"]
            cells += (
                [f"{it['resolution']}², {it['samples']:.0f}, {it['bake_s']:.2f} s", f"{it['bake_s'] / t:.0f}"]
                if it
                else ["not reached", "-"]
            )
            lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(
        "Our time is solve + bake (kernels loaded); Cycles' is the bake call alone (Blender's start and scene build are extra)."
    )
    return "\n".join(lines)


def score(rows: list[dict], work: Path, cb, hits, dirs, keep) -> None:
    """Each Cycles bake's errors, raw and denoised by OIDN, and texture bytes (into ``rows``)."""
    from iat.measure.metrics import reference_errors

    for r in rows:
        n, s = r["resolution"], r["samples"]
        tex = np.load(work / f"bake_{n}_{s}.npy")
        uv = np.load(work / f"uv_{n}.npy")
        img = lightmap_image(tex, uv, hits, dirs.shape[:2])
        r.update(reference_errors(img, cb.ref, cb.mask))
        dn = oidn_denoise(tex)
        if dn is not None:
            den = reference_errors(lightmap_image(dn[0], uv, hits, dirs.shape[:2]), cb.ref, cb.mask)
            r["oidn"] = {"denoise_s": dn[1], **den}
        if keep:
            Path(keep).mkdir(parents=True, exist_ok=True)
            for name in (f"bake_{n}_{s}.npy", f"uv_{n}.npy"):
                (Path(keep) / name).write_bytes((work / name).read_bytes())
        r["texture_bytes_rgba16f_mips"] = int(round(n * n * 8 * 4 / 3))
        r["texture_bytes_rgba8"] = n * n * 4
        r["texture_bytes_rgba32f"] = n * n * 16
        print(
            {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items() if k != "oidn"},
            r.get("oidn"),
            flush=True,
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--settings",
        default=DEFAULT_SETTINGS,
        help="atlas resolutions x Cycles samples, groups separated by ';' (default %(default)s)",
    )
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-ours", action="store_true", help="skip our presets (keep those in cycles.json)")
    ap.add_argument("--out", default=str(OUT_JSON))
    ap.add_argument("--report", action="store_true", help="only print the tables of --out")
    ap.add_argument("--keep", default="", help="a folder to keep the baked atlases and UVs in (.npy)")
    ap.add_argument(
        "--rescore",
        default="",
        help="score the atlases kept in this folder (timings from --out) instead of baking",
    )
    a = ap.parse_args(argv)
    if a.report:
        res = json.loads(Path(a.out).read_text())
        comparisons(res)
        print(format_md(res))
        return 0
    if importlib.util.find_spec("bpy") is None:
        print("cycles_bench: skipped, no bpy in this Python (pip install bpy==4.2.* on Python 3.11)")
        return 0
    settings = parse_settings(a.settings)
    from solver_bench import Cornell

    head = subprocess.run(
        ["git", "-C", str(ROOT), "log", "-1", "--format=%h"], capture_output=True, text=True, check=False
    )
    meta = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "head": head.stdout.strip(),
        "cpus": os.cpu_count(),
        "uptime_before": uptime(),
        "command": "benchmarks/cycles_bench.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "reference": "Mitsuba 4096 spp seed 3, 96 x 96 box filter (solver_bench quality)",
    }
    cb = Cornell(spp=4096, seed=3)
    job, wt = scene_job(cb.scene)
    dirs, eye = camera_rays(cb.camera, SIZE)
    hits = ray_cast(wt, eye, dirs)
    meta["camera_check_subpixels"] = check_camera(cb.camera, dirs, eye, hits)
    print(f"camera check: {meta['camera_check_subpixels']:.2e} sub-pixels", flush=True)

    old = json.loads(Path(a.out).read_text()) if Path(a.out).is_file() else {}
    ours = old.get("ours") if (a.no_ours or a.rescore) else run_ours(cb, a.repeats)
    cb.renderer.release()
    if a.rescore:  # the bakes of an earlier run (``--keep``), its timings from --out
        crow, cmeta = old["cycles"], {}
        meta = {
            **old["meta"],
            "rescored": meta["date"],
            "camera_check_subpixels": meta["camera_check_subpixels"],
        }
        meta.pop("solver_json_quality_date", None)
        score(crow, Path(a.rescore), cb, hits, dirs, None)
        meta["uptime_after"] = old["meta"].get("uptime_after", "")
    else:
        with tempfile.TemporaryDirectory(prefix="cycles_bench_") as tmp:
            work = Path(tmp)
            crow, cmeta = run_cycles(job, settings, work)
            meta.update(cmeta)
            score(crow, work, cb, hits, dirs, a.keep)
        meta["uptime_after"] = uptime()
    res = {"meta": meta, "cycles": crow, "ours": ours}
    cq = committed_quality()
    if cq:
        res["ours_solver_json"] = cq.get("rows")
        meta["solver_json_quality"] = {k: cq.get(k) for k in ("date", "load", "commit")}
    if not a.rescore and old.get("cycles"):  # the run before this one, for the record
        res["previous_run"] = {"meta": old.get("meta"), "cycles": old["cycles"], "ours": old.get("ours")}
    elif old.get("previous_run"):
        res["previous_run"] = old["previous_run"]
    comparisons(res)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(format_md(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
