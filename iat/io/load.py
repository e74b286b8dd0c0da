"""Loading a model file into a :class:`~iat.io.scene.Scene` (:func:`load_scene`).

- Geometry comes from trimesh (``process=False``); node transforms are applied
  here (glTF: from pygltflib's node tree, :class:`~iat.io.gltf.GltfDocument`, since
  trimesh's graph loses a camera node's mesh and children), with the winding flipped
  under mirroring.
- Vertices are welded (:data:`iat.geometry.mesh.WELD_REL_TOL`), zero-area triangles
  dropped, and coplanar same-material triangle pairs merged into convex quads
  (:func:`iat.geometry.mesh.merge_quads`); before that, ``cut`` cuts the faces other objects pierce
  along the crossings (:func:`iat.geometry.pierce.cut_pierced`); ``max_edge`` pre-splits big patches
  (:func:`iat.geometry.mesh.split_patches`); ``discontinuity`` cuts roots along the hard shadows
  of the file's lights, last (:func:`iat.geometry.discontinuity.split_discontinuities`).
- Materials: ``albedo = baseColorFactor x mean(baseColorTexture)`` (texture
  decoded sRGB -> linear), ``emission = emissiveFactor x emissiveStrength``;
  OBJ: ``Kd`` (x mean of ``map_Kd``) and ``Ke``. ``Material.detail`` is the
  base colour texture times its factor, so its mean is the albedo; row 0 is the
  image's top. Geometry without a material gets one default material (albedo 0.5).
  An albedo outside [0, 1] is clamped (its detail texture scaled to match) with an
  :class:`iat.errors.IATWarning` naming the file and the materials.
- ``progress(fraction, message)`` is called between the stages (parse, weld, quad
  merge, pre-split); returning False raises :class:`iat.errors.Cancelled`.
- ``Scene.patch_uv`` is TEXCOORD_0 in the glTF convention (``(0, 0)`` is the
  top-left of the image, ``v`` grows downwards): texel ``detail[int(v h), int(u w)]``.
  OBJ ``vt`` is converted (``v -> 1 - v``).
- Lights (KHR_lights_punctual point, spot and directional), perspective cameras and the
  ``iat_camera_paths`` and ``iat_sky`` root extras are read with pygltflib.
- OBJ files are checked first for missing texture files and, after a failed parse,
  for face indices out of range, so the error names the cause.
"""

from __future__ import annotations

import io
import logging
import warnings
from pathlib import Path

import numpy as np

from iat.errors import Cancelled, IATWarning, LoadError, OptionError
from iat.geometry.discontinuity import split_discontinuities
from iat.geometry.faults import fault_faces
from iat.geometry.mesh import (
    compact_vertices,
    corner_positions,
    degenerate_faces,
    merge_quads,
    split_patches,
    weld_vertices,
)
from iat.geometry.panels import make_panels
from iat.geometry.pierce import CUTS, cut_pierced
from iat.geometry.sides import SIDES, add_back_faces, classify_sides, object_ids, repeated_faces, twin_patches
from iat.io.dae import dae_frame
from iat.io.gltf import GltfDocument
from iat.io.ifc import read_ifc
from iat.io.images import decode_texture
from iat.io.messages import one_line
from iat.io.obj import check_obj_textures, decode_text, obj_index_out_of_range, triangulate_ngons
from iat.io.scene import Material, Scene
from iat.progress import Progress

log = logging.getLogger(__name__)

#: File extensions :func:`load_scene` reads.
SUPPORTED_EXTENSIONS = (".glb", ".gltf", ".obj", ".off", ".ply", ".stl", ".dae", ".zae", ".ifc")

_DEFAULT_KEY = ("default",)


def _trimesh_material(mat, path: Path) -> Material:
    """A trimesh SimpleMaterial (OBJ) or PBRMaterial -> Material."""
    from trimesh.visual.material import PBRMaterial, SimpleMaterial

    name = getattr(mat, "name", None) or ""
    albedo = np.full(3, 0.5)
    emission = np.zeros(3)
    image = None

    def floats(v):
        try:
            a = np.asarray([float(x) for x in np.ravel(v)], dtype=np.float64)
        except (TypeError, ValueError):
            return None
        if a.size == 1:
            a = np.repeat(a, 3)
        return a[:3] if a.size >= 3 else None

    if isinstance(mat, SimpleMaterial):
        kw = getattr(mat, "kwargs", {}) or {}
        kd = floats(kw["kd"]) if "kd" in kw else None
        if kd is None and getattr(mat, "diffuse", None) is not None:
            kd = np.asarray(mat.diffuse, dtype=np.float64)[:3] / 255.0
        if kd is not None:
            albedo = kd
        ke = floats(kw["ke"]) if "ke" in kw else None
        if ke is not None:
            emission = ke
        image = getattr(mat, "image", None)
    elif isinstance(mat, PBRMaterial):
        f = mat.baseColorFactor
        if f is not None:
            f = np.asarray(f, dtype=np.float64)[:3]
            albedo = (
                f / 255.0
                if f.max() > 1.0 or np.issubdtype(np.asarray(mat.baseColorFactor).dtype, np.integer)
                else f
            )
        else:
            albedo = np.ones(3)
        e = mat.emissiveFactor
        if e is not None:
            emission = np.asarray(e, dtype=np.float64)[:3]
        image = mat.baseColorTexture
    detail = None
    if image is not None:
        img = decode_texture(image, path, name or "image")
        detail = (img * albedo.astype(np.float32)).astype(np.float32)
        albedo = albedo * img.reshape(-1, 3).mean(axis=0, dtype=np.float64)
    return Material(name=name, albedo=albedo, emission=emission, detail=detail)  # clamped by load_scene


def _trimesh_material_key(tm) -> tuple:
    """What makes two trimesh materials the same IAT material: trimesh's COLLADA reader copies
    one material per geometry (the copies share their texture images)."""
    fields = ("name", "baseColorFactor", "emissiveFactor", "baseColorTexture", "image", "kwargs", "diffuse")
    key = []
    for f in fields:
        v = getattr(tm, f, None)
        if isinstance(v, np.ndarray | list | tuple):
            v = tuple(np.ravel(v).tolist())
        elif isinstance(v, dict):
            v = repr(sorted(v.items()))
        elif v is not None and not isinstance(v, str):
            v = id(v)
        key.append(v)
    return ("trimesh", type(tm).__name__, *key)


def _check_binary_stl(path: Path) -> None:
    """Raise LoadError for a binary STL whose size disagrees with its triangle count (trimesh then
    tries it as ASCII and finds nothing)."""
    with open(path, "rb") as f:
        head = f.read(84)
    size = path.stat().st_size
    if head.lstrip().startswith(b"solid") or len(head) < 84:
        return  # ASCII (or too short to be binary): trimesh's to judge
    n = int.from_bytes(head[80:84], "little")
    if size != 84 + 50 * n:
        raise LoadError(
            f"cannot read STL file (truncated or corrupt file): {n} triangles need {84 + 50 * n} bytes, "
            f"the file has {size}",
            path,
        )


def _load_trimesh(path: Path, ext: str, gl: GltfDocument | None):
    """A trimesh Scene of the file: OBJ from its decoded, re-triangulated text
    (:mod:`iat.io.obj`), a glTF whose primitives were converted from ``gl.converted_glb``."""
    import trimesh

    kind = ext[1:].upper()
    text = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            resolver = trimesh.resolvers.FilePathResolver(str(path))
            if ext in (".obj", ".off"):
                # trimesh guesses the encoding of non-UTF-8 text with charset_normalizer, which is absent
                text = decode_text(path.read_bytes(), path, kind)
                if ext == ".obj":
                    text = triangulate_ngons(text, path)
                data, file_type = io.BytesIO(text.encode("utf-8")), ext[1:]
            elif gl is not None and gl.converted_glb is not None:
                data, file_type = io.BytesIO(gl.converted_glb), "glb"
            else:
                return trimesh.load_scene(str(path), process=False)
            return trimesh.load_scene(data, file_type=file_type, resolver=resolver, process=False)
    except LoadError:
        raise
    except Exception as e:  # noqa: BLE001 - trimesh raises a zoo of types on bad input
        if ext == ".obj" and isinstance(e, IndexError) and text is not None and obj_index_out_of_range(text):
            raise LoadError("face index out of range", path) from e
        cause = "not valid data" if isinstance(e, ImportError) else one_line(e)  # charset_normalizer
        raise LoadError(f"cannot read {kind} file (truncated or corrupt file): {cause}", path) from e


def _instances(tscene, path: Path, gl: GltfDocument | None, world: dict | None):
    """[(world_from_geometry (4, 4), geometry name, material spec)] for every placed geometry.

    glTF: walked from pygltflib's nodes (trimesh's graph drops the first camera
    node's mesh and cuts off that node's children), the spec being the glTF
    material index (None: the default material). Other formats, or a glTF
    whose primitives cannot be matched to trimesh's geometries: trimesh's
    graph, the spec being ``"trimesh"`` (use the geometry's own material).
    """
    if gl is not None:
        out = gl.mesh_instances(world, tscene.geometry)
        if out is not None:
            return out
        log.warning("%s: glTF primitives not matched to trimesh's geometries; trimesh's graph used", path)
    out = []
    for node in tscene.graph.nodes_geometry:
        try:
            T, gname = tscene.graph[node]
        except ValueError as e:  # a node cut off from the root
            log.warning("%s: node %s skipped (%s)", path, node, one_line(e))
            continue
        out.append((T, gname, "trimesh"))
    return out


def _collect(tscene, path: Path, gl: GltfDocument | None, world: dict | None = None, counts=None):
    """Flatten a trimesh Scene to world arrays.

    Returns vertices (n, 3) float64, faces (f, 3) int64, face_material (f,) int64,
    face_uv (f, 3, 2) float64 (glTF convention: v down from the image top), materials.
    counts : a list that gets each placed geometry's face count (its faces come one after the other).
    """
    import trimesh
    from trimesh.path.path import Path as LinePath
    from trimesh.visual.texture import TextureVisuals

    materials: list[Material] = []
    keys: dict = {}

    def material_index(key, make) -> int:
        if key not in keys:
            keys[key] = len(materials)
            materials.append(make())
        return keys[key]

    Vs, Fs, Ms, UVs = [], [], [], []
    offset = 0
    n_points = n_lines = 0
    for T, gname, spec in _instances(tscene, path, gl, world):
        geom = tscene.geometry.get(gname)
        if isinstance(geom, trimesh.PointCloud):
            n_points += 1
            continue
        if isinstance(geom, LinePath):
            n_lines += 1
            continue
        if not isinstance(geom, trimesh.Trimesh):
            continue
        V = np.asarray(geom.vertices, dtype=np.float64).reshape(-1, 3)
        F = np.asarray(geom.faces)
        if F.size == 0:
            continue
        if F.ndim != 2 or F.shape[1] != 3:
            raise LoadError("faces are not triangles", path)
        F = F.astype(np.int64)
        if F.min() < 0 or F.max() >= len(V):
            raise LoadError("face index out of range", path)
        T = np.asarray(T, dtype=np.float64)
        with np.errstate(invalid="ignore", over="ignore"):
            W = V @ T[:3, :3].T + T[:3, 3]
        used = np.zeros(len(V), dtype=bool)
        used[F.ravel()] = True
        if not np.isfinite(W[used]).all():
            raise LoadError("non-finite vertex coordinates", path)
        if not np.isfinite(W).all():
            log.info("%s: %s has unused non-finite vertices (ignored)", path, gname)
            W = np.where(np.isfinite(W), W, 0.0)
        # per-corner UVs, flipped back to the glTF convention (trimesh moves the origin to the bottom)
        visual = geom.visual if isinstance(geom.visual, TextureVisuals) else None
        uv = None if visual is None else visual.uv
        if uv is not None and len(uv) == len(V):
            uvc = np.asarray(uv, dtype=np.float64)[:, :2][F]
            uvc[..., 1] = 1.0 - uvc[..., 1]
            uvc = np.where(np.isfinite(uvc), uvc, 0.0)
        else:
            uvc = np.zeros((len(F), 3, 2))
        if np.linalg.det(T[:3, :3]) < 0:
            F = F[:, ::-1]
            uvc = uvc[:, ::-1]
        # material
        if spec != "trimesh":
            if spec is None or not 0 <= spec < len(gl.doc.materials):
                mi = material_index(_DEFAULT_KEY, lambda: Material(name="default"))
            else:
                mi = material_index(("gltf", spec), lambda gm=spec: gl.material(gm))
        else:
            tm = None if visual is None else visual.material
            if tm is None:
                mi = material_index(_DEFAULT_KEY, lambda: Material(name="default"))
            else:
                mi = material_index(_trimesh_material_key(tm), lambda tm=tm: _trimesh_material(tm, path))
        Vs.append(W)
        if counts is not None:
            counts.append(len(F))
        Fs.append(F + offset)
        Ms.append(np.full(len(F), mi, dtype=np.int64))
        UVs.append(uvc)
        offset += len(W)
    if not Fs:
        if n_points or n_lines:
            only = {(True, False): "point cloud", (False, True): "lines", (True, True): "points and lines"}
            raise LoadError(f"no triangles ({only[bool(n_points), bool(n_lines)]} only)", path)
        raise LoadError("no triangles", path)
    return np.concatenate(Vs), np.concatenate(Fs), np.concatenate(Ms), np.concatenate(UVs), materials


_MAX_NAMED = 5  # materials named in the clamped-albedo warning

# fraction of load_scene's progress reached at the end of each stage (measured on a 1 M-triangle STL:
# parse 0.6 s, placing 1.7 s, weld 1.8 s, quad merge 2.9 s)
_STAGES = {"parse": 0.1, "collect": 0.33, "weld": 0.58, "merge": 0.95, "split": 0.98, "lights": 0.99}


def _clamp_albedo(materials: list[Material], path: Path) -> None:
    """Clamp each material's albedo to [0, 1] in place, scaling its detail texture to match.

    Warns once (:class:`iat.errors.IATWarning`) naming the file and the clamped materials
    with their albedo as read.
    """
    clamped = []
    for m in materials:  # a handful of materials: no hot path
        clipped = np.clip(m.albedo, 0.0, 1.0)
        if np.array_equal(clipped, m.albedo, equal_nan=True):  # NaN is the solver's to refuse
            continue
        clamped.append(f"{m.name or '(unnamed)'!r} ({', '.join(f'{a:g}' for a in m.albedo)})")
        if m.detail is not None:
            ratio = np.divide(clipped, m.albedo, out=np.ones(3), where=m.albedo != 0)
            m.detail = (m.detail * ratio.astype(np.float32)).astype(np.float32)
        m.albedo = clipped
    if clamped:
        shown = ", ".join(clamped[:_MAX_NAMED])
        if len(clamped) > _MAX_NAMED:
            shown += f" and {len(clamped) - _MAX_NAMED} more"
        noun = "material" if len(clamped) == 1 else "materials"
        warnings.warn(
            f"{path}: albedo outside [0, 1] clamped in {len(clamped)} {noun}: {shown}",
            IATWarning,
            stacklevel=3,
        )


def load_scene(
    path: str | Path,
    max_edge: float | None = None,
    progress: Progress | None = None,
    panels: bool = True,
    discontinuity: bool = False,
    sides: str = "auto",
    cut: bool | str = "auto",
) -> Scene:
    """Load a model file (glTF/GLB, OBJ+MTL, PLY, STL, OFF) into a :class:`Scene`.

    Geometry is read by trimesh (each node's transform applied here, winding
    flipped under mirroring), vertices are welded, zero-area triangles dropped,
    and coplanar triangle pairs merged back into quads (:func:`merge_quads`).
    glTF materials, ``KHR_lights_punctual`` lights, cameras and the
    ``iat_camera_paths`` root extras are read with pygltflib. An albedo outside
    [0, 1] is clamped with an :class:`iat.errors.IATWarning`.

    max_edge : pre-split patches longer than this (scene units) into a regular grid
      (:func:`split_patches`); None keeps the root patches as they are.
    panels : group coplanar patches that hold triangles into panels, rectangle roots cut to the
      surface (:func:`iat.geometry.panels.make_panels`; cells no longer than ``max_edge``).
    discontinuity : cut the roots along the hard shadow boundaries of the file's point, spot and
      directional lights (:func:`iat.geometry.discontinuity.split_discontinuities`; last, after
      the lights are read).
    sides : ``"auto"`` (default): IFC's inside-out closed solids are turned outward and its open
      sheets get a back face (its own patch); elsewhere only faces of glTF ``doubleSided``
      materials get one. ``"both"``: every format as IFC. ``"front"``: the faces as the file has
      them. :data:`iat.geometry.sides.SIDES`; what was found is ``Scene.sides``.
    cut : ``"crossings"`` (True): cut the faces that other objects pierce along the
      crossings, so that no patch or panel cell spans both sides of another surface
      (:func:`iat.geometry.pierce.cut_pierced`; a wall through a ceiling is lit above it and dark
      below it); ``"all"``: also along the faces of other objects that rest on them (a slab ending on
      a wall's face, a wall on a slab); ``"none"`` (False) keeps them whole; ``"auto"`` (default):
      ``"all"`` for IFC and with ``sides="both"`` (a model taken as built, whose elements rest on
      each other), else ``"crossings"``. Either way what was found is ``Scene.pierce``
      (``Scene.pierce.mode``: what was cut).
    progress : ``progress(fraction, message) -> bool``, called at the start of each
      stage (parse, weld, quad merge, pre-split) and with 1.0 at the end, fractions
      non-decreasing; returning False raises :class:`iat.errors.Cancelled`.
    Raises :class:`iat.errors.LoadError` naming the file and the cause.
    """
    path = Path(path)

    def report(fraction: float, message: str) -> None:
        if progress is not None and progress(fraction, message) is False:
            raise Cancelled("load cancelled", path)

    if max_edge is not None and not (max_edge > 0 and np.isfinite(max_edge)):
        raise OptionError(f"max_edge must be a positive number, got {max_edge!r}")
    if sides not in SIDES:
        raise OptionError(f"sides must be one of {', '.join(SIDES)}, got {sides!r}")
    cut = ("none", "crossings")[cut] if isinstance(cut, bool) else cut
    if cut not in CUTS:
        raise OptionError(f"cut must be one of {', '.join(CUTS)}, got {cut!r}")
    if not path.exists():
        raise LoadError("file not found", path)
    if not path.is_file():
        raise LoadError("not a regular file", path)
    ext = path.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        supported = ", ".join(SUPPORTED_EXTENSIONS)
        raise LoadError(f"unsupported file type '{path.suffix or '(none)'}' (supported: {supported})", path)
    if path.stat().st_size == 0:
        raise LoadError("empty file", path)

    report(0.0, f"reading {path.name}")
    counts: list[int] = []  # faces per object (IFC element, placed glTF primitive, OBJ group)
    gl = GltfDocument(path) if ext in (".gltf", ".glb") else None
    world = None
    if ext == ".ifc":
        V, F, M, UV, materials = read_ifc(path, report, 0.0, _STAGES["collect"], counts=counts)
    else:
        if ext == ".obj":
            check_obj_textures(path)
        elif ext == ".stl":
            _check_binary_stl(path)
        tscene = _load_trimesh(path, ext, gl)
        report(_STAGES["parse"], "placing geometry")
        world = gl.node_world() if gl is not None else None
        V, F, M, UV, materials = _collect(tscene, path, gl, world, counts)
        del tscene
        if ext in (".dae", ".zae"):
            V = V @ dae_frame(path).T
    _clamp_albedo(materials, path)
    objects = np.repeat(np.arange(len(counts)), counts) if sum(counts) == len(F) else object_ids(F)

    report(_STAGES["collect"], "welding vertices")
    V, F = weld_vertices(V, F)
    bad = degenerate_faces(V, F)
    if bad.all():
        raise LoadError("only degenerate faces", path)
    if bad.any():
        log.info("%s: dropped %d zero-area faces of %d", path, int(bad.sum()), len(F))
        F, M, UV, objects = F[~bad], M[~bad], UV[~bad], objects[~bad]
    again = repeated_faces(F)
    repeats = V[F[again]]  # the coincident faces of Scene.faults (iat.geometry.faults)
    if again.any():  # each copy would receive the light there and reflect it again
        msg = f"{path}: dropped {int(again.sum())} faces repeating another in the same place"
        warnings.warn(IATWarning(msg), stacklevel=2)
        F, M, UV, objects = F[~again], M[~again], UV[~again], objects[~again]
    side = classify_sides(
        V,
        F,
        objects,
        M,
        UV,
        mode=sides,
        double_sided=np.array([m.double_sided for m in materials], dtype=bool),
        one_sided=np.array([m.emission.max() > 0 or m.transmission > 0 for m in materials], dtype=bool),
        sheets_two_sided=ext == ".ifc",  # IFC elements are physical; other files are one-sided by convention
        turn_solids=ext == ".ifc",
        enclosures=ext != ".ifc",
        probes=None if gl is None else [lt.position for lt in gl.lights(world) if lt.kind != "directional"],
    )
    turned = (side.faces != F).any(axis=1)  # inside-out faces turned outward (Scene.faults)
    F, UV = side.faces, side.face_uv
    n_mat = len(materials)  # faces that get a back face carry material + n_mat until the patches are made
    M = np.where(side.back, M + n_mat, M)
    # faces other objects pierce are cut along the crossings; (material, side of the cuts) pairs
    # stand in for the materials until the patches are made (iat.geometry.pierce)
    if cut == "auto":  # a model taken as built: its elements rest on each other
        cut = "all" if ext == ".ifc" or sides == "both" else "crossings"
    pierced = cut_pierced(V, F, M, UV, objects, cut=cut != "none", contacts=cut == "all")
    faults = fault_faces(V, F, turned, side.back, pierced.cut, repeats)
    V, F, UV, M, code_material = pierced.vertices, pierced.faces, pierced.face_uv, pierced.code, pierced.codes
    report(_STAGES["weld"], "merging quads")
    corners, pmat, puv = merge_quads(V, F, M, UV)
    if max_edge is not None:
        report(_STAGES["merge"], "splitting patches")
        V, corners, pmat, puv = split_patches(V, corners, pmat, puv, max_edge)
    clip_uv = clip_patch = None
    if panels:
        report(_STAGES["split"], "making panels")
        has_detail = np.array([m.detail is not None for m in materials], dtype=bool)
        has_detail = np.tile(has_detail, 2)
        if code_material is not None:
            has_detail = has_detail[code_material]
        roots = make_panels(V, corners, pmat, puv, has_detail, cell_max=max_edge)
        V, corners, pmat, puv = roots.vertices, roots.corners, roots.material, roots.uv
        clip_uv, clip_patch = roots.clip_uv, roots.clip_patch
    if code_material is not None:
        pmat = code_material[pmat]
    twin = pmat >= n_mat
    pmat = np.where(twin, pmat - n_mat, pmat)
    if twin.any():  # a back the file has already (split along another diagonal) is kept, not doubled
        twin &= ~twin_patches(corner_positions(V, corners), corners[:, 3] >= 0)
        corners, pmat, puv, clip_uv, clip_patch = add_back_faces(
            corners, pmat, puv, clip_uv, clip_patch, twin
        )
    side.report.twin_patches = int(twin.sum())
    V, corners = compact_vertices(V, corners)  # dropped faces and panels leave vertices unused

    scene = Scene(
        vertices=V,
        patch_corners=corners,
        patch_material=pmat,
        materials=materials,
        patch_uv=puv,
        path=str(path),
        clip_uv=clip_uv,
        clip_patch=clip_patch,
        sides=side.report,
        pierce=pierced.report,
        faults=faults,
    )
    if gl is not None:
        report(_STAGES["split"], "reading lights and cameras")
        scene.lights = gl.lights(world)
        scene.cameras = gl.cameras(world, scene)
        scene.camera_paths = gl.camera_paths()
        scene.sky = gl.sky()
    if discontinuity:
        report(_STAGES["lights"], "cutting along shadow boundaries")
        scene = split_discontinuities(scene)
    report(1.0, "loaded")
    log.info(
        "%s: %d triangles -> %d patches (%d quads), %d materials, %d lights, %d cameras",
        path,
        len(F),
        scene.n_patches,
        int(scene.patch_is_quad.sum()),
        len(materials),
        len(scene.lights),
        len(scene.cameras),
    )
    return scene
