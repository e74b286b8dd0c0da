"""Model files built by hand for the loader tests: a small glTF writer on pygltflib (:class:`Gltf`),
the unit quad, text files, and the check that a load fails with a one-line LoadError."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from PIL import Image

from iat.errors import LoadError
from iat.io.load import load_scene

FLOAT, UINT32 = 5126, 5125


class Gltf:
    """Build a glTF document by hand: meshes, materials, nodes, lights, cameras, images."""

    def __init__(self):
        self.doc = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
        self.blob = bytearray()
        self.roots: list[int] = []

    def _view(self, data: bytes) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc.bufferViews.append(
            pygltflib.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data))
        )
        self.blob += data
        return len(self.doc.bufferViews) - 1

    def accessor(self, arr, kind: str, ctype: int) -> int:
        """A float32 (FLOAT) or uint32 (UINT32) accessor of ``arr`` on a new buffer view; its index."""
        arr = np.ascontiguousarray(arr, dtype=np.float32 if ctype == FLOAT else np.uint32)
        acc = pygltflib.Accessor(
            bufferView=self._view(arr.tobytes()), componentType=ctype, count=len(arr), type=kind
        )
        if kind == "VEC3" and np.isfinite(arr).all():
            acc.min = arr.min(axis=0).tolist()
            acc.max = arr.max(axis=0).tolist()
        self.doc.accessors.append(acc)
        return len(self.doc.accessors) - 1

    def mesh(self, positions, indices, material=None, uv=None, name=None) -> int:
        attrs = pygltflib.Attributes(
            POSITION=self.accessor(np.asarray(positions).reshape(-1, 3), "VEC3", FLOAT)
        )
        if uv is not None:
            attrs.TEXCOORD_0 = self.accessor(np.asarray(uv).reshape(-1, 2), "VEC2", FLOAT)
        prim = pygltflib.Primitive(
            attributes=attrs,
            indices=self.accessor(np.asarray(indices).ravel(), "SCALAR", UINT32),
            material=material,
        )
        self.doc.meshes.append(pygltflib.Mesh(primitives=[prim], name=name))
        return len(self.doc.meshes) - 1

    def material(
        self, base=(0.5, 0.5, 0.5, 1.0), emissive=None, strength=None, texture=None, name=None
    ) -> int:
        pbr = pygltflib.PbrMetallicRoughness(baseColorFactor=list(base))
        if texture is not None:
            pbr.baseColorTexture = pygltflib.TextureInfo(index=texture)
        m = pygltflib.Material(pbrMetallicRoughness=pbr, name=name)
        if emissive is not None:
            m.emissiveFactor = list(emissive)
        if strength is not None:
            m.extensions = {"KHR_materials_emissive_strength": {"emissiveStrength": strength}}
            self._use("KHR_materials_emissive_strength")
        self.doc.materials.append(m)
        return len(self.doc.materials) - 1

    def texture_png(self, rgb_uint8, uri: str | None = None) -> int:
        """A PNG texture, embedded in the buffer (uri None) or referenced as an external file."""
        if uri is None:
            buf = io.BytesIO()
            Image.fromarray(np.asarray(rgb_uint8, dtype=np.uint8), "RGB").save(buf, format="PNG")
            img = pygltflib.Image(bufferView=self._view(buf.getvalue()), mimeType="image/png")
        else:
            img = pygltflib.Image(uri=uri)
        self.doc.images.append(img)
        self.doc.textures.append(pygltflib.Texture(source=len(self.doc.images) - 1))
        return len(self.doc.textures) - 1

    def node(self, root=True, **kw) -> int:
        self.doc.nodes.append(pygltflib.Node(**kw))
        i = len(self.doc.nodes) - 1
        if root:
            self.roots.append(i)
        return i

    def _use(self, ext):
        if ext not in self.doc.extensionsUsed:
            self.doc.extensionsUsed.append(ext)

    def light(self, light: dict) -> int:
        self._use("KHR_lights_punctual")
        ext = self.doc.extensions.setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append(light)
        return len(ext["lights"]) - 1

    def camera(self, yfov, znear, zfar=None) -> int:
        self.doc.cameras.append(
            pygltflib.Camera(
                type="perspective", perspective=pygltflib.Perspective(yfov=yfov, znear=znear, zfar=zfar)
            )
        )
        return len(self.doc.cameras) - 1

    def save(self, path):
        path = str(path)
        self.doc.scenes = [pygltflib.Scene(nodes=self.roots)]
        self.doc.scene = 0
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        self.doc.buffers = [pygltflib.Buffer(byteLength=len(blob))]
        if path.endswith(".glb"):
            self.doc.set_binary_blob(blob)
            self.doc.save_binary(path)
        else:
            bin_name = path.rsplit("/", 1)[-1].replace(".gltf", ".bin")
            with open(path.replace(".gltf", ".bin"), "wb") as f:
                f.write(blob)
            self.doc.buffers[0].uri = bin_name
            self.doc.save_json(path)
        return Path(path)


ROOT = Path(__file__).resolve().parents[2]
QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)  # faces +Z
QUAD_TRIS = [[0, 1, 2], [2, 3, 0]]  # trimesh's own split of a quad


def quad_gltf(path, **material):
    g = Gltf()
    mat = g.material(**material) if material else None
    g.node(mesh=g.mesh(QUAD, QUAD_TRIS, material=mat))
    return g.save(path)


def write(path, text):
    path.write_text(text)
    return path


def assert_load_error(path, *words, **kw):
    with pytest.raises(LoadError) as ei:
        load_scene(path, **kw)
    msg = str(ei.value)
    assert "\n" not in msg
    assert path.name in msg
    for w in words:
        assert w in msg, msg
    return ei.value
