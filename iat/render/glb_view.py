"""Draw a GLB as :func:`iat.export.gltf.export_glb` writes it, with our own moderngl code.

This is the check that an exported file shows what the IAT renderer shows: it
reads the glTF with pygltflib (no trimesh) and draws every triangle
primitive **unlit**, as a glTF viewer does with ``KHR_materials_unlit``:

    colour = baseColorFactor x baseColorTexture(TEXCOORD_t) x COLOR_0
    radiance = colour x radiance_scale

- ``baseColorTexture`` is sRGB: uploaded as ``GL_SRGB8_ALPHA8`` so the GPU decodes
  before it filters (as every conforming viewer does).
- ``COLOR_0`` (VEC3 or VEC4, float or normalised integers) is linear; absent = 1.
- Sampler: ``magFilter`` / ``minFilter`` as stored (mipmaps built when the min
  filter asks for them), ``wrapS`` / ``wrapT`` CLAMP_TO_EDGE, REPEAT or
  MIRRORED_REPEAT (mirroring is folded in the shader). No sampler: LINEAR,
  LINEAR_MIPMAP_LINEAR, REPEAT.
- ``radiance_scale``: the material's ``extras.radiance_scale``, else the root's
  ``extras.iat.radiance_scale``, else 1 (a plain file is drawn as its colours).
- Layered export (material ``extras.iat_illumination = {index, texCoord,
  radiance_scale}``): the illumination texture is multiplied in, read with its
  own texture coordinate set; its ``radiance_scale`` wins.
- Node hierarchy (``matrix`` or TRS) is applied; cameras, lights, normals,
  emission and alpha are ignored (the exporter writes none that matter).

``render_glb(path, camera, size, ctx=None)`` returns ``(h, w, 3) float32`` linear
radiance (row 0 at the top), the same convention as :meth:`iat.render.renderer.Renderer.render`.
For several images of one file keep a :class:`GlbView`.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pygltflib import GLTF2

from iat.errors import LoadError, RenderError
from iat.render import gl

__all__ = ["GlbDocument", "GlbPrimitive", "GlbView", "is_iat_export", "load_glb", "render_glb"]

# glTF enums
_NEAREST, _LINEAR = 9728, 9729
_MIPMAP_MIN = {9984, 9985, 9986, 9987}
_CLAMP, _MIRROR, _REPEAT = 33071, 33648, 10497
_TRIANGLES = 4
_COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GL_SRGB8_ALPHA8 = 0x8C43


# -- reading (pure numpy, no GL) ---------------------------------------------------------------------
@dataclass
class GlbPrimitive:
    """One triangle primitive, in world space.

    positions : (n, 3) float32 world (node transforms applied)
    indices : (m, 3) uint32
    colors : (n, 4) float32 linear COLOR_0 (ones when absent)
    uv0, uv1 : (n, 2) float32 TEXCOORD_0 / TEXCOORD_1 (zeros when absent)
    factor : (4,) baseColorFactor
    base_texture, base_set : texture index of baseColorTexture (None) and its texCoord set
    ill_texture, ill_set : the layered export's illumination texture (None) and its set
    ill_rgbm : the illumination texture's RGBM range (``--hdr``: texel = sRGB-decoded rgb x alpha x
      this), 0 for a plain sRGB texture
    radiance_scale : colour x this = radiance
    material : material index or None; node : node name
    """

    positions: np.ndarray
    indices: np.ndarray
    colors: np.ndarray
    uv0: np.ndarray
    uv1: np.ndarray
    factor: np.ndarray
    base_texture: int | None
    base_set: int
    ill_texture: int | None
    ill_set: int
    ill_rgbm: float
    radiance_scale: float
    material: int | None
    node: str


@dataclass
class GlbDocument:
    """What :func:`load_glb` reads: primitives, decoded textures and samplers, root extras.

    textures : {texture index: dict(image=(h, w, 4) uint8 sRGB-encoded RGBA, min=, mag=, wrap_s=, wrap_t=)}
    """

    path: Path
    json: dict
    primitives: list[GlbPrimitive] = field(default_factory=list)
    textures: dict[int, dict] = field(default_factory=dict)

    @property
    def extras(self) -> dict:
        return self.json.get("extras") or {}

    @property
    def triangles(self) -> int:
        return int(sum(len(p.indices) for p in self.primitives))

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 min and max corner of all positions."""
        if not self.primitives:
            return np.zeros((2, 3))
        v = np.concatenate([p.positions for p in self.primitives]).astype(np.float64)
        return np.array([v.min(axis=0), v.max(axis=0)])

    def default_camera(self):
        """A camera framing the bounds from +Z (exported files carry no camera)."""
        from iat.camera import Camera

        lo, hi = self.bounds
        c = (lo + hi) / 2
        r = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
        return Camera(eye=c + np.array([0.0, 0.0, 2.2 * r]), target=c, yfov=50.0, znear=r * 0.01, zfar=r * 10)


def _read_glb(data: bytes, path: Path) -> tuple[dict, bytes]:
    """The JSON document (a dict, glTF defaults written out) and the BIN chunk (b"" when none) of a
    GLB's bytes, read with pygltflib."""
    if len(data) < 20:
        raise LoadError("not a GLB file (too short)", path)
    version = int.from_bytes(data[4:8], "little")
    if data[:4] == b"glTF" and version != 2:
        raise LoadError(f"GLB version {version}, only 2 is supported", path)
    # pygltflib reads chunks up to the header's length: a file cut short is read as far as it goes
    if int.from_bytes(data[8:12], "little") > len(data):
        data = data[:8] + len(data).to_bytes(4, "little") + data[12:]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # chunks of unknown type are skipped
            gltf = GLTF2.load_from_bytes(data)
    except OSError as e:  # pygltflib's "header does not appear to be valid glb format"
        raise LoadError("not a GLB file (bad magic)", path) from e
    except struct.error as e:
        raise LoadError(f"truncated GLB file: {e}", path) from e
    except AttributeError as e:  # a BIN chunk before the JSON chunk
        raise LoadError("GLB without a JSON chunk before its BIN chunk", path) from e
    if gltf is None:
        raise LoadError("GLB without a JSON chunk", path)
    return json.loads(gltf.to_json()), bytes(gltf.binary_blob() or b"")


def _buffers(doc: dict, binary: bytes, path: Path) -> list[bytes]:
    import base64

    out = []
    for i, b in enumerate(doc.get("buffers", [])):
        uri = b.get("uri")
        if uri is None:
            if i != 0:
                raise LoadError(f"buffer {i} has no uri", path)
            out.append(binary)
        elif uri.startswith("data:"):
            out.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            try:
                out.append((path.parent / uri).read_bytes())
            except OSError as e:
                raise LoadError(f"buffer {i}: cannot read {uri}: {e}", path) from e
    return out


def _view_bytes(doc: dict, bufs: list[bytes], v: int) -> tuple[bytes, int]:
    view = doc["bufferViews"][v]
    buf = bufs[view["buffer"]]
    start = view.get("byteOffset", 0)
    return buf[start : start + view["byteLength"]], int(view.get("byteStride", 0))


def _accessor(doc: dict, bufs: list[bytes], index: int, path: Path) -> np.ndarray:
    """(count, width) float64 (or integer for indices) values of an accessor, normalisation applied."""
    acc = doc["accessors"][index]
    if "sparse" in acc:
        raise LoadError(f"accessor {index}: sparse accessors are not supported", path)
    dt = np.dtype(_COMPONENT[acc["componentType"]])
    width = _WIDTH[acc["type"]]
    count = int(acc["count"])
    if "bufferView" not in acc:
        return np.zeros((count, width), dtype=dt)
    data, stride = _view_bytes(doc, bufs, acc["bufferView"])
    off = int(acc.get("byteOffset", 0))
    elem = dt.itemsize * width
    if stride and stride != elem:
        rows = np.frombuffer(data, dtype=np.uint8, count=stride * (count - 1) + elem, offset=off)
        idx = (np.arange(count)[:, None] * stride + np.arange(elem)[None, :]).ravel()
        a = rows[idx].view(dt).reshape(count, width)
    else:
        a = np.frombuffer(data, dtype=dt, count=count * width, offset=off).reshape(count, width)
    if acc.get("normalized") and dt.kind in "iu":
        info = np.iinfo(dt)
        a = np.maximum(a.astype(np.float64) / info.max, -1.0)
    return a


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major in the file
    m = np.eye(4)
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m[:3, :3] = r * np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)[None, :]
    m[:3, 3] = node.get("translation", [0.0, 0.0, 0.0])
    return m


def _decode_image(doc: dict, bufs: list[bytes], image: int, path: Path) -> np.ndarray:
    from PIL import Image

    img = doc["images"][image]
    if "bufferView" in img:
        raw, _ = _view_bytes(doc, bufs, img["bufferView"])
    else:
        uri = img.get("uri", "")
        if uri.startswith("data:"):
            import base64

            raw = base64.b64decode(uri.split(",", 1)[1])
        else:
            raw = (path.parent / uri).read_bytes()
    with Image.open(io.BytesIO(raw)) as im:
        return np.ascontiguousarray(np.asarray(im.convert("RGBA"), dtype=np.uint8))


def is_iat_export(path: str | Path) -> bool:
    """True when ``path`` is a GLB written by :func:`iat.export.gltf.export_glb` (root ``extras.iat``)."""
    p = Path(path)
    try:
        doc, _ = _read_glb(p.read_bytes(), p)
    except (OSError, LoadError, ValueError, TypeError, KeyError, AttributeError):
        return False
    return isinstance(doc.get("extras"), dict) and "iat" in doc["extras"]


def load_glb(path: str | Path) -> GlbDocument:
    """Read a .glb (or a .gltf with data/relative buffers) into world-space primitives and textures.

    Raises :class:`iat.errors.LoadError` naming the file and the cause.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise LoadError(f"cannot read: {e}", path) from e
    try:
        if path.suffix.lower() == ".gltf":
            doc, binary = json.loads(data.decode("utf-8")), b""
        else:
            doc, binary = _read_glb(data, path)
        return _load(doc, binary, path)
    except LoadError:
        raise
    except (KeyError, IndexError, ValueError, TypeError) as e:
        raise LoadError(f"malformed glTF: {type(e).__name__}: {e}", path) from e


def _load(doc: dict, binary: bytes, path: Path) -> GlbDocument:
    bufs = _buffers(doc, binary, path)
    out = GlbDocument(path=path, json=doc)
    root_scale = 1.0
    iat = (doc.get("extras") or {}).get("iat")
    if isinstance(iat, dict) and "radiance_scale" in iat:
        root_scale = float(iat["radiance_scale"])
    materials = doc.get("materials", [])
    samplers = doc.get("samplers", [])

    def texture(t: int) -> None:
        if t in out.textures:
            return
        tex = doc["textures"][t]
        s = samplers[tex["sampler"]] if "sampler" in tex else {}
        out.textures[t] = dict(
            image=_decode_image(doc, bufs, tex["source"], path),
            mag=int(s.get("magFilter", _LINEAR)),
            min=int(s.get("minFilter", 9987)),
            wrap_s=int(s.get("wrapS", _REPEAT)),
            wrap_t=int(s.get("wrapT", _REPEAT)),
        )

    scenes = doc.get("scenes") or []
    nodes = doc.get("nodes", [])
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:  # no scene: every node that is nobody's child
        kids = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in kids]
    stack = [(int(i), np.eye(4)) for i in roots]
    while stack:
        ni, parent = stack.pop()
        node = nodes[ni]
        world = parent @ _node_matrix(node)
        stack.extend((int(c), world) for c in node.get("children", []))
        if "mesh" not in node:
            continue
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim.get("mode", _TRIANGLES) != _TRIANGLES:
                continue  # points / lines / strips: nothing the exporter writes
            attrs = prim["attributes"]
            pos = _accessor(doc, bufs, attrs["POSITION"], path).astype(np.float64)
            n = len(pos)
            pos = pos @ world[:3, :3].T + world[:3, 3]
            if "indices" in prim:
                idx = _accessor(doc, bufs, prim["indices"], path).astype(np.int64).reshape(-1)
            else:
                idx = np.arange(n, dtype=np.int64)
            idx = idx[: len(idx) // 3 * 3].reshape(-1, 3)
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise LoadError(f"mesh {node['mesh']}: index out of range", path)
            col = np.ones((n, 4))
            if "COLOR_0" in attrs:
                c = _accessor(doc, bufs, attrs["COLOR_0"], path).astype(np.float64)
                col[:, : c.shape[1]] = c
            uvs = []
            for k in ("TEXCOORD_0", "TEXCOORD_1"):
                uvs.append(
                    _accessor(doc, bufs, attrs[k], path).astype(np.float32)
                    if k in attrs
                    else np.zeros((n, 2), np.float32)
                )
            m = prim.get("material")
            mat = materials[m] if m is not None else {}
            pbr = mat.get("pbrMetallicRoughness", {})
            factor = np.asarray(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]), dtype=np.float32)
            base = pbr.get("baseColorTexture")
            extras = mat.get("extras") or {}
            scale = float(extras.get("radiance_scale", root_scale))
            ill = extras.get("iat_illumination")
            ill_tex, ill_set, ill_rgbm = None, 0, 0.0
            if isinstance(ill, dict) and "index" in ill:
                ill_tex, ill_set = int(ill["index"]), int(ill.get("texCoord", 0))
                if ill.get("encoding") == "rgbm":
                    ill_rgbm = float(ill.get("rgbm_range", 0.0))
                scale = float(ill.get("radiance_scale", scale))
                texture(ill_tex)
            if base is not None:
                texture(int(base["index"]))
            out.primitives.append(
                GlbPrimitive(
                    positions=pos.astype(np.float32),
                    indices=idx.astype(np.uint32),
                    colors=col.astype(np.float32),
                    uv0=uvs[0],
                    uv1=uvs[1],
                    factor=factor,
                    base_texture=None if base is None else int(base["index"]),
                    base_set=0 if base is None else int(base.get("texCoord", 0)),
                    ill_texture=ill_tex,
                    ill_set=ill_set,
                    ill_rgbm=ill_rgbm,
                    radiance_scale=scale,
                    material=m,
                    node=str(node.get("name", ni)),
                )
            )
    return out


# -- drawing -------------------------------------------------------------------------------------------
class GlbView:
    """A GLB on the GPU: ``GlbView(path, ctx=None).render(camera, size)``; ``release()`` frees it.

    ctx : a moderngl context, or None to create (and own) an EGL standalone context.
    Attributes: ``document`` (:class:`GlbDocument`), ``triangles``, ``draw_calls`` (per frame).
    """

    def __init__(self, path_or_doc, ctx=None):
        import moderngl

        self._mgl = moderngl
        self.document = path_or_doc if isinstance(path_or_doc, GlbDocument) else load_glb(path_or_doc)
        self._owns = ctx is None
        if ctx is None:
            try:
                ctx = moderngl.create_standalone_context(backend="egl")
            except Exception as e:
                raise RenderError(f"cannot create an EGL OpenGL context: {e}") from e
        self.ctx = ctx
        self._objects: list[Any] = []
        try:
            self._prog = self._keep(gl.program(ctx, "glb"))
            self._white = self._keep(ctx.texture((1, 1), 4, bytes([255, 255, 255, 255])))
            self._textures = {t: self._texture(d) for t, d in self.document.textures.items()}
            self._draws = [self._primitive(p) for p in self.document.primitives if len(p.indices)]
        except Exception:
            self.release()
            raise
        self._target: tuple | None = None
        self.triangles = self.document.triangles
        self.draw_calls = len(self._draws)

    def _keep(self, obj):
        self._objects.append(obj)
        return obj

    def _texture(self, d: dict):
        mgl = self._mgl
        img = d["image"]
        h, w = img.shape[:2]
        tex = self._keep(self.ctx.texture((w, h), 4, img.tobytes(), internal_format=_GL_SRGB8_ALPHA8))
        tex.repeat_x = d["wrap_s"] != _CLAMP
        tex.repeat_y = d["wrap_t"] != _CLAMP
        mag = mgl.NEAREST if d["mag"] == _NEAREST else mgl.LINEAR
        mn = d["min"] if d["min"] in (_NEAREST, _LINEAR) or d["min"] in _MIPMAP_MIN else 9987
        if mn in _MIPMAP_MIN:
            tex.build_mipmaps()
        tex.filter = (mn, mag)  # glTF filter enums are the GL ones
        return tex

    def _primitive(self, p: GlbPrimitive):
        ctx = self.ctx
        bufs = [
            (
                self._keep(ctx.buffer(np.ascontiguousarray(p.positions, np.float32).tobytes())),
                "3f",
                "in_position",
            ),
            (self._keep(ctx.buffer(np.ascontiguousarray(p.colors, np.float32).tobytes())), "4f", "in_color"),
            (self._keep(ctx.buffer(np.ascontiguousarray(p.uv0, np.float32).tobytes())), "2f", "in_uv0"),
            (self._keep(ctx.buffer(np.ascontiguousarray(p.uv1, np.float32).tobytes())), "2f", "in_uv1"),
        ]
        ibuf = self._keep(ctx.buffer(np.ascontiguousarray(p.indices, np.uint32).tobytes()))
        content = [(b, f, n) for b, f, n in bufs if n in self._prog]  # unused attributes are optimised out
        vao = self._keep(ctx.vertex_array(self._prog, content, index_buffer=ibuf, index_element_size=4))
        return vao, p

    def _mirror(self, t: int | None) -> tuple[bool, bool]:
        if t is None:
            return (False, False)
        d = self.document.textures[t]
        return (d["wrap_s"] == _MIRROR, d["wrap_t"] == _MIRROR)

    def _set(self, name: str, value) -> None:
        if name in self._prog:
            if name == "clip_from_world":
                self._prog[name].write(value)
            else:
                self._prog[name].value = value

    def draw(self, camera, size: tuple[int, int], exposure: float = 1.0, tonemap: bool = False) -> None:
        """Draw into the bound framebuffer at its viewport, whose aspect is ``size`` (w, h): exposure x
        linear radiance, or with ``tonemap`` clamped and sRGB-encoded for a display framebuffer."""
        mgl, ctx = self._mgl, self.ctx
        w, h = (int(v) for v in size)
        clip = np.asarray(camera.clip_from_world(w / h), dtype=np.float64).T.astype("f4").tobytes()
        ctx.enable(mgl.DEPTH_TEST)
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        self._set("clip_from_world", clip)
        self._set("base_tex", 0)
        self._set("ill_tex", 1)
        self._set("exposure", float(exposure))
        self._set("tonemap", bool(tonemap))
        try:
            for vao, p in self._draws:
                base = self._textures.get(p.base_texture) if p.base_texture is not None else None
                ill = self._textures.get(p.ill_texture) if p.ill_texture is not None else None
                (base or self._white).use(0)
                (ill or self._white).use(1)
                self._set("use_base", base is not None)
                self._set("use_ill", ill is not None)
                self._set("base_set", int(p.base_set))
                self._set("ill_set", int(p.ill_set))
                self._set("ill_rgbm", float(p.ill_rgbm))
                self._set("base_mirror", self._mirror(p.base_texture))
                self._set("ill_mirror", self._mirror(p.ill_texture))
                self._set("factor", tuple(float(x) for x in p.factor))
                self._set("radiance_scale", float(p.radiance_scale))
                vao.render(mgl.TRIANGLES)
        finally:
            ctx.disable(mgl.DEPTH_TEST)

    def render(self, camera, size: tuple[int, int] = (640, 480)) -> np.ndarray:
        """Draw offscreen; ``(h, w, 3) float32`` linear radiance, row 0 at the top."""
        if self.ctx is None:
            raise RenderError("GlbView already released")
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise RenderError(f"bad image size {size}")
        ctx = self.ctx
        if self._target is None or self._target[0] != (w, h):
            if self._target is not None:
                for o in self._target[1:]:
                    o.release()
                    self._objects.remove(o)
            color = self._keep(ctx.renderbuffer((w, h), 4, dtype="f4"))
            depth = self._keep(ctx.depth_renderbuffer((w, h)))
            fbo = self._keep(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
            self._target = ((w, h), fbo, color, depth)
        fbo = self._target[1]
        prev = ctx.fbo
        try:
            fbo.use()
            ctx.viewport = (0, 0, w, h)
            fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
            self.draw(camera, (w, h))
            ctx.finish()
            raw = fbo.read(viewport=(0, 0, w, h), components=3, dtype="f4", alignment=1)
        finally:
            if prev is not None and prev is not fbo:
                try:
                    prev.use()
                except Exception:  # a released framebuffer: nothing to go back to
                    pass
        return np.frombuffer(raw, dtype=np.float32).reshape(h, w, 3)[::-1].copy()

    def release(self) -> None:
        """Free every GL object (and the context when this view created it)."""
        for o in reversed(getattr(self, "_objects", [])):
            try:
                o.release()
            except Exception:  # already gone with its context
                pass
        self._objects = []
        self._target = None
        if getattr(self, "_owns", False) and self.ctx is not None:
            self.ctx.release()
        self.ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def render_glb(path, camera, size: tuple[int, int] = (640, 480), ctx=None) -> np.ndarray:
    """``(h, w, 3) float32`` linear radiance of the GLB at ``path`` seen by ``camera`` (see module doc).

    ctx : a moderngl context to draw with, or None for a temporary EGL standalone context.
    """
    with GlbView(path, ctx) as view:
        return view.render(camera, size)
