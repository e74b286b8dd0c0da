"""The renderer: draws a Scene (preview), a Solution (mesh) or a Baked (IAT) with moderngl.

Shared by the viewer (a window context is passed in), the CLI, the tests and the
benchmark (headless: an EGL standalone context, Mesa llvmpipe here).

Modes
-----
``preview``  every patch of a :class:`~iat.scene.Scene` unlit: ``emission + 0.5 x albedo``
``mesh``     the solution's leaf triangles, one radiance per vertex, Gouraud-interpolated
``iat``      a Baked: its vertex-coloured mesh part plus one textured polygon per
             textured patch, the atlas pages in one texture array
``split``    mesh left of ``split x width``, IAT right of it (scissor)
``diff``     ``|mesh - iat| x diff_gain`` (both drawn to float targets, combined in a fullscreen pass)

Solution sets (lighting states, e.g. times of day; :mod:`iat.solution_set`)
---------------------------------------------------------------------------
:meth:`Renderer.set_solution_set` (mesh mode) and :meth:`Renderer.set_baked_set`
(IAT mode) take several aligned solutions / a :class:`~iat.bake.BakedSet`;
:meth:`Renderer.set_blend` picks the two neighbouring states ``a``, ``b`` and the
mix ``w``. IAT mode samples state a's and state b's page layers (all states sit in
one texture array, state k's page p at layer ``k * n_pages + p``) and mixes them
in one pass; mesh mode mixes two colour attributes per vertex. ``w = 0`` draws
state a exactly (the second lookup is skipped), so a blend at a key time equals
that solution's own image.

:meth:`Renderer.render` returns linear radiance as ``(h, w, 3) float32`` read
back from an RGBA32F framebuffer (exact, no tone map); :meth:`Renderer.draw`
draws into the bound framebuffer with exposure and sRGB encoding in the shader.

Atlas convention: ``pages[layer, y, x]`` is the texel whose centre is at
``uv = ((x + 0.5) / W, (y + 0.5) / H)`` of that page (row ``y = 0`` at ``v = 0``).

GL memory: every GL object the renderer creates is kept in one registry and
released by :meth:`Renderer.release`. Re-setting data writes buffers and
textures in place when the size allows (a buffer is orphaned with a new size
when the data grows, or shrinks below a quarter, keeping its name and its
vertex arrays), so re-baking every frame does not grow GL memory. Data that is a
prefix of a read-only array (the Baker's mesh parts) is written as the whole
array once, then drawn by count; the Baker's page arrays already on the GPU are
not written again. The page texture is kept when new pages fit in it (written into
its corner, texture coordinates scaled exactly; :meth:`Renderer._page_texture_size`),
so it may be larger than the bake's :class:`~iat.bake.MemoryReport` counts:
:attr:`Renderer.page_texture` gives both.
"""

from __future__ import annotations

import importlib.resources
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iat.bake.baker import BYTES_PER_TEXEL, GPU_DTYPES, to_gpu
from iat.errors import RenderError

log = logging.getLogger(__name__)

try:  # the lattice -> world map lives in quadtree.py once it exists
    from iat.geometry.quadtree import lattice_to_world
except ImportError:  # pragma: no cover - depends on the order modules land in

    def lattice_to_world(
        patch_corners: np.ndarray,
        patch_is_quad: np.ndarray,
        patch: np.ndarray,
        i: np.ndarray,
        j: np.ndarray,
        n: int,
    ) -> np.ndarray:
        """World positions of lattice points.

        patch_corners : (P, 4, 3) float64 world corners (triangles repeat corner 2 in slot 3)
        patch_is_quad : (P,) bool
        patch, i, j : (k,) int lattice point (i, j) of patch ``patch``; ``(u, v) = (i / n, j / n)``
        n : lattice intervals per side (``2 ** max_depth``)
        Returns (k, 3) float64: bilinear in the 4 corners for quads,
        ``c0 + u (c1 - c0) + v (c2 - c0)`` for triangles.
        """
        corners = np.asarray(patch_corners, dtype=np.float64)
        patch = np.asarray(patch, dtype=np.int64)
        u = (np.asarray(i, dtype=np.float64) / n)[:, None]
        v = (np.asarray(j, dtype=np.float64) / n)[:, None]
        c = corners[patch]
        quad = (1 - u) * (1 - v) * c[:, 0] + u * (1 - v) * c[:, 1] + u * v * c[:, 2] + (1 - u) * v * c[:, 3]
        tri = c[:, 0] + u * (c[:, 1] - c[:, 0]) + v * (c[:, 2] - c[:, 0])
        is_quad = np.asarray(patch_is_quad, dtype=bool)[patch]
        return np.where(is_quad[:, None], quad, tri)


MODES = ("preview", "mesh", "iat", "split", "diff")
#: constant standing in for lighting in preview mode: colour = emission + PREVIEW_AMBIENT x albedo
PREVIEW_AMBIENT = 0.5
#: baker pixel format -> (moderngl dtype of the upload, GL internal format or 0 for moderngl's own).
#: rgba8 is GL_SRGB8_ALPHA8 (decoded to linear before filtering and mipmapping); rgb9e5 is
#: GL_RGB9_E5, written from half floats that hold the baker's 9e5-rounded values exactly
PIXEL_FORMATS = {
    "rgba16f": ("f2", 0),
    "rgba32f": ("f4", 0),
    "rgba8": ("f1", 0x8C43),
    "rgb9e5": ("f2", 0x8C3D),
}
_GL_TEXTURE_2D_ARRAY = 0x8C1A
_GL_FORMAT_TYPE = {"f1": (0x1908, 0x1401), "f2": (0x1908, 0x140B)}  # GL_RGBA + UNSIGNED_BYTE / HALF_FLOAT
_MIN_BUFFER = 64  # bytes; GL buffers are never created empty


# -- shader lookup ----------------------------------------------------------------------------
def shader_dir() -> Any:
    """The ``.glsl`` files: ``iat/render/shaders`` (package data), as an ``importlib.resources``
    Traversable (a :class:`pathlib.Path` in a source tree)."""
    d = importlib.resources.files("iat.render") / "shaders"
    if not (d / "mesh.glsl").is_file():
        raise RenderError(f"shader directory not found: {d}")
    return d


def shader_source(name: str, stage: str) -> str:
    """Source of program ``name`` (``shaders/<name>.glsl``) for ``stage`` "VERTEX_SHADER" / "FRAGMENT_SHADER".

    The file holds both stages in ``#if defined VERTEX_SHADER`` / ``#elif defined
    FRAGMENT_SHADER`` sections; this prepends ``#version 330 core`` and the define.
    """
    path = shader_dir() / f"{name}.glsl"
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise RenderError(f"cannot read shader: {e}", path) from e
    return f"#version 330 core\n#define {stage}\n#line 1\n{text}"


_LIBGL = None


def _libgl():
    """The process's GL entry points (glvnd's libOpenGL, else libGL), for the one call moderngl
    lacks: glTexImage3D with an internal format (sRGB8 and RGB9_E5 texture arrays)."""
    global _LIBGL
    if _LIBGL is None:
        import ctypes

        for name in ("libOpenGL.so.0", "libGL.so.1", "libGL.so", "opengl32"):
            try:
                lib = ctypes.CDLL(name)
                f = lib.glTexImage3D
            except (OSError, AttributeError):
                continue
            f.argtypes = (
                [ctypes.c_uint] + [ctypes.c_int] * 6 + [ctypes.c_uint, ctypes.c_uint, ctypes.c_void_p]
            )
            f.restype = None
            _LIBGL = lib
            break
        else:
            raise RenderError("cannot load libOpenGL/libGL to create an sRGB8 or RGB9_E5 texture array")
    return _LIBGL


# -- GL object bookkeeping --------------------------------------------------------------------
class _Registry:
    """Every GL object the renderer owns, so that ``release()`` frees them all and tests can count them."""

    def __init__(self):
        self._objects: dict[int, Any] = {}

    def add(self, obj):
        self._objects[id(obj)] = obj
        return obj

    def release(self, obj) -> None:
        if obj is not None and self._objects.pop(id(obj), None) is not None:
            obj.release()

    def release_all(self) -> None:
        # vertex arrays first, then programs, framebuffers, attachments, buffers
        objs = list(self._objects.values())
        order = {"VertexArray": 0, "Framebuffer": 1, "Program": 2}
        objs.sort(key=lambda o: order.get(type(o).__name__, 3))
        for o in objs:
            o.release()
        self._objects.clear()

    def __len__(self) -> int:
        return len(self._objects)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for o in self._objects.values():
            out[type(o).__name__] = out.get(type(o).__name__, 0) + 1
        return out


def _frozen_root(raw: np.ndarray) -> np.ndarray | None:
    """The read-only, contiguous array ``raw`` is a prefix of (same dtype, same start), or None."""
    root = raw.base
    if (
        isinstance(root, np.ndarray)
        and not root.flags.writeable
        and root.flags.c_contiguous
        and root.dtype == raw.dtype
        and raw.nbytes <= root.nbytes
        and raw.__array_interface__["data"][0] == root.__array_interface__["data"][0]
    ):
        return root
    return None


def _upload(ctx, reg: _Registry, buf, data: np.ndarray):
    """Write ``data`` into ``buf`` in place; orphan it with a new size when the data grows
    (or shrinks below a quarter). Creates the buffer when ``buf`` is None. Returns the buffer.

    A prefix of a read-only array (the Baker's mesh parts are prefixes of one depth-sorted mesh)
    is written as the whole array, once: while the buffer holds that array, later prefixes of it
    write nothing (the draw call's count selects the prefix). Written from the array's memory
    (no ``tobytes`` copy)."""
    raw = np.ascontiguousarray(data)
    root = _frozen_root(raw)
    src = raw if root is None else root
    if buf is not None and root is not None and getattr(buf, "iat_source", None) is root:
        return buf  # already holds the whole frozen array
    nbytes = src.nbytes
    if buf is None:
        buf = reg.add(ctx.buffer(reserve=max(nbytes, _MIN_BUFFER), dynamic=True))
    elif nbytes > buf.size or (buf.size > _MIN_BUFFER and nbytes < buf.size // 4):
        buf.orphan(max(nbytes, _MIN_BUFFER))
    if nbytes:
        buf.write(memoryview(src.reshape(-1)).cast("B"))
    buf.iat_source = root  # the frozen array it now holds whole (None: anything else)
    return buf


@dataclass
class _Geometry:
    """Indexed triangles with per-vertex attributes, drawn by ranges (one range per draw call).

    attrs : (name, components) of the float attributes, in the program's ``in_<name>``
    ranges : [(key, first_index, index_count)]: key -1 = plain, else a material with a detail texture
    """

    program: Any
    attrs: list[tuple[str, int]]
    buffers: dict[str, Any] = field(default_factory=dict)
    index_buffer: Any = None
    vao: Any = None
    n_triangles: int = 0
    ranges: list[tuple[int, int, int]] = field(default_factory=list)

    def upload(
        self,
        ctx,
        reg: _Registry,
        arrays: dict[str, np.ndarray],
        indices: np.ndarray,
        tri_key: np.ndarray | None = None,
    ) -> None:
        """arrays : name -> (n, components) float32; indices : (t, 3) uint32;
        tri_key : (t,) int, -1 for plain triangles, else the detail material (one draw call per key)."""
        indices = np.asarray(indices, dtype=np.uint32).reshape(-1, 3)
        ranges = [(-1, 0, 3 * len(indices))]
        if tri_key is not None and len(indices):
            tri_key = np.asarray(tri_key, dtype=np.int64).reshape(-1)
            order = np.argsort(tri_key, kind="stable")
            indices = indices[order]
            keys, starts, counts = np.unique(tri_key[order], return_index=True, return_counts=True)
            ranges = [(int(k), 3 * int(s), 3 * int(c)) for k, s, c in zip(keys, starts, counts, strict=True)]
        for name, comps in self.attrs:
            a = np.asarray(arrays[name], dtype=np.float32).reshape(-1, comps)
            self.buffers[name] = _upload(ctx, reg, self.buffers.get(name), a)
        self.index_buffer = _upload(ctx, reg, self.index_buffer, indices)
        if self.vao is None:
            content = [(self.buffers[name], f"{comps}f", f"in_{name}") for name, comps in self.attrs]
            self.vao = reg.add(
                ctx.vertex_array(self.program, content, index_buffer=self.index_buffer, index_element_size=4)
            )
        self.n_triangles = len(indices)
        self.ranges = [r for r in ranges if r[2] > 0]

    def calls(self):
        """(key, first_index, index_count) of each draw call."""
        return list(self.ranges)

    def render_range(self, first: int, count: int) -> None:
        import moderngl

        self.vao.render(moderngl.TRIANGLES, vertices=count, first=first)

    def release(self, reg: _Registry) -> None:
        reg.release(self.vao)
        for b in self.buffers.values():
            reg.release(b)
        reg.release(self.index_buffer)
        self.buffers.clear()
        self.vao = self.index_buffer = None
        self.n_triangles = 0
        self.ranges = []


@dataclass
class _Target:
    """An offscreen framebuffer: RGBA32F colour (renderbuffer, or texture when sampled later) + depth."""

    size: tuple[int, int]
    color: Any
    depth: Any
    fbo: Any


def _vec(a, n: int, name: str, dtype=np.float32) -> np.ndarray:
    a = np.asarray(a, dtype=dtype)
    if a.size % n:
        raise RenderError(f"{name} has {a.size} values, not a multiple of {n}")
    return a.reshape(-1, n)


def _check_indices(indices: np.ndarray, n_vertices: int, name: str) -> None:
    if indices.size and (indices.min() < 0 or indices.max() >= n_vertices):
        raise RenderError(f"{name} refer to vertex {int(indices.max())} but there are {n_vertices} vertices")


class Renderer:
    """Draws preview / mesh / IAT images with moderngl.

    ctx : a moderngl context (the viewer's window context), or None to create an
          EGL standalone context (headless), which the renderer then owns and releases.
    """

    #: keep the page texture when new pages fit in it (:meth:`_page_texture_size`); False re-creates
    #: it whenever the pages' size changes (the benchmark's ``--no-reuse``, for comparison)
    reuse_pages = True

    def __init__(self, ctx=None):
        import moderngl

        self._moderngl = moderngl
        self._owns_ctx = ctx is None
        if ctx is None:
            try:
                ctx = moderngl.create_standalone_context(backend="egl")
            except Exception as e:  # moderngl raises plain Exception subclasses here
                raise RenderError(f"cannot create an EGL OpenGL context: {e}") from e
        self.ctx = ctx
        # where to return after offscreen work: moderngl rebinds "the bound framebuffer" whenever it
        # creates one, so our framebuffers must never stay bound once released
        self._home = ctx.fbo if ctx.fbo is not None else ctx.detect_framebuffer()
        self._reg = _Registry()
        self._programs: dict[str, Any] = {}
        for name in ("mesh", "iat", "preview", "composite"):
            self._programs[name] = self._program(name)
        self._fullscreen = self._reg.add(ctx.vertex_array(self._programs["composite"], []))
        # bound to the detail unit when a draw has no detail texture, so that unit never holds a
        # texture that is also the render target (a feedback loop in diff mode)
        self._white = self._reg.add(ctx.texture((1, 1), 4, np.ones(4, np.float32).tobytes(), dtype="f4"))
        mesh, iat, preview = self._programs["mesh"], self._programs["iat"], self._programs["preview"]
        self._solution = _Geometry(mesh, [("position", 3), ("color", 3), ("color_b", 3)])
        self._baked_mesh = _Geometry(mesh, [("position", 3), ("color", 3), ("color_b", 3)])
        self._baked_tex = _Geometry(
            iat, [("position", 3), ("uv", 2), ("layer", 1), ("detail_uv", 2), ("detail", 1)]
        )
        self._preview = _Geometry(preview, [("position", 3), ("emission", 3), ("albedo", 3), ("uv", 2)])
        self._has = {"preview": False, "mesh": False, "iat": False}
        self._pages = None  # texture array
        self._pages_key: tuple | None = None
        self._pages_src: np.ndarray | None = None  # the array last written to the page texture
        self._pages_region: tuple = (0, 0, 0)  # (w, h, layers) of the pages in it (its corner)
        self._page_scale = 1.0
        # solution sets: per-state vertex colours (CPU) of the solution mesh and of the baked mesh
        # part, the (a, b) pair uploaded as color / color_b, the states and pages per state in IAT mode
        self._colors: dict[str, list[np.ndarray]] = {"mesh": [], "iat": []}
        self._colors_pair: dict[str, tuple[int, int]] = {"mesh": (0, 0), "iat": (0, 0)}
        self._iat_states = 1
        self._iat_pages = 1
        self._blend: tuple[int, int, float] = (0, 0, 0.0)
        self._detail: dict[str, dict[int, Any]] = {"iat": {}, "preview": {}}
        self._targets: dict[str, _Target] = {}
        self._last: dict[str, Any] = {"mode": None, "triangles": 0, "draw_calls": 0, "modes": {}}
        self._released = False

    # -- lifetime ---------------------------------------------------------------------------
    def release(self) -> None:
        """Release every GL object created by this renderer (and the context if it created it)."""
        if self._released:
            return
        if any(self.ctx.fbo is t.fbo for t in self._targets.values()):
            self._home.use()
        self._reg.release_all()
        self._detail = {"iat": {}, "preview": {}}
        self._targets.clear()
        self._pages = None
        if self._owns_ctx:
            self.ctx.release()
        self._released = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def gl_object_count(self) -> int:
        """How many GL objects this renderer holds now (constant across re-sets of same-shaped data)."""
        return len(self._reg)

    def _alive(self):
        if self._released:
            raise RenderError("renderer already released")

    def _program(self, name: str):
        try:
            return self._reg.add(
                self.ctx.program(
                    vertex_shader=shader_source(name, "VERTEX_SHADER"),
                    fragment_shader=shader_source(name, "FRAGMENT_SHADER"),
                )
            )
        except RenderError:
            raise
        except Exception as e:
            raise RenderError(f"shader {name}.glsl does not compile: {e}") from e

    # -- textures ---------------------------------------------------------------------------
    def _texture2d(self, old, data: np.ndarray):
        """(h, w, 3) float -> RGBA32F repeating, mipmapped texture; written in place when the size matches."""
        h, w = data.shape[:2]
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[..., :3] = data[..., :3]
        if old is not None and old.size == (w, h):
            old.write(rgba.tobytes())
            tex = old
        else:
            self._reg.release(old)
            tex = self._reg.add(self.ctx.texture((w, h), 4, rgba.tobytes(), dtype="f4"))
            tex.repeat_x = tex.repeat_y = True
            tex.filter = (self._moderngl.LINEAR_MIPMAP_LINEAR, self._moderngl.LINEAR)
        tex.build_mipmaps()
        return tex

    def _set_details(self, which: str, textures: dict[int, np.ndarray]) -> None:
        cur = self._detail[which]
        for m in list(cur):
            if m not in textures:
                self._reg.release(cur.pop(m))
        for m, img in textures.items():
            img = np.asarray(img, dtype=np.float32)
            if img.ndim != 3 or img.shape[2] < 3 or img.shape[0] == 0 or img.shape[1] == 0:
                raise RenderError(f"detail texture of material {m} has shape {img.shape}, expected (h, w, 3)")
            cur[int(m)] = self._texture2d(cur.get(int(m)), img)

    def _gpu_pages(self, baked, pages: np.ndarray | None, pixel_format: str, scale: float) -> np.ndarray:
        """The ``(n, H, W, 4)`` array to write for ``baked``: its ``gpu_form()`` when the baker made
        one for this format (no conversion), else ``pages`` (float, ``(n, H, W, 3)``) converted."""
        if pixel_format not in PIXEL_FORMATS:
            raise RenderError(f"unknown pixel format {pixel_format!r} (known: {', '.join(PIXEL_FORMATS)})")
        if pages is None:
            gpu_form = getattr(baked, "gpu_form", None)
            g = gpu_form() if gpu_form is not None else None
            if g is not None:
                return g
            pages = np.asarray(baked.pages)
        pages = np.asarray(pages)
        if pages.ndim != 4 or pages.shape[3] < 3:
            raise RenderError(f"baked pages have shape {pages.shape}, expected (n_pages, H, W, 3)")
        return to_gpu(pages, pixel_format, scale)

    def _set_pages(
        self, data: np.ndarray, pixel_format: str, mipmaps: bool, mip_levels: int | None = None
    ) -> None:
        """Upload atlas pages in their GPU form ``(n, H, W, 4)`` (:func:`iat.bake.to_gpu`), written
        from the array itself (no copy); the same read-only array as last time is not written again.
        With mipmaps, only the ``mip_levels`` the atlas gutters allow are built, so coarse levels
        never blend neighbouring tiles (None: the full chain)."""
        mgl = self._moderngl
        dtype, internal = PIXEL_FORMATS[pixel_format]
        if data.ndim != 4 or data.shape[3] != 4 or data.dtype != GPU_DTYPES[pixel_format]:
            raise RenderError(
                f"{pixel_format} pages have shape {data.shape} {data.dtype}, expected (n, H, W, 4)"
            )
        n, h, w = data.shape[:3]
        max_layers = int(self.ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
        max_size = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])
        if n > max_layers or max(w, h) > max_size:
            raise RenderError(
                f"the atlas has {n} page(s) of {w}x{h}; this GL allows {max_layers} layers of at most"
                f" {max_size}x{max_size}: lower the scale, raise the threshold or set a budget"
            )
        # the mip levels are part of the key: a texture that once held a mip chain keeps it allocated
        levels = (mip_levels or 0) if mipmaps else 1
        region = (w, h, n)
        if self._pages is not None and self._pages_key is not None and self._pages_region == region:
            if self._pages_key[3:] == (pixel_format, levels):
                if data is self._pages_src and not data.flags.writeable:
                    return  # the baker's cached pages, already on the GPU with their mip levels
        for _ in range(8):  # GL error flags are sticky: clear what others left, so ours is ours
            stale = self.ctx.error
            if stale == "GL_NO_ERROR":
                break
            log.debug("GL error before uploading pages (not ours): %s", stale)
        key = self._page_texture_size(w, h, n, pixel_format, levels)
        if self._pages is None or self._pages_key != key:
            self._reg.release(self._pages)
            self._pages = None
            aw, ah, an = key[:3]
            tex = self._reg.add(self.ctx.texture_array((aw, ah, an), 4, None, dtype=dtype))
            if internal:  # re-specify level 0 with the internal format moderngl cannot ask for
                fmt, typ = _GL_FORMAT_TYPE[dtype]
                tex.use(0)
                _libgl().glTexImage3D(_GL_TEXTURE_2D_ARRAY, 0, internal, aw, ah, an, 0, fmt, typ, None)
            tex.repeat_x = tex.repeat_y = False
            self._pages, self._pages_key = tex, key
        self._pages_src, self._pages_region = None, region
        if key[:3] == region:
            self._pages.write(memoryview(np.ascontiguousarray(data)))
        else:  # the pages' corner of a larger array (texture coordinates are scaled to match)
            self._pages.write(memoryview(np.ascontiguousarray(data)), viewport=(0, 0, 0, w, h, n))
        if mipmaps and (mip_levels is None or mip_levels > 1):
            self._pages.build_mipmaps(0, 1000 if mip_levels is None else mip_levels - 1)
            self._pages.filter = (mgl.LINEAR_MIPMAP_LINEAR, mgl.LINEAR)
        else:
            self._pages.filter = (mgl.LINEAR, mgl.LINEAR)
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"uploading {pixel_format} pages of {w}x{h}x{n} failed: {err}")
        self._pages_src = data

    def _page_texture_size(self, w: int, h: int, n: int, pixel_format: str, levels: int) -> tuple:
        """The page texture for ``n`` pages of ``w`` x ``h``: ``(W, H, N, pixel_format, levels)``.

        The texture held now when the pages fit in its corner, else one grown to the largest size
        seen in each dimension: re-creating a 2048 x 2048 array costs 25-55 ms on llvmpipe, which a
        scale slider would pay on every step that changes the atlas size. Kept only when the
        texture coordinates scale exactly (``W / w`` and ``H / h`` powers of two: the Baker's pages
        always are), the mip levels stay inside the pages (``w`` and ``h`` multiples of
        ``2**(levels - 1)``; never for a full chain) and the pages use at least 1/64 of it (so a
        texture left large by an earlier bake is given back once the pages become much smaller).
        """

        def pow2(a: int, b: int) -> bool:
            return a % b == 0 and ((a // b) & (a // b - 1)) == 0

        exact = (w, h, n, pixel_format, levels)
        old = self._pages_key
        if (
            not self.reuse_pages
            or self._pages is None
            or old is None
            or old[3:] != (pixel_format, levels)
            or levels == 0
        ):
            return exact
        align = 1 << max(levels - 1, 0)
        if w % align or h % align:
            return exact
        aw, ah, an = max(old[0], w), max(old[1], h), max(old[2], n)
        if not (pow2(aw, w) and pow2(ah, h)):
            return exact
        if 64 * w * h * n < aw * ah * an:
            return exact
        max_layers = int(self.ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
        max_size = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])
        if an > max_layers or max(aw, ah) > max_size:
            return exact
        return (aw, ah, an, pixel_format, levels)

    @property
    def page_texture(self) -> dict:
        """The IAT page texture: ``allocated`` ``(W, H, layers)`` and the ``used`` corner ``(w, h,
        layers)`` of the pages last set, and ``bytes`` allocated at level 0 (the bake's
        :class:`~iat.bake.MemoryReport` counts what the pages need; the array may be larger, see
        :meth:`_page_texture_size`). Empty without pages."""
        if self._pages is None or self._pages_key is None:
            return {}
        aw, ah, an, fmt = self._pages_key[:4]
        return {
            "allocated": (aw, ah, an),
            "used": tuple(self._pages_region),
            "pixel_format": fmt,
            "bytes": int(aw * ah * an * BYTES_PER_TEXEL.get(fmt, 8)),
        }

    def _page_uv(self, uv: np.ndarray) -> np.ndarray:
        """Atlas UVs of the pages set last, in the page texture (scaled when the texture is larger;
        exact: the factors are powers of two)."""
        if self._pages_key is None or tuple(self._pages_key[:2]) == tuple(self._pages_region[:2]):
            return uv
        w, h = self._pages_region[:2]
        f = np.array([w / self._pages_key[0], h / self._pages_key[1]], dtype=np.float32)
        return uv * f

    # -- data -------------------------------------------------------------------------------
    def set_scene(self, scene) -> None:
        """Preview geometry of a :class:`~iat.scene.Scene`: every patch, unlit albedo + emission.

        Quads become two triangles (0, 1, 2), (0, 2, 3); triangles one. Materials with a
        ``detail`` texture are drawn with it (one draw call per such material).
        """
        self._alive()
        corners = np.asarray(scene.corner_positions, dtype=np.float64).reshape(-1, 4, 3)
        p = len(corners)
        is_quad = np.asarray(scene.patch_corners)[:, 3] >= 0
        mat = np.asarray(scene.patch_material, dtype=np.int64).reshape(-1)
        materials = scene.materials
        albedo = np.array([m.albedo for m in materials], dtype=np.float64).reshape(-1, 3)
        emission = np.array([m.emission for m in materials], dtype=np.float64).reshape(-1, 3)
        if p and (mat.min() < 0 or mat.max() >= len(materials)):
            raise RenderError(f"scene patch_material refers to material {int(mat.max())} of {len(materials)}")
        uv = scene.patch_uv if scene.patch_uv is not None else np.zeros((p, 4, 2))
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 4, 2)
        base = 4 * np.arange(p, dtype=np.uint32)
        t1 = np.stack([base, base + 1, base + 2], axis=1)
        t2 = np.stack([base, base + 2, base + 3], axis=1)[is_quad]
        indices = np.concatenate([t1, t2])
        tri_patch = np.concatenate([np.arange(p), np.nonzero(is_quad)[0]])
        details = {i: m.detail for i, m in enumerate(materials) if getattr(m, "detail", None) is not None}
        detail_mat = np.array(sorted(details), dtype=np.int64)
        tri_mat = mat[tri_patch]
        tri_key = np.where(np.isin(tri_mat, detail_mat), tri_mat, -1)
        self._set_details("preview", details)
        self._preview.upload(
            self.ctx,
            self._reg,
            {
                "position": corners.reshape(-1, 3),
                "emission": np.repeat(emission[mat], 4, axis=0),
                "albedo": np.repeat(albedo[mat], 4, axis=0),
                "uv": uv.reshape(-1, 2),
            },
            indices,
            tri_key,
        )
        self._has["preview"] = True

    def set_solution(self, solution) -> None:
        """Mesh-mode geometry of a Solution: vertex-coloured leaf triangles (Gouraud).

        Uses ``max_depth, patch_corners (P,4,3), patch_is_quad (P,), vert_key (V,) int64,
        vert_radiance (V,3), tri_vertices (T,3)``; vertex positions come from the lattice keys.
        """
        self.set_solution_set([solution])

    def set_solution_set(self, solutions) -> None:
        """Mesh-mode geometry of aligned solutions (same vertex keys and triangles: solved on one
        mesh, :mod:`iat.solution_set`), one radiance per vertex and state; :meth:`set_blend` mixes
        two of them. Positions and triangles come from the first."""
        self._alive()
        solutions = list(solutions)
        if not solutions:
            raise RenderError("set_solution_set needs at least one solution")
        solution = solutions[0]
        n = 2 ** int(solution.max_depth)
        key = np.asarray(solution.vert_key, dtype=np.int64).reshape(-1)
        m = n + 1
        j, i, patch = key % m, (key // m) % m, key // (m * m)
        corners = np.asarray(solution.patch_corners, dtype=np.float64).reshape(-1, 4, 3)
        if key.size and (key.min() < 0 or patch.max() >= len(corners)):
            raise RenderError(f"solution vertex keys refer to patch {int(patch.max())} of {len(corners)}")
        pos = lattice_to_world(corners, np.asarray(solution.patch_is_quad, dtype=bool), patch, i, j, n)
        tris = np.asarray(solution.tri_vertices, dtype=np.int64).reshape(-1, 3)
        _check_indices(tris, len(key), "solution tri_vertices")
        colors = []
        for k, sol in enumerate(solutions):
            rad = _vec(sol.vert_radiance, 3, "vert_radiance")
            if len(rad) != len(key):
                raise RenderError(f"solution has {len(key)} vertex keys but {len(rad)} radiance values")
            if k and (
                not np.array_equal(np.asarray(sol.vert_key).reshape(-1), key)
                or not np.array_equal(np.asarray(sol.tri_vertices).reshape(-1, 3), tris)
            ):
                raise RenderError(f"solution {k} of the set is not on the same mesh as solution 0")
            colors.append(np.ascontiguousarray(rad))
        self._colors["mesh"] = colors
        a, b = self._pair("mesh")
        self._solution.upload(
            self.ctx, self._reg, {"position": pos, "color": colors[a], "color_b": colors[b]}, tris
        )
        self._colors_pair["mesh"] = (a, b)
        self._has["mesh"] = True

    # -- blending -----------------------------------------------------------------------------
    def set_blend(self, a: int, b: int | None = None, w: float = 0.0) -> None:
        """Show state ``a`` mixed with state ``b`` by ``w`` in [0, 1] (linear radiance):
        ``(1 - w) a + w b``; ``w = 0`` draws ``a`` exactly. Indices beyond a set's size are
        clamped to its last state (a single solution is a set of one).
        See :func:`iat.solution_set.blend_weights` for the pair and weight of a time."""
        a = int(a)
        b = a if b is None else int(b)
        w = float(w)
        if a < 0 or b < 0:
            raise RenderError(f"blend states must be >= 0, got {a}, {b}")
        if not (0.0 <= w <= 1.0):
            raise RenderError(f"blend weight must be in [0, 1], got {w}")
        self._blend = (a, b, w)
        for which, geo in (("mesh", self._solution), ("iat", self._baked_mesh)):
            pair = self._pair(which)
            colors = self._colors[which]
            if colors and geo.buffers and pair != self._colors_pair[which]:
                geo.buffers["color"] = _upload(self.ctx, self._reg, geo.buffers["color"], colors[pair[0]])
                geo.buffers["color_b"] = _upload(self.ctx, self._reg, geo.buffers["color_b"], colors[pair[1]])
                self._colors_pair[which] = pair

    @property
    def blend(self) -> tuple[int, int, float]:
        """(a, b, w) as last set by :meth:`set_blend`."""
        return self._blend

    def n_states(self, mode: str = "iat") -> int:
        """States (solutions) uploaded for ``mode`` "mesh" or "iat" (1 for a single solution)."""
        if mode == "iat":
            return int(self._iat_states) if self._has["iat"] else 0
        return len(self._colors["mesh"])

    def _pair(self, which: str) -> tuple[int, int]:
        n = max(len(self._colors[which]), 1) if which == "mesh" else max(self._iat_states, 1)
        a, b, _ = self._blend
        return min(a, n - 1), min(b, n - 1)

    def set_baked(self, baked) -> None:
        """IAT-mode data of a Baked: its vertex-coloured mesh part and its textured part.

        The textured part is drawn in one call for the patches without detail texture and
        one call per detail material (``baked.detail_textures: {material: (h,w,3)}``,
        applied where ``tex_detail`` is 1, or on every vertex of that material when the
        field is absent). Pages go into one texture array, rewritten in place when they fit
        in it with the same ``policy.pixel_format`` and mip levels (into its corner when
        smaller, see :meth:`_page_texture_size`), mipmapped when ``policy.mipmaps``:
        ``baked.gpu_form()`` (the Baker's pages in their GPU dtype) is written as it is and not
        at all when the texture already holds that very array; other Baked-likes' float
        ``pages`` are converted (:func:`iat.bake.to_gpu`). rgba8 pages are GL_SRGB8_ALPHA8,
        rgb9e5 pages GL_RGB9_E5 (4 bytes a texel, as the memory report counts).
        """
        self._set_baked(baked, [baked.mesh_radiance], None, 1)

    def set_baked_set(self, baked_set) -> None:
        """IAT-mode data of a :class:`~iat.bake.BakedSet`: the shared geometry once, every state's
        pages in one texture array (state k's page p at layer ``k * n_pages + p``) and every
        state's mesh-part colours; :meth:`set_blend` picks and mixes two states."""
        pages = np.asarray(baked_set.pages)
        if pages.ndim != 5:
            raise RenderError(
                f"baked set pages have shape {pages.shape}, expected (n_states, n_pages, H, W, 3)"
            )
        n = int(pages.shape[0])
        rad = np.asarray(baked_set.mesh_radiance)
        if rad.ndim != 3 or rad.shape[0] != n:
            raise RenderError(f"baked set mesh_radiance has shape {rad.shape}, expected ({n}, M, 3)")
        self._set_baked(baked_set, list(rad), pages.reshape(-1, *pages.shape[2:]), n)

    def _set_baked(self, baked, mesh_colors: list, all_pages: np.ndarray | None, n_states: int) -> None:
        """all_pages : (n_states x n_pages, H, W, 3) float pages, or None: ``baked``'s own (its
        GPU form when it has one)."""
        self._alive()
        policy = getattr(baked, "policy", None)
        pixel_format = str(getattr(policy, "pixel_format", "rgba16f") or "rgba16f")
        mipmaps = bool(getattr(policy, "mipmaps", False))

        mpos = _vec(baked.mesh_positions, 3, "mesh_positions")
        colors = [np.ascontiguousarray(_vec(c, 3, "mesh_radiance")) for c in mesh_colors]
        midx = np.asarray(baked.mesh_indices, dtype=np.int64).reshape(-1, 3)
        for mrad in colors:
            if len(mpos) != len(mrad):
                raise RenderError(
                    f"baked mesh part has {len(mpos)} positions but {len(mrad)} radiance values"
                )
        _check_indices(midx, len(mpos), "baked mesh_indices")

        tpos = _vec(baked.tex_positions, 3, "tex_positions")
        k = len(tpos)
        tuv = _vec(baked.tex_uv, 2, "tex_uv")
        tlayer = _vec(baked.tex_layer, 1, "tex_layer")
        tduv = getattr(baked, "tex_detail_uv", None)
        tduv = np.zeros((k, 2), np.float32) if tduv is None else _vec(tduv, 2, "tex_detail_uv")
        tmat = getattr(baked, "tex_material", None)
        tmat = np.full(k, -1, np.int64) if tmat is None else np.asarray(tmat, dtype=np.int64).reshape(-1)
        tidx = np.asarray(baked.tex_indices, dtype=np.int64).reshape(-1, 3)
        rows = {"tex_uv": tuv, "tex_layer": tlayer, "tex_detail_uv": tduv, "tex_material": tmat}
        for name, a in rows.items():
            if len(a) != k:
                raise RenderError(f"baked {name} has {len(a)} rows but tex_positions has {k}")
        _check_indices(tidx, k, "baked tex_indices")

        details = dict(getattr(baked, "detail_textures", None) or {})
        tdetail = getattr(baked, "tex_detail", None)
        if tdetail is None:
            tdetail = np.isin(tmat, list(details)).astype(np.float32)
        else:
            tdetail = np.asarray(tdetail, dtype=np.float32).reshape(-1)
            if len(tdetail) != k:
                raise RenderError(f"baked tex_detail has {len(tdetail)} rows but tex_positions has {k}")
        # a triangle goes to its material's detail draw call when its first vertex asks for detail
        tri_key = np.full(len(tidx), -1, np.int64)
        if len(tidx) and details:
            v0 = tidx[:, 0]
            use = (tdetail[v0] > 0.5) & np.isin(tmat[v0], list(details))
            tri_key[use] = tmat[v0][use]

        per_state = 0
        if len(tidx):
            scale = 1.0
            if pixel_format == "rgba8":  # GPU texel = sRGB8(page / page_scale); the shader multiplies back
                scale = getattr(baked, "page_scale", None)
                if not scale:
                    p = np.asarray(all_pages if all_pages is not None else baked.pages, np.float64)
                    scale = max(p[..., :3].max(initial=0.0), 1e-30)
            pages = self._gpu_pages(baked, all_pages, pixel_format, float(scale))
            per_state = pages.shape[0] // max(n_states, 1)
            if pages.shape[0] == 0:
                raise RenderError(f"baked has textured triangles but its pages have shape {pages.shape}")
            if tlayer.size and (tlayer.min() < 0 or tlayer.max() > per_state - 1):
                raise RenderError(f"baked tex_layer refers to page {int(tlayer.max())} of {per_state}")
            self._set_pages(pages, pixel_format, mipmaps, getattr(baked, "mip_levels", None))
            self._page_scale = float(scale)
        self._set_details("iat", {int(m): v for m, v in details.items()})
        self._iat_states, self._iat_pages = int(n_states), max(int(per_state), 1)
        self._colors["iat"] = colors
        a, b = self._pair("iat")
        self._baked_mesh.upload(
            self.ctx, self._reg, {"position": mpos, "color": colors[a], "color_b": colors[b]}, midx
        )
        self._colors_pair["iat"] = (a, b)
        if len(tidx):
            tuv = self._page_uv(tuv)
        self._baked_tex.upload(
            self.ctx,
            self._reg,
            {"position": tpos, "uv": tuv, "layer": tlayer, "detail_uv": tduv, "detail": tdetail},
            tidx,
            tri_key,
        )
        self._has["iat"] = True

    # -- drawing ----------------------------------------------------------------------------
    def _target(self, name: str, size: tuple[int, int], sampled: bool) -> _Target:
        t = self._targets.get(name)
        if t is not None and t.size == size:
            return t
        if t is not None:
            if self.ctx.fbo is t.fbo:
                self._home.use()
            for o in (t.fbo, t.color, t.depth):
                self._reg.release(o)
        ctx = self.ctx
        if sampled:
            color = self._reg.add(ctx.texture(size, 4, dtype="f4"))
            color.filter = (self._moderngl.NEAREST, self._moderngl.NEAREST)
        else:
            color = self._reg.add(ctx.renderbuffer(size, 4, dtype="f4"))
        depth = self._reg.add(ctx.depth_renderbuffer(size))
        fbo = self._reg.add(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
        t = self._targets[name] = _Target(size, color, depth, fbo)
        return t

    def _need(self, mode: str) -> None:
        what = {"preview": "set_scene", "mesh": "set_solution", "iat": "set_baked"}
        for m in {"split": ("mesh", "iat"), "diff": ("mesh", "iat")}.get(mode, (mode,)):
            if not self._has[m]:
                raise RenderError(f"mode {mode!r} needs {what[m]}() first")

    @staticmethod
    def _uniforms(prog, values: dict) -> None:
        for name, v in values.items():
            if prog.get(name, None) is not None:
                if name == "clip_from_world":
                    prog[name].write(v)
                else:
                    prog[name].value = v

    def _draw_mode(self, mode: str, clip: bytes, exposure: float, tonemap: bool, stats: dict) -> None:
        """Draw one of preview / mesh / iat into the bound framebuffer, counting triangles and calls."""
        common = {"clip_from_world": clip, "exposure": float(exposure), "tonemap": bool(tonemap)}
        tris = calls = 0
        w = float(self._blend[2])
        if mode == "mesh" or mode == "iat":
            g = self._solution if mode == "mesh" else self._baked_mesh
            pa, pb = self._pair(mode)
            if g.n_triangles:
                self._uniforms(g.program, {**common, "blend": w if pa != pb else 0.0})
                for _, first, count in g.calls():
                    g.render_range(first, count)
                    tris, calls = tris + count // 3, calls + 1
        if mode == "iat" and self._baked_tex.n_triangles:
            g = self._baked_tex
            self._pages.use(0)
            pa, pb = self._pair("iat")
            blend = {
                "layer_a": float(pa * self._iat_pages),
                "layer_b": float(pb * self._iat_pages),
                "blend": w if pa != pb else 0.0,
            }
            pages = {"pages": 0, "detail": 1, "page_scale": self._page_scale}
            self._uniforms(g.program, {**common, **blend, **pages})
            for key, first, count in g.calls():
                tex = self._detail["iat"].get(key)
                (tex if tex is not None else self._white).use(1)
                self._uniforms(g.program, {"use_detail": tex is not None})
                g.render_range(first, count)
                tris, calls = tris + count // 3, calls + 1
        if mode == "preview" and self._preview.n_triangles:
            g = self._preview
            self._uniforms(g.program, {**common, "detail": 1, "ambient": PREVIEW_AMBIENT})
            for key, first, count in g.calls():
                tex = self._detail["preview"].get(key)
                (tex if tex is not None else self._white).use(1)
                self._uniforms(g.program, {"use_detail": tex is not None})
                g.render_range(first, count)
                tris, calls = tris + count // 3, calls + 1
        s = stats.setdefault(mode, {"triangles": 0, "draw_calls": 0})
        s["triangles"] += tris
        s["draw_calls"] += calls

    def _frame(self, target, viewport, camera, mode, exposure, tonemap, split, diff_gain, clear) -> None:
        if mode not in MODES:
            raise RenderError(f"unknown render mode {mode!r} (known: {', '.join(MODES)})")
        self._alive()
        self._need(mode)
        ctx, mgl = self.ctx, self._moderngl
        x, y, w, h = (int(v) for v in viewport)
        if w <= 0 or h <= 0:
            raise RenderError(f"empty viewport {tuple(viewport)}")
        clip = np.asarray(camera.clip_from_world(w / h), dtype=np.float64).T.astype("f4").tobytes()
        stats: dict[str, dict] = {}
        ctx.enable(mgl.DEPTH_TEST)
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        try:
            if mode == "diff":
                for name, sub in (("diff_a", "mesh"), ("diff_b", "iat")):
                    t = self._target(name, (w, h), sampled=True)
                    t.fbo.use()
                    t.fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
                    self._draw_mode(sub, clip, 1.0, False, stats)
                target.use()
                ctx.viewport = (x, y, w, h)
                ctx.disable(mgl.DEPTH_TEST)
                self._targets["diff_a"].color.use(0)
                self._targets["diff_b"].color.use(1)
                prog = self._programs["composite"]
                self._uniforms(
                    prog,
                    {
                        "image_a": 0,
                        "image_b": 1,
                        "offset": (x, y),
                        "gain": float(diff_gain),
                        "exposure": float(exposure),
                        "tonemap": bool(tonemap),
                    },
                )
                self._fullscreen.render(mgl.TRIANGLES, vertices=3)
            else:
                target.use()
                ctx.viewport = (x, y, w, h)
                if clear:
                    target.clear(0.0, 0.0, 0.0, 1.0, depth=1.0, viewport=(x, y, w, h))
                if mode == "split":
                    sw = int(round(min(max(float(split), 0.0), 1.0) * w))
                    ctx.scissor = (x, y, sw, h)
                    self._draw_mode("mesh", clip, exposure, tonemap, stats)
                    ctx.scissor = (x + sw, y, w - sw, h)
                    self._draw_mode("iat", clip, exposure, tonemap, stats)
                    ctx.scissor = None
                else:
                    self._draw_mode(mode, clip, exposure, tonemap, stats)
        finally:
            ctx.disable(mgl.DEPTH_TEST)
        self._last = {
            "mode": mode,
            "triangles": sum(s["triangles"] for s in stats.values()),
            "draw_calls": sum(s["draw_calls"] for s in stats.values()) + (mode == "diff"),
            "modes": stats,
        }

    def render(
        self,
        camera,
        size: tuple[int, int] = (640, 480),
        mode: str = "mesh",
        exposure: float | None = None,
        split: float = 0.5,
        diff_gain: float = 1.0,
    ) -> np.ndarray:
        """Draw offscreen and return ``(h, w, 3) float32`` linear radiance, row 0 at the top.

        camera : anything with ``clip_from_world(aspect) -> (4, 4)`` (a :class:`~iat.camera.Camera`)
        size : (w, h) pixels; the aspect ratio is w / h
        mode : "mesh" | "iat" | "preview" | "split" | "diff"
        exposure : None (radiance as is) or a multiplier applied in the shader; never a tone map
        split : fraction of the width drawn in mesh mode (split mode)
        diff_gain : multiplier on |mesh - iat| (diff mode)
        """
        self._alive()
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise RenderError(f"bad image size {size}")
        prev = self.ctx.fbo
        if prev is None or isinstance(prev.mglo, self._moderngl.InvalidObject):  # none, or released
            prev = self._home
        t = self._target("out", (w, h), sampled=False)
        e = 1.0 if exposure is None else float(exposure)
        try:
            self._frame(t.fbo, (0, 0, w, h), camera, mode, e, False, split, diff_gain, True)
            self.ctx.finish()
            raw = t.fbo.read(viewport=(0, 0, w, h), components=3, dtype="f4", alignment=1)
        finally:
            prev.use()  # leave the caller's framebuffer (and its viewport) bound
        return np.frombuffer(raw, dtype=np.float32).reshape(h, w, 3)[::-1].copy()

    def draw(
        self,
        camera,
        mode: str,
        viewport: tuple[int, int, int, int],
        exposure: float = 1.0,
        tonemap: bool = True,
        split: float = 0.5,
        diff_gain: float = 1.0,
        clear: bool = True,
        target=None,
    ) -> None:
        """Draw into ``target`` (default: the bound framebuffer, ``ctx.fbo``) inside ``viewport``.

        viewport : (x, y, w, h) in the target's pixels (GL convention, y up)
        tonemap : True for a display framebuffer (exposure, clamp, sRGB encode in the shader);
                  False writes exposure x linear radiance (float targets)
        clear : clear colour (black) and depth inside the viewport first
        """
        self._alive()
        target = target if target is not None else self.ctx.fbo
        if target is None:
            raise RenderError("draw() needs a bound framebuffer (or target=); use render() headless")
        self._frame(target, viewport, camera, mode, exposure, tonemap, split, diff_gain, clear)

    def stats(self) -> dict:
        """Counts of the last frame: ``{"mode", "triangles", "draw_calls", "modes": {mode: {"triangles",
        "draw_calls"}}, "gl_objects"}`` (split and diff list both mesh and iat under "modes")."""
        out = dict(self._last)
        out["modes"] = {k: dict(v) for k, v in self._last["modes"].items()}
        out["gl_objects"] = len(self._reg)
        return out
