"""glTF documents read with pygltflib: the parts trimesh drops or changes.

:class:`GltfDocument` opens a ``.gltf`` / ``.glb`` (buffers and images from the
GLB binary chunk, data URIs or files next to it) and reads materials
(``albedo = baseColorFactor x mean(baseColorTexture)``, ``emission =
emissiveFactor x emissiveStrength``), the node tree (:meth:`GltfDocument.node_world`,
world matrices ``(4, 4)`` float64 for column vectors), the mesh instances matched to
trimesh's geometry, ``KHR_lights_punctual`` point and spot lights, perspective
cameras and the ``iat_camera_paths`` root extras. :func:`local_matrix` is one node's
``parent_from_node``.
"""

from __future__ import annotations

import base64
import logging
import urllib.parse
from pathlib import Path

import numpy as np

from iat.camera import Camera
from iat.color import LUMINANCE_WEIGHTS, LUMINOUS_EFFICACY
from iat.errors import LoadError, OptionError
from iat.io.glb import quat_to_matrix
from iat.io.gltf_primitives import check_primitives, check_version, convert_primitives
from iat.io.ies import read_ies
from iat.io.images import decode_texture
from iat.io.messages import one_line
from iat.io.scene import Light, Material, Scene, Sky

#: root extras key of a model's sky (the daylight it is lit by with no lighting state chosen)
SKY_KEY = "iat_sky"

log = logging.getLogger(__name__)


def _get(obj, key, default=None):
    """Attribute or dict item (pygltflib leaves extensions as dicts)."""
    if obj is None:
        return default
    if isinstance(obj, dict):
        v = obj.get(key, default)
    else:
        v = getattr(obj, key, default)
    return default if v is None else v


def local_matrix(node) -> np.ndarray:
    """(4, 4) float64 parent_from_node of a pygltflib node."""
    if node.matrix is not None:
        return np.array(node.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    if node.scale is not None:
        m = np.diag([*map(float, node.scale), 1.0]) @ m
    if node.rotation is not None:
        r = np.eye(4)
        r[:3, :3] = quat_to_matrix(node.rotation)
        m = r @ m
    if node.translation is not None:
        t = np.eye(4)
        t[:3, 3] = np.asarray(node.translation, dtype=np.float64)
        m = t @ m
    return m


#: a material of alphaMode BLEND with less alpha than this is glass (transmittance 1 - alpha)
GLASS_ALPHA = 0.5


class GltfDocument:
    """A glTF file opened with pygltflib (``doc``); raises :class:`iat.errors.LoadError` for an
    unparsable file, a glTF version other than 2, a missing buffer or texture file, or
    inconsistent accessors (:mod:`iat.io.gltf_primitives`)."""

    def __init__(self, path: Path):
        import pygltflib

        self.path = path
        self.base = path.parent
        check_version(path)
        try:
            doc = pygltflib.GLTF2().load(str(path))
        except Exception as e:  # noqa: BLE001 - pygltflib raises struct.error, JSONDecodeError, ...
            raise LoadError(f"cannot parse glTF (truncated or corrupt file): {one_line(e)}", path) from e
        if doc is None:
            raise LoadError("cannot parse glTF (truncated or corrupt file)", path)
        self.doc = doc
        self._buffers: dict[int, bytes] = {}
        self._material_cache: dict[int, Material] = {}
        self._check_external_files()
        check_primitives(self)
        #: the file as a GLB with fans and Draco primitives converted (``doc`` matches it), or None
        self.converted_glb = convert_primitives(self)
        if self.converted_glb is not None:
            self._buffers = {}

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

    def buffer(self, i: int) -> bytes:
        """The bytes of buffer ``i`` (the GLB chunk, a data URI or a file next to the glTF)."""
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
                data = self.buffer(v.buffer)[off : off + v.byteLength]
            elif im.uri:
                data = (
                    self._data_uri(im.uri)
                    if im.uri.startswith("data:")
                    else self._external(im.uri).read_bytes()
                )
            else:
                raise ValueError("image has neither uri nor bufferView")
        except (IndexError, ValueError, TypeError, OSError) as e:
            raise LoadError(f"cannot read texture image #{index} ({one_line(e)})", self.path) from e
        return decode_texture(data, self.path, what)

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
        # glass: KHR_materials_transmission, or a blended material mostly see-through
        transmission = float(
            _get(_get(m.extensions or {}, "KHR_materials_transmission"), "transmissionFactor", 0.0)
        )
        rgba = np.asarray(_get(pbr, "baseColorFactor", [1.0, 1.0, 1.0, 1.0]), dtype=np.float64).reshape(-1)
        alpha = float(rgba[3]) if len(rgba) > 3 else 1.0
        if m.alphaMode == "BLEND" and alpha < GLASS_ALPHA:
            transmission = max(transmission, 1.0 - alpha)
        mat = Material(
            name=m.name or f"material_{index}",
            albedo=albedo,  # clamped by load_scene, which warns
            emission=emission,
            detail=detail,
            transmission=float(np.clip(transmission, 0.0, 1.0)),
            double_sided=bool(m.doubleSided),
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
            m = parent @ local_matrix(nodes[i])
            world[i] = m
            stack.extend((c, m) for c in (nodes[i].children or []))
        return world

    def lights(self, world: dict[int, np.ndarray]) -> list[Light]:
        """``KHR_lights_punctual`` lights placed by ``world``: point and spot (candela read as
        W/sr), directional as a sun (lux read as W/m², a disc of ``extras.angular_diameter``
        degrees, default 0.53)."""
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
            if kind not in ("point", "spot", "directional"):
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
                    inner_cone=float(spot.get("innerConeAngle", 0.0)),
                    outer_cone=float(spot.get("outerConeAngle", np.pi / 4)),
                    name=name,
                    **_sun_disc(d),
                    **{"intensity": float(d.get("intensity", 1.0)), **_ies(d, self.base)},
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

    def sky(self) -> Sky | None:
        """The root ``extras["iat_sky"]`` (:meth:`iat.io.scene.Sky.from_spec`), or None; a malformed
        one is a LoadError naming the file."""
        extras = self.doc.extras if isinstance(self.doc.extras, dict) else {}
        try:
            return Sky.from_spec(extras.get(SKY_KEY))
        except OptionError as e:
            raise LoadError(f"{SKY_KEY}: {e}", self.path) from None

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
                        log.warning("%s: camera path %r ignored (%s)", self.path, name, one_line(e))
                return paths
        return {}


def _ies(d: dict, base: Path) -> dict:
    """A point or spot light whose ``extras.ies`` names an IES LM-63 file (relative to the glTF):
    ``{"ies": Photometry, "intensity": its peak candela in W/sr per unit colour}`` (the file's
    candela through the one conversion, times ``extras.ies_scale``, default 1), or {}."""
    extras = d.get("extras") or {}
    if d.get("type", "point") == "directional" or not extras.get("ies"):
        return {}
    ies = read_ies(base / str(extras["ies"]))
    y = float(np.asarray(d.get("color", [1.0, 1.0, 1.0]), dtype=np.float64)[:3] @ LUMINANCE_WEIGHTS)
    scale = float(extras.get("ies_scale", 1.0))
    return {"ies": ies, "intensity": scale * ies.peak / (LUMINOUS_EFFICACY * max(y, 1e-12))}


def _sun_disc(d: dict) -> dict:
    """``{"angular_diameter": radians}`` from a directional light's ``extras`` (degrees), or {}."""
    extras = d.get("extras") or {}
    if d.get("type") != "directional" or "angular_diameter" not in extras:
        return {}
    return {"angular_diameter": float(np.radians(float(extras["angular_diameter"])))}
