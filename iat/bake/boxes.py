"""Tile boxes and the pages made of them.

A box is a scaled tile with its boundary ring replaced by the harmonised one (when it has one),
divided by the albedo on detail patches, padded by edge replication to the gutter and the mip
alignment, in its GPU form (:func:`~iat.bake.formats.to_gpu`): :func:`build_boxes`. Its
``source = (tile, ring, is_tri, factor)`` rebuilds the float32 box (:func:`box_source_tile`).
:class:`PageEntry` holds the blitted GPU pages and makes the float32 pages on demand.
"""

from __future__ import annotations

import numpy as np

from iat.bake import atlas
from iat.bake.flatten import extend_triangle, populated_empty
from iat.bake.formats import GPU_DTYPES, from_gpu, to_gpu
from iat.bake.seams import ring_index

#: tiles per chunk when boxes are built (float32 temporaries of a few MB, reused)
BOX_CHUNK_BYTES = 2 << 20


def build_boxes(
    tiles: list,
    rings: list,
    is_tri: np.ndarray,
    factors: list,
    gutter: int,
    align: int,
    pixel_format: str,
    page_scale: float = 1.0,
) -> list:
    """``[(source, GPU-form (bs, bs, 4) box)]`` of (scaled) ``tiles`` ``(n, n, 3)`` float32.

    rings : per tile, its harmonised boundary ring ``(ring length, 3)`` (:func:`ring_index`
      order; triangles re-extended) or None; is_tri : (k,) bool
    factors : per tile, the ``(3,)`` float32 detail divisor (1 / albedo) or None
    gutter, align : the box is the tile plus ``gutter`` texels each side, rounded up to ``align``
    pixel_format, page_scale : the GPU form (rgba8 stores sRGB8 of ``value / page_scale``)
    Tiles of one side are done together, in chunks whose float32 temporary is reused; only the
    GPU form is kept.
    """
    out: list = [None] * len(tiles)
    if not len(tiles):
        return out
    sides = np.array([t.shape[0] for t in tiles], dtype=np.int64)
    g = gutter
    gdt = GPU_DTYPES[pixel_format]
    has_ring = np.array([r is not None for r in rings], dtype=bool)
    has_factor = np.array([f is not None for f in factors], dtype=bool)
    for n in np.unique(sides).tolist():
        sel = np.flatnonzero(sides == n)
        bs = int(atlas.align_up(n + 2 * g, align))
        gpu = populated_empty((len(sel), bs, bs, 4), gdt)
        step = max(1, BOX_CHUNK_BYTES // (bs * bs * 12))
        buf = np.empty((min(step, len(sel)), bs, bs, 3), dtype=np.float32)
        for c0 in range(0, len(sel), step):
            chunk = sel[c0 : c0 + step]
            b = buf[: len(chunk)]
            inner = b[:, g : g + n, g : g + n]
            for j, q in enumerate(chunk.tolist()):
                inner[j] = tiles[q]
            for tri in (False, True):  # harmonised rings, one scatter per kind
                js = np.flatnonzero(has_ring[chunk] & (is_tri[chunk] == tri))
                if not len(js):
                    continue
                rows, cols = ring_index(n, tri)
                inner[js[:, None], rows[None], cols[None]] = np.stack([rings[q] for q in chunk[js].tolist()])
                if tri:
                    inner[js] = extend_triangle(inner[js])
            dj = np.flatnonzero(has_factor[chunk])
            if len(dj):
                inner[dj] *= np.stack([factors[q] for q in chunk[dj].tolist()])[:, None, None, :]
            if g or bs > n:  # edge replication, as np.pad(mode="edge")
                b[:, :g, g : g + n] = inner[:, :1]
                b[:, g + n :, g : g + n] = inner[:, -1:]
                b[:, :, :g] = b[:, :, g : g + 1]
                b[:, :, g + n :] = b[:, :, g + n - 1 : g + n]
            to_gpu(b, pixel_format, page_scale, out=gpu[c0 : c0 + len(chunk)])
        for j, q in enumerate(sel.tolist()):
            out[q] = ((tiles[q], rings[q], bool(is_tri[q]), factors[q]), gpu[j])
    return out


def box_source_tile(src) -> np.ndarray:
    """The float32 tile a box was padded from: ``src = (tile, ring or None, is_tri, factor or
    None)`` (the scaled tile, its harmonised boundary ring, and the detail divisor)."""
    tile, ring, is_tri, factor = src
    t = np.array(tile, dtype=np.float32, copy=True)
    if ring is not None:
        rows, cols = ring_index(t.shape[0], is_tri)
        t[rows, cols] = ring
        if is_tri:
            extend_triangle(t[None])
    if factor is not None:
        t *= factor
    return t


class PageEntry:
    """One cached set of pages: the GPU form (built by the bake) and the float32 pages, made on
    first use (export, seams, tests) and kept: from the GPU form for the quantised formats (it
    holds exactly the stored values), else blitted from the boxes' sources (:func:`box_source_tile`)."""

    def __init__(self, gpu: np.ndarray, sources: list, packing: atlas.Packing, policy, align: int, scale8):
        self.gpu = gpu
        self._sources, self._packing, self._align = sources, packing, align
        self._fmt, self._gutter, self._scale8 = policy.pixel_format, policy.gutter, scale8
        self._float32: np.ndarray | None = None

    def float32(self) -> np.ndarray:
        if self._float32 is None:
            n, h, w = self.gpu.shape[:3]
            if self._fmt in ("rgba8", "rgb9e5"):
                pages = np.ascontiguousarray(from_gpu(self.gpu, self._fmt, self._scale8))
            else:
                pages = np.zeros((n, h, w, 3), dtype=np.float32)
                if self._sources:
                    tiles = [box_source_tile(src) for src in self._sources]
                    atlas.blit(pages, tiles, self._packing.placements, self._gutter, self._align)
            pages.flags.writeable = False
            self._float32 = pages
        return self._float32
