"""Shared helpers for the sample model scripts (house, cave, lavapit, pool; Cornell box: the command line).

- :class:`ModelBuilder` wraps :class:`iat.glb.GlbBuilder`: it collects planar
  quads (written as the triangles ``[0, 1, 2], [2, 3, 0]``) and triangles per
  object, with flat normals and, for materials that carry a detail texture,
  world-planar ``TEXCOORD_0`` that repeats across the surface (uv beyond
  ``[0, 1]``, REPEAT sampler). Axis-aligned rectangles are split into a grid of
  panels of at most ``panel`` metres (the report's pre-radiosity polygons),
  with rectangular holes (doors, windows, pits) cut out on the grid lines.
- :func:`walk_path`: a smooth camera path through way points (Catmull-Rom,
  resampled by arc length), as the ``{eye, target, up, yfov}`` dicts stored in
  the root ``extras["iat_camera_paths"]``.
- :func:`fbm3`: deterministic 3-D value noise from an integer hash (no random
  generator, so the same numbers on every machine and numpy version).
- :func:`tile_texture` and :func:`png_bytes`: procedural tile textures as PNG
  bytes (sRGB, stored deflate blocks: identical bytes whatever zlib is installed).
- :func:`assemble` puts a model together (geometry, lights, meshes, cameras, extras);
  :func:`script_main` is every script's ``python sample_models/NAME.py [-o PATH]``.

Orientation conventions (as ``iat.io.scene``): a quad's corners run counter-clockwise
seen from its front, its normal is ``cross(c2 - c0, c3 - c1)``; radiosity uses
the front side only, so room faces look into the room and furniture faces out.
Everything is deterministic: the same calls give the same bytes.
"""

from __future__ import annotations

import argparse
import math
import struct
import sys
import zlib
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parent.parent
if str(_ROOT) not in sys.path:  # run as a script: make `iat` importable from the checkout
    sys.path.insert(0, str(_ROOT))

from iat.camera import Camera  # noqa: E402
from iat.color import srgb_encode  # noqa: E402
from iat.io.glb import GlbBuilder  # noqa: E402

__all__ = [
    "Camera",
    "ModelBuilder",
    "walk_path",
    "fbm3",
    "value_noise3",
    "tile_texture",
    "png_bytes",
    "AXES",
]

#: face name -> (axis, sign) of its outward normal, for boxes
AXES = {"-x": (0, -1), "+x": (0, 1), "-y": (1, -1), "+y": (1, 1), "-z": (2, -1), "+z": (2, 1)}

# in-plane axes (a, b) of a face whose normal is +axis: e_a x e_b = e_axis
_PLANE_AXES = {0: (1, 2), 1: (2, 0), 2: (0, 1)}

_TRI = np.array([[0, 1, 2], [2, 3, 0]], dtype=np.uint32)


def _subdivide(breaks: list[float], panel: float) -> list[float]:
    """Sorted break points with every interval split into equal parts no longer than ``panel``."""
    out = [breaks[0]]
    for a, b in zip(breaks[:-1], breaks[1:], strict=True):
        n = max(1, math.ceil((b - a) / panel - 1e-9))
        out.extend(a + (b - a) * k / n for k in range(1, n + 1))
    return out


class ModelBuilder:
    """Collect the faces of a model by object, then write one GLB.

    Attributes
    ----------
    glb : GlbBuilder
        the underlying writer (cameras, lights, extras go straight to it)
    panel : float
        default largest panel edge (metres) for :meth:`face`, :meth:`box`, :meth:`room`
    """

    def __init__(self, panel: float = 1.25):
        self.glb = GlbBuilder()
        self.panel = float(panel)
        self._mat_index: dict[str, int] = {}
        self._mat_period: dict[str, float | None] = {}
        self._objects: dict[str, dict] = {}  # name -> {material, quads: [...], tris: [...]}

    # -- materials ---------------------------------------------------------------------------------
    def material(
        self,
        name: str,
        base_color=(0.7, 0.7, 0.7),
        emissive=(0.0, 0.0, 0.0),
        texture: bytes | None = None,
        period: float | None = None,
        transmission: float = 0.0,
    ) -> str:
        """Add a material; returns its name (used to pick it in :meth:`face` and friends).

        texture : PNG bytes of a detail texture (baseColorTexture) repeated every ``period``
            metres along both in-plane axes of every face that uses the material.
        transmission : thin glass passing that fraction of the light (0: opaque).
        """
        if texture is not None and not (period and period > 0):
            raise ValueError(f"material {name!r}: a texture needs a period > 0")
        self._mat_index[name] = self.glb.add_material(
            name, base_color, emissive=emissive, base_color_png=texture, transmission=transmission
        )
        self._mat_period[name] = float(period) if texture is not None else None
        return name

    def _object(self, obj: str, material: str) -> dict:
        if material not in self._mat_index:
            raise ValueError(f"unknown material {material!r}")
        o = self._objects.setdefault(obj, {"material": material, "quads": [], "tris": []})
        if o["material"] != material:
            raise ValueError(f"object {obj!r} already uses material {o['material']!r}")
        return o

    # -- raw polygons ------------------------------------------------------------------------------
    def quad(self, obj: str, material: str, corners, uv=None) -> None:
        """One planar quad ``(4, 3)`` (counter-clockwise seen from its front); uv ``(4, 2)`` or None."""
        c = np.asarray(corners, dtype=np.float64).reshape(4, 3)
        self._object(obj, material)["quads"].append((c, None if uv is None else np.asarray(uv, float)))

    def tri(self, obj: str, material: str, corners) -> None:
        """One triangle ``(3, 3)`` (counter-clockwise seen from its front)."""
        c = np.asarray(corners, dtype=np.float64).reshape(3, 3)
        self._object(obj, material)["tris"].append(c)

    # -- axis-aligned rectangles --------------------------------------------------------------------
    def face(
        self,
        obj: str,
        material: str,
        lo,
        hi,
        sign: int,
        holes=(),
        panel: float | None = None,
        skip_cells=None,
    ) -> int:
        """An axis-aligned rectangle split into panels; returns the number of quads added.

        lo, hi : (3,) opposite corners; exactly one axis has ``lo == hi`` (the plane)
        sign : +1 or -1, the normal is ``sign * e_axis``
        holes : ``[(lo3, hi3), ...]`` boxes whose in-plane extent is cut out (their edges
            become grid lines; cells inside a hole are left out)
        panel : largest panel edge in metres (default: the builder's)
        """
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        flat = np.flatnonzero(np.abs(hi - lo) < 1e-12)
        if flat.size != 1:
            raise ValueError(f"face of {obj!r}: need exactly one flat axis, got {lo} {hi}")
        axis = int(flat[0])
        a, b = _PLANE_AXES[axis]
        if sign < 0:
            a, b = b, a
        panel = self.panel if panel is None else float(panel)
        amin, amax = sorted((lo[a], hi[a]))
        bmin, bmax = sorted((lo[b], hi[b]))
        hole_ab = []
        abreaks, bbreaks = {amin, amax}, {bmin, bmax}
        for hlo, hhi in holes:
            ha0, ha1 = sorted((float(hlo[a]), float(hhi[a])))
            hb0, hb1 = sorted((float(hlo[b]), float(hhi[b])))
            ha0, ha1, hb0, hb1 = max(ha0, amin), min(ha1, amax), max(hb0, bmin), min(hb1, bmax)
            if ha1 - ha0 < 1e-9 or hb1 - hb0 < 1e-9:
                continue
            hole_ab.append((ha0, ha1, hb0, hb1))
            abreaks |= {ha0, ha1}
            bbreaks |= {hb0, hb1}
        ab = _subdivide(sorted(abreaks), panel)
        bb = _subdivide(sorted(bbreaks), panel)
        period = self._mat_period[material] if material in self._mat_period else None
        o = self._object(obj, material)
        n = 0
        for j in range(len(bb) - 1):
            for i in range(len(ab) - 1):
                ca, cb = 0.5 * (ab[i] + ab[i + 1]), 0.5 * (bb[j] + bb[j + 1])
                if any(h[0] < ca < h[1] and h[2] < cb < h[3] for h in hole_ab):
                    continue
                if skip_cells is not None and skip_cells(ca, cb):
                    continue
                corners = np.empty((4, 3))
                corners[:, axis] = lo[axis]
                corners[:, a] = (ab[i], ab[i + 1], ab[i + 1], ab[i])
                corners[:, b] = (bb[j], bb[j], bb[j + 1], bb[j + 1])
                uv = None
                if period:
                    uv = np.column_stack([corners[:, a], -corners[:, b]]) / period
                o["quads"].append((corners, uv))
                n += 1
        return n

    def box(
        self,
        obj: str,
        material: str,
        lo,
        hi,
        skip=("-y",),
        inward: bool = False,
        holes: dict | None = None,
        panel: float | None = None,
    ) -> None:
        """The faces of the axis-aligned box ``[lo, hi]``.

        skip : face names (``"-x"``, ``"+y"``, ...) left out: hidden ones (on the floor,
            against a wall) or open ones
        inward : faces look into the box (a room) instead of out of it (furniture)
        holes : ``{face name: [(lo3, hi3), ...]}`` openings cut out of single faces
        """
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        for fname, (axis, sign) in AXES.items():
            if fname in skip:
                continue
            flo, fhi = lo.copy(), hi.copy()
            if sign > 0:
                flo[axis] = hi[axis]
            else:
                fhi[axis] = lo[axis]
            self.face(
                obj,
                material,
                flo,
                fhi,
                -sign if inward else sign,
                holes=(holes or {}).get(fname, ()),
                panel=panel,
            )

    # -- output ------------------------------------------------------------------------------------
    def counts(self) -> dict:
        """``{"quads": q, "triangles": t, "gltf_triangles": 2 q + t}`` over all objects."""
        q = sum(len(o["quads"]) for o in self._objects.values())
        t = sum(len(o["tris"]) for o in self._objects.values())
        return {"quads": q, "triangles": t, "gltf_triangles": 2 * q + t}

    def all_polygons(self) -> list[np.ndarray]:
        """Every face as a ``(3, 3)`` or ``(4, 3)`` corner array (for checks)."""
        out = []
        for o in self._objects.values():
            out.extend(c for c, _ in o["quads"])
            out.extend(o["tris"])
        return out

    def emit_meshes(self) -> None:
        """Write one mesh (and root node) per object into :attr:`glb`."""
        for name, o in self._objects.items():
            pos, nrm, uvs, idx = [], [], [], []
            textured = self._mat_period[o["material"]] is not None
            base = 0
            for c, uv in o["quads"]:
                nq = np.cross(c[2] - c[0], c[3] - c[1])
                pos.append(c)
                nrm.append(np.repeat(nq[None] / np.linalg.norm(nq), 4, axis=0))
                if textured:
                    uvs.append(uv if uv is not None else np.zeros((4, 2)))
                idx.append(_TRI + base)
                base += 4
            for c in o["tris"]:
                nt = np.cross(c[1] - c[0], c[2] - c[0])
                pos.append(c)
                nrm.append(np.repeat(nt[None] / np.linalg.norm(nt), 3, axis=0))
                if textured:
                    uvs.append(np.zeros((3, 2)))
                idx.append(np.array([[base, base + 1, base + 2]], dtype=np.uint32))
                base += 3
            if not pos:
                continue
            mesh = self.glb.add_mesh(
                name,
                np.concatenate(pos),
                np.concatenate(idx),
                self._mat_index[o["material"]],
                normals=np.concatenate(nrm),
                uv0=np.concatenate(uvs) if textured else None,
            )
            self.glb.add_node(name, mesh=mesh)


# -- camera paths ------------------------------------------------------------------------------------


def _catmull_rom(points: np.ndarray, samples_per_segment: int = 64, knot_dims: int = 3) -> np.ndarray:
    """Dense ``(m, k)`` samples of the centripetal Catmull-Rom curve through ``points`` ``(n, k)``.

    Centripetal knots (square root of the distance between way points, measured on the
    first ``knot_dims`` coordinates) keep the curve free of loops and overshoot where
    way points are unevenly spaced. The ends are extended by reflection.
    """
    p = np.asarray(points, dtype=np.float64)
    ext = np.concatenate([p[:1] * 2 - p[1:2], p, p[-1:] * 2 - p[-2:-1]])
    gaps = np.linalg.norm(np.diff(ext[:, :knot_dims], axis=0), axis=1)
    knots = np.concatenate([[0.0], np.cumsum(np.sqrt(np.maximum(gaps, 1e-9)))])
    u = np.linspace(0.0, 1.0, samples_per_segment, endpoint=False)[:, None]
    out = []
    for i in range(1, len(ext) - 2):
        p0, p1, p2, p3 = ext[i - 1], ext[i], ext[i + 1], ext[i + 2]
        t0, t1, t2, t3 = knots[i - 1], knots[i], knots[i + 1], knots[i + 2]
        t = t1 + (t2 - t1) * u
        a1 = ((t1 - t) * p0 + (t - t0) * p1) / (t1 - t0)
        a2 = ((t2 - t) * p1 + (t - t1) * p2) / (t2 - t1)
        a3 = ((t3 - t) * p2 + (t - t2) * p3) / (t3 - t2)
        b1 = ((t2 - t) * a1 + (t - t0) * a2) / (t2 - t0)
        b2 = ((t3 - t) * a2 + (t - t1) * a3) / (t3 - t1)
        out.append(((t2 - t) * b1 + (t - t1) * b2) / (t2 - t1))
    out.append(p[-1:])
    return np.concatenate(out)


def walk_path(
    waypoints,
    n: int,
    yfov: float = 60.0,
    look_ahead: float = 1.5,
    look_down: float = 0.25,
    targets=None,
    lean_towards=None,
    lean: float = 0.0,
) -> list[dict]:
    """A smooth walk of ``n`` poses through ``waypoints`` ``(k, 3)`` eye positions.

    The eyes are spaced evenly by arc length along a Catmull-Rom curve. The target is
    the point ``look_ahead`` metres further along the curve, ``look_down`` metres lower
    (past the end: along the last tangent), moved the fraction ``lean`` of the way towards
    the point ``lean_towards`` (to keep something in view). ``targets`` ``(k, 3)``, when given, is
    interpolated along the same curve instead (for a walk that looks at a fixed spot).
    Returns ``[{"eye", "target", "up", "yfov"}, ...]`` with numbers rounded to 1e-4.
    """
    wp = np.asarray(waypoints, dtype=np.float64)
    both = wp if targets is None else np.hstack([wp, np.asarray(targets, dtype=np.float64)])
    dense = _catmull_rom(both)
    eyes = dense[:, :3]
    seg = np.linalg.norm(np.diff(eyes, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    want = np.linspace(0.0, total, n)

    def at(d):
        d = np.clip(d, 0.0, total)
        return np.column_stack([np.interp(d, s, dense[:, k]) for k in range(dense.shape[1])])

    e = at(want)
    if targets is None:
        ahead = want + look_ahead
        tg = at(ahead)[:, :3]
        over = ahead > total
        if np.any(over):
            tangent = eyes[-1] - eyes[-8]
            tangent /= np.linalg.norm(tangent)
            tg[over] = eyes[-1] + tangent * (ahead[over] - total)[:, None]
        if lean_towards is not None:
            tg += lean * (np.asarray(lean_towards, dtype=np.float64)[None] - tg)
        tg[:, 1] -= look_down
    else:
        tg = e[:, 3:]
    return [
        {
            "eye": [round(float(x), 4) for x in e[i, :3]],
            "target": [round(float(x), 4) for x in tg[i]],
            "up": [0.0, 1.0, 0.0],
            "yfov": float(yfov),
        }
        for i in range(n)
    ]


def loop_waypoints(ax: float, az: float, rc: float, y: float, gap: float = 0.6) -> np.ndarray:
    """``(k, 3)`` way points once around a rounded rectangle at height ``y``.

    Half extents ``ax``, ``az``, corner radius ``rc``; counter-clockwise seen from above
    (+x towards +z), from the middle of the +x side back to ``gap`` metres short of it.
    Every side gets way points at most 2 m apart so the spline keeps straight.
    """
    corners = (
        (ax - rc, az - rc, 0.0),
        (-(ax - rc), az - rc, 90.0),
        (-(ax - rc), -(az - rc), 180.0),
        (ax - rc, -(az - rc), 270.0),
    )
    pts = [(ax, 0.0)]
    for cx, cz, a0 in corners:
        arc = [
            (cx + rc * math.cos(math.radians(a0 + da)), cz + rc * math.sin(math.radians(a0 + da)))
            for da in (0.0, 45.0, 90.0)
        ]
        start = np.array(pts[-1])
        n = max(1, math.ceil(np.linalg.norm(np.array(arc[0]) - start) / 2.0))
        pts += [tuple(start + (np.array(arc[0]) - start) * k / n) for k in range(1, n)]
        pts += arc
    end = np.array((ax, -gap))
    start = np.array(pts[-1])
    n = max(1, math.ceil(np.linalg.norm(end - start) / 2.0))
    pts += [tuple(start + (end - start) * k / n) for k in range(1, n + 1)]
    return np.array([(x, y, z) for x, z in pts])


def add_cameras(mb: ModelBuilder, cameras: list[Camera], path: list[dict], aspect: float = 16 / 9) -> None:
    """Add the file's cameras and the default camera path (root extras)."""
    for cam in cameras:
        mb.glb.add_camera_node(cam, aspect=aspect)
    mb.glb.extras["iat_camera_paths"] = {"default": path}


# -- a whole model ------------------------------------------------------------------------------------


def assemble(
    geometry, lights, cameras: list[Camera], path: list[dict], panel: float = 1.25, extras: dict | None = None
) -> ModelBuilder:
    """A :class:`ModelBuilder` holding a whole model, not yet written: ``geometry(mb)`` and
    ``lights(mb)`` add their parts, then the meshes, the ``cameras``, the default camera ``path``
    and the root ``extras`` (after ``iat_camera_paths``) follow, in that order."""
    mb = ModelBuilder(panel=panel)
    geometry(mb)
    lights(mb)
    mb.emit_meshes()
    add_cameras(mb, cameras, path)
    mb.glb.extras.update(extras or {})
    return mb


def script_main(build, default_path: Path, description: str, argv: list[str] | None = None) -> int:
    """A sample script's command line: ``-o PATH`` (default ``default_path``); writes the model with
    ``build(path)`` and prints the path written."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("-o", "--output", default=str(default_path), help="output .glb (default: %(default)s)")
    args = ap.parse_args(argv)
    print(build(args.output))
    return 0


# -- noise --------------------------------------------------------------------------------------------

_M64 = np.uint64(0xFFFFFFFFFFFFFFFF)


def _hash3(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, seed: int) -> np.ndarray:
    """Uniform ``[0, 1)`` float64 from integer lattice coordinates (splitmix64-style mixing)."""
    with np.errstate(over="ignore"):
        h = (
            ix.astype(np.int64).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
            ^ iy.astype(np.int64).astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
            ^ iz.astype(np.int64).astype(np.uint64) * np.uint64(0x165667B19E3779F9)
            ^ np.uint64(seed) * np.uint64(0xD6E8FEB86659FD93)
        )
        h ^= h >> np.uint64(30)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(27)
        h *= np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(31)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def value_noise3(p, seed: int = 0) -> np.ndarray:
    """Smooth value noise in ``[-1, 1]`` at points ``p`` ``(n, 3)`` (lattice spacing 1)."""
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    i0 = np.floor(p)
    f = p - i0
    w = f * f * (3.0 - 2.0 * f)  # smoothstep
    i0 = i0.astype(np.int64)
    out = np.zeros(len(p))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                h = _hash3(i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz, seed)
                wt = (
                    (w[:, 0] if dx else 1 - w[:, 0])
                    * (w[:, 1] if dy else 1 - w[:, 1])
                    * (w[:, 2] if dz else 1 - w[:, 2])
                )
                out += wt * h
    return out * 2.0 - 1.0


def fbm3(p, octaves: int = 4, seed: int = 0, lacunarity: float = 2.0, gain: float = 0.5) -> np.ndarray:
    """Fractal sum of :func:`value_noise3` octaves, roughly in ``[-1, 1]``."""
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    total, amp, norm, freq = np.zeros(len(p)), 1.0, 0.0, 1.0
    for k in range(octaves):
        total += amp * value_noise3(p * freq, seed + 101 * k)
        norm += amp
        amp *= gain
        freq *= lacunarity
    return total / norm


# -- textures -----------------------------------------------------------------------------------------


def _srgb8(linear: np.ndarray) -> np.ndarray:
    """(h, w, 3) linear RGB -> uint8 sRGB codes (clamped to [0, 1] first)."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.round(srgb_encode(x) * 255.0).astype(np.uint8)


def png_bytes(linear_rgb) -> bytes:
    """PNG file bytes of an ``(h, w, 3)`` linear RGB image in ``[0, 1]`` (sRGB encoded, 8 bit).

    The zlib stream uses stored (uncompressed) deflate blocks, so the bytes do not
    depend on the zlib build; keep the images small.
    """
    img = _srgb8(linear_rgb)
    h, w, _ = img.shape
    raw = b"".join(b"\x00" + img[y].tobytes() for y in range(h))  # filter type 0 per row
    blocks = bytearray(b"\x78\x01")
    for k in range(0, max(len(raw), 1), 65535):
        part = raw[k : k + 65535]
        final = 1 if k + 65535 >= len(raw) else 0
        blocks += struct.pack("<BHH", final, len(part), len(part) ^ 0xFFFF) + part
    blocks += struct.pack(">I", zlib.adler32(raw) & 0xFFFFFFFF)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", bytes(blocks)) + chunk(b"IEND", b"")


def tile_texture(
    size: int,
    tiles: int,
    color,
    grout,
    grout_width: float = 0.06,
    variation: float = 0.06,
    speckle: float = 0.03,
    seed: int = 0,
    offset_rows: bool = False,
) -> np.ndarray:
    """``(size, size, 3) float64`` linear RGB image of ``tiles x tiles`` square tiles with grout.

    color, grout : (3,) linear RGB of the tiles and the joints
    grout_width : joint width as a fraction of a tile
    variation : per-tile brightness spread; speckle : per-pixel noise amplitude
    offset_rows : shift every other row by half a tile (running bond, as bricks)
    The image tiles seamlessly (repeat wrap).
    """
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    u = (x + 0.5) / size * tiles
    v = (y + 0.5) / size * tiles
    row = np.floor(v)
    if offset_rows:
        u = u + 0.5 * (row % 2)
    col = np.floor(u) % tiles
    fu, fv = u - np.floor(u), v - row
    g = grout_width / 2
    joint = (fu < g) | (fu > 1 - g) | (fv < g) | (fv > 1 - g)
    tile_shade = 1.0 + variation * (2 * _hash3(col, row, np.zeros_like(col), seed) - 1)
    pix = 1.0 + speckle * (2 * _hash3(x, y, np.ones_like(x), seed + 7) - 1)
    c = np.asarray(color, dtype=np.float64)[None, None] * (tile_shade * pix)[..., None]
    gr = np.asarray(grout, dtype=np.float64)[None, None] * pix[..., None]
    return np.clip(np.where(joint[..., None], gr, c), 0.0, 1.0)
