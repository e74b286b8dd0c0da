"""What a solve spends per ray, and Embree called from a compiled kernel (issue 18).

1. **Budget.** One solve on one thread (``IAT_RAY_THREADS=1``, numba's kernels on one thread), with wall
   clocks around the gather's steps: the form-factor kernel, ``block_inputs``, ``gather_rays`` (the
   samples' weights and rays), ``Visibility.visible`` (embreex) and ``gather_finish`` (the field
   read at the visible samples). Nanoseconds per gather ray each: the ceiling of "rays per second
   of solve against bare embreex" is embree's share of the per-ray time, before anything else a
   solve does (meshing, Python, the ambient term).
2. **Embree from numba.** The library embreex bundles, loaded with ctypes; a scene of the model's
   opaque triangles built through its C API; ``rtcOccluded1`` called from an ``njit`` loop (the
   ray as a 48-byte float32 / uint32 record). Checks that it answers as embreex does on the same
   rays, and compares their rays per second, on one thread and on two (``prange``).

Usage: ``.venv/bin/python benchmarks/ray_budget.py [--model pool] [--convergence 0.2]``; writes
``benchmarks/ray_budget.md`` and ``.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("IAT_RAY_THREADS", "1")

import argparse  # noqa: E402
import ctypes  # noqa: E402
import glob  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from numba import get_num_threads, njit, prange, set_num_threads  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from solver_bench import random_rays  # noqa: E402

import iat.radiosity.kernels as kernels_module  # noqa: E402
from iat.io.load import load_scene  # noqa: E402
from iat.radiosity import SolveOptions, solve  # noqa: E402
from iat.radiosity.visibility import Visibility  # noqa: E402

#: the gather's steps timed in part 1: (where the name is looked up, name)
STEPS = (
    (kernels_module, "patch_form_factors"),
    (kernels_module, "block_inputs"),
    (kernels_module, "gather_rays"),
    (Visibility, "visible"),
    (kernels_module, "gather_finish"),
)


def budget(model: str, convergence: float) -> dict:
    """Part 1: seconds, calls and ns per gather ray of each step of one solve of ``model``."""
    seconds, calls, rays = Counter(), Counter(), Counter()
    lock = threading.Lock()
    originals = [(owner, name, getattr(owner, name)) for owner, name in STEPS]

    def timed(name, fn):
        def call(*args, **kwargs):
            t = time.perf_counter()
            out = fn(*args, **kwargs)
            dt = time.perf_counter() - t
            with lock:
                seconds[name] += dt
                calls[name] += 1
                if name == "visible":
                    rays[name] += len(args[1])
            return out

        return call

    scene = load_scene(ROOT / "sample_models" / f"{model}.glb")
    solve(scene, SolveOptions(max_shots=5))  # the kernels loaded
    for owner, name, fn in originals:
        setattr(owner, name, timed(name, fn))
    threads = get_num_threads()
    set_num_threads(1)  # the gathers run on this thread (one ray thread), their kernels too
    try:
        t = time.perf_counter()
        sol = solve(scene, SolveOptions(convergence=convergence))
        wall = time.perf_counter() - t
    finally:
        set_num_threads(threads)
        for owner, name, fn in originals:
            setattr(owner, name, fn)
    n = max(rays["visible"], 1)
    steps = {
        name: {"s": seconds[name], "calls": calls[name], "ns_per_ray": 1e9 * seconds[name] / n}
        for _, name in STEPS
    }
    return {
        "model": model,
        "convergence": convergence,
        "solve_s": wall,
        "rays_total": int(sol.stats["rays"]),
        "gather_rays": int(rays["visible"]),
        "steps": steps,
    }


def embree_library() -> str | None:
    """The path of the Embree library embreex bundles, or None."""
    import embreex

    found = sorted(glob.glob(str(Path(embreex.__path__[0]).parent / "embreex.libs" / "libembree4*.so*")))
    return found[0] if found else None


def embree_scene(lib, triangles: np.ndarray) -> int:
    """An Embree scene of ``triangles`` (T, 3, 3) through the C API; its handle."""
    vp, size = ctypes.c_void_p, ctypes.c_size_t
    lib.rtcNewDevice.restype, lib.rtcNewDevice.argtypes = vp, [ctypes.c_char_p]
    lib.rtcNewScene.restype, lib.rtcNewScene.argtypes = vp, [vp]
    lib.rtcNewGeometry.restype, lib.rtcNewGeometry.argtypes = vp, [vp, ctypes.c_int]
    lib.rtcSetNewGeometryBuffer.restype = vp
    lib.rtcSetNewGeometryBuffer.argtypes = [vp, ctypes.c_int, ctypes.c_uint, ctypes.c_int, size, size]
    lib.rtcAttachGeometry.restype, lib.rtcAttachGeometry.argtypes = ctypes.c_uint, [vp, vp]
    for name in ("rtcCommitGeometry", "rtcReleaseGeometry", "rtcCommitScene"):
        getattr(lib, name).argtypes = [vp]
    verts = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 3)
    index = np.arange(len(verts), dtype=np.uint32)
    device = lib.rtcNewDevice(None)
    scene = lib.rtcNewScene(device)
    geom = lib.rtcNewGeometry(device, 0)  # RTC_GEOMETRY_TYPE_TRIANGLE
    ctypes.memmove(
        lib.rtcSetNewGeometryBuffer(geom, 1, 0, 0x9003, 12, len(verts)), verts.ctypes.data, verts.nbytes
    )
    ctypes.memmove(
        lib.rtcSetNewGeometryBuffer(geom, 0, 0, 0x5003, 12, len(index) // 3), index.ctypes.data, index.nbytes
    )
    lib.rtcCommitGeometry(geom)
    lib.rtcAttachGeometry(scene, geom)
    lib.rtcReleaseGeometry(geom)
    lib.rtcCommitScene(scene)
    return scene


def tracers(lib):
    """``trace(scene, o, d, t, out)`` (one thread) and ``trace2`` (``prange`` blocks): out[i] True
    where ``rtcOccluded1`` finds a hit before t[i]."""
    size = ctypes.c_size_t
    occluded1 = ctypes.CFUNCTYPE(None, size, size, size)(ctypes.cast(lib.rtcOccluded1, ctypes.c_void_p).value)

    @njit(nogil=True)
    def trace(scene, o, d, t, out):
        buf = np.empty(16, np.float32)  # a 16-byte aligned RTCRay inside
        a = (16 - buf.ctypes.data % 16) // 4
        ray = buf[a : a + 12]
        bits = ray.view(np.uint32)
        ptr = ray.ctypes.data
        for i in range(o.shape[0]):
            ray[0], ray[1], ray[2], ray[3] = o[i, 0], o[i, 1], o[i, 2], 0.0
            ray[4], ray[5], ray[6], ray[7] = d[i, 0], d[i, 1], d[i, 2], 0.0
            ray[8] = t[i]
            bits[9], bits[10], bits[11] = 0xFFFFFFFF, 0, 0  # mask, id, flags
            occluded1(scene, ptr, 0)
            out[i] = ray[8] < 0  # tfar -inf on a hit

    @njit(nogil=True, parallel=True)
    def trace2(scene, o, d, t, out):
        n, blocks = o.shape[0], 64
        for b in prange(blocks):
            lo, hi = b * n // blocks, (b + 1) * n // blocks
            trace(scene, o[lo:hi], d[lo:hi], t[lo:hi], out[lo:hi])

    return trace, trace2


def from_numba(model: str, n: int = 1 << 21, rounds: int = 3) -> dict:
    """Part 2: embreex and Embree called from numba on the same ``n`` random rays of ``model``."""
    path = embree_library()
    if path is None:
        return {"skipped": "embreex's bundled libembree4 not found"}
    lib = ctypes.CDLL(path)
    scene = load_scene(ROOT / "sample_models" / f"{model}.glb")
    vis = Visibility.of_scene(scene, threads=1)
    o, d, t = random_rays(scene, n)
    t = t * np.random.default_rng(1).random(n)  # some rays short enough to pass
    o, d, t = (np.ascontiguousarray(x, dtype=np.float32) for x in (o, d, t))
    handle = embree_scene(lib, scene.world_triangles()[vis.opaque])
    trace, trace2 = tracers(lib)
    out1, out2 = np.zeros(n, bool), np.zeros(n, bool)
    trace(handle, o[:8], d[:8], t[:8], out1[:8])  # compile
    trace2(handle, o[:64], d[:64], t[:64], out2[:64])
    best = {"embreex": 0.0, "numba": 0.0, "numba_2_threads": 0.0}
    same = True
    with vis:
        for _ in range(rounds):
            t0 = time.perf_counter()
            ref = vis.occluded_chunk(o, d, t) == 0
            t1 = time.perf_counter()
            trace(handle, o, d, t, out1)
            t2 = time.perf_counter()
            trace2(handle, o, d, t, out2)
            t3 = time.perf_counter()
            same &= bool(np.array_equal(ref, out1) and np.array_equal(ref, out2))
            for key, dt in (("embreex", t1 - t0), ("numba", t2 - t1), ("numba_2_threads", t3 - t2)):
                best[key] = max(best[key], n / dt)
    return {
        "model": model,
        "rays": n,
        "occluded_fraction": float(ref.mean()),
        "same_answers": same,
        "library": Path(path).name,
        "rays_per_s": best,
    }


def format_md(res: dict) -> str:
    b, e = res["budget"], res["embree_from_numba"]
    lines = [
        "# Ray budget of a solve, and Embree from numba (`benchmarks/ray_budget.py`)",
        "",
        f"Run {res['when']}, {os.cpu_count()} CPUs, load {res['load']:.2f}.",
        "",
        f"## Budget: {b['model']} at convergence {b['convergence']}, one thread",
        "",
        f"Solve {b['solve_s']:.1f} s, {b['rays_total']:,} rays of which {b['gather_rays']:,} in gathers.",
        "",
        "| step | s | calls | ns per gather ray |",
        "|---|---:|---:|---:|",
    ]
    for name, s in b["steps"].items():
        lines.append(f"| `{name}` | {s['s']:.2f} | {s['calls']:,} | {s['ns_per_ray']:.0f} |")
    other = b["solve_s"] - sum(s["s"] for s in b["steps"].values())
    lines.append(
        f"| the rest of the solve (meshing, each call's Python, the ambient term) | {other:.2f} | | |"
    )
    vis = b["steps"]["visible"]["ns_per_ray"]
    rest = sum(s["ns_per_ray"] for k, s in b["steps"].items() if k != "visible")
    lines += [
        "",
        f"Embree's share of these steps alone: {vis / (vis + rest):.0%} (the rest of the solve not counted).",
        "",
        "## Embree called from a numba kernel",
        "",
    ]
    if "skipped" in e:
        lines.append(f"Skipped: {e['skipped']}.")
    else:
        r = e["rays_per_s"]
        lines += [
            f"{e['model']}, {e['rays']:,} random rays ({e['occluded_fraction']:.0%} occluded), "
            f"`{e['library']}`; the same answers as embreex: **{e['same_answers']}**.",
            "",
            "| tracer | M rays/s |",
            "|---|---:|",
            f"| embreex `run(query='OCCLUDED')`, one thread | {r['embreex'] / 1e6:.2f} |",
            f"| `rtcOccluded1` from an `njit` loop, one thread | {r['numba'] / 1e6:.2f} |",
            f"| the same, two threads (`prange`) | {r['numba_2_threads'] / 1e6:.2f} |",
        ]
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default="pool")
    ap.add_argument("--convergence", type=float, default=0.2)
    ap.add_argument("--rays-model", default="house", help="model of part 2's random rays")
    args = ap.parse_args(argv)
    res = {
        "when": time.strftime("%Y-%m-%dT%H:%M"),
        "budget": budget(args.model, args.convergence),
        "embree_from_numba": from_numba(args.rays_model),
        "load": os.getloadavg()[0],
    }
    out = ROOT / "benchmarks"
    (out / "ray_budget.json").write_text(json.dumps(res, indent=1))
    (out / "ray_budget.md").write_text(format_md(res))
    print(format_md(res))


if __name__ == "__main__":
    main()
