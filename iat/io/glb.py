"""A small glTF 2.0 binary (GLB) writer.

:class:`GlbBuilder` collects meshes, materials (with optional embedded PNG base
colour textures), cameras and ``KHR_lights_punctual`` lights, and writes one
self-contained ``.glb``. The JSON and the binary chunk are built by hand so the
output is byte-for-byte deterministic: the same calls give the same bytes (no
timestamps, no dictionary-order surprises). pygltflib's writer is not used: it orders
the JSON keys by its own dataclass fields and always writes a BIN chunk, so the
committed sample models would change.

Conventions
-----------
- Right-handed, +Y up, metres (glTF). Every array is little-endian.
- Colours are linear RGB. ``emissive`` is radiance: a value above 1 is written
  as ``emissiveFactor`` normalised to a maximum of 1 plus
  ``KHR_materials_emissive_strength`` equal to that maximum.
- Matrices given to :meth:`GlbBuilder.add_node` are ``(4, 4)`` row-major math
  matrices (column vectors, as :mod:`iat.camera`); they are stored column-major
  as glTF wants.
- Quaternions are ``(x, y, z, w)`` (glTF order).
- Cameras look down their local -Z with +Y up; spot lights point down local -Z.

Each accessor gets its own buffer view (4-byte aligned), so no ``byteStride`` is
needed. Only the extensions actually used are listed in ``extensionsUsed``;
none is required.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

from iat.camera import Camera

__all__ = ["GlbBuilder", "quat_from_matrix", "quat_to_matrix", "look_rotation"]

# glTF enums
_FLOAT = 5126
_UINT = 5125
_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_LINEAR = 9729
_LINEAR_MIPMAP_LINEAR = 9987
_REPEAT = 10497
_TRIANGLES = 4

_GLB_MAGIC = 0x46546C67  # "glTF"
_CHUNK_JSON = 0x4E4F534A  # "JSON"
_CHUNK_BIN = 0x004E4942  # "BIN\0"

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

EXT_EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"
EXT_UNLIT = "KHR_materials_unlit"
EXT_TRANSMISSION = "KHR_materials_transmission"
EXT_LIGHTS = "KHR_lights_punctual"


# -- small math helpers ----------------------------------------------------------------------------


def quat_from_matrix(r: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(4,) float64`` in (x, y, z, w) order of a ``(3, 3)`` rotation matrix.

    The sign is fixed so that ``w >= 0`` (deterministic output).
    """
    m = np.asarray(r, dtype=np.float64).reshape(3, 3)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q, dtype=np.float64)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def quat_to_matrix(q) -> np.ndarray:
    """``(3, 3) float64`` rotation matrix of a quaternion ``(x, y, z, w)`` (normalised here)."""
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


def look_rotation(forward, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """``(3, 3) float64`` rotation whose local -Z maps to ``forward`` and local +Y leans to ``up``.

    Columns are the local axes in world space: (right, true up, -forward). When
    ``forward`` is parallel to ``up`` another perpendicular is picked.
    """
    f = np.asarray(forward, dtype=np.float64).reshape(3)
    nf = np.linalg.norm(f)
    if not np.isfinite(nf) or nf < 1e-300:
        raise ValueError("look_rotation: zero or non-finite direction")
    f = f / nf
    s = np.cross(f, np.asarray(up, dtype=np.float64).reshape(3))
    if np.linalg.norm(s) < 1e-9:
        s = np.cross(f, [1.0, 0.0, 0.0] if abs(f[0]) < 0.9 else [0.0, 0.0, 1.0])
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    return np.column_stack([s, u, -f])


def _floats(values, n: int | None = None, what: str = "value") -> list[float]:
    """Plain Python floats (finite) from a sequence, optionally checking its length."""
    a = np.asarray(values, dtype=np.float64).reshape(-1)
    if n is not None and a.size != n:
        raise ValueError(f"{what}: expected {n} numbers, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what}: non-finite number")
    return [float(x) for x in a]


def _json_default(o: Any):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"glb: cannot write {type(o).__name__} as JSON")


class GlbBuilder:
    """Build a glTF 2.0 binary file in memory, then :meth:`to_bytes` or :meth:`write` it.

    Every ``add_*`` method returns the index of what it created (material, mesh,
    node, camera index; the light helpers return the index of the *node* that
    carries the light). Nodes that are nobody's child are the roots of the one
    scene, in creation order.

    Attributes
    ----------
    extras : dict
        JSON-serialisable data written as the root ``extras`` (for example
        ``{"iat_camera_paths": {...}}``). Numpy arrays and scalars are converted.
    generator : str
        ``asset.generator``; constant by default so output stays deterministic.
    """

    def __init__(self, generator: str = "IAT iat.glb"):
        self.generator = generator
        self.extras: dict = {}
        self._bin = bytearray()
        self._buffer_views: list[dict] = []
        self._accessors: list[dict] = []
        self._images: list[dict] = []
        self._textures: list[dict] = []
        self._samplers: list[dict] = []
        self._materials: list[dict] = []
        self._meshes: list[dict] = []
        self._nodes: list[dict] = []
        self._cameras: list[dict] = []
        self._lights: list[dict] = []
        self._extensions_used: set[str] = set()
        self._material_texcoord: list[int | None] = []  # texCoord used by each material's texture

    # -- binary data --------------------------------------------------------------------------------
    def _add_view(self, data: bytes, target: int | None = None) -> int:
        while len(self._bin) % 4:
            self._bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self._bin), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self._bin.extend(data)
        self._buffer_views.append(view)
        return len(self._buffer_views) - 1

    def _add_accessor(
        self, array: np.ndarray, kind: str, target: int | None, with_bounds: bool = False
    ) -> int:
        """One accessor + buffer view for a ``(n,)`` or ``(n, k)`` float32/uint32 array."""
        if array.dtype == np.float32:
            ctype, le = _FLOAT, array.astype("<f4", copy=False)
        elif array.dtype == np.uint32:
            ctype, le = _UINT, array.astype("<u4", copy=False)
        else:  # pragma: no cover - callers convert first
            raise ValueError(f"glb: unsupported dtype {array.dtype}")
        view = self._add_view(np.ascontiguousarray(le).tobytes(), target)
        acc = {"bufferView": view, "componentType": ctype, "count": int(array.shape[0]), "type": kind}
        if with_bounds:
            acc["min"] = [float(x) for x in array.min(axis=0)]
            acc["max"] = [float(x) for x in array.max(axis=0)]
        self._accessors.append(acc)
        return len(self._accessors) - 1

    # -- materials ----------------------------------------------------------------------------------
    def add_material(
        self,
        name: str,
        base_color=(1.0, 1.0, 1.0, 1.0),
        emissive=(0.0, 0.0, 0.0),
        base_color_png: bytes | None = None,
        unlit: bool = False,
        double_sided: bool = False,
        base_color_texcoord: int = 0,
        transmission: float = 0.0,
    ) -> int:
        """Add a diffuse material (metallic 0, roughness 1); returns its index.

        base_color : (3,) or (4,) linear RGB(A) in [0, 1] (``baseColorFactor``; alpha 1 if omitted)
        emissive : (3,) emitted radiance, linear RGB, >= 0. Written as ``emissiveFactor`` and, when
            its maximum exceeds 1, ``emissiveFactor / max`` plus ``KHR_materials_emissive_strength = max``.
        base_color_png : PNG file bytes embedded as the ``baseColorTexture`` (repeat wrap, trilinear
            mipmap filtering), read with ``TEXCOORD_<base_color_texcoord>`` (0 or 1).
        unlit : add ``KHR_materials_unlit`` (viewers show the base colour as is).
        double_sided : glTF ``doubleSided``.
        transmission : in [0, 1]; above 0 the material is thin glass passing that fraction of the
            light (``KHR_materials_transmission`` ``transmissionFactor``).
        """
        bc = _floats(base_color, what=f"material {name!r} base_color")
        if len(bc) == 3:
            bc.append(1.0)
        if len(bc) != 4:
            raise ValueError(f"material {name!r} base_color: expected 3 or 4 numbers")
        if min(bc) < 0.0 or max(bc) > 1.0:
            raise ValueError(f"material {name!r} base_color: values must be in [0, 1]")
        em = _floats(emissive, 3, what=f"material {name!r} emissive")
        if min(em) < 0.0:
            raise ValueError(f"material {name!r} emissive: negative radiance")
        if base_color_texcoord not in (0, 1):
            raise ValueError(f"material {name!r}: base_color_texcoord must be 0 or 1")
        if not 0.0 <= float(transmission) <= 1.0:
            raise ValueError(f"material {name!r}: transmission must be in [0, 1]")

        pbr: dict = {"baseColorFactor": bc, "metallicFactor": 0.0, "roughnessFactor": 1.0}
        mat: dict = {"name": str(name), "pbrMetallicRoughness": pbr}
        extensions: dict = {}
        peak = max(em)
        if peak > 1.0:
            mat["emissiveFactor"] = [e / peak for e in em]
            extensions[EXT_EMISSIVE_STRENGTH] = {"emissiveStrength": peak}
            self._extensions_used.add(EXT_EMISSIVE_STRENGTH)
        elif peak > 0.0:
            mat["emissiveFactor"] = em
        if unlit:
            extensions[EXT_UNLIT] = {}
            self._extensions_used.add(EXT_UNLIT)
        if transmission > 0.0:
            extensions[EXT_TRANSMISSION] = {"transmissionFactor": float(transmission)}
            self._extensions_used.add(EXT_TRANSMISSION)
        if base_color_png is not None:
            tex = self._add_png_texture(bytes(base_color_png), name)
            info = {"index": tex}
            if base_color_texcoord:
                info["texCoord"] = base_color_texcoord
            pbr["baseColorTexture"] = info
            self._material_texcoord.append(base_color_texcoord)
        else:
            self._material_texcoord.append(None)
        if double_sided:
            mat["doubleSided"] = True
        if extensions:
            mat["extensions"] = extensions
        self._materials.append(mat)
        return len(self._materials) - 1

    def _add_png_texture(self, png: bytes, name: str) -> int:
        if not png.startswith(_PNG_SIGNATURE):
            raise ValueError(f"material {name!r}: base_color_png is not PNG data")
        view = self._add_view(png)
        self._images.append({"name": str(name), "bufferView": view, "mimeType": "image/png"})
        if not self._samplers:
            self._samplers.append(
                {"magFilter": _LINEAR, "minFilter": _LINEAR_MIPMAP_LINEAR, "wrapS": _REPEAT, "wrapT": _REPEAT}
            )
        self._textures.append({"sampler": 0, "source": len(self._images) - 1})
        return len(self._textures) - 1

    # -- meshes -------------------------------------------------------------------------------------
    def add_mesh(
        self,
        name: str,
        positions,
        indices,
        material: int | None = None,
        normals=None,
        uv0=None,
        uv1=None,
        colors=None,
    ) -> int:
        """Add a mesh of one indexed triangle primitive; returns its index.

        positions : (n, 3) float32 (converted), finite, n >= 1
        indices : (m, 3) uint32 (converted) triangle corners, m >= 1, each < n
        material : index from :meth:`add_material`, or None for the glTF default
        normals : (n, 3) float32, normalised here (must be non-zero)
        uv0, uv1 : (n, 2) float32 ``TEXCOORD_0`` / ``TEXCOORD_1``
        colors : (n, 3) or (n, 4) float32 ``COLOR_0`` (linear)
        """
        pos = self._vertex_array(name, "positions", positions, (3,))
        n = pos.shape[0]
        if n == 0:
            raise ValueError(f"mesh {name!r}: no vertices")
        idx = np.asarray(indices)
        if idx.ndim != 2 or idx.shape[1] != 3 or idx.shape[0] == 0:
            raise ValueError(f"mesh {name!r}: indices must have shape (m, 3) with m >= 1, got {idx.shape}")
        if not np.issubdtype(idx.dtype, np.integer):
            raise ValueError(f"mesh {name!r}: indices must be integers")
        if idx.min() < 0 or idx.max() >= n:
            raise ValueError(f"mesh {name!r}: index out of range [0, {n})")
        idx = idx.astype(np.uint32).reshape(-1)

        if material is not None:
            if not 0 <= int(material) < len(self._materials):
                raise ValueError(f"mesh {name!r}: no material {material}")
            texcoord = self._material_texcoord[int(material)]
            if texcoord is not None and (uv0, uv1)[texcoord] is None:
                raise ValueError(f"mesh {name!r}: material {material} needs TEXCOORD_{texcoord}")

        attributes = {"POSITION": self._add_accessor(pos, "VEC3", _ARRAY_BUFFER, with_bounds=True)}
        if normals is not None:
            nrm = self._vertex_array(name, "normals", normals, (3,), n).astype(np.float64)
            length = np.linalg.norm(nrm, axis=1, keepdims=True)
            if np.any(length < 1e-12):
                raise ValueError(f"mesh {name!r}: zero normal")
            attributes["NORMAL"] = self._add_accessor(
                (nrm / length).astype(np.float32), "VEC3", _ARRAY_BUFFER
            )
        for key, uv in (("TEXCOORD_0", uv0), ("TEXCOORD_1", uv1)):
            if uv is not None:
                a = self._vertex_array(name, key, uv, (2,), n)
                attributes[key] = self._add_accessor(a, "VEC2", _ARRAY_BUFFER)
        if colors is not None:
            c = self._vertex_array(name, "colors", colors, (3, 4), n)
            attributes["COLOR_0"] = self._add_accessor(
                c, "VEC3" if c.shape[1] == 3 else "VEC4", _ARRAY_BUFFER
            )

        prim: dict = {
            "attributes": attributes,
            "indices": self._add_accessor(idx, "SCALAR", _ELEMENT_ARRAY_BUFFER),
            "mode": _TRIANGLES,
        }
        if material is not None:
            prim["material"] = int(material)
        self._meshes.append({"name": str(name), "primitives": [prim]})
        return len(self._meshes) - 1

    @staticmethod
    def _vertex_array(name, what, values, widths, n=None) -> np.ndarray:
        a = np.asarray(values, dtype=np.float32)
        if a.ndim != 2 or a.shape[1] not in widths:
            raise ValueError(
                f"mesh {name!r}: {what} must have shape (n, {'|'.join(map(str, widths))}), got {a.shape}"
            )
        if n is not None and a.shape[0] != n:
            raise ValueError(f"mesh {name!r}: {what} has {a.shape[0]} rows, positions have {n}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"mesh {name!r}: non-finite {what}")
        return np.ascontiguousarray(a)

    # -- nodes, cameras, lights ---------------------------------------------------------------------
    def add_node(
        self,
        name: str,
        mesh: int | None = None,
        translation=None,
        rotation=None,
        matrix=None,
        camera: int | None = None,
        light: int | None = None,
        children=None,
    ) -> int:
        """Add a node; returns its index.

        translation : (3,) scene units
        rotation : (4,) quaternion (x, y, z, w), normalised here
        matrix : (4, 4) row-major affine transform (exclusive with translation/rotation)
        camera, light : indices from :meth:`add_camera` / :meth:`add_light`
        children : node indices (each node may have one parent only)
        """
        node: dict = {"name": str(name)}
        if matrix is not None and (translation is not None or rotation is not None):
            raise ValueError(f"node {name!r}: give either matrix or translation/rotation")
        if camera is not None:
            if not 0 <= int(camera) < len(self._cameras):
                raise ValueError(f"node {name!r}: no camera {camera}")
            node["camera"] = int(camera)
        if children:
            kids = [int(c) for c in children]
            if any(not 0 <= c < len(self._nodes) for c in kids) or len(set(kids)) != len(kids):
                raise ValueError(f"node {name!r}: bad children {kids}")
            node["children"] = kids
        if matrix is not None:
            m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
            node["matrix"] = _floats(m.T, 16, what=f"node {name!r} matrix")  # column-major
        if mesh is not None:
            if not 0 <= int(mesh) < len(self._meshes):
                raise ValueError(f"node {name!r}: no mesh {mesh}")
            node["mesh"] = int(mesh)
        if rotation is not None:
            q = np.asarray(_floats(rotation, 4, what=f"node {name!r} rotation"))
            nq = np.linalg.norm(q)
            if nq < 1e-12:
                raise ValueError(f"node {name!r}: zero quaternion")
            # rounded: the last bits of a normalised quaternion differ between CPUs (SIMD paths)
            node["rotation"] = [round(float(x), 12) for x in q / nq]
        if translation is not None:
            node["translation"] = _floats(translation, 3, what=f"node {name!r} translation")
        if light is not None:
            if not 0 <= int(light) < len(self._lights):
                raise ValueError(f"node {name!r}: no light {light}")
            node["extensions"] = {EXT_LIGHTS: {"light": int(light)}}
        self._nodes.append(node)
        return len(self._nodes) - 1

    def add_camera(
        self, name: str, yfov_deg: float, znear: float, zfar: float | None = None, aspect: float | None = None
    ) -> int:
        """Add a perspective camera; returns its index.

        yfov_deg : vertical field of view in degrees, in (0, 180)
        znear, zfar : clip distances (scene units), 0 < znear < zfar; zfar None means infinite
        aspect : width / height, or None to let the viewer use its own
        """
        if not 0.0 < float(yfov_deg) < 180.0:
            raise ValueError(f"camera {name!r}: yfov must be in (0, 180) degrees")
        if not float(znear) > 0.0 or (zfar is not None and not float(zfar) > float(znear)):
            raise ValueError(f"camera {name!r}: need 0 < znear < zfar")
        persp: dict = {"yfov": float(np.radians(float(yfov_deg))), "znear": float(znear)}
        if zfar is not None:
            persp["zfar"] = float(zfar)
        if aspect is not None:
            if not float(aspect) > 0.0:
                raise ValueError(f"camera {name!r}: aspect must be > 0")
            persp["aspectRatio"] = float(aspect)
        self._cameras.append({"name": str(name), "type": "perspective", "perspective": persp})
        return len(self._cameras) - 1

    def add_camera_node(self, camera: Camera, aspect: float | None = None, name: str | None = None) -> int:
        """Add a camera and the node that places it from an :class:`iat.camera.Camera`.

        The node sits at ``camera.eye`` and is rotated so its local -Z points from the
        eye to the target and its local +Y is the camera's up (made orthogonal).
        Returns the node index.
        """
        label = name if name is not None else (camera.name or f"camera_{len(self._cameras)}")
        cam = self.add_camera(label, camera.yfov, camera.znear, camera.zfar, aspect)
        rot = quat_from_matrix(look_rotation(camera.target - camera.eye, camera.up))
        return self.add_node(label, camera=cam, translation=camera.eye, rotation=rot)

    def add_light(
        self,
        name: str,
        kind: str,
        color=(1.0, 1.0, 1.0),
        intensity: float = 1.0,
        light_range: float | None = None,
        inner: float = 0.0,
        outer: float = np.pi / 4,
    ) -> int:
        """Add a ``KHR_lights_punctual`` light (not placed); returns its light index.

        kind : "point", "spot" or "directional"
        color : (3,) linear RGB; intensity : candela (point/spot) or lux (directional), >= 0
        light_range : glTF ``range`` cut-off distance (scene units), or None for infinite
        inner, outer : spot cone half-angles in radians, 0 <= inner < outer <= pi/2
        """
        if kind not in ("point", "spot", "directional"):
            raise ValueError(f"light {name!r}: unknown kind {kind!r}")
        if not float(intensity) >= 0.0:
            raise ValueError(f"light {name!r}: intensity must be >= 0")
        light: dict = {
            "name": str(name),
            "type": kind,
            "color": _floats(color, 3, what=f"light {name!r} color"),
            "intensity": float(intensity),
        }
        if light_range is not None:
            if not float(light_range) > 0.0:
                raise ValueError(f"light {name!r}: range must be > 0")
            light["range"] = float(light_range)
        if kind == "spot":
            if not 0.0 <= float(inner) < float(outer) <= np.pi / 2:
                raise ValueError(f"light {name!r}: need 0 <= inner < outer <= pi/2 (radians)")
            light["spot"] = {"innerConeAngle": float(inner), "outerConeAngle": float(outer)}
        self._lights.append(light)
        self._extensions_used.add(EXT_LIGHTS)
        return len(self._lights) - 1

    def add_point_light(self, name: str, color, intensity: float, position) -> int:
        """Add a point light and a node at ``position`` (3,); returns the node index."""
        light = self.add_light(name, "point", color, intensity)
        return self.add_node(name, light=light, translation=position)

    def add_spot_light(
        self, name: str, color, intensity: float, position, direction, inner: float, outer: float
    ) -> int:
        """Add a spot light and its node; returns the node index.

        position : (3,); direction : (3,) world vector the cone points along (normalised here)
        inner, outer : cone half-angles in radians
        """
        light = self.add_light(name, "spot", color, intensity, inner=inner, outer=outer)
        rot = quat_from_matrix(look_rotation(direction))
        return self.add_node(name, light=light, translation=position, rotation=rot)

    def add_directional_light(
        self, name: str, color, intensity: float, direction, angular_diameter_deg: float | None = None
    ) -> int:
        """Add a directional light (a sun) and its node; returns the node index.

        intensity : lux, read as W/m² per unit colour; direction : (3,) world vector the light
        travels along; angular_diameter_deg : the disc's diameter, degrees (``extras``; None: the
        reader's default)
        """
        light = self.add_light(name, "directional", color, intensity)
        if angular_diameter_deg is not None:
            self._lights[light]["extras"] = {"angular_diameter": float(angular_diameter_deg)}
        rot = quat_from_matrix(look_rotation(direction))
        return self.add_node(name, light=light, rotation=rot)

    # -- output -------------------------------------------------------------------------------------
    def to_json(self) -> dict:
        """The glTF JSON document (a fresh dict each call)."""
        doc: dict = {"asset": {"version": "2.0", "generator": self.generator}}
        if self._extensions_used:
            doc["extensionsUsed"] = sorted(self._extensions_used)
        if self._nodes:
            parent: dict[int, int] = {}
            for i, node in enumerate(self._nodes):
                for c in node.get("children", ()):
                    if c in parent:
                        raise ValueError(f"node {c} has two parents ({parent[c]} and {i})")
                    parent[c] = i
            doc["scene"] = 0
            doc["scenes"] = [{"nodes": [i for i in range(len(self._nodes)) if i not in parent]}]
            doc["nodes"] = self._nodes
        for key, items in (
            ("meshes", self._meshes),
            ("materials", self._materials),
            ("cameras", self._cameras),
            ("textures", self._textures),
            ("images", self._images),
            ("samplers", self._samplers),
            ("accessors", self._accessors),
            ("bufferViews", self._buffer_views),
        ):
            if items:
                doc[key] = items
        if self._bin:
            doc["buffers"] = [{"byteLength": self._padded_bin_length()}]
        if self._lights:
            doc["extensions"] = {EXT_LIGHTS: {"lights": self._lights}}
        if self.extras:
            doc["extras"] = self.extras
        return json.loads(json.dumps(doc, default=_json_default, allow_nan=False))

    def _padded_bin_length(self) -> int:
        return (len(self._bin) + 3) // 4 * 4

    def to_bytes(self) -> bytes:
        """The complete GLB file: 12-byte header, JSON chunk (space padded), BIN chunk (zero padded).

        Raises ValueError if something cannot be written (e.g. NaN or an unknown type in extras).
        """
        try:
            text = json.dumps(self.to_json(), separators=(",", ":"), ensure_ascii=False, allow_nan=False)
        except TypeError as e:
            raise ValueError(str(e)) from e
        js = text.encode("utf-8")
        js += b" " * (-len(js) % 4)
        chunks = struct.pack("<II", len(js), _CHUNK_JSON) + js
        if self._bin:
            binary = bytes(self._bin) + b"\0" * (-len(self._bin) % 4)
            chunks += struct.pack("<II", len(binary), _CHUNK_BIN) + binary
        return struct.pack("<III", _GLB_MAGIC, 2, 12 + len(chunks)) + chunks

    def write(self, path: str | Path) -> Path:
        """Write the GLB to ``path`` atomically; returns the path.

        The bytes go to a temporary file ``.<name>.<random>.tmp`` in the same directory, which
        is flushed, fsynced and then renamed over ``path`` (``os.replace``), by
        :func:`iat.fsutil.atomic_write`. On any error the previous file at ``path`` is left
        untouched and the temporary file removed; stale temporaries of killed writers (older
        than an hour) are removed after a successful write.
        """
        from iat.fsutil import atomic_write

        data = self.to_bytes()  # serialisation errors happen before anything touches the disk
        return atomic_write(path, lambda f: f.write(data), make_parents=False)
