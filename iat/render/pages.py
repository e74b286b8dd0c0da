"""The IAT page texture: atlas pages in one GL texture array, their GPU form, reuse and mip levels.

Atlas convention: ``pages[layer, y, x]`` is the texel whose centre is at
``uv = ((x + 0.5) / W, (y + 0.5) / H)`` of that page (row ``y = 0`` at ``v = 0``).

The texture is kept when new pages fit in it (written into its corner, texture coordinates scaled
exactly; :meth:`PageTexture.size_for`), so it may be larger than the bake's
:class:`~iat.bake.memory.MemoryReport` counts: :meth:`PageTexture.info` gives both. The Baker's page
arrays (read-only) already on the GPU are not written again.
"""

from __future__ import annotations

import logging

import numpy as np

from iat.bake.formats import BYTES_PER_TEXEL, GPU_DTYPES, to_gpu
from iat.errors import RenderError
from iat.render.gl import Registry, respecify_texture_array

log = logging.getLogger(__name__)

#: baker pixel format -> (moderngl dtype of the upload, GL internal format or 0 for moderngl's own).
#: rgba8 is GL_SRGB8_ALPHA8 (decoded to linear before filtering and mipmapping); rgb9e5 is
#: GL_RGB9_E5, written from half floats that hold the baker's 9e5-rounded values exactly
PIXEL_FORMATS = {
    "rgba16f": ("f2", 0),
    "rgba32f": ("f4", 0),
    "rgba8": ("f1", 0x8C43),
    "rgb9e5": ("f2", 0x8C3D),
}


def gpu_pages(baked, pages: np.ndarray | None, pixel_format: str) -> tuple[np.ndarray, float]:
    """The ``(n, H, W, 4)`` array to write for ``baked`` and the scale the shader multiplies its
    texels by.

    The array: ``baked.gpu_form()`` when ``pages`` is None and the baker made one for this format
    (no conversion), else ``pages`` (float ``(n, H, W, 3)``; None: ``baked.pages``) converted by
    :func:`iat.bake.formats.to_gpu`. The scale: 1, except for rgba8, whose texel is
    ``sRGB8(page / scale)``: ``baked.page_scale``, else the pages' maximum.
    """
    scale = 1.0
    if pixel_format == "rgba8":
        scale = getattr(baked, "page_scale", None)
        if not scale:
            p = np.asarray(pages if pages is not None else baked.pages, np.float64)
            scale = max(p[..., :3].max(initial=0.0), 1e-30)
    scale = float(scale)
    if pixel_format not in PIXEL_FORMATS:
        raise RenderError(f"unknown pixel format {pixel_format!r} (known: {', '.join(PIXEL_FORMATS)})")
    if pages is None:
        gpu_form = getattr(baked, "gpu_form", None)
        g = gpu_form() if gpu_form is not None else None
        if g is not None:
            return g, scale
        pages = np.asarray(baked.pages)
    pages = np.asarray(pages)
    if pages.ndim != 4 or pages.shape[3] < 3:
        raise RenderError(f"baked pages have shape {pages.shape}, expected (n_pages, H, W, 3)")
    return to_gpu(pages, pixel_format, scale), scale


class PageTexture:
    """The page texture array of one renderer: created, written in place or grown, and released
    through the renderer's :class:`~iat.render.gl.Registry`.

    ``texture`` : the moderngl TextureArray, None before the first upload.
    """

    def __init__(self, ctx, reg: Registry):
        self._ctx = ctx
        self._reg = reg
        self.texture = None
        self._key: tuple | None = None  # (W, H, layers, pixel_format, levels) of the texture
        self._src: np.ndarray | None = None  # the array last written to it
        self._region: tuple = (0, 0, 0)  # (w, h, layers) of the pages in it (its corner)

    def forget(self) -> None:
        """Drop the texture (after the registry released it)."""
        self.texture = None

    def upload(
        self, data: np.ndarray, pixel_format: str, mipmaps: bool, mip_levels: int | None, reuse: bool
    ) -> None:
        """Upload atlas pages in their GPU form ``(n, H, W, 4)`` (:func:`gpu_pages`), written
        from the array itself (no copy); the same read-only array as last time is not written again.
        With mipmaps, only the ``mip_levels`` the atlas gutters allow are built, so coarse levels
        never blend neighbouring tiles (None: the full chain). reuse : see :meth:`size_for`."""
        import moderngl as mgl

        ctx = self._ctx
        dtype, internal = PIXEL_FORMATS[pixel_format]
        if data.ndim != 4 or data.shape[3] != 4 or data.dtype != GPU_DTYPES[pixel_format]:
            raise RenderError(
                f"{pixel_format} pages have shape {data.shape} {data.dtype}, expected (n, H, W, 4)"
            )
        n, h, w = data.shape[:3]
        max_layers = int(ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
        max_size = int(ctx.info["GL_MAX_TEXTURE_SIZE"])
        if n > max_layers or max(w, h) > max_size:
            raise RenderError(
                f"the atlas has {n} page(s) of {w}x{h}; this GL allows {max_layers} layers of at most"
                f" {max_size}x{max_size}: lower the scale, raise the threshold or set a budget"
            )
        # the mip levels are part of the key: a texture that once held a mip chain keeps it allocated
        levels = (mip_levels or 0) if mipmaps else 1
        region = (w, h, n)
        if self.texture is not None and self._key is not None and self._region == region:
            if self._key[3:] == (pixel_format, levels):
                if data is self._src and not data.flags.writeable:
                    return  # the baker's cached pages, already on the GPU with their mip levels
        for _ in range(8):  # GL error flags are sticky: clear what others left, so ours is ours
            stale = ctx.error
            if stale == "GL_NO_ERROR":
                break
            log.debug("GL error before uploading pages (not ours): %s", stale)
        key = self.size_for(w, h, n, pixel_format, levels, reuse)
        if self.texture is None or self._key != key:
            self._reg.release(self.texture)
            self.texture = None
            tex = self._reg.add(ctx.texture_array(key[:3], 4, None, dtype=dtype))
            if internal:  # re-specify level 0 with the internal format moderngl cannot ask for
                respecify_texture_array(tex, internal, dtype)
            tex.repeat_x = tex.repeat_y = False
            self.texture, self._key = tex, key
        self._src, self._region = None, region
        if key[:3] == region:
            self.texture.write(memoryview(np.ascontiguousarray(data)))
        else:  # the pages' corner of a larger array (texture coordinates are scaled to match)
            self.texture.write(memoryview(np.ascontiguousarray(data)), viewport=(0, 0, 0, w, h, n))
        if mipmaps and (mip_levels is None or mip_levels > 1):
            self.texture.build_mipmaps(0, 1000 if mip_levels is None else mip_levels - 1)
            self.texture.filter = (mgl.LINEAR_MIPMAP_LINEAR, mgl.LINEAR)
        else:
            self.texture.filter = (mgl.LINEAR, mgl.LINEAR)
        err = ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"uploading {pixel_format} pages of {w}x{h}x{n} failed: {err}")
        self._src = data

    def size_for(self, w: int, h: int, n: int, pixel_format: str, levels: int, reuse: bool) -> tuple:
        """The page texture for ``n`` pages of ``w`` x ``h``: ``(W, H, N, pixel_format, levels)``.

        With ``reuse``, the texture held now when the pages fit in its corner, else one grown to the
        largest size seen in each dimension: re-creating a 2048 x 2048 array costs 25-55 ms on
        llvmpipe, which a scale slider would pay on every step that changes the atlas size. Kept
        only when the texture coordinates scale exactly (``W / w`` and ``H / h`` powers of two: the
        Baker's pages always are), the mip levels stay inside the pages (``w`` and ``h`` multiples
        of ``2**(levels - 1)``; never for a full chain) and the pages use at least 1/64 of it (so a
        texture left large by an earlier bake is given back once the pages become much smaller).
        Without ``reuse``: exactly the pages' size.
        """

        def pow2(a: int, b: int) -> bool:
            return a % b == 0 and ((a // b) & (a // b - 1)) == 0

        exact = (w, h, n, pixel_format, levels)
        old = self._key
        if not reuse or self.texture is None or old is None or old[3:] != (pixel_format, levels):
            return exact
        if levels == 0:
            return exact
        align = 1 << max(levels - 1, 0)
        if w % align or h % align:
            return exact
        aw, ah, an = max(old[0], w), max(old[1], h), max(old[2], n)
        if not (pow2(aw, w) and pow2(ah, h)):
            return exact
        if 64 * w * h * n < aw * ah * an:
            return exact
        max_layers = int(self._ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"])
        max_size = int(self._ctx.info["GL_MAX_TEXTURE_SIZE"])
        if an > max_layers or max(aw, ah) > max_size:
            return exact
        return (aw, ah, an, pixel_format, levels)

    def info(self) -> dict:
        """``allocated`` ``(W, H, layers)`` and the ``used`` corner ``(w, h, layers)`` of the pages
        last set, their ``pixel_format`` and the ``bytes`` allocated at level 0. Empty without pages."""
        if self.texture is None or self._key is None:
            return {}
        aw, ah, an, fmt = self._key[:4]
        return {
            "allocated": (aw, ah, an),
            "used": tuple(self._region),
            "pixel_format": fmt,
            "bytes": int(aw * ah * an * BYTES_PER_TEXEL.get(fmt, 8)),
        }

    def scale_uv(self, uv: np.ndarray) -> np.ndarray:
        """(k, 2) float32 atlas UVs of the pages set last -> UVs in the texture (scaled when it is
        larger; exact: the factors are powers of two)."""
        if self._key is None or tuple(self._key[:2]) == tuple(self._region[:2]):
            return uv
        w, h = self._region[:2]
        f = np.array([w / self._key[0], h / self._key[1]], dtype=np.float32)
        return uv * f
