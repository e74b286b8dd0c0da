"""Scenes: world-space arrays of root patches, materials, lights and cameras.

A *patch* is a root polygon of the report: a planar convex quad (coplanar
triangle pairs merged back) or a triangle. Quads keep their corners in order
around the polygon; triangles store ``-1`` as their fourth corner.

Lattice parametrisation (shared by the solver, the baker and the renderer):
for a quad with corners c0..c3 the point at ``(u, v)`` in ``[0, 1]^2`` is
``(1-u)(1-v) c0 + u(1-v) c1 + u v c2 + (1-u) v c3``; for a triangle
``c0 + u (c1 - c0) + v (c2 - c0)`` with ``u + v <= 1``.

Loading (:func:`load_scene`)
----------------------------
- Geometry comes from trimesh (``process=False``); node transforms are applied
  here (glTF: from pygltflib's node tree, since trimesh's graph loses a camera
  node's mesh and children), with the winding flipped under mirroring.
- Vertices are welded (:data:`WELD_REL_TOL`), zero-area triangles dropped, and
  coplanar same-material triangle pairs merged into convex quads
  (:func:`merge_quads`); ``max_edge`` pre-splits big patches (:func:`split_patches`).
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
- Lights (KHR_lights_punctual point and spot), perspective cameras and the
  ``iat_camera_paths`` root extras are read with pygltflib.
"""

from __future__ import annotations

import base64
import hashlib
import io
import logging
import re
import urllib.parse
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iat.camera import Camera
from iat.errors import Cancelled, IATWarning, LoadError, OptionError
from iat.progress import Progress


@dataclass
class Material:
    """A diffuse material.

    albedo : (3,) float64 linear RGB in [0, 1] (baseColorFactor x mean of its texture)
    emission : (3,) float64 emitted radiance, linear RGB (emissiveFactor x strength)
    detail : (h, w, 3) float32 linear RGB albedo texture repeated on the surface, or None
    """

    name: str = ""
    albedo: np.ndarray = field(default_factory=lambda: np.full(3, 0.5))
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    detail: np.ndarray | None = None

    def __post_init__(self):
        self.albedo = np.asarray(self.albedo, dtype=np.float64).reshape(3)
        self.emission = np.asarray(self.emission, dtype=np.float64).reshape(3)


@dataclass
class Light:
    """A KHR_lights_punctual point or spot light.

    kind : "point" or "spot" (directional lights are not supported by the solver)
    position : (3,) float64 world
    direction : (3,) float64 unit vector the spot points along (world)
    color : (3,) float64 linear RGB
    intensity : float, W/sr per unit colour (glTF candela read as radiometric)
    inner_cone, outer_cone : spot cone half-angles in radians
    """

    kind: str = "point"
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    direction: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0, 0.0]))
    color: np.ndarray = field(default_factory=lambda: np.ones(3))
    intensity: float = 1.0
    inner_cone: float = 0.0
    outer_cone: float = np.pi / 4
    name: str = ""

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.direction = np.asarray(self.direction, dtype=np.float64).reshape(3)
        self.color = np.asarray(self.color, dtype=np.float64).reshape(3)

    @property
    def radiant_intensity(self) -> np.ndarray:
        """(3,) float64 intensity x colour."""
        return self.color * float(self.intensity)


@dataclass
class Scene:
    """World-space arrays of a model.

    vertices : (n, 3) float64 world positions
    patch_corners : (p, 4) int64 indices into ``vertices``; -1 in column 3 for triangles
    patch_material : (p,) int64 index into ``materials``
    patch_uv : (p, 4, 2) float64 detail-texture UVs at the corners (0 where none)
    materials, lights, cameras : lists
    camera_paths : named lists of Camera poses (walkthrough paths), may be empty
    path : the file it came from ("" when built in memory)
    """

    vertices: np.ndarray
    patch_corners: np.ndarray
    patch_material: np.ndarray
    materials: list[Material]
    patch_uv: np.ndarray | None = None
    lights: list[Light] = field(default_factory=list)
    cameras: list[Camera] = field(default_factory=list)
    camera_paths: dict[str, list[Camera]] = field(default_factory=dict)
    path: str = ""

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.patch_corners = np.asarray(self.patch_corners, dtype=np.int64).reshape(-1, 4)
        self.patch_material = np.asarray(self.patch_material, dtype=np.int64).reshape(-1)
        if self.patch_uv is None:
            self.patch_uv = np.zeros((len(self.patch_corners), 4, 2))
        self.patch_uv = np.asarray(self.patch_uv, dtype=np.float64).reshape(-1, 4, 2)

    # -- derived per-patch data -------------------------------------------------
    @property
    def n_patches(self) -> int:
        return len(self.patch_corners)

    @property
    def patch_is_quad(self) -> np.ndarray:
        """(p,) bool: True for quads, False for triangles."""
        return self.patch_corners[:, 3] >= 0

    @property
    def corner_positions(self) -> np.ndarray:
        """(p, 4, 3) float64 corner positions; a triangle's 4th corner repeats its 3rd."""
        c = self.patch_corners.copy()
        tri = c[:, 3] < 0
        c[tri, 3] = c[tri, 2]
        return self.vertices[c]

    @property
    def patch_normal(self) -> np.ndarray:
        """(p, 3) float64 unit normals (right-handed winding of the corners)."""
        c = self.corner_positions
        n = np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
        tri = ~self.patch_is_quad
        n[tri] = np.cross(c[tri, 1] - c[tri, 0], c[tri, 2] - c[tri, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    @property
    def patch_area(self) -> np.ndarray:
        """(p,) float64 areas in square scene units."""
        c = self.corner_positions
        a = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
        q = self.patch_is_quad
        a[q] += 0.5 * np.linalg.norm(np.cross(c[q, 2] - c[q, 0], c[q, 3] - c[q, 0]), axis=1)
        return a

    @property
    def patch_albedo(self) -> np.ndarray:
        """(p, 3) float64 albedo per patch."""
        return np.array([m.albedo for m in self.materials])[self.patch_material]

    @property
    def patch_emission(self) -> np.ndarray:
        """(p, 3) float64 emitted radiance per patch."""
        return np.array([m.emission for m in self.materials])[self.patch_material]

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 min and max corner of the used vertices."""
        used = np.zeros(len(self.vertices), dtype=bool)
        used[self.patch_corners[self.patch_corners >= 0]] = True
        v = self.vertices[used]
        return np.array([v.min(axis=0), v.max(axis=0)])

    def default_camera(self) -> Camera:
        """The file's first camera, or one that frames the bounds from +Z."""
        if self.cameras:
            return self.cameras[0]
        lo, hi = self.bounds
        c = (lo + hi) / 2
        r = max(np.linalg.norm(hi - lo) / 2, 1e-6)
        return Camera(eye=c + np.array([0.0, 0.0, 2.2 * r]), target=c, yfov=50.0, znear=r * 0.01, zfar=r * 10)


# ----------------------------------------------------------------------------
# Loading
# ----------------------------------------------------------------------------

log = logging.getLogger(__name__)

#: File extensions :func:`load_scene` reads.
SUPPORTED_EXTENSIONS = (".glb", ".gltf", ".obj", ".off", ".ply", ".stl")

#: Coplanarity tolerance for merging triangle pairs into quads (radians between normals).
QUAD_ANGLE_TOL = 1e-4
#: Positions closer than this times the bounding-box diagonal are welded.
WELD_REL_TOL = 1e-9

_DEFAULT_KEY = ("default",)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear (same shape, float32)."""
    c = np.asarray(c, dtype=np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _one_line(e: BaseException, limit: int = 200) -> str:
    msg = " ".join(str(e).split())
    if len(msg) > limit:
        msg = msg[: limit - 3] + "..."
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__


def _decode_image(data, path: Path, what: str) -> np.ndarray:
    """Encoded image bytes or a PIL image -> (h, w, 3) float32 linear RGB."""
    from PIL import Image

    try:
        img = data if isinstance(data, Image.Image) else Image.open(io.BytesIO(data))
        img.load()
        if img.mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(img, dtype=np.float32) / 65535.0
            a = np.repeat(a[..., None], 3, axis=2)
        else:
            a = np.asarray(img.convert("RGB"), dtype=np.float32) / 255.0
    except Exception as e:  # noqa: BLE001 - any decoder failure is a bad file
        raise LoadError(f"cannot decode texture {what} ({_one_line(e)})", path) from e
    if a.ndim != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise LoadError(f"cannot decode texture {what} (empty image)", path)
    return np.ascontiguousarray(srgb_to_linear(np.clip(a, 0.0, 1.0)))


def _get(obj, key, default=None):
    """Attribute or dict item (pygltflib leaves extensions as dicts)."""
    if obj is None:
        return default
    if isinstance(obj, dict):
        v = obj.get(key, default)
    else:
        v = getattr(obj, key, default)
    return default if v is None else v


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = (float(t) for t in q)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    if n > 0:
        x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _node_local(node) -> np.ndarray:
    """(4, 4) float64 parent_from_node of a pygltflib node."""
    if node.matrix is not None:
        return np.array(node.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    if node.scale is not None:
        m = np.diag([*map(float, node.scale), 1.0]) @ m
    if node.rotation is not None:
        r = np.eye(4)
        r[:3, :3] = _quat_matrix(node.rotation)
        m = r @ m
    if node.translation is not None:
        t = np.eye(4)
        t[:3, 3] = np.asarray(node.translation, dtype=np.float64)
        m = t @ m
    return m


class _Gltf:
    """The parts of a glTF that trimesh drops or changes, read with pygltflib."""

    def __init__(self, path: Path):
        import pygltflib

        self.path = path
        self.base = path.parent
        try:
            doc = pygltflib.GLTF2().load(str(path))
        except Exception as e:  # noqa: BLE001 - pygltflib raises struct.error, JSONDecodeError, ...
            raise LoadError(f"cannot parse glTF (truncated or corrupt file): {_one_line(e)}", path) from e
        if doc is None:
            raise LoadError("cannot parse glTF (truncated or corrupt file)", path)
        self.doc = doc
        self._buffers: dict[int, bytes] = {}
        self._material_cache: dict[int, Material] = {}
        self._check_external_files()

    # -- raw bytes ---------------------------------------------------------------
    def _external(self, uri: str) -> Path:
        return self.base / urllib.parse.unquote(uri)

    def _check_external_files(self):
        for b in self.doc.buffers:
            uri = b.uri
            if uri and not uri.startswith("data:") and not self._external(uri).is_file():
                raise LoadError(f"missing buffer file {uri}", self.path)
        for im in self.doc.images:
            uri = im.uri
            if uri and not uri.startswith("data:") and not self._external(uri).is_file():
                raise LoadError(f"missing texture file {uri}", self.path)

    @staticmethod
    def _data_uri(uri: str) -> bytes:
        head, _, data = uri.partition(",")
        if head.endswith(";base64"):
            return base64.b64decode(data)
        return urllib.parse.unquote_to_bytes(data)

    def _buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.doc.buffers[i]
            if b.uri is None:
                data = self.doc.binary_blob() or b""
            elif b.uri.startswith("data:"):
                data = self._data_uri(b.uri)
            else:
                data = self._external(b.uri).read_bytes()
            self._buffers[i] = data
        return self._buffers[i]

    def image(self, index: int) -> np.ndarray:
        """(h, w, 3) float32 linear RGB of image ``index``."""
        try:
            im = self.doc.images[index]
            what = im.uri if im.uri and not im.uri.startswith("data:") else (im.name or f"#{index}")
            if im.bufferView is not None:
                v = self.doc.bufferViews[im.bufferView]
                off = v.byteOffset or 0
                data = self._buffer(v.buffer)[off : off + v.byteLength]
            elif im.uri:
                data = (
                    self._data_uri(im.uri)
                    if im.uri.startswith("data:")
                    else self._external(im.uri).read_bytes()
                )
            else:
                raise ValueError("image has neither uri nor bufferView")
        except (IndexError, ValueError, TypeError, OSError) as e:
            raise LoadError(f"cannot read texture image #{index} ({_one_line(e)})", self.path) from e
        return _decode_image(data, self.path, what)

    def texture_image(self, tex_info) -> np.ndarray | None:
        if tex_info is None:
            return None
        t = _get(tex_info, "index")
        if t is None or not 0 <= t < len(self.doc.textures):
            log.warning("%s: texture index %s out of range, ignored", self.path, t)
            return None
        tex = self.doc.textures[t]
        src = tex.source
        if src is None:  # EXT_texture_webp and friends keep the source in an extension
            for ext in (tex.extensions or {}).values():
                if isinstance(ext, dict) and ext.get("source") is not None:
                    src = ext["source"]
                    break
        if src is None or not 0 <= src < len(self.doc.images):
            log.warning("%s: texture %d has no usable image, ignored", self.path, t)
            return None
        return self.image(src)

    # -- materials ---------------------------------------------------------------
    def material(self, index: int) -> Material:
        if index in self._material_cache:
            return self._material_cache[index]
        m = self.doc.materials[index]
        pbr = m.pbrMetallicRoughness
        factor = np.asarray(_get(pbr, "baseColorFactor", [1.0, 1.0, 1.0, 1.0]), dtype=np.float64)[:3]
        tex_info = _get(pbr, "baseColorTexture")
        detail = None
        albedo = factor.copy()
        if tex_info is not None:
            if _get(tex_info, "texCoord", 0) != 0:
                log.warning(
                    "%s: material %s uses TEXCOORD_%s for its base colour; TEXCOORD_0 is used",
                    self.path,
                    m.name or index,
                    _get(tex_info, "texCoord"),
                )
            img = self.texture_image(tex_info)
            if img is not None:
                detail = (img * factor.astype(np.float32)).astype(np.float32)
                albedo = factor * img.reshape(-1, 3).mean(axis=0, dtype=np.float64)
        emissive = np.asarray(m.emissiveFactor if m.emissiveFactor else [0.0, 0.0, 0.0], dtype=np.float64)[:3]
        strength = float(
            _get(_get(m.extensions or {}, "KHR_materials_emissive_strength"), "emissiveStrength", 1.0)
        )
        emission = emissive * strength
        if m.emissiveTexture is not None and emission.any():
            img = self.texture_image(m.emissiveTexture)
            if img is not None:
                emission = emission * img.reshape(-1, 3).mean(axis=0, dtype=np.float64)
        mat = Material(
            name=m.name or f"material_{index}",
            albedo=albedo,  # clamped by load_scene, which warns
            emission=emission,
            detail=detail,
        )
        self._material_cache[index] = mat
        return mat

    def geometry_primitives(self) -> dict[str, tuple[int, int]]:
        """trimesh geometry name -> (mesh, primitive), replaying trimesh 5's naming."""
        from trimesh.util import unique_name

        taken: dict[str, bool] = {}
        counts: dict = {}
        out = {}
        for mi, mesh in enumerate(self.doc.meshes):
            for pi, prim in enumerate(mesh.primitives):
                name = unique_name(mesh.name if mesh.name is not None else "GLTF", taken, counts=counts)
                mode = 4 if prim.mode is None else prim.mode
                if mode in (0, 1, 4, 5):
                    taken[name] = True
                    out[name] = (mi, pi)
        return out

    def mesh_instances(self, world: dict[int, np.ndarray], geometry: dict):
        """[(world_from_mesh, trimesh geometry name, material index or None)], or None when
        a primitive cannot be matched to trimesh's geometry (name missing or vertex count differs)."""
        import trimesh

        name_of = {v: k for k, v in self.geometry_primitives().items()}
        out = []
        for i in sorted(world):
            mi = self.doc.nodes[i].mesh
            if mi is None:
                continue
            if not 0 <= mi < len(self.doc.meshes):
                log.warning("%s: node %s refers to mesh %s that does not exist", self.path, i, mi)
                continue
            for pi, prim in enumerate(self.doc.meshes[mi].primitives):
                name = name_of.get((mi, pi))
                if name is None:
                    log.warning(
                        "%s: mesh %s primitive %s of mode %s skipped (not supported)",
                        self.path,
                        mi,
                        pi,
                        prim.mode,
                    )
                    continue
                geom = geometry.get(name)
                if geom is None:
                    return None
                if isinstance(geom, trimesh.Trimesh | trimesh.PointCloud):
                    try:
                        count = self.doc.accessors[prim.attributes.POSITION].count
                    except (IndexError, TypeError, AttributeError):
                        return None
                    if count != len(geom.vertices):
                        return None
                out.append((world[i], name, prim.material))
        return out

    # -- nodes, lights, cameras -----------------------------------------------
    def node_world(self) -> dict[int, np.ndarray]:
        """node index -> (4, 4) world_from_node, for the nodes of the active scene."""
        doc = self.doc
        nodes = doc.nodes
        if doc.scenes:
            si = doc.scene if doc.scene is not None and 0 <= doc.scene < len(doc.scenes) else 0
            roots = list(doc.scenes[si].nodes or [])
        else:
            children = {c for n in nodes for c in (n.children or [])}
            roots = [i for i in range(len(nodes)) if i not in children]
        world: dict[int, np.ndarray] = {}
        stack = [(r, np.eye(4)) for r in roots]
        while stack:
            i, parent = stack.pop()
            if not (isinstance(i, int) and 0 <= i < len(nodes)) or i in world:
                continue
            m = parent @ _node_local(nodes[i])
            world[i] = m
            stack.extend((c, m) for c in (nodes[i].children or []))
        return world

    def lights(self, world: dict[int, np.ndarray]) -> list[Light]:
        ext = _get(self.doc.extensions or {}, "KHR_lights_punctual")
        defs = _get(ext, "lights", [])
        out = []
        for i in sorted(world):
            node = self.doc.nodes[i]
            li = _get(_get(node.extensions or {}, "KHR_lights_punctual"), "light")
            if li is None:
                continue
            if not 0 <= li < len(defs):
                log.warning("%s: node %s refers to light %s that does not exist", self.path, i, li)
                continue
            d = defs[li]
            kind = d.get("type", "point")
            name = d.get("name") or node.name or f"light_{li}"
            if kind == "directional":
                log.warning("%s: directional light %r skipped (not supported)", self.path, name)
                continue
            if kind not in ("point", "spot"):
                log.warning("%s: light %r of unknown type %r skipped", self.path, name, kind)
                continue
            m = world[i]
            direction = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
            nd = np.linalg.norm(direction)
            direction = direction / nd if nd > 0 else np.array([0.0, 0.0, -1.0])
            spot = d.get("spot") or {}
            out.append(
                Light(
                    kind=kind,
                    position=m[:3, 3].copy(),
                    direction=direction,
                    color=np.asarray(d.get("color", [1.0, 1.0, 1.0]), dtype=np.float64)[:3],
                    intensity=float(d.get("intensity", 1.0)),
                    inner_cone=float(spot.get("innerConeAngle", 0.0)),
                    outer_cone=float(spot.get("outerConeAngle", np.pi / 4)),
                    name=name,
                )
            )
        return out

    def cameras(self, world: dict[int, np.ndarray], scene: Scene) -> list[Camera]:
        out = []
        for i in sorted(world):
            node = self.doc.nodes[i]
            if node.camera is None:
                continue
            if not 0 <= node.camera < len(self.doc.cameras):
                log.warning("%s: node %s refers to camera %s that does not exist", self.path, i, node.camera)
                continue
            c = self.doc.cameras[node.camera]
            name = node.name or c.name or f"camera_{node.camera}"
            if c.type != "perspective" or c.perspective is None:
                log.warning("%s: camera %r is not perspective, skipped", self.path, name)
                continue
            p = c.perspective
            m = world[i]
            eye = m[:3, 3].copy()
            fwd = m[:3, :3] @ np.array([0.0, 0.0, -1.0])
            up = m[:3, :3] @ np.array([0.0, 1.0, 0.0])
            fwd = fwd / max(np.linalg.norm(fwd), 1e-300)
            up = up / max(np.linalg.norm(up), 1e-300)
            znear = float(p.znear) if p.znear else 0.01
            if p.zfar:
                zfar = float(p.zfar)
            else:  # infinite projection in the file: reach beyond the far side of the model
                bounds = scene.bounds
                centre = bounds.mean(axis=0)
                reach = np.linalg.norm(eye - centre) + np.linalg.norm(bounds[1] - bounds[0])
                zfar = max(1000.0 * znear, 2.0 * reach)
            yfov = float(np.degrees(p.yfov)) if p.yfov else 60.0
            out.append(Camera(eye=eye, target=eye + fwd, up=up, yfov=yfov, znear=znear, zfar=zfar, name=name))
        return out

    def camera_paths(self) -> dict[str, list[Camera]]:
        sources = [self.doc.extras]
        if self.doc.scenes:
            sources += [s.extras for s in self.doc.scenes]
        for extras in sources:
            if isinstance(extras, dict) and isinstance(extras.get("iat_camera_paths"), dict):
                paths = {}
                for name, poses in extras["iat_camera_paths"].items():
                    try:
                        paths[str(name)] = [Camera.from_dict(p) for p in poses]
                    except (TypeError, ValueError, KeyError, AttributeError) as e:
                        log.warning("%s: camera path %r ignored (%s)", self.path, name, _one_line(e))
                return paths
        return {}


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
        img = _decode_image(image, path, name or "image")
        detail = (img * albedo.astype(np.float32)).astype(np.float32)
        albedo = albedo * img.reshape(-1, 3).mean(axis=0, dtype=np.float64)
    return Material(name=name, albedo=albedo, emission=emission, detail=detail)  # clamped by load_scene


def _check_obj_textures(path: Path):
    """Raise LoadError when an OBJ's material library names a texture file that is missing."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise LoadError(f"cannot read file: {_one_line(e)}", path) from e
    libs = [
        m.decode("utf-8", "replace").strip()
        for m in re.findall(rb"^[ \t]*mtllib[ \t]+([^\r\n]+)", data, re.M)
    ]
    for lib in libs:
        mtl = path.parent / lib
        if mtl.is_file():
            mtls = [mtl]
        else:
            mtls = [path.parent / t for t in lib.split() if (path.parent / t).is_file()]
            if not mtls:
                log.warning("%s: material library %s not found; default materials used", path, lib)
                continue
        for m in mtls:
            for line in m.read_text(errors="replace").splitlines():
                toks = line.strip().split()
                if len(toks) < 2:
                    continue
                key = toks[0].lower()
                if not (key.startswith("map_") or key in ("bump", "disp", "decal", "norm", "refl")):
                    continue
                rest = line.strip()[len(toks[0]) :].strip()
                last = toks[-1].replace("\\", "/")
                cands = {rest, toks[-1], last, last.rsplit("/", 1)[-1]}
                if any((m.parent / c).is_file() for c in cands):
                    continue
                raise LoadError(f"missing texture file {toks[-1]}", path)


def _obj_index_out_of_range(path: Path) -> bool:
    """True when an OBJ face refers to a vertex that does not exist (only run after a failed load)."""
    try:
        lines = path.read_bytes().decode("latin-1").splitlines()
    except OSError:
        return False
    nv = sum(1 for ln in lines if ln.startswith("v ") or ln.startswith("v\t"))
    for ln in lines:
        if not (ln.startswith("f ") or ln.startswith("f\t")):
            continue
        for tok in ln.split()[1:]:
            try:
                i = int(tok.split("/")[0])
            except ValueError:
                continue
            if i == 0 or i > nv or -i > nv:
                return True
    return False


def _load_trimesh(path: Path, ext: str):
    import trimesh

    kind = ext[1:].upper()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                return trimesh.load_scene(str(path), process=False)
            except ImportError as e:
                # trimesh guesses the encoding of non-UTF-8 text with charset_normalizer, which is absent:
                # text formats in Latin-1 are read here, anything else is not a text file
                data = path.read_bytes()
                if ext not in (".obj", ".off") or b"\0" in data:
                    raise LoadError(
                        f"cannot read {kind} file (truncated or corrupt file): not valid data", path
                    ) from e
                text = io.BytesIO(data.decode("latin-1").encode("utf-8"))
                resolver = trimesh.resolvers.FilePathResolver(str(path))
                return trimesh.load_scene(text, file_type=ext[1:], resolver=resolver, process=False)
    except LoadError:
        raise
    except Exception as e:  # noqa: BLE001 - trimesh raises a zoo of types on bad input
        if ext == ".obj" and isinstance(e, IndexError) and _obj_index_out_of_range(path):
            raise LoadError("face index out of range", path) from e
        raise LoadError(f"cannot read {kind} file (truncated or corrupt file): {_one_line(e)}", path) from e


def _instances(tscene, path: Path, gl: _Gltf | None, world: dict | None):
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
            log.warning("%s: node %s skipped (%s)", path, node, _one_line(e))
            continue
        out.append((T, gname, "trimesh"))
    return out


def _collect(tscene, path: Path, gl: _Gltf | None, world: dict | None = None):
    """Flatten a trimesh Scene to world arrays.

    Returns vertices (n, 3) float64, faces (f, 3) int64, face_material (f,) int64,
    face_uv (f, 3, 2) float64 (glTF convention: v down from the image top), materials.
    """
    import trimesh
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
    n_points = 0
    for T, gname, spec in _instances(tscene, path, gl, world):
        geom = tscene.geometry.get(gname)
        if isinstance(geom, trimesh.PointCloud):
            n_points += 1
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
                mi = material_index(("trimesh", id(tm)), lambda tm=tm: _trimesh_material(tm, path))
        Vs.append(W)
        Fs.append(F + offset)
        Ms.append(np.full(len(F), mi, dtype=np.int64))
        UVs.append(uvc)
        offset += len(W)
    if not Fs:
        if n_points:
            raise LoadError("no triangles (point cloud only)", path)
        raise LoadError("no triangles", path)
    return np.concatenate(Vs), np.concatenate(Fs), np.concatenate(Ms), np.concatenate(UVs), materials


# ----------------------------------------------------------------------------
# Array steps (pure functions, vectorised)
# ----------------------------------------------------------------------------


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (faster than np.cross on big arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt((a * a).sum(axis=-1))


def _group_rows(key: np.ndarray):
    """Group equal rows of an (n, 3) int64 array.

    Returns (order, new_group): ``key[order]`` has equal rows adjacent and
    ``new_group[i]`` is True where sorted row i starts a new group.
    """
    # sort one int64 hash instead of three columns; check the hash did not merge distinct rows
    with np.errstate(over="ignore"):
        h = key[:, 0] * np.int64(-7046029254386353131) + key[:, 1] * np.int64(0x5851F42D4C957F2D)
        h = (h ^ (h >> np.int64(29))) + key[:, 2] * np.int64(0x2545F4914F6CDD1D)
    order = np.argsort(h, kind="stable")
    hs = h[order]
    new_group = np.ones(len(key), dtype=bool)
    new_group[1:] = hs[1:] != hs[:-1]
    ks = key[order]
    same = ~new_group[1:]
    if same.any() and (ks[1:][same] != ks[:-1][same]).any():  # hash collision: sort by the rows
        order = np.lexsort(key.T[::-1])
        ks = key[order]
        new_group[1:] = (ks[1:] != ks[:-1]).any(axis=1)
    return order, new_group


def weld_vertices(vertices: np.ndarray, faces: np.ndarray, rel_tol: float = WELD_REL_TOL):
    """Merge vertices whose positions agree within ``rel_tol`` x bounding-box diagonal.

    vertices : (n, 3) float64; faces : (..., k) int64 indices (negative entries kept as they are)
    Returns (vertices (m, 3) float64 of the used vertices only, faces remapped).
    Unused vertices are dropped; the order follows a spatial hash, not the input.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    valid = faces >= 0
    used_mask = np.zeros(len(vertices), dtype=bool)
    used_mask[faces[valid]] = True
    used = np.flatnonzero(used_mask)
    if len(used) == 0:
        return np.zeros((0, 3)), faces.copy()
    V = vertices[used]
    lo = V.min(axis=0)
    diag = float(np.linalg.norm(V.max(axis=0) - lo))
    q = max(diag * rel_tol, 1e-300)
    key = np.round((V - lo) / q).astype(np.int64)
    order, new_group = _group_rows(key)
    group = np.cumsum(new_group) - 1
    inv_used = np.empty(len(V), dtype=np.int64)
    inv_used[order] = group
    out_v = V[order[new_group]]  # representative: the first of each group
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = inv_used
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return out_v, out_f


def _weld_some(vertices: np.ndarray, faces: np.ndarray, weldable: np.ndarray, rel_tol: float = WELD_REL_TOL):
    """:func:`weld_vertices` restricted to the ``weldable`` (n,) bool vertices; the others stay distinct."""
    faces = np.asarray(faces, dtype=np.int64)
    w = np.flatnonzero(weldable)
    Vw = vertices[w]
    lo = Vw.min(axis=0)
    q = max(float(np.linalg.norm(Vw.max(axis=0) - lo)) * rel_tol, 1e-300)
    order, new_group = _group_rows(np.round((Vw - lo) / q).astype(np.int64))
    remap = np.empty(len(vertices), dtype=np.int64)
    remap[w[order]] = np.cumsum(new_group) - 1
    n_w = int(new_group.sum())
    rest = np.flatnonzero(~weldable)
    remap[rest] = n_w + np.arange(len(rest))
    out_v = np.concatenate([Vw[order[new_group]], vertices[rest]])
    valid = faces >= 0
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return compact_vertices(out_v, out_f)


def compact_vertices(vertices: np.ndarray, faces: np.ndarray):
    """Drop the vertices no face uses, keeping the order of the others.

    vertices : (n, 3); faces : (..., k) int64 (negative entries kept as they are)
    Returns (vertices (m, 3), faces remapped).
    """
    faces = np.asarray(faces, dtype=np.int64)
    valid = faces >= 0
    used = np.zeros(len(vertices), dtype=bool)
    used[faces[valid]] = True
    remap = np.cumsum(used) - 1
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return np.asarray(vertices)[used], out_f


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) float64 areas of triangles ``faces`` (f, 3)."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return 0.5 * _norm(_cross(v1 - v0, v2 - v0))


def degenerate_faces(vertices: np.ndarray, faces: np.ndarray, rel: float = 1e-12) -> np.ndarray:
    """(f,) bool: zero-area triangles (repeated corners, or twice the area below ``rel`` x longest edge²)."""
    v0, v1, v2 = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    e0, e1, e2 = v1 - v0, v2 - v1, v0 - v2
    cr = _norm(_cross(e0, -e2))
    longest2 = np.maximum(np.maximum((e0 * e0).sum(1), (e1 * e1).sum(1)), (e2 * e2).sum(1))
    rep = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    return rep | (cr <= rel * longest2) | (longest2 == 0)


def merge_quads(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_material: np.ndarray,
    face_uv: np.ndarray | None = None,
    angle_tol: float = QUAD_ANGLE_TOL,
    uv_tol: float = 1e-6,
):
    """Merge coplanar triangle pairs back into convex quads.

    Two triangles pair when they share an edge (in opposite directions; edges
    used by up to 8 triangles are searched), have the same material, the same detail UVs on the
    shared corners, normals within ``angle_tol`` radians, and their union is a
    strictly convex quad. A greedy matching (best-shaped quads first: largest
    smallest corner sine, ties broken by a fixed-seed shuffle) picks disjoint
    pairs; every step is vectorised.

    vertices : (n, 3) float64; faces : (f, 3) int64, non-degenerate
    face_material : (f,) int64; face_uv : (f, 3, 2) float64 or None
    Returns patch_corners (p, 4) int64 (-1 in column 3 for triangles),
    patch_material (p,) int64, patch_uv (p, 4, 2) float64. Quads keep the
    triangles' winding (a split ``[0,1,2],[2,3,0]`` comes back as ``[0,1,2,3]``);
    patches come in the order of their first triangle.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    M = np.asarray(face_material, dtype=np.int64).reshape(-1)
    nf = len(F)
    UV = np.zeros((nf, 3, 2)) if face_uv is None else np.asarray(face_uv, dtype=np.float64).reshape(nf, 3, 2)
    if nf == 0:
        return np.zeros((0, 4), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 4, 2))

    Ff = F.ravel()  # corner h = 3 f + k; half-edge h goes from Ff[h] to Ff[next(h)]
    UVf = UV.reshape(-1, 2)
    v0, v1, v2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    N = _cross(v1 - v0, v2 - v0)
    N /= np.maximum(_norm(N), 1e-300)[:, None]

    h = np.arange(3 * nf)
    h_next = h - h % 3 + (h % 3 + 1) % 3
    h_to = Ff[h_next]
    nv = int(F.max()) + 1
    key = np.minimum(Ff, h_to) * nv + np.maximum(Ff, h_to)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    length = np.diff(np.r_[start, len(ks)])
    # candidate pairs: every two half-edges on the same edge (an edge shared by more than two
    # triangles, as in double-sided walls, gives all its pairs; the filters below pick the valid ones)
    cand_a, cand_b = [], []
    for c in np.unique(length[(length >= 2) & (length <= 8)]):
        st = start[length == c]
        ii, jj = np.triu_indices(int(c), 1)
        cand_a.append(order[(st[:, None] + ii).ravel()])
        cand_b.append(order[(st[:, None] + jj).ravel()])
    ha = np.concatenate(cand_a) if cand_a else np.zeros(0, dtype=np.int64)
    hb = np.concatenate(cand_b) if cand_b else np.zeros(0, dtype=np.int64)
    del key, order, ks, start, length, cand_a, cand_b

    fa, fb = ha // 3, hb // 3
    ok = (Ff[ha] == h_to[hb]) & (fa != fb) & (M[fa] == M[fb])
    ha, hb, fa, fb = ha[ok], hb[ok], fa[ok], fb[ok]
    ok = (N[fa] * N[fb]).sum(axis=1) >= np.cos(angle_tol)
    ha, hb, fa, fb = ha[ok], hb[ok], fa[ok], fb[ok]
    ha1, hb1 = h_next[ha], h_next[hb]
    ha2, hb2 = h_next[ha1], h_next[hb1]
    # same UVs at the two shared corners: a[k] == b[k'+1] and a[k+1] == b[k']
    du = np.maximum(np.abs(UVf[ha] - UVf[hb1]).max(axis=1), np.abs(UVf[ha1] - UVf[hb]).max(axis=1))
    ok = du <= uv_tol * np.maximum(1.0, np.abs(UVf[ha]).max(axis=1))
    ha, hb, fa, fb, ha1, ha2, hb2 = (x[ok] for x in (ha, hb, fa, fb, ha1, ha2, hb2))

    # quad around a's winding: a[k+1], a[k+2], a[k], b's opposite corner; corners 1 and 3
    # are triangle corners (convex by construction), corners 0 and 2 end the shared diagonal
    p0, p1, p2, p3 = V[Ff[ha1]], V[Ff[ha2]], V[Ff[ha]], V[Ff[hb2]]
    n = N[fa]
    e01, e12, e23, e30 = p1 - p0, p2 - p1, p3 - p2, p0 - p3
    l01, l12, l23, l30 = _norm(e01), _norm(e12), _norm(e23), _norm(e30)
    s0 = (_cross(e30, e01) * n).sum(1) / np.maximum(l30 * l01, 1e-300)
    s1 = (_cross(e01, e12) * n).sum(1) / np.maximum(l01 * l12, 1e-300)
    s2 = (_cross(e12, e23) * n).sum(1) / np.maximum(l12 * l23, 1e-300)
    s3 = (_cross(e23, e30) * n).sum(1) / np.maximum(l23 * l30, 1e-300)
    score = np.minimum(np.minimum(s0, s1), np.minimum(s2, s3))
    ok = (s0 > 1e-6) & (s2 > 1e-6)
    ha, hb, fa, fb, ha1, ha2, hb2, score = (x[ok] for x in (ha, hb, fa, fb, ha1, ha2, hb2, score))

    # greedy matching: a candidate wins when it ranks best at both of its faces
    m = len(ha)
    rng = np.random.default_rng(0)
    rank = np.empty(m, dtype=np.int64)
    rank[np.lexsort((rng.random(m), -np.round(score, 3)))] = np.arange(m)
    matched = np.zeros(nf, dtype=bool)
    best = np.full(nf, m, dtype=np.int64)
    idx = np.arange(m)
    chosen = []
    while len(idx):
        a_, b_, r = fa[idx], fb[idx], rank[idx]
        best[a_] = m
        best[b_] = m
        np.minimum.at(best, a_, r)
        np.minimum.at(best, b_, r)
        win = (best[a_] == r) & (best[b_] == r)
        chosen.append(idx[win])
        matched[a_[win]] = True
        matched[b_[win]] = True
        idx = idx[~(matched[a_] | matched[b_])]
    win = np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)

    qa, qb = fa[win], fb[win]
    qh = np.stack([ha1[win], ha2[win], ha[win], hb2[win]], axis=1)
    q_corners = Ff[qh]
    q_uv = UVf[qh]
    tri = np.flatnonzero(~matched)
    t_corners = np.concatenate([F[tri], np.full((len(tri), 1), -1, dtype=np.int64)], axis=1)
    t_uv = UV[tri][:, [0, 1, 2, 2]]

    first = np.concatenate([np.minimum(qa, qb), tri])
    o = np.argsort(first, kind="stable")
    corners = np.concatenate([q_corners, t_corners])[o]
    material = np.concatenate([M[qa], M[tri]])[o]
    uv = np.concatenate([q_uv, t_uv])[o]
    return corners, material, uv


def split_patches(
    vertices: np.ndarray,
    patch_corners: np.ndarray,
    patch_material: np.ndarray,
    patch_uv: np.ndarray,
    max_edge: float,
):
    """Pre-split patches longer than ``max_edge`` into regular grids of root patches.

    A quad whose longest edge exceeds ``max_edge`` becomes ``n x m`` quads with
    ``n = ceil(longest u-edge / max_edge)``, ``m = ceil(longest v-edge / max_edge)``
    (bilinear in its own parametrisation); a triangle becomes ``4**k`` triangles,
    ``k = ceil(log2(longest edge / max_edge))``. Materials are copied, UVs
    interpolated, windings kept; new vertices are welded to their neighbours.

    vertices : (n, 3) float64; patch_corners : (p, 4) int64; patch_material : (p,) int64;
    patch_uv : (p, 4, 2) float64.
    Returns (vertices, patch_corners, patch_material, patch_uv), children in
    place of their parent.
    """
    if not (max_edge > 0 and np.isfinite(max_edge)):
        raise OptionError(f"max_edge must be a positive number, got {max_edge!r}")
    V = np.asarray(vertices, dtype=np.float64)
    C = np.asarray(patch_corners, dtype=np.int64).reshape(-1, 4)
    Mat = np.asarray(patch_material, dtype=np.int64).reshape(-1)
    UV = np.asarray(patch_uv, dtype=np.float64).reshape(-1, 4, 2)
    is_quad = C[:, 3] >= 0
    P = V[np.where(is_quad[:, None], C, C[:, [0, 1, 2, 2]])]

    pts, on_edge, kids, kid_mat, kid_uv, kid_parent = [], [], [], [], [], []
    n_pts = len(V)  # index of the next new point

    # quads: an (n + 1) x (m + 1) lattice of points per parent, point (a, b) at base + b (n + 1) + a
    q = np.flatnonzero(is_quad)
    c = P[q]
    n = np.ceil(np.maximum(_norm(c[:, 1] - c[:, 0]), _norm(c[:, 2] - c[:, 3])) / max_edge)
    m = np.ceil(np.maximum(_norm(c[:, 3] - c[:, 0]), _norm(c[:, 2] - c[:, 1])) / max_edge)
    n, m = np.maximum(n, 1).astype(np.int64), np.maximum(m, 1).astype(np.int64)
    sel = (n > 1) | (m > 1)
    q, c, n, m = q[sel], c[sel], n[sel], m[sel]
    if len(q):
        cnt = (n + 1) * (m + 1)
        base = n_pts + np.cumsum(cnt) - cnt
        pid = np.repeat(np.arange(len(q)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        a, b = local % (n[pid] + 1), local // (n[pid] + 1)
        u, v = a / n[pid], b / m[pid]
        w = [(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v]
        acc = w[0][:, None] * c[pid, 0]
        for i in range(1, 4):
            acc += w[i][:, None] * c[pid, i]
        pts.append(acc)
        on_edge.append((a == 0) | (b == 0) | (a == n[pid]) | (b == m[pid]))
        n_pts += len(u)
        del acc, w, u, v, a, b, local, pid
        cnt = n * m
        pid = np.repeat(np.arange(len(q)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        nn, mm = n[pid], m[pid]
        a, b = local % nn, local // nn
        row = nn + 1
        first = base[pid] + b * row + a
        kids.append(np.stack([first, first + 1, first + row + 1, first + row], axis=1))
        uvq = UV[q]
        if uvq.any():
            us = np.stack([a, a + 1, a + 1, a], axis=1) / nn[:, None]
            vs = np.stack([b, b, b + 1, b + 1], axis=1) / mm[:, None]
            uvp = uvq[pid]
            kid_uv.append(
                ((1 - us) * (1 - vs))[..., None] * uvp[:, None, 0]
                + (us * (1 - vs))[..., None] * uvp[:, None, 1]
                + (us * vs)[..., None] * uvp[:, None, 2]
                + ((1 - us) * vs)[..., None] * uvp[:, None, 3]
            )
        else:
            kid_uv.append(np.zeros((len(pid), 4, 2)))
        kid_mat.append(Mat[q][pid])
        kid_parent.append(q[pid])

    # triangles: the lattice i + j <= N, N = 2**k, per parent
    t = np.flatnonzero(~is_quad)
    c = P[t][:, :3]
    longest = np.maximum(
        np.maximum(_norm(c[:, 1] - c[:, 0]), _norm(c[:, 2] - c[:, 1])), _norm(c[:, 0] - c[:, 2])
    )
    k = np.zeros(len(t), dtype=np.int64)
    big = longest > max_edge
    k[big] = np.ceil(np.log2(longest[big] / max_edge)).astype(np.int64)
    for level in np.unique(k[big]):
        sel = t[k == level]
        cs = P[sel][:, :3]
        N = 1 << int(level)
        i, j = np.meshgrid(np.arange(N + 1), np.arange(N + 1), indexing="ij")
        inside = (i + j) <= N
        table = np.full((N + 1, N + 1), -1, dtype=np.int64)
        table[inside] = np.arange(int(inside.sum()))
        li, lj = i[inside], j[inside]
        u, v = li / N, lj / N
        w = np.stack([1 - u - v, u, v])  # (3, s)
        pts.append(np.einsum("ws,twd->tsd", w, cs).reshape(-1, 3))
        n_lat = len(li)
        on_edge.append(np.tile((li == 0) | (lj == 0) | (li + lj == N), len(sel)))
        bases = n_pts + n_lat * np.arange(len(sel))
        n_pts += n_lat * len(sel)
        i, j = i[:N, :N], j[:N, :N]
        up, dn = (i + j) <= N - 1, (i + j) <= N - 2
        iu, ju, idn, jdn = i[up], j[up], i[dn], j[dn]
        # the down triangles keep the parent's winding: (i+1, j+1), (i, j+1), (i+1, j)
        ci = np.concatenate([np.stack([iu, iu + 1, iu], 1), np.stack([idn + 1, idn, idn + 1], 1)])
        cj = np.concatenate([np.stack([ju, ju, ju + 1], 1), np.stack([jdn + 1, jdn + 1, jdn], 1)])
        sub = table[ci, cj]  # (s, 3)
        s = len(sub)
        tri = (bases[:, None, None] + sub[None]).reshape(-1, 3)
        kids.append(np.concatenate([tri, np.full((len(tri), 1), -1, dtype=np.int64)], axis=1))
        u, v = ci / N, cj / N
        wt = np.stack([1 - u - v, u, v], axis=2)  # (s, 3, 3)
        uvs = np.einsum("scw,twd->tscd", wt, UV[sel][:, :3]).reshape(-1, 3, 2)
        kid_uv.append(uvs[:, [0, 1, 2, 2]])
        kid_mat.append(np.repeat(Mat[sel], s))
        kid_parent.append(np.repeat(sel, s))
    if not kids:
        V, C = compact_vertices(V, C)
        return V, C, Mat, UV

    split = np.zeros(len(C), dtype=bool)
    split[q] = True
    split[t[big]] = True
    keep = np.flatnonzero(~split)
    allV = np.concatenate([V, *pts])
    corners = np.concatenate([C[keep], *kids])
    material = np.concatenate([Mat[keep], *kid_mat])
    uv = np.concatenate([UV[keep], *kid_uv])
    parent = np.concatenate([keep, *kid_parent])
    o = np.argsort(parent, kind="stable")
    # only points on a parent's boundary can coincide with others: weld those, keep the interior as is
    weldable = np.concatenate([np.ones(len(V), dtype=bool), *on_edge])
    allV, corners = _weld_some(allV, corners[o], weldable)
    return allV, corners, material[o], uv[o]


_MAX_NAMED = 5  # materials named in the clamped-albedo warning

# fraction of load_scene's progress reached at the end of each stage (measured on a 1 M-triangle STL:
# parse 0.6 s, placing 1.7 s, weld 1.8 s, quad merge 2.9 s)
_STAGES = {"parse": 0.1, "collect": 0.33, "weld": 0.58, "merge": 0.95, "split": 0.98}


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


def load_scene(path: str | Path, max_edge: float | None = None, progress: Progress | None = None) -> Scene:
    """Load a model file (glTF/GLB, OBJ+MTL, PLY, STL, OFF) into a :class:`Scene`.

    Geometry is read by trimesh (each node's transform applied here, winding
    flipped under mirroring), vertices are welded, zero-area triangles dropped,
    and coplanar triangle pairs merged back into quads (:func:`merge_quads`).
    glTF materials, ``KHR_lights_punctual`` lights, cameras and the
    ``iat_camera_paths`` root extras are read with pygltflib. An albedo outside
    [0, 1] is clamped with an :class:`iat.errors.IATWarning`.

    max_edge : pre-split patches longer than this (scene units) into a regular grid
      (:func:`split_patches`); None keeps the root patches as they are.
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
    gl = _Gltf(path) if ext in (".gltf", ".glb") else None
    if ext == ".obj":
        _check_obj_textures(path)
    tscene = _load_trimesh(path, ext)
    report(_STAGES["parse"], "placing geometry")
    world = gl.node_world() if gl is not None else None
    V, F, M, UV, materials = _collect(tscene, path, gl, world)
    del tscene
    _clamp_albedo(materials, path)

    report(_STAGES["collect"], "welding vertices")
    V, F = weld_vertices(V, F)
    bad = degenerate_faces(V, F)
    if bad.all():
        raise LoadError("only degenerate faces", path)
    if bad.any():
        log.info("%s: dropped %d zero-area faces of %d", path, int(bad.sum()), len(F))
        F, M, UV = F[~bad], M[~bad], UV[~bad]
    report(_STAGES["weld"], "merging quads")
    corners, pmat, puv = merge_quads(V, F, M, UV)
    if max_edge is not None:
        report(_STAGES["merge"], "splitting patches")
        V, corners, pmat, puv = split_patches(V, corners, pmat, puv, max_edge)
    else:
        V, corners = compact_vertices(V, corners)  # dropped faces may leave vertices unused

    scene = Scene(
        vertices=V,
        patch_corners=corners,
        patch_material=pmat,
        materials=materials,
        patch_uv=puv,
        path=str(path),
    )
    if gl is not None:
        report(_STAGES["split"], "reading lights and cameras")
        scene.lights = gl.lights(world)
        scene.cameras = gl.cameras(world, scene)
        scene.camera_paths = gl.camera_paths()
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


def scene_digest(scene: Scene) -> str:
    """sha1 hex digest of the geometry and materials a solution depends on.

    Covers vertices, patch corners, patch materials, each material's albedo and
    emission, and the lights (kind, position, direction, radiant intensity,
    cones): not names, detail textures, UVs, cameras or the path.
    """
    h = hashlib.sha1()
    h.update(b"iat-scene-v1")
    h.update(np.ascontiguousarray(scene.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_corners, dtype="<i8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_material, dtype="<i8").tobytes())
    for m in scene.materials:
        h.update(np.ascontiguousarray(m.albedo, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(m.emission, dtype="<f8").tobytes())
    for lt in scene.lights:
        h.update(lt.kind.encode())
        for a in (lt.position, lt.direction, lt.radiant_intensity, [lt.inner_cone, lt.outer_cone]):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()
