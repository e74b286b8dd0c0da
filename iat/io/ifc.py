"""IFC (``.ifc``) read with ifcopenshell (the optional extra ``pip install 'iat[ifc]'``).

:func:`read_ifc` meshes every physical element with ``ifcopenshell.geom`` in world
coordinates (``use-world-coords``; openings subtracted by ifcopenshell), in parallel
on every core, and returns the arrays :func:`iat.io.load.load_scene` welds and merges.

- IFC is Z up: ``(x, y, z) -> (x, z, -y)`` (:data:`iat.io.dae.UP_TO_Y`), a rotation, so
  windings keep their sense. Lengths are metres (ifcopenshell converts the file's unit).
- Skipped: spaces, zones, openings and other non-physical elements (:data:`SKIPPED`).
- Materials: one per surface style (named by the style, ``use-material-names``):
  albedo = the style's diffuse colour (surface colour when it has none). Glass
  (a window, door, plate or curtain wall part whose style transparency is over 0.5,
  or a style named glass) is its own material named ``"glass: <style> (transparency t)"``,
  of transmission ``t`` (``GLASS_DEFAULT_TRANSMISSION`` when a style named glass gives none).
- IFC files carry no lights or cameras.
"""

from __future__ import annotations

import logging
import multiprocessing
from pathlib import Path

import numpy as np

from iat.errors import LoadError
from iat.io.dae import UP_TO_Y
from iat.io.messages import one_line
from iat.io.scene import Material

log = logging.getLogger(__name__)

#: element classes (and their subclasses) that are not surfaces of the building
SKIPPED = (
    "IfcSpace",
    "IfcSpatialZone",
    "IfcExternalSpatialElement",
    "IfcOpeningElement",
    "IfcVoidingFeature",
    "IfcAnnotation",
    "IfcGrid",
    "IfcVirtualElement",
    "IfcAlignment",
)
#: element classes whose transparent parts are glass
GLAZED = ("IfcWindow", "IfcDoor", "IfcPlate", "IfcCurtainWall", "IfcMember")
GLASS_TRANSPARENCY = 0.5
_END = b"END-ISO-10303-21"
_TAIL = 4096  # bytes read from the end to find the terminator
_REPORTS = 50  # progress calls across the elements


def _open(path: Path):
    """(ifcopenshell, ifcopenshell.geom, the opened file); LoadError naming the extra or the fault."""
    try:
        import ifcopenshell
        import ifcopenshell.geom
    except ImportError as e:
        raise LoadError("reading IFC needs ifcopenshell: pip install 'iat[ifc]'", path) from e
    with open(path, "rb") as f:
        head = f.read(16)
        f.seek(max(0, path.stat().st_size - _TAIL))
        tail = f.read()
    if not head.startswith(b"ISO-10303-21"):
        raise LoadError("cannot read IFC file: not an IFC-SPF file (no ISO-10303-21 header)", path)
    if _END not in tail:
        raise LoadError("cannot read IFC file (truncated file): no END-ISO-10303-21 at the end", path)
    try:
        f = ifcopenshell.open(str(path))
    except Exception as e:  # noqa: BLE001 - ifcopenshell.Error, RuntimeError, ...
        raise LoadError(f"cannot read IFC file (truncated or corrupt file): {one_line(e)}", path) from e
    return ifcopenshell, ifcopenshell.geom, f


def _skipped_classes(ifcopenshell, f) -> list[str]:
    """The names in :data:`SKIPPED` that the file's schema has (IFC2X3 lacks some)."""
    schema = ifcopenshell.ifcopenshell_wrapper.schema_by_name(f.schema)
    out = []
    for name in SKIPPED:
        try:
            schema.declaration_by_name(name)
        except RuntimeError:
            continue
        out.append(name)
    return out


def _colour(style) -> np.ndarray:
    """(3,) float64 diffuse colour of an ifcopenshell style (surface colour when it has none)."""
    for c in (style.diffuse, style.surface):
        rgb = None if c is None else np.asarray(c.components, dtype=np.float64)
        if rgb is not None and rgb.shape == (3,) and np.isfinite(rgb).all():
            return rgb
    return np.full(3, 0.5)


#: transmittance of a glass whose style gives no transparency (clear float glass, normal incidence)
GLASS_DEFAULT_TRANSMISSION = 0.85


def _material(style, element_type: str) -> tuple[tuple, Material]:
    """(key, Material) of an ifcopenshell style on an element of class ``element_type``."""
    name = style.name or "default"
    albedo = _colour(style)
    t = float(style.transparency) if style.transparency is not None else 0.0
    t = t if np.isfinite(t) else 0.0
    glass = "glass" in name.lower() or (element_type in GLAZED and t > GLASS_TRANSPARENCY)
    if glass:
        name = f"glass: {name} (transparency {t:g})"
    tau = (t if t > 0 else GLASS_DEFAULT_TRANSMISSION) if glass else 0.0
    return (name, albedo.tobytes(), glass), Material(name=name, albedo=albedo, transmission=tau)


def read_ifc(path: Path, report, start: float, end: float, counts: list | None = None):
    """Mesh an IFC file: vertices (n, 3) float64 metres Y up, faces (f, 3) int64, face_material
    (f,) int64, face_uv (f, 3, 2) zeros, materials. ``counts`` (a list) gets each element's face
    count, in the order of the faces (:mod:`iat.geometry.sides` classifies per element).

    ``report(fraction, message)`` is called about 50 times across the elements,
    fractions from ``start`` to ``end`` in proportion to the elements meshed.
    """
    ifcopenshell, geom, f = _open(path)
    skipped = _skipped_classes(ifcopenshell, f)
    total = sum(
        1
        for p in f.by_type("IfcProduct")
        if p.Representation is not None and not any(p.is_a(c) for c in skipped)
    )
    settings = geom.settings()
    settings.set("use-world-coords", True)
    settings.set("use-material-names", True)
    report(start, f"meshing {total} IFC elements")
    try:
        it = geom.iterator(settings, f, multiprocessing.cpu_count(), exclude=skipped)
        ok = it.initialize()
    except Exception as e:  # noqa: BLE001 - the geometry kernel's errors
        raise LoadError(f"cannot mesh IFC file: {one_line(e)}", path) from e
    if not ok:
        raise LoadError("no triangles (no IFC element with geometry)", path)
    shapes = []  # (element id, V, F, material ids, styles, type): the kernel's threads finish in any order
    done = 0
    step = max(1, total // _REPORTS)
    while True:
        try:
            shape = it.get()
            g = shape.geometry
            V = np.asarray(g.verts, dtype=np.float64).reshape(-1, 3)
            F = np.asarray(g.faces, dtype=np.int64).reshape(-1, 3)
            mids = np.asarray(g.material_ids, dtype=np.int64).reshape(-1)
            shapes.append((int(shape.id), V, F, mids, list(g.materials), shape.type))
        except Exception as e:  # noqa: BLE001
            raise LoadError(f"cannot mesh IFC file: {one_line(e)}", path) from e
        done += 1
        if done % step == 0:
            report(
                start + (end - start) * min(done / max(total, 1), 1.0),
                f"meshed {done} of {total} IFC elements",
            )
        if not it.next():
            break
    materials: list[Material] = []
    keys: dict = {}
    Vs, Fs, Ms = [], [], []
    offset = 0
    for _, V, F, mids, styles, kind in sorted(shapes, key=lambda t: t[0]):  # file order: deterministic
        if not len(F):
            continue
        mids = mids if len(mids) == len(F) else np.full(len(F), -1)
        mids = np.where((mids >= 0) & (mids < len(styles)), mids, -1)
        local = np.empty(len(styles) + 1, dtype=np.int64)  # style id + 1 -> material index
        for s in np.unique(mids):
            key, mat = (("default",), Material(name="default")) if s < 0 else _material(styles[s], kind)
            if key not in keys:
                keys[key] = len(materials)
                materials.append(mat)
            local[s + 1] = keys[key]
        Vs.append(V @ UP_TO_Y[b"Z"].T)
        if counts is not None:
            counts.append(len(F))
        Fs.append(F + offset)
        Ms.append(local[mids + 1])
        offset += len(V)
    if not Fs:
        raise LoadError("no triangles (no IFC element with geometry)", path)
    F = np.concatenate(Fs)
    return np.concatenate(Vs), F, np.concatenate(Ms), np.zeros((len(F), 3, 2)), materials
