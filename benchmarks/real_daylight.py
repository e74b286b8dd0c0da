"""Issue 36: how right IAT mode is by daylight on real and generated buildings, at each quality preset,
against Mitsuba 3 path-traced references whose BSDFs reflect on both sides (the building as built).

Cases:

- the generated faults of ``tests/test_real_daylight.py`` (a 4 x 5 m room by the default daylight,
  each with one fault: an inside-out ceiling, an open-sheet sofa, walls through the roof in the sun,
  coincident faces, albedo 0.97, no ground; and the tidy room), two views each;
- ``madrid``: ``../shared/real-models/revit2021-madrid-house.ifc`` (Revit 2021, 74 k triangles) with
  its default daylight (its IfcSite: 40.42 N, 3.71 W, 10:00 on the equinox after the fixed day of
  the test module), cameras at eye height inside it, found by tracing rays (it has no IfcSpace: see
  :func:`house_cameras`), looking along the room.

Per view and preset: the relative error on the lit pixels (4 x 4 blocks, and per pixel), the share of
lit pixels IAT leaves black, bias, the reference's own noise; per solve: seconds, elements, shots,
peak resident memory during the solve (sampled every 20 ms from /proc/self/statm) and its rise over
the memory before. Mitsuba references are cached in ``out/real_daylight/refs`` (the 64 x 48
``floor`` views of the generated cases share ``tests/refs``); side-by-side PNGs (IAT | Mitsuba |
relative error, red = IAT too bright, blue = too dark) go to ``out/real_daylight/png``.

    .venv/bin/python benchmarks/real_daylight.py [--cases tidy,near_white,...|none] [--house]
        [--presets draft,default,fine] [--house-presets draft,default] [--json F] [--md F]

The JSON and Markdown are written as each case finishes (a long run keeps what it measured).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import test_real_daylight as trd  # noqa: E402

OUT = ROOT / "out" / "real_daylight"
HOUSE = ROOT.parent / "shared" / "real-models" / "revit2021-madrid-house.ifc"
#: the house's views: pixels, samples per pixel (two halves of seeds 1 and 2), how many rooms
HOUSE_SIZE = (64, 48)
HOUSE_SPP = 1024
HOUSE_VIEWS = 3
EYE_HEIGHT = 1.6
#: a view is kept when at least this share of its pixels is on the model (not outside, not the sky)
MIN_SURFACE = 0.9


# -- memory --------------------------------------------------------------------------------------------
def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class PeakRSS:
    """Peak resident memory of this process while the block runs (sampled every 20 ms)."""

    def __enter__(self):
        self.before = self.peak = _rss()
        self._stop = threading.Event()

        def watch():
            while not self._stop.wait(0.02):
                self.peak = max(self.peak, _rss())

        self._t = threading.Thread(target=watch, daemon=True)
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()
        self.peak = max(self.peak, _rss())


# -- images --------------------------------------------------------------------------------------------
def save_side_by_side(path: Path, img, ref, surface) -> None:
    """IAT | Mitsuba | relative error of 4 x 4 block means (red: IAT brighter, blue: darker, full at
    +-25 %; grey: off the model), 4x enlarged; the two float images beside it as ``.npz``."""
    from PIL import Image

    from iat.color import LUMINANCE_WEIGHTS
    from iat.measure.metrics import srgb_tonemap

    yr, yi = ref @ LUMINANCE_WEIGHTS, img @ LUMINANCE_WEIGHTS
    exposure = 0.8 / max(float(np.percentile(yr[surface], 99)) if surface.any() else 1.0, 1e-12)
    a, b = srgb_tonemap(img, exposure), srgb_tonemap(ref, exposure)
    k = trd.COARSE
    br, bi = trd._blocks(yr, k), trd._blocks(yi, k)
    rel = np.clip((bi - br) / np.maximum(br, 1e-9) / 0.25, -1, 1)
    rel = np.kron(rel, np.ones((k, k)))
    err = np.stack([np.clip(rel, 0, 1), np.zeros_like(rel), np.clip(-rel, 0, 1)], axis=-1)
    err[~surface[: err.shape[0], : err.shape[1]]] = 0.25
    gap = np.ones((a.shape[0], 2, 3))
    row = np.concatenate([a, gap, b, gap, err], axis=1)
    im = Image.fromarray((np.clip(row, 0, 1) * 255).astype(np.uint8))
    path.parent.mkdir(parents=True, exist_ok=True)
    im.resize((im.width * 4, im.height * 4), Image.NEAREST).save(path)
    np.savez_compressed(
        path.with_suffix(".npz"), iat=img.astype(np.float32), ref=ref.astype(np.float32), surface=surface
    )


# -- the house's cameras -------------------------------------------------------------------------------
def _trace(tris: np.ndarray, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(distance, triangle)`` of each ray's first hit (inf, -1 where it escapes)."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    sc = rtcs.EmbreeScene()
    v = np.ascontiguousarray(tris.reshape(-1, 3), dtype=np.float32)
    TriangleMesh(sc, v, np.arange(len(v), dtype=np.int32).reshape(-1, 3))
    res = sc.run(origins.astype(np.float32), dirs.astype(np.float32), output=1)
    prim = np.asarray(res["primID"], dtype=np.int64)
    dist = np.where(prim >= 0, np.asarray(res["tfar"], dtype=np.float64), np.inf)
    return dist, prim


def house_cameras(scene, renderer, size, count: int, spacing: float = 0.5) -> list:
    """``[(name, Camera)]``: eye-height views inside the building, found from its triangles (the house
    has no IfcSpace). Floors are the heights holding the most upward-facing area; candidate eyes
    stand on a ``spacing`` grid :data:`EYE_HEIGHT` above each, and are kept when, of 200 directions
    around them, at most 2 % escape (glass is hit: a room is closed), every one of 16 horizontal
    directions meets something within 15 m, at least 90 % of the hits see a surface's front (not
    inside a solid), the nearest hit is 0.5 m away or more, and the floor below is at eye height.
    Each looks horizontally along its longest free line of 16; the ``count`` longest lines, eyes
    at least 2 m apart, whose view is at least :data:`MIN_SURFACE` on the model."""
    from iat.camera import Camera
    from iat.measure.reference import SUPERSAMPLE

    tris = scene.world_triangles()
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    area = np.linalg.norm(n, axis=1) / 2
    n = n / np.maximum(2 * area, 1e-300)[:, None]
    up = (n[:, 1] > 0.95) & (area > 0)
    y = tris[:, :, 1].mean(axis=1)
    lo, hi = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
    bins = np.round(y[up] / 0.1).astype(np.int64)
    levels = np.bincount(bins - bins.min(), weights=area[up])
    floors = []
    for k in np.argsort(levels)[::-1]:
        fy = (k + bins.min()) * 0.1
        if levels[k] < 5.0 or any(abs(fy - f) < 2.2 for f in floors):
            continue
        floors.append(fy)
        if len(floors) == 3:
            break
    rng = np.random.default_rng(0)
    sphere = rng.normal(size=(200, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    ang = np.arange(16) * (2 * np.pi / 16)
    horiz = np.stack([np.cos(ang), np.zeros(16), np.sin(ang)], axis=1)
    cands = []
    xs = np.arange(lo[0] + spacing / 2, hi[0], spacing)
    zs = np.arange(lo[2] + spacing / 2, hi[2], spacing)
    for fy in floors:
        gx, gz = (a.ravel() for a in np.meshgrid(xs, zs))
        eyes = np.stack([gx, np.full(gx.shape, fy + EYE_HEIGHT), gz], axis=1)
        o = np.repeat(eyes, len(sphere), axis=0)
        d = np.tile(sphere, (len(eyes), 1))
        dist, prim = _trace(tris, o, d)
        dist, prim = dist.reshape(len(eyes), -1), prim.reshape(len(eyes), -1)
        hit = prim >= 0
        front = hit & ((n[np.maximum(prim, 0)] * sphere[None]).sum(axis=2) < 0)
        down, _ = _trace(tris, eyes, np.tile([0.0, -1.0, 0.0], (len(eyes), 1)))
        hd, _ = _trace(tris, np.repeat(eyes, 16, axis=0), np.tile(horiz, (len(eyes), 1)))
        ok = (
            (hit.mean(axis=1) >= 0.98)
            & (hd.reshape(len(eyes), 16) < 15.0).all(axis=1)
            & (front.sum(axis=1) >= 0.9 * hit.sum(axis=1))
            & (np.where(hit, dist, np.inf).min(axis=1) >= 0.5)
            & (np.abs(down - EYE_HEIGHT) < 0.15)
        )
        for e in eyes[ok]:
            hd, _ = _trace(tris, np.tile(e, (16, 1)), horiz)
            k = int(np.argmax(np.where(np.isfinite(hd), hd, -1)))
            if np.isfinite(hd[k]):
                cands.append((float(hd[k]), e, horiz[k]))
    cands.sort(key=lambda c: -c[0])
    out: list = []
    w, h = size
    for length, eye, d in cands:
        if any(np.linalg.norm(eye - c.eye) < 2.0 for _, c in out):
            continue
        cam = Camera(eye=eye, target=eye + d, yfov=75.0, znear=0.05, zfar=200.0, name=f"line {length:.1f} m")
        cov = renderer.render(cam, (w * SUPERSAMPLE, h * SUPERSAMPLE), mode="preview").max(axis=-1) > 0
        if float(cov.mean()) >= MIN_SURFACE:
            out.append((f"view{len(out) + 1}", cam))
        if len(out) >= count:
            break
    return out


# -- the sky seen through openings and panes -------------------------------------------------------------
def sky_seen(scene, camera, size, cache_dir) -> np.ndarray:
    """(h, w) bool: pixels where the sky is seen through an opening or a pane (Mitsuba, emitters seen
    directly only, no lights: IAT mode draws no sky there); left out of the house's comparison."""
    import copy

    from iat.color import LUMINANCE_WEIGHTS
    from iat.measure.reference import render_reference_cached

    sky_only = copy.copy(scene)
    sky_only.lights = []
    img = render_reference_cached(sky_only, camera, size, 16, cache_dir, seed=1, max_depth=1, two_sided=True)
    return img.astype(np.float64) @ LUMINANCE_WEIGHTS > 0


def views_of(desc: dict) -> dict:
    """The house's cameras again from the run's ``views`` texts (eyes to 1 cm; directions snapped
    to the 16 that :func:`house_cameras` tries)."""
    import re

    from iat.camera import Camera

    out = {}
    for name, text in desc.items():
        nums = [float(x) for x in re.findall(r"-?\d+\.?\d*", text)]
        eye, d = np.array(nums[:3]), np.array(nums[3:6])
        a = round(np.degrees(np.arctan2(d[2], d[0])) / 22.5) * np.radians(22.5)
        d = np.array([np.cos(a), 0.0, np.sin(a)])
        out[name] = Camera(eye=eye, target=eye + d, yfov=75.0, znear=0.05, zfar=200.0)
    return out


def rescore_house(result: dict, views: dict, presets) -> list:
    """The house's rows again from the IAT images its run saved (``out/real_daylight/png/*.npz``; no
    solve), against its two-sided references (glass as the solver has it: :mod:`iat.measure.reference`),
    the pixels where the sky is seen left out (:func:`sky_seen`)."""
    from iat.io.load import load_scene
    from iat.lighting.daylight_default import apply_daylight

    as_built = load_scene(HOUSE, sides="front")
    apply_daylight(as_built, today=trd.TODAY)
    old = {(r["view"], r["preset"]): r for r in result["rows"] if r["case"] == "madrid"}
    rows = []
    for vname, cam in views.items():
        ref, half = trd.reference(as_built, cam, HOUSE_SIZE, HOUSE_SPP, OUT / "refs")
        seen = sky_seen(as_built, cam, HOUSE_SIZE, OUT / "refs")
        for q in presets:
            f = OUT / "png" / f"madrid-{vname}-{q}.npz"
            if not f.is_file() or (vname, q) not in old:
                continue
            d = np.load(f)
            surface = d["surface"] & ~seen
            fig = trd.view_figures(d["iat"].astype(np.float64), ref, surface, half)
            save_side_by_side(OUT / "png" / f"madrid-{vname}-{q}-rescored.png", d["iat"], ref, surface)
            row = {
                **old[(vname, q)],
                **{k: round(v, 4) if isinstance(v, float) else v for k, v in fig.items()},
            }
            row["reference"] = "two-sided, glass as the solver has it (volpath, one pane counted once)"
            rows.append(row)
            e, b, bias = fig["rel_error"], fig["black"], fig["bias"]
            print(f"  madrid/{vname} {q}: error {e:.3f}, black {b:.4f}, bias {bias:+.3f}", flush=True)
    return rows


# -- one case --------------------------------------------------------------------------------------------
def measure_case(name, scene, as_built, views, presets, size, spp, ref_dirs, renderer, extra=None) -> list:
    """Rows ``{case, view, preset, ...figures, solve_s, elements, ...}`` of one model."""
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy
    from iat.errors import SolveError
    from iat.radiosity import SolveOptions, solve

    refs = {}
    for vname, cam in views.items():
        t0 = time.perf_counter()
        refs[vname] = trd.reference(as_built, cam, size, spp, ref_dirs.get(vname, OUT / "refs"))
        print(f"  {name}/{vname}: reference {time.perf_counter() - t0:.1f} s", flush=True)
    rows = []
    for q in presets:
        with PeakRSS() as mem:
            t0 = time.perf_counter()
            try:
                sol = solve(scene, SolveOptions.preset(q))
                err = None
            except SolveError as e:
                sol, err = None, str(e)
            solve_s = time.perf_counter() - t0
        base = {
            "case": name,
            "preset": q,
            "solve_s": round(solve_s, 2),
            "peak_rss_mib": round(mem.peak / 2**20, 1),
            "rss_rise_mib": round((mem.peak - mem.before) / 2**20, 1),
            **(extra or {}),
        }
        if sol is None:
            rows.append({**base, "view": "-", "error": err})
            print(f"  {name} {q}: SolveError {err}", flush=True)
            continue
        st = sol.stats
        base.update(elements=int(st["elements"]), shots=int(st["shots"]), unshot=float(st["unshot_fraction"]))
        t0 = time.perf_counter()
        baked = Baker(sol, scene).bake(BakePolicy())
        base["bake_s"] = round(time.perf_counter() - t0, 2)
        for vname, cam in views.items():
            ref, half = refs[vname]
            img, surface = trd.iat_image(renderer, scene, baked, cam, size)
            f = trd.view_figures(img, ref, surface, half)
            save_side_by_side(OUT / "png" / f"{name}-{vname}-{q}.png", img, ref, surface)
            rows.append(
                {
                    **base,
                    "view": vname,
                    **{k: round(v, 4) if isinstance(v, float) else v for k, v in f.items()},
                }
            )
            print(
                f"  {name}/{vname} {q}: error {f['rel_error']:.3f} (px {f['rel_error_px']:.3f}, "
                f"ref noise {f['ref_noise']:.3f}), black {f['black']:.4f}, bias {f['bias']:+.3f}; "
                f"{solve_s:.1f} s, {base['elements']} elements, {base['peak_rss_mib']} MiB",
                flush=True,
            )
    return rows


def generated(cases, presets, renderer) -> list:
    rows = []
    for c in cases:
        path = trd.write_case(c, OUT / "cases")
        scene, as_built = trd.load_case(path), trd.load_case(path, sides="front")
        sides = scene.sides.to_dict()
        extra = {
            "patches": int(scene.n_patches),
            "sides": {k: sides[k] for k in ("inside_out", "flipped_faces", "open_sheets", "twin_patches")},
        }
        dirs = {"floor": trd.REFS}  # the tests' view: one cache
        rows += measure_case(
            c, scene, as_built, trd.VIEWS, presets, trd.TEST_SIZE, trd.TEST_SPP, dirs, renderer, extra
        )
    return rows


def house(presets, renderer) -> list:
    from iat.geometry.discontinuity import cut_new_lights
    from iat.io.load import load_scene
    from iat.lighting.daylight_default import apply_daylight

    t0 = time.perf_counter()
    scene = load_scene(HOUSE)
    load_s = time.perf_counter() - t0
    line = apply_daylight(scene, today=trd.TODAY)
    scene = cut_new_lights(scene)  # its sun's shadows, as iat solve cuts them
    print(f"madrid: loaded in {load_s:.1f} s, {scene.n_patches} patches; {line}", flush=True)
    as_built = load_scene(HOUSE, sides="front")
    apply_daylight(as_built, today=trd.TODAY)
    renderer.set_scene(scene)
    cams = house_cameras(scene, renderer, HOUSE_SIZE, HOUSE_VIEWS)
    desc = {
        n: f"eye {np.round(c.eye, 2).tolist()} towards {np.round(c.forward, 2).tolist()}" for n, c in cams
    }
    print("madrid views: " + "; ".join(f"{n}: {t}" for n, t in desc.items()), flush=True)
    views = dict(cams)
    extra = {"patches": int(scene.n_patches), "load_s": round(load_s, 1), "views": desc}
    return measure_case("madrid", scene, as_built, views, presets, HOUSE_SIZE, HOUSE_SPP, {}, renderer, extra)


# -- output ----------------------------------------------------------------------------------------------
def markdown(result: dict) -> str:
    lines = [
        "# Real and generated buildings by daylight against Mitsuba (issue 36)",
        "",
        f"`{result['command']}`, {result['date']}, load average "
        f"{result['load_average']} on {result['cpus']} cores. IAT mode (default bake) against a two-sided "
        "Mitsuba reference; error = mean relative luminance error on the lit 4 x 4 blocks (per pixel in "
        "brackets), black = share of lit pixels under 1 % of the view's mean, noise = the reference's own "
        "on the blocks.",
        "",
        "| case | view | preset | error | (per pixel) | black | bias | ref noise | solve s | elements "
        "| shots | peak MiB | rise MiB | code |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    codes: dict[str, str] = {}
    for r in result["rows"]:
        tag = codes.setdefault(r.get("code", "?"), "abcdefghij"[len(codes) % 10])
        if "error" in r:
            lines.append(
                f"| {r['case']} | - | {r['preset']} | SolveError: {r['error']} "
                f"|||||| {r['solve_s']} |||| {tag} |"
            )
            continue
        lines.append(
            f"| {r['case']} | {r['view']} | {r['preset']} | {r['rel_error']:.3f} | ({r['rel_error_px']:.3f}) "
            f"| {r['black']:.4f} | {r['bias']:+.3f} | {r['ref_noise']:.3f} | {r['solve_s']:.1f} "
            f"| {r['elements']} | {r['shots']} | {r['peak_rss_mib']:.0f} | {r['rss_rise_mib']:.0f} | {tag} |"
        )
    lines += ["", "Code measured (commit, then the files of iat/ modified in the shared tree then):", ""]
    lines += [f"- {tag}: {code}" for code, tag in codes.items()]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(trd.CASES), help="generated cases (comma-separated) or none")
    ap.add_argument("--presets", default="draft,default,fine")
    ap.add_argument("--house", action="store_true", help="also the Madrid house (minutes)")
    ap.add_argument("--house-presets", default="draft,default")
    ap.add_argument(
        "--rescore-house",
        action="store_true",
        help="redo the house rows from its saved IAT images (no solve), sky-seen pixels left out",
    )
    ap.add_argument("--json", default=str(ROOT / "benchmarks" / "real_daylight.json"))
    ap.add_argument("--md", default=str(ROOT / "benchmarks" / "real_daylight.md"))
    args = ap.parse_args(argv)
    import moderngl

    from iat.render.renderer import Renderer

    cases = [] if args.cases in ("", "none") else args.cases.split(",")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    status = subprocess.run(["git", "status", "--short", "iat"], cwd=ROOT, capture_output=True, text=True)
    dirty = sorted(line[3:] for line in status.stdout.splitlines() if line.strip())
    result = {
        "command": "python benchmarks/real_daylight.py "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "commit": commit.stdout.strip(),
        "code": commit.stdout.strip() + ("+" + ",".join(dirty) if dirty else ""),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average": [round(x, 1) for x in os.getloadavg()],
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "rows": [],
    }
    if Path(args.json).is_file():  # keep rows of cases this run does not redo
        old = json.loads(Path(args.json).read_text())
        redo = set(cases) | ({"madrid"} if args.house else set())
        result["rows"] = [r for r in old.get("rows", []) if r["case"] not in redo]
    r = Renderer(moderngl.create_standalone_context(backend="egl"))

    def write():
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
        Path(args.md).write_text(markdown(result))

    def add(rows):  # the code measured: what this process imported (the tree at its start)
        result["rows"] += [{**row, "code": result["code"]} for row in rows]
        write()

    late = [
        c for c in cases if c in ("wall_through_slab", "slab_ends_on_wall")
    ]  # others change the solver for it: measured last
    for c in [c for c in cases if c not in late]:
        add(generated([c], args.presets.split(","), r))
    if args.house:
        add(house(args.house_presets.split(","), r))
    if args.house or args.rescore_house:  # the house's figures without the pixels where the sky is seen
        desc = next(row["views"] for row in result["rows"] if row["case"] == "madrid")
        new = rescore_house(result, views_of(desc), args.house_presets.split(","))
        result["rows"] = [row for row in result["rows"] if row["case"] != "madrid"] + new
        write()
    for c in late:
        add(generated([c], args.presets.split(","), r))
    r.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
