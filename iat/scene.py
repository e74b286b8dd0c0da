"""Scenes: world-space arrays of root patches, materials, lights and cameras.

A *patch* is a root polygon of the report: a planar convex quad (coplanar
triangle pairs merged back) or a triangle. Quads keep their corners in order
around the polygon; triangles store ``-1`` as their fourth corner.

Lattice parametrisation (shared by the solver, the baker and the renderer):
for a quad with corners c0..c3 the point at ``(u, v)`` in ``[0, 1]^2`` is
``(1-u)(1-v) c0 + u(1-v) c1 + u v c2 + (1-u) v c3``; for a triangle
``c0 + u (c1 - c0) + v (c2 - c0)`` with ``u + v <= 1``.
"""

from __future__ import annotations

import base64
import hashlib
import io
import logging
import urllib.parse
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import LoadError, OptionError


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
        v = self.vertices[np.unique(self.patch_corners[self.patch_corners >= 0])]
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
            albedo=np.clip(albedo, 0.0, 1.0),
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

    def primitive_material(self, mi: int, pi: int) -> int | None:
        return self.doc.meshes[mi].primitives[pi].material

    def primitive_vertex_count(self, mi: int, pi: int) -> int | None:
        try:
            a = self.doc.meshes[mi].primitives[pi].attributes.POSITION
            return self.doc.accessors[a].count
        except (IndexError, AttributeError, TypeError):
            return None

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

    def cameras(self, world: dict[int, np.ndarray], bounds: np.ndarray) -> list[Camera]:
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
    return Material(name=name, albedo=np.clip(albedo, 0.0, 1.0), emission=emission, detail=detail)


def _check_obj_textures(path: Path):
    """Raise LoadError when an OBJ's material library names a texture file that is missing."""
    try:
        text = path.read_text(errors="replace")
    except OSError as e:
        raise LoadError(f"cannot read file: {_one_line(e)}", path) from e
    libs = []
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("mtllib"):
            rest = s[6:].strip()
            if rest:
                libs.append(rest)
    for lib in libs:
        mtl = path.parent / lib
        if not mtl.is_file():
            cands = [path.parent / t for t in lib.split()]
            found = [c for c in cands if c.is_file()]
            if not found:
                log.warning("%s: material library %s not found; default materials used", path, lib)
                continue
            mtls = found
        else:
            mtls = [mtl]
        for m in mtls:
            for line in m.read_text(errors="replace").splitlines():
                toks = line.strip().split()
                if not toks:
                    continue
                key = toks[0].lower()
                if not (key.startswith("map_") or key in ("bump", "disp", "decal", "norm", "refl")):
                    continue
                if len(toks) < 2:
                    continue
                rest = line.strip()[len(toks[0]) :].strip()
                if (m.parent / rest).is_file() or (m.parent / toks[-1]).is_file():
                    continue
                raise LoadError(f"missing texture file {toks[-1]}", path)


def _load_trimesh(path: Path, ext: str):
    import trimesh

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return trimesh.load_scene(str(path), process=False)
    except Exception as e:  # noqa: BLE001 - trimesh raises a zoo of types on bad input
        raise LoadError(
            f"cannot read {ext[1:].upper()} file (truncated or corrupt file): {_one_line(e)}", path
        ) from e


def _collect(tscene, path: Path, gl: _Gltf | None):
    """Flatten a trimesh Scene to world arrays.

    Returns vertices (n, 3) float64, faces (f, 3) int64, face_material (f,) int64,
    face_uv (f, 3, 2) float64 (glTF convention: v down from the image top), materials.
    """
    import trimesh

    materials: list[Material] = []
    keys: dict = {}

    def material_index(key, make) -> int:
        if key not in keys:
            keys[key] = len(materials)
            materials.append(make())
        return keys[key]

    prim_of = gl.geometry_primitives() if gl is not None else {}
    Vs, Fs, Ms, UVs = [], [], [], []
    offset = 0
    n_points = n_other = 0
    for node in tscene.graph.nodes_geometry:
        T, gname = tscene.graph[node]
        geom = tscene.geometry.get(gname)
        if isinstance(geom, trimesh.PointCloud):
            n_points += 1
            continue
        if not isinstance(geom, trimesh.Trimesh):
            n_other += 1
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
        W = V @ T[:3, :3].T + T[:3, 3]
        used = np.zeros(len(V), dtype=bool)
        used[F.ravel()] = True
        if not np.isfinite(W[used]).all():
            raise LoadError("non-finite vertex coordinates", path)
        if not np.isfinite(W).all():
            log.info("%s: %s has unused non-finite vertices (ignored)", path, gname)
            W = np.where(np.isfinite(W), W, 0.0)
        # per-corner UVs, flipped back to the glTF convention (trimesh moves the origin to the bottom)
        uv = getattr(geom.visual, "uv", None)
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
        mi = None
        if gl is not None and gname in prim_of:
            m_, p_ = prim_of[gname]
            cnt = gl.primitive_vertex_count(m_, p_)
            if cnt is not None and cnt == len(V):
                gm = gl.primitive_material(m_, p_)
                if gm is None:
                    mi = material_index(_DEFAULT_KEY, lambda: Material(name="default"))
                elif 0 <= gm < len(gl.doc.materials):
                    mi = material_index(("gltf", gm), lambda gm=gm: gl.material(gm))
        if mi is None:
            tm = getattr(geom.visual, "material", None)
            if gl is not None:
                log.warning(
                    "%s: geometry %r not matched to a glTF primitive; trimesh's material used", path, gname
                )
            if tm is None or getattr(geom.visual, "kind", None) != "texture":
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


def weld_vertices(vertices: np.ndarray, faces: np.ndarray, rel_tol: float = WELD_REL_TOL):
    """Merge vertices whose positions agree within ``rel_tol`` x bounding-box diagonal.

    vertices : (n, 3) float64; faces : (..., k) int64 indices (negative entries kept as they are)
    Returns (vertices (m, 3) float64 of the used vertices only, faces remapped).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    valid = faces >= 0
    used = np.unique(faces[valid])
    if len(used) == 0:
        return np.zeros((0, 3)), faces.copy()
    V = vertices[used]
    lo = V.min(axis=0)
    diag = float(np.linalg.norm(V.max(axis=0) - lo))
    q = max(diag * rel_tol, 1e-300)
    key = np.round((V - lo) / q).astype(np.int64)
    order = np.lexsort(key.T[::-1])
    ks = key[order]
    new_group = np.ones(len(ks), dtype=bool)
    new_group[1:] = (ks[1:] != ks[:-1]).any(axis=1)
    group = np.cumsum(new_group) - 1
    inv_used = np.empty(len(V), dtype=np.int64)
    inv_used[order] = group
    # representative: first vertex of each group in sorted order
    out_v = V[order[new_group]]
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = inv_used
    out_f = faces.copy()
    out_f[valid] = remap[faces[valid]]
    return out_v, out_f


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) float64 areas of triangles ``faces`` (f, 3)."""
    v = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def degenerate_faces(vertices: np.ndarray, faces: np.ndarray, rel: float = 1e-12) -> np.ndarray:
    """(f,) bool: zero-area triangles (repeated corners, or area below ``rel`` x longest edge squared)."""
    v = vertices[faces]
    cr = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    e2 = np.max(
        [
            ((v[:, 1] - v[:, 0]) ** 2).sum(1),
            ((v[:, 2] - v[:, 1]) ** 2).sum(1),
            ((v[:, 0] - v[:, 2]) ** 2).sum(1),
        ],
        axis=0,
    )
    rep = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    return rep | (cr <= rel * e2) | (e2 == 0)


def merge_quads(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_material: np.ndarray,
    face_uv: np.ndarray | None = None,
    angle_tol: float = QUAD_ANGLE_TOL,
    uv_tol: float = 1e-6,
):
    """Merge coplanar triangle pairs back into convex quads.

    Two triangles pair when they share an edge (used by exactly these two, in
    opposite directions), have the same material, the same detail UVs on the
    shared corners, normals within ``angle_tol`` radians, and their union is a
    strictly convex quad. A greedy matching (best-shaped quads first, ties broken
    by a fixed-seed shuffle) picks disjoint pairs; every step is vectorised.

    vertices : (n, 3) float64; faces : (f, 3) int64, non-degenerate
    face_material : (f,) int64; face_uv : (f, 3, 2) float64 or None
    Returns patch_corners (p, 4) int64 (-1 in column 3 for triangles),
    patch_material (p,) int64, patch_uv (p, 4, 2) float64. Quads keep the
    triangles' winding; patches come in the order of their first triangle.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    M = np.asarray(face_material, dtype=np.int64).reshape(-1)
    nf = len(F)
    UV = np.zeros((nf, 3, 2)) if face_uv is None else np.asarray(face_uv, dtype=np.float64).reshape(nf, 3, 2)

    cr = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = cr / np.maximum(np.linalg.norm(cr, axis=1, keepdims=True), 1e-300)

    # half-edge h = 3 f + k goes from F[f, k] to F[f, k + 1]
    h_from = F.ravel()
    h_to = F[:, [1, 2, 0]].ravel()
    nv = max(int(F.max()) + 1, 1) if nf else 1
    key = np.minimum(h_from, h_to) * nv + np.maximum(h_from, h_to)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    length = np.diff(np.r_[start, len(ks)])
    two = start[length == 2]
    ha, hb = order[two], order[two + 1]
    fa, ka = ha // 3, ha % 3
    fb, kb = hb // 3, hb % 3

    ok = (h_from[ha] == h_to[hb]) & (fa != fb) & (M[fa] == M[fb])
    ok &= (N[fa] * N[fb]).sum(axis=1) >= np.cos(angle_tol)
    # same UVs at the two shared corners: a[ka] == b[kb+1], a[ka+1] == b[kb]
    ka1, kb1 = (ka + 1) % 3, (kb + 1) % 3
    du = np.abs(UV[fa, ka] - UV[fb, kb1]).max(axis=1)
    du = np.maximum(du, np.abs(UV[fa, ka1] - UV[fb, kb]).max(axis=1))
    ok &= du <= uv_tol * np.maximum(1.0, np.abs(UV[fa, ka]).max(axis=1))
    fa, ka, fb, kb, ka1 = fa[ok], ka[ok], fb[ok], kb[ok], ka1[ok]
    ka2, kb2 = (ka + 2) % 3, (kb + 2) % 3
    # quad around a's winding: a[k+1], a[k+2], a[k], b's opposite corner
    quad = np.stack([F[fa, ka1], F[fa, ka2], F[fa, ka], F[fb, kb2]], axis=1)
    P = V[quad]
    E = np.roll(P, -1, axis=1) - P  # E_i = P_{i+1} - P_i
    Ep = np.roll(E, 1, axis=1)  # E_{i-1}
    turn = (np.cross(Ep, E) * N[fa][:, None, :]).sum(axis=2)
    le = np.linalg.norm(E, axis=2)
    sin = turn / np.maximum(le * np.roll(le, 1, axis=1), 1e-300)
    convex = (sin > 1e-6).all(axis=1)
    quad, fa, fb, ka, kb, ka1, ka2, kb2 = (x[convex] for x in (quad, fa, fb, ka, kb, ka1, ka2, kb2))
    score = sin[convex].min(axis=1)

    # greedy matching: a candidate wins when it ranks best at both of its faces
    m = len(quad)
    rng = np.random.default_rng(0)
    order = np.lexsort((rng.random(m), -np.round(score, 3)))
    rank = np.empty(m, dtype=np.int64)
    rank[order] = np.arange(m)
    matched = np.zeros(nf, dtype=bool)
    active = np.ones(m, dtype=bool)
    chosen = []
    best = np.full(nf, m, dtype=np.int64)
    while True:
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        best[fa[idx]] = m
        best[fb[idx]] = m
        np.minimum.at(best, fa[idx], rank[idx])
        np.minimum.at(best, fb[idx], rank[idx])
        r = rank[idx]
        win = idx[(best[fa[idx]] == r) & (best[fb[idx]] == r)]
        chosen.append(win)
        matched[fa[win]] = True
        matched[fb[win]] = True
        active[idx] = ~(matched[fa[idx]] | matched[fb[idx]])
    win = np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)

    qa, qb = fa[win], fb[win]
    q_corners = quad[win]
    q_uv = np.stack([UV[qa, ka1[win]], UV[qa, ka2[win]], UV[qa, ka[win]], UV[qb, kb2[win]]], axis=1)
    tri = np.flatnonzero(~matched)
    t_corners = np.concatenate([F[tri], np.full((len(tri), 1), -1, dtype=np.int64)], axis=1)
    t_uv = np.concatenate([UV[tri], UV[tri][:, 2:3]], axis=1)

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
    ``k = ceil(log2(longest edge / max_edge))``. Materials are copied and UVs
    interpolated; new vertices are welded to their neighbours.

    Returns (vertices, patch_corners, patch_material, patch_uv), children in
    place of their parent.
    """
    if not (max_edge > 0 and np.isfinite(max_edge)):
        raise OptionError(f"max_edge must be a positive number, got {max_edge!r}")
    V = np.asarray(vertices, dtype=np.float64)
    C = np.asarray(patch_corners, dtype=np.int64).reshape(-1, 4)
    Mat = np.asarray(patch_material, dtype=np.int64).reshape(-1)
    UV = np.asarray(patch_uv, dtype=np.float64).reshape(-1, 4, 2)
    p = len(C)
    is_quad = C[:, 3] >= 0
    C3 = np.where(is_quad, C[:, 3], C[:, 2])
    P = V[np.stack([C[:, 0], C[:, 1], C[:, 2], C3], axis=1)]

    new_pos, new_uv, new_mat, new_parent = [], [], [], []

    # quads
    q = np.flatnonzero(is_quad)
    c = P[q]
    length = lambda a, b: np.linalg.norm(c[:, b] - c[:, a], axis=1)  # noqa: E731
    n = np.maximum(np.ceil(np.maximum(length(0, 1), length(3, 2)) / max_edge), 1).astype(np.int64)
    m = np.maximum(np.ceil(np.maximum(length(0, 3), length(1, 2)) / max_edge), 1).astype(np.int64)
    sq = (n > 1) | (m > 1)
    q, c, n, m = q[sq], c[sq], n[sq], m[sq]
    if len(q):
        cnt = n * m
        pid = np.repeat(np.arange(len(q)), cnt)
        local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        nn, mm = n[pid], m[pid]
        a, b = local % nn, local // nn
        us = np.stack([a, a + 1, a + 1, a], axis=1) / nn[:, None]
        vs = np.stack([b, b, b + 1, b + 1], axis=1) / mm[:, None]
        w = np.stack(
            [(1 - us) * (1 - vs), us * (1 - vs), us * vs, (1 - us) * vs], axis=2
        )  # (k, 4 corners, 4 weights)
        new_pos.append(np.einsum("kcw,kwd->kcd", w, c[pid]))
        new_uv.append(np.einsum("kcw,kwd->kcd", w, UV[q][pid]))
        new_mat.append(Mat[q][pid])
        new_parent.append(q[pid])

    # triangles
    t = np.flatnonzero(~is_quad)
    c = P[t][:, :3]
    longest = np.max([np.linalg.norm(c[:, (i + 1) % 3] - c[:, i], axis=1) for i in range(3)], axis=0)
    with np.errstate(divide="ignore"):
        k = np.ceil(np.log2(np.maximum(longest, 1e-300) / max_edge))
    k = np.maximum(k, 0).astype(np.int64)
    for level in np.unique(k[k > 0]):
        sel = t[k == level]
        cs = P[sel][:, :3]
        N = 1 << int(level)
        i, j = np.meshgrid(np.arange(N), np.arange(N), indexing="ij")
        up = (i + j) <= N - 1
        dn = (i + j) <= N - 2
        iu, ju, idn, jdn = i[up], j[up], i[dn], j[dn]
        # (s, 3) lattice corners of each sub-triangle; the down ones keep the parent's winding
        ci = np.concatenate([np.stack([iu, iu + 1, iu], 1), np.stack([idn + 1, idn, idn + 1], 1)])
        cj = np.concatenate([np.stack([ju, ju, ju + 1], 1), np.stack([jdn + 1, jdn + 1, jdn], 1)])
        u, v = ci / N, cj / N
        w = np.stack([1 - u - v, u, v], axis=2)  # (s, 3, 3)
        s = len(ci)
        pos = np.einsum("scw,twd->tscd", w, cs).reshape(-1, 3, 3)
        uvs = np.einsum("scw,twd->tscd", w, UV[sel][:, :3]).reshape(-1, 3, 2)
        new_pos.append(np.concatenate([pos, pos[:, 2:3]], axis=1))
        new_uv.append(np.concatenate([uvs, uvs[:, 2:3]], axis=1))
        new_mat.append(np.repeat(Mat[sel], s))
        new_parent.append(np.repeat(sel, s))
    if not new_pos:
        return V, C, Mat, UV

    split = np.zeros(p, dtype=bool)
    split[np.concatenate(new_parent)] = True
    keep = np.flatnonzero(~split)
    pos = np.concatenate(new_pos)
    k_new = len(pos)
    new_is_quad = np.concatenate(
        [np.ones(len(x), dtype=bool) for x in new_pos[: 1 if len(q) else 0]]
        + [np.zeros(len(x), dtype=bool) for x in new_pos[1 if len(q) else 0 :]]
    )
    idx = len(V) + np.arange(k_new * 4).reshape(k_new, 4)
    idx[~new_is_quad, 3] = -1
    allV = np.concatenate([V, pos.reshape(-1, 3)])
    corners = np.concatenate([C[keep], idx])
    material = np.concatenate([Mat[keep], np.concatenate(new_mat)])
    uv = np.concatenate([UV[keep], np.concatenate(new_uv)])
    parent = np.concatenate([keep, np.concatenate(new_parent)])
    o = np.argsort(parent, kind="stable")
    corners, material, uv = corners[o], material[o], uv[o]
    allV, corners = weld_vertices(allV, corners)
    return allV, corners, material, uv


def load_scene(path: str | Path, max_edge: float | None = None) -> Scene:
    """Load a model file (glTF/GLB, OBJ+MTL, PLY, STL, OFF) into a :class:`Scene`.

    Geometry is read by trimesh (each node's transform applied here, winding
    flipped under mirroring), vertices are welded, zero-area triangles dropped,
    and coplanar triangle pairs merged back into quads (:func:`merge_quads`).
    glTF materials, ``KHR_lights_punctual`` lights, cameras and the
    ``iat_camera_paths`` root extras are read with pygltflib.

    max_edge : pre-split patches longer than this (scene units) into a regular grid
      (:func:`split_patches`); None keeps the root patches as they are.
    Raises :class:`iat.errors.LoadError` naming the file and the cause.
    """
    path = Path(path)
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

    gl = _Gltf(path) if ext in (".gltf", ".glb") else None
    if ext == ".obj":
        _check_obj_textures(path)
    tscene = _load_trimesh(path, ext)
    V, F, M, UV, materials = _collect(tscene, path, gl)

    V, F = weld_vertices(V, F)
    bad = degenerate_faces(V, F)
    if bad.all():
        raise LoadError("only degenerate faces", path)
    if bad.any():
        log.info("%s: dropped %d zero-area faces of %d", path, int(bad.sum()), len(F))
        F, M, UV = F[~bad], M[~bad], UV[~bad]
    corners, pmat, puv = merge_quads(V, F, M, UV)
    if max_edge is not None:
        V, corners, pmat, puv = split_patches(V, corners, pmat, puv, max_edge)
    V, corners = weld_vertices(V, corners)  # compact to the vertices in use

    scene = Scene(
        vertices=V,
        patch_corners=corners,
        patch_material=pmat,
        materials=materials,
        patch_uv=puv,
        path=str(path),
    )
    if gl is not None:
        world = gl.node_world()
        scene.lights = gl.lights(world)
        scene.cameras = gl.cameras(world, scene.bounds)
        scene.camera_paths = gl.camera_paths()
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

    Covers vertices, patch corners, patch materials and each material's albedo
    and emission (not names, lights' names, cameras or the path).
    """
    h = hashlib.sha1()
    h.update(b"iat-scene-v1")
    h.update(np.ascontiguousarray(scene.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_corners, dtype="<i8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_material, dtype="<i8").tobytes())
    for m in scene.materials:
        h.update(np.ascontiguousarray(m.albedo, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(m.emission, dtype="<f8").tobytes())
    return h.hexdigest()
