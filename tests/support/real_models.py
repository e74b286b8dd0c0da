"""Small test models written by real tools, deterministic, for :mod:`tests.test_real_models` and
``benchmarks/real_models_bench.py``.

- :func:`ifc_house`: an IFC4 house written with ifcopenshell's API (0.9): project / site /
  building / storey, four exterior walls with window and door openings (``IfcOpeningElement``
  voids by ``feature.add_feature``), gable ends, an interior wall with a door, a floor slab, a
  pitched roof of two sloped slabs (``IfcRoof`` aggregating two ``IfcSlab`` ROOF), a lowered
  ceiling and a rug whose outline is a skewed quadrilateral, and surface colours. GlobalIds and
  the header time stamp are fixed, so the bytes are the same on every run.
- :func:`blender_room`: a room with a window, a door, a table and a ceiling lamp, built by
  Blender (``bpy``, boolean modifiers for the holes) in a subprocess running
  ``tests/support/blender_room.py`` and exported by Blender's glTF (GLB, with a point light) and
  OBJ (n-gons kept) exporters.
- :func:`collada_room`: a small room written with pycollada's API (three materials, an emissive
  ceiling panel).
- :func:`ngon_obj`: plain OBJ text with a concave L-shaped floor face and a ring written as one
  keyhole face (outer circle, bridge, inner circle reversed); :data:`RING_AREA` is its exact area.
- :func:`skewed_quad_obj`: one strongly skewed quad (two triangles) under a point light.

Each writer takes an output directory and returns the model's path (``blender_room`` a dict).
Model coordinates are metres. Z-up IFC coordinates become Y-up as ``(x, y, z) -> (x, z, -y)``
(:func:`ifc_to_yup`), as Blender's and glTF's conventions do.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.support.ifc_builder import IfcBuilder, prism

BLENDER_SCRIPT = Path(__file__).with_name("blender_room.py")
BLENDER_TIMEOUT_S = 120

#: IFC house: a point light in the skewed room (IFC Z-up coordinates, metres) and its intensity (W/sr).
IFC_LIGHT = (1.9, -2.5, 1.9)
IFC_LIGHT_INTENSITY = 6.0
#: IFC house: the interior camera (Z-up): in the skewed room looking at the west wall's window.
IFC_EYE, IFC_TARGET = (3.2, -0.7, 1.5), (0.0, -3.0, 1.3)
#: The skewed rug / lowered ceiling outline (Z-up x, y), the brief's corners scaled by 0.5.
SKEW_OUTLINE = ((0.05, -0.05), (0.05, -4.95), (3.72, -2.005), (3.72, -0.15))

#: The Blender room (Y-up, as exported): eye in a corner looking at the window and the door, the
#: lamp just out of view (else it sets the 99.5th percentile and the walls count as unlit).
ROOM_EYE, ROOM_TARGET = (1.6, 1.2, 1.1), (-1.2, 0.7, -1.0)

#: The COLLADA room (Y-up): eye and target.
DAE_EYE, DAE_TARGET = (1.7, 1.2, 1.2), (-1.0, 0.6, -1.0)  # the lamp just out of view

#: The n-gon OBJ: the keyhole ring's radii, points per circle and exact area (of the polygons).
RING_R_OUT, RING_R_IN, RING_N = 1.0, 0.5, 33
RING_AREA = 0.5 * RING_N * np.sin(2 * np.pi / RING_N) * (RING_R_OUT**2 - RING_R_IN**2)
#: The L-shaped floor face of the n-gon OBJ: 3 x 2 minus 1.5 x 1.
L_AREA = 3.0 * 2.0 - 1.5 * 1.0

#: The skewed quad: the brief's corners scaled by 0.2 (x, -z on the floor y = 0); light 0.5 m above.
SKEW_QUAD = ((0.0, 0.0), (0.0, -9.8), (7.34, -3.91), (7.34, -0.2))
SKEW_SCALE = 0.2
SKEW_LIGHT_HEIGHT = 0.5


def ifc_to_yup(p) -> np.ndarray:
    """A Z-up IFC point ``(x, y, z)`` as the Y-up point ``(x, z, -y)``."""
    x, y, z = np.asarray(p, dtype=np.float64)
    return np.array([x, z, -y])


# -- IFC ---------------------------------------------------------------------------------------


def _wall(b, name, xyz, rot_deg, length, height, thickness, style, openings=()):
    """A ground-floor wall from ``xyz`` along its local x, rotated ``rot_deg`` about z."""
    a = np.radians(rot_deg)
    start = np.asarray(xyz[:2], float)
    end = start + length * np.array([np.cos(a), np.sin(a)])
    return b.wall(name, 0, start, end, xyz[2], height, thickness, style, openings)


def ifc_house(out_dir) -> Path:
    """Write ``house.ifc`` (about 6.4 x 5.4 m, walls 2.6 m, ridge 3.5 m) into ``out_dir``."""
    out = Path(out_dir) / "house.ifc"
    b = IfcBuilder("iat house")
    wall_s = b.style("wall", (0.78, 0.74, 0.66))
    inner_s = b.style("inner wall", (0.70, 0.76, 0.80))
    floor_s = b.style("floor", (0.50, 0.38, 0.26))
    roof_s = b.style("roof", (0.62, 0.22, 0.16))
    ceiling_s = b.style("ceiling", (0.85, 0.85, 0.82))
    rug_s = b.style("rug", (0.25, 0.35, 0.60))
    h = 2.6
    # interior x in [0, 6], y in [-5, 0]; exterior walls 0.2 m outside it
    _wall(
        b,
        "south wall",
        (-0.2, 0.0, 0.0),
        0.0,
        6.4,
        h,
        0.2,
        wall_s,
        openings=[(1.0, 2.2, 0.9, 2.0), (4.4, 5.6, 0.9, 2.0)],
    )
    _wall(
        b,
        "north wall",
        (-0.2, -5.2, 0.0),
        0.0,
        6.4,
        h,
        0.2,
        wall_s,
        openings=[(1.4, 2.6, 0.9, 2.0), (4.7, 5.6, 0.0, 2.1)],
    )
    _wall(b, "west wall", (0.0, -5.0, 0.0), 90.0, 5.0, h, 0.2, wall_s, openings=[(1.8, 3.2, 1.0, 2.0)])
    _wall(b, "east wall", (6.2, -5.0, 0.0), 90.0, 5.0, h, 0.2, wall_s, openings=[(2.0, 3.0, 1.0, 2.0)])
    _wall(b, "interior wall", (3.9, -5.0, 0.0), 90.0, 5.0, h, 0.1, inner_s, openings=[(3.5, 4.4, 0.0, 2.1)])
    b.slab(
        "floor slab",
        0,
        [(-0.2, 0.2), (-0.2, -5.2), (6.2, -5.2), (6.2, 0.2)],
        -0.2,
        0.2,
        floor_s,
        predefined="FLOOR",
    )
    b.slab("lowered ceiling", 0, SKEW_OUTLINE, 2.3, 0.1, ceiling_s, predefined="USERDEFINED")
    b.slab("rug", 0, SKEW_OUTLINE, 0.0, 0.02, rug_s, ifc_class="IfcCovering", predefined="FLOORING")
    # gables: triangles over the west and east walls up to the ridge
    ridge_y, ridge_z = -2.5, 3.5
    gable = [(-5.2, h), (0.2, h), (ridge_y, ridge_z)]
    for name, x0 in (("west gable", -0.2), ("east gable", 6.0)):
        v, fc = prism(gable, x0, x0 + 0.2)
        b.mesh(name, v, fc, wall_s, ifc_class="IfcWall", storey=0)
    # roof: two sloped slabs 0.15 m thick, lower faces through the wall tops and the ridge
    roof = b.run("root.create_entity", b.f, ifc_class="IfcRoof", name="roof", predefined_type="GABLE_ROOF")
    b.run("spatial.assign_container", b.f, products=[roof], relating_structure=b.storey(0))
    slope = (ridge_z - h) / (ridge_y - 0.2)  # dz/dy on the south side (negative y goes up)
    halves = []
    for side, (y_eave, y_ridge) in (("south", (0.5, ridge_y)), ("north", (-5.5, ridge_y))):
        s = slope if side == "south" else -slope
        z_eave = h + s * (y_eave - 0.2 if side == "south" else y_eave + 5.2)
        prof = [(y_eave, z_eave), (y_ridge, ridge_z), (y_ridge, ridge_z + 0.15), (y_eave, z_eave + 0.15)]
        v, fc = prism(prof, -0.4, 6.4)
        halves.append(b.mesh(f"roof {side}", v, fc, roof_s, predefined="ROOF"))
    b.run("aggregate.assign_object", b.f, products=halves, relating_object=roof)
    b.write(out, "iat-house")
    return out


def ifc_triangles(path) -> dict:
    """Triangulate ``path`` with ifcopenshell's geometry kernel (world coordinates, Z up):
    ``{ifc class: triangles}``, the total and the material colours seen (openings excluded)."""
    import ifcopenshell
    import ifcopenshell.geom

    f = ifcopenshell.open(str(path))
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    it = ifcopenshell.geom.iterator(settings, f)
    per_class: dict[str, int] = {}
    colours, verts = set(), []
    if it.initialize():
        while True:
            sh = it.get()
            if sh.type != "IfcOpeningElement":
                g = sh.geometry
                per_class[sh.type] = per_class.get(sh.type, 0) + len(g.faces) // 3
                verts.append(np.asarray(g.verts, dtype=np.float64).reshape(-1, 3))
                for m in g.materials:
                    colours.add(tuple(round(float(c), 3) for c in m.diffuse.components))
            if not it.next():
                break
    v = np.concatenate(verts) if verts else np.zeros((0, 3))
    return {
        "per_class": per_class,
        "triangles": sum(per_class.values()),
        "colours": colours,
        "bounds": (v.min(axis=0), v.max(axis=0)) if len(v) else None,
    }


# -- Blender -----------------------------------------------------------------------------------


def bpy_available() -> str | None:
    """None when ``import bpy`` works in a subprocess of this interpreter, else the reason."""
    r = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        return f"import bpy failed: {(r.stderr.strip().splitlines() or ['?'])[-1]}"
    return None


def blender_room(out_dir) -> dict:
    """Run Blender on ``tests/support/blender_room.py``: ``{"glb": path, "obj": path}``.
    Raises RuntimeError with Blender's output when it fails or times out."""
    out = Path(out_dir) / "blender"
    try:
        r = subprocess.run(
            [sys.executable, str(BLENDER_SCRIPT), str(out)],
            capture_output=True,
            text=True,
            timeout=BLENDER_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired as e:
        raise RuntimeError(f"Blender did not finish in {BLENDER_TIMEOUT_S} s") from e
    paths = {"glb": out / "room.glb", "obj": out / "room.obj"}
    if r.returncode != 0 or not all(p.is_file() for p in paths.values()):
        raise RuntimeError(f"Blender failed (rc {r.returncode}): {r.stdout[-2000:]}{r.stderr[-2000:]}")
    return paths


def glb_point_lights(path) -> list[dict]:
    """The ``KHR_lights_punctual`` lights of a GLB as written (read back with pygltflib)."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    return list((g.extensions or {}).get("KHR_lights_punctual", {}).get("lights", []))


# -- COLLADA -----------------------------------------------------------------------------------


def _room_quads(w: float, d: float, h: float):
    """Inward-facing quads of a ``w x d x h`` box room (Y up, floor at y = 0, centred on x, z):
    ``[(name, 4 corners)]``."""
    x, z = w / 2, d / 2
    return [
        ("floor", [(-x, 0, -z), (-x, 0, z), (x, 0, z), (x, 0, -z)]),
        ("ceiling", [(-x, h, -z), (x, h, -z), (x, h, z), (-x, h, z)]),
        ("wall", [(-x, 0, -z), (x, 0, -z), (x, h, -z), (-x, h, -z)]),
        ("wall", [(x, 0, z), (-x, 0, z), (-x, h, z), (x, h, z)]),
        ("wall", [(-x, 0, z), (-x, 0, -z), (-x, h, -z), (-x, h, z)]),
        ("wall", [(x, 0, -z), (x, 0, z), (x, h, z), (x, h, -z)]),
    ]


def collada_room(out_dir) -> Path:
    """Write ``room.dae`` with pycollada: a 4 x 3 x 2.5 m room (floor, walls, ceiling: three
    materials), a box table and a 0.6 m emissive panel 5 cm under the ceiling, facing down."""
    import collada
    from collada import geometry, material, scene, source

    out = Path(out_dir) / "room.dae"
    mesh = collada.Collada()
    colours = {
        "wall": ((0.72, 0.70, 0.66), None),
        "floor": ((0.40, 0.30, 0.22), None),
        "ceiling": ((0.85, 0.85, 0.85), None),
        "table": ((0.55, 0.30, 0.20), None),
        "lamp": ((0.9, 0.9, 0.9), (6.0, 5.8, 5.2)),
    }
    mats = {}
    for name, (rgb, em) in colours.items():
        kw = {"emission": (*em, 1.0)} if em is not None else {}
        effect = material.Effect(f"{name}-effect", [], "lambert", diffuse=(*rgb, 1.0), **kw)
        mat = material.Material(f"{name}-material", name, effect)
        mesh.effects.append(effect)
        mesh.materials.append(mat)
        mats[name] = mat
    quads = _room_quads(4.0, 3.0, 2.5)
    # table: a 1.0 x 0.1 x 0.7 slab top at 0.75 m (outward faces), one leg block in the middle
    for lo, hi in (((0.0, 0.7, -0.8), (1.0, 0.8, -0.1)), ((0.4, 0.0, -0.5), (0.6, 0.7, -0.4))):
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        quads += [
            ("table", [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)]),
            ("table", [(x0, y0, z1), (x0, y0, z0), (x1, y0, z0), (x1, y0, z1)]),
            ("table", [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]),
            ("table", [(x1, y0, z0), (x0, y0, z0), (x0, y1, z0), (x1, y1, z0)]),
            ("table", [(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)]),
            ("table", [(x1, y0, z1), (x1, y0, z0), (x1, y1, z0), (x1, y1, z1)]),
        ]
    quads.append(("lamp", [(-0.3, 2.45, -0.3), (-0.3, 2.45, 0.3), (0.3, 2.45, 0.3), (0.3, 2.45, -0.3)][::-1]))
    nodes = []
    for name in colours:
        polys = [c for n, c in quads if n == name]
        verts = np.array([p for c in polys for p in c], dtype=np.float64)
        tris = np.array([[4 * k + i for i in (0, 1, 2, 0, 2, 3)] for k in range(len(polys))])
        src = source.FloatSource(f"{name}-verts", verts.ravel(), ("X", "Y", "Z"))
        geom = geometry.Geometry(mesh, f"{name}-geom", name, [src])
        inputs = source.InputList()
        inputs.addInput(0, "VERTEX", f"#{name}-verts")
        geom.primitives.append(geom.createTriangleSet(tris.ravel(), inputs, f"{name}-ref"))
        mesh.geometries.append(geom)
        nodes.append(
            scene.Node(
                name,
                children=[
                    scene.GeometryNode(geom, [scene.MaterialNode(f"{name}-ref", mats[name], inputs=[])])
                ],
            )
        )
    mesh.scenes.append(scene.Scene("room", nodes))
    mesh.scene = mesh.scenes[0]
    mesh.assetInfo.created = mesh.assetInfo.modified = _fixed_time()
    mesh.write(str(out))
    return out


def _fixed_time():  # noqa: N802 - a constant made on demand
    import datetime

    return datetime.datetime(2026, 1, 1)


# -- plain OBJ ---------------------------------------------------------------------------------


def ngon_obj(out_dir) -> Path:
    """Write ``ngons.obj``: an L-shaped (concave) floor face at y = 0 and, beside it, a ring at
    y = 0 written as one keyhole face: the outer circle (counter-clockwise seen from +y), a bridge
    to the inner circle, the inner circle reversed, and back. Both faces face +y."""
    out = Path(out_dir) / "ngons.obj"
    lines = ["# concave and holed n-gons for iat's OBJ triangulation", "o lshape"]
    # L in the x-z plane; a face facing +y runs clockwise in (x, z) seen from above... keep the
    # order (x, -z) counter-clockwise: seen from +y, counter-clockwise in (x, -z) is a +y normal
    lshape = [(0.0, 0.0), (3.0, 0.0), (3.0, 1.0), (1.5, 1.0), (1.5, 2.0), (0.0, 2.0)]
    for x, mz in lshape:
        lines.append(f"v {x:.6f} 0.000000 {-mz:.6f}")
    lines.append("f " + " ".join(str(i + 1) for i in range(len(lshape))))
    lines.append("o ring")
    cx, cmz = 5.0, 1.0
    base = len(lshape)
    ang = 2 * np.pi * np.arange(RING_N) / RING_N
    outer = [(cx + RING_R_OUT * np.cos(a), cmz + RING_R_OUT * np.sin(a)) for a in ang]
    inner = [(cx + RING_R_IN * np.cos(a), cmz + RING_R_IN * np.sin(a)) for a in ang]
    for x, mz in outer + inner:
        lines.append(f"v {x:.9f} 0.000000 {-mz:.9f}")
    o = [base + 1 + i for i in range(RING_N)]
    n = [base + 1 + RING_N + i for i in range(RING_N)]
    # keyhole: outer 0..N-1, back to outer 0, bridge to inner 0, inner reversed, inner 0 again
    face = o + [o[0], n[0]] + [n[i] for i in range(RING_N - 1, 0, -1)] + [n[0]]
    lines.append("f " + " ".join(map(str, face)))
    out.write_text("\n".join(lines) + "\n")
    return out


def skewed_quad_obj(out_dir) -> tuple[Path, np.ndarray]:
    """Write ``skewed.obj``: :data:`SKEW_QUAD` scaled by :data:`SKEW_SCALE` on the floor y = 0
    (facing +y) as two triangles; returns the path and a light position 0.5 m above the quad's
    centroid (Y up)."""
    out = Path(out_dir) / "skewed.obj"
    pts = np.array([(x * SKEW_SCALE, 0.0, -y * SKEW_SCALE) for x, y in SKEW_QUAD])
    lines = ["# one strongly skewed quad as two triangles", "o skewed"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in pts]
    # corners run clockwise in (x, y_ifc) -> seen from +y (looking down -y) counter-clockwise in (x, -z)...
    # orient both triangles to face +y
    tri = [(0, 1, 2), (0, 2, 3)]
    n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
    if n[1] < 0:
        tri = [(a, c, b) for a, b, c in tri]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tri]
    out.write_text("\n".join(lines) + "\n")
    light = pts.mean(axis=0) + np.array([0.0, SKEW_LIGHT_HEIGHT, 0.0])
    return out, light


def skewed_quad_corners() -> np.ndarray:
    """(4, 3) the skewed quad's corners (Y up) as :func:`skewed_quad_obj` writes them."""
    return np.array([(x * SKEW_SCALE, 0.0, -y * SKEW_SCALE) for x, y in SKEW_QUAD])


# -- the figures -------------------------------------------------------------------------------

#: What the tests require of IAT against the mesh on a model's interior view.
MIN_PSNR_DB = 40.0
MAX_DOTTED = 0.005
IMAGE_SIZE = (256, 256)


def percentile_psnr(test, reference, q: float = 99.5) -> float:
    """PSNR of the luminance of ``test`` against ``reference`` (linear, no tone map), the peak
    being the ``q``-th percentile of the reference's luminance, not its maximum."""
    from iat.measure.metrics import luminance

    a, b = luminance(test), luminance(reference)
    mse = float(np.mean((a - b) ** 2))
    peak = float(np.percentile(b, q))
    if mse == 0.0:
        return float("inf")
    return float(10.0 * np.log10(peak * peak / mse)) if peak > 0 else float("-inf")


def dotted_fraction(test, reference, rel: float = 0.02, drop: float = 0.5, q: float = 99.5) -> float:
    """The "dotted rows and wedges" measure: of the lit pixels of ``reference`` (luminance above
    ``rel`` x its ``q``-th percentile), the fraction where ``test``'s luminance is below ``drop``
    x the reference's."""
    from iat.measure.metrics import luminance

    a, b = luminance(test), luminance(reference)
    lit = b > rel * float(np.percentile(b, q))
    if not lit.any():
        return 0.0
    return float(np.mean(a[lit] < drop * b[lit]))


def highlight(img, top: float = 0.01) -> np.ndarray:
    """(x, y) pixel position of the luminance-weighted centroid of the brightest ``top`` fraction
    of the pixels of ``img`` after a 3 x 3 box blur."""
    from iat.measure.metrics import luminance

    y = luminance(img)
    pad = np.pad(y, 1, mode="edge")
    y = sum(pad[i : i + y.shape[0], j : j + y.shape[1]] for i in range(3) for j in range(3)) / 9.0
    cut = np.quantile(y, 1.0 - top)
    rows, cols = np.nonzero(y >= cut)
    w = y[rows, cols]
    return np.array([np.sum(cols * w) / w.sum(), np.sum(rows * w) / w.sum()])


def camera(eye, target, yfov: float = 70.0, up=(0.0, 1.0, 0.0)):
    from iat.camera import Camera

    return Camera(
        eye=np.asarray(eye, float),
        target=np.asarray(target, float),
        up=np.asarray(up, float),
        yfov=yfov,
        znear=0.02,
        zfar=100.0,
    )


def model_cameras() -> dict:
    """The interior view of each model, Y up."""
    return {
        "ifc": camera(ifc_to_yup(IFC_EYE), ifc_to_yup(IFC_TARGET)),
        "glb": camera(ROOM_EYE, ROOM_TARGET),
        "obj": camera(ROOM_EYE, ROOM_TARGET),
        "dae": camera(DAE_EYE, DAE_TARGET),
    }


def add_ifc_light(scene) -> None:
    """Append the IFC house's point light (IFC files have none) to ``scene``, in place."""
    from iat.io.scene import Light

    scene.lights.append(
        Light(kind="point", position=ifc_to_yup(IFC_LIGHT), intensity=IFC_LIGHT_INTENSITY, name="test lamp")
    )


def figures(scene, solution, baked, mesh_img, iat_img) -> dict:
    """The figures of one model: patches, triangles of the mesh and IAT modes, texture memory,
    PSNR (99.5th-percentile peak) and the dotted fraction of IAT against the mesh image."""
    mem = baked.memory
    return {
        "patches": int(scene.n_patches),
        "mesh_tris": int(len(solution.tri_vertices)),
        "iat_tris": int(len(baked.mesh_indices) + len(baked.tex_indices)),
        "iat_mesh_tris": int(len(baked.mesh_indices)),
        "iat_tex_tris": int(len(baked.tex_indices)),
        "texture_bytes": int(mem.texture_bytes),
        "memory_bytes": int(mem.texture_bytes + mem.vertex_bytes + mem.index_bytes),
        "psnr_db": percentile_psnr(iat_img, mesh_img),
        "dotted": dotted_fraction(iat_img, mesh_img),
        "lit_fraction": float(np.mean(_lum(mesh_img) > 0.02 * float(np.percentile(_lum(mesh_img), 99.5)))),
    }


def _lum(img) -> np.ndarray:
    from iat.measure.metrics import luminance

    return luminance(img)


def describe(name: str, f: dict) -> str:
    """One line of a model's figures, for failure messages."""
    mem_s = f"texture {f['texture_bytes'] / 2**20:.3f} MiB (GPU total {f['memory_bytes'] / 2**20:.3f} MiB)"
    return (
        f"{name}: {f['patches']} patches, triangles mesh {f['mesh_tris']} / IAT {f['iat_tris']} "
        f"({f['iat_mesh_tris']} mesh part + {f['iat_tex_tris']} textured), {mem_s}, "
        f"PSNR {f['psnr_db']:.2f} dB, dotted {100 * f['dotted']:.3f} % of lit pixels "
        f"(lit {100 * f['lit_fraction']:.1f} % of the image), solve {f.get('solve_s', float('nan')):.1f} s"
    )


def skewed_quad_renders(out_dir, form: str, renderer) -> dict:
    """The skewed-quad lamp test: a point light 0.5 m over the quad, seen from straight above.

    form : "obj file" (the quad as two triangles in an OBJ, as the loader makes it) or "one quad
    patch" (given to the solver as one bilinear root). Returns scene, baked, mesh and iat images,
    the highlights (px) and their distance.
    """
    from iat.bake.baker import bake
    from iat.bake.policy import BakePolicy
    from iat.io.load import load_scene
    from iat.io.scene import Light, Material, Scene
    from iat.radiosity import SolveOptions, solve

    path, light = skewed_quad_obj(out_dir)
    if form == "obj file":
        scene = load_scene(path)
    else:
        scene = Scene(
            vertices=skewed_quad_corners(),
            patch_corners=[[0, 1, 2, 3]],
            patch_material=[0],
            materials=[Material(name="floor", albedo=[0.6, 0.6, 0.6])],
        )
        if scene.patch_normal[0, 1] < 0:
            scene.patch_corners = scene.patch_corners[:, ::-1].copy()
    scene.lights.append(Light(kind="point", position=light, intensity=1.0))
    sol = solve(scene, SolveOptions())
    baked = bake(sol, scene, BakePolicy())
    centre = skewed_quad_corners().mean(axis=0)
    cam = camera(centre + [0.0, 3.0, 0.0], centre, yfov=45.0, up=(0.0, 0.0, -1.0))
    renderer.set_solution(sol)
    renderer.set_baked(baked)
    mesh = renderer.render(cam, size=IMAGE_SIZE, mode="mesh")
    iat = renderer.render(cam, size=IMAGE_SIZE, mode="iat")
    pm, pi = highlight(mesh), highlight(iat)
    return {
        "scene": scene,
        "baked": baked,
        "mesh": mesh,
        "iat": iat,
        "highlights": (pm, pi),
        "distance": float(np.linalg.norm(pm - pi)),
    }


def solve_and_bake(name: str, scene) -> tuple:
    """``(solution, baked, solve_s, bake_s)`` of a real-tool model at the defaults (the IFC house
    gets its lamp first: IFC carries no lights)."""
    import time

    from iat.bake.baker import bake
    from iat.bake.policy import BakePolicy
    from iat.radiosity import SolveOptions, solve

    if name == "ifc":
        add_ifc_light(scene)
    t0 = time.perf_counter()
    sol = solve(scene, SolveOptions())
    solve_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    baked = bake(sol, scene, BakePolicy())
    return sol, baked, solve_s, time.perf_counter() - t0
