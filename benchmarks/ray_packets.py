"""Embree's rays one at a time against packets of 8 (issue 41): the rays a second of
``rtcOccluded1`` and ``rtcOccluded8`` on one thread, through :mod:`iat.radiosity.embree`'s own
helpers (``occluded1``; ``set_lane`` and ``visible8``), on three kinds of rays of a model:

- **sky**: from 3 000 random triangles' centres, 32 x 32 stratified cosine directions each (a
  random rotation per point), a packet holding 8 consecutive strata, as ``traced.sky_rays`` does;
- **gather**: from the same points to an 8 x 8 stratified pattern on one large triangle (a shooter),
  a packet holding 8 consecutive samples, as ``traced.gather_traced`` does;
- **random**: ``ray_budget.random_rays`` (incoherent), a packet holding 8 consecutive rays.

Whether both give the same answers, ray for ray, is checked on each.

    .venv/bin/python benchmarks/ray_packets.py [MODEL ...] [--rounds 3]

MODEL: a file ``load_scene`` reads (default: the furnished house of ``real_models_bench.py``, the
Revit Madrid house and the sample house). Prints a markdown table.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, set_num_threads

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from ray_budget import random_rays  # noqa: E402

from iat.io.load import load_scene  # noqa: E402
from iat.radiosity import embree  # noqa: E402

SIDE = 32  # sky strata a side
SHOOTER = 8  # gather samples a side


@njit(cache=True)
def _sky(i, j, rot, n, t1, t2, k, out):
    u = ((i + 0.5) / SIDE + rot[k, 0]) % 1.0
    v = ((j + 0.5) / SIDE + rot[k, 1]) % 1.0
    r, ph = math.sqrt(u), 2.0 * math.pi * v
    dx, dy, dz = r * math.cos(ph), r * math.sin(ph), math.sqrt(max(1.0 - u, 0.0))
    for c in range(3):
        out[c] = dx * t1[k, c] + dy * t2[k, c] + dz * n[k, c]


@njit(cache=True)
def rays_of(kind, o, n, t1, t2, rot, tri):
    """(R, 3) float32 directions and (R,) float32 lengths of the ``kind`` (0 sky, 1 gather) rays
    from o (k, 3), in the order the packets take them."""
    per = SIDE * SIDE if kind == 0 else SHOOTER * SHOOTER
    d = np.empty((o.shape[0] * per, 3), np.float32)
    t = np.empty(o.shape[0] * per, np.float32)
    w = np.empty(3)
    q = 0
    for k in range(o.shape[0]):
        for a in range(SIDE if kind == 0 else SHOOTER):
            for b in range(SIDE if kind == 0 else SHOOTER):
                if kind == 0:
                    _sky(a, b, rot, n, t1, t2, k, w)
                    t[q] = 1e30
                else:  # a stratified point of the triangle tri (3, 3), by the square-root map
                    su = math.sqrt((a + rot[k, 0]) / SHOOTER)
                    sv = (b + rot[k, 1]) / SHOOTER
                    for c in range(3):
                        w[c] = (
                            (1 - su) * tri[0, c] + su * (1 - sv) * tri[1, c] + su * sv * tri[2, c] - o[k, c]
                        )
                    r = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
                    w /= max(r, 1e-30)
                    t[q] = max(r - 1e-3, 0.0)
                d[q, 0], d[q, 1], d[q, 2] = w[0], w[1], w[2]
                q += 1
    return d, t


@njit(cache=True)
def one_at_a_time(fn, scene, o, d, t, per, out):
    rec, bits = embree.ray_record()
    for q in range(d.shape[0]):
        k = q // per
        out[q] = embree.occluded1(
            fn, scene, rec, bits, o[k, 0], o[k, 1], o[k, 2], d[q, 0], d[q, 1], d[q, 2], t[q]
        )


@njit(cache=True)
def in_packets(fn8, scene, o, d, t, per, out):
    pk = embree.packet_record()
    none = np.ones(1)
    for a in range(0, d.shape[0], embree.PACKET):
        m = min(embree.PACKET, d.shape[0] - a)
        for lane in range(m):
            q, k = a + lane, (a + lane) // per
            embree.set_lane(pk, lane, o[k, 0], o[k, 1], o[k, 2], d[q, 0], d[q, 1], d[q, 2], t[q])
        embree.visible8(fn8, 0, scene, 0, none, pk, m)
        for lane in range(m):
            out[a + lane] = pk[3][lane] == 0.0


def rates(path: Path, rounds: int) -> list[tuple]:
    scene = load_scene(path)
    tris = scene.world_triangles()
    es = embree.EmbreeScene(tris)
    rng = np.random.default_rng(1)
    tri = tris[rng.choice(len(tris), 3000)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None] + 1e-30
    size = float(np.ptp(tris.reshape(-1, 3), axis=0).max())
    o = np.ascontiguousarray(tri.mean(axis=1) + 1e-5 * size * n, dtype=np.float32)
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)
    rot = rng.random((len(o), 2))
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    shooter = np.ascontiguousarray(tris[int(np.argmax(area))], dtype=np.float64)
    kinds = {}
    for kind, name in ((0, "sky"), (1, "gather")):
        d, t = rays_of(kind, o, n, t1, t2, rot, shooter)
        kinds[name] = (o, d, t, len(t) // len(o))
    ro, rd, rt = random_rays(scene, 1 << 21)
    rt = rt * rng.random(len(rt))
    kinds["random"] = tuple(np.ascontiguousarray(x, dtype=np.float32) for x in (ro, rd, rt)) + (1,)
    set_num_threads(1)
    rows = []
    for name, (oo, d, t, per) in kinds.items():
        one, eight = np.zeros(len(t), bool), np.zeros(len(t), bool)
        best = [0.0, 0.0]
        for _ in range(rounds):
            for j, (f, fn, out) in enumerate(
                ((one_at_a_time, es.entry.occluded1, one), (in_packets, es.entry.occluded8, eight))
            ):
                t0 = time.perf_counter()
                f(fn, es.handle, oo, d, t, per, out)
                best[j] = max(best[j], len(t) / (time.perf_counter() - t0))
        same = bool(np.array_equal(one, eight))
        rows.append((path.name, name, len(t), float(one.mean()), best[0] / 1e6, best[1] / 1e6, same))
    es.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="*")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    models = [Path(m) for m in args.models] or [
        ROOT / "out" / "real_models_daylight" / "furnished-house.ifc",
        ROOT.parent / "shared" / "real-models" / "revit2021-madrid-house.ifc",
        ROOT / "sample_models" / "house.glb",
    ]
    head = "| model | rays | count | occluded | one at a time M/s | packets of 8 M/s | ratio | same |"
    print(head)
    print("|---|---|---:|---:|---:|---:|---:|---|")
    for path in models:
        if not path.exists():
            print(f"| {path.name} | (missing: `real_models_bench.py daylight` writes the furnished house) |")
            continue
        for name, kind, count, occ, r1, r8, same in rates(path, args.rounds):
            print(
                f"| {name} | {kind} | {count:,} | {occ:.0%} | {r1:.2f} | {r8:.2f} | {r8 / r1:.2f}x | {same} |"
            )


if __name__ == "__main__":
    main()
