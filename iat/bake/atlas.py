"""Packing tiles into atlas pages with gutters (report §5.5).

A tile of ``w x h`` texels is placed inside a *box* of
``align_up(w + 2 g) x align_up(h + 2 g)`` texels (``g`` = gutter, ``align_up``
rounds up to a multiple of ``align``); box origins are multiples of ``align``.
The tile's texel (0, 0) sits at ``(x, y) = box origin + g``; the ring around
the tile, at least ``g`` texels wide (wider on the far sides when alignment
rounds the box up), repeats the tile's edge texels (:func:`blit`).

Mip levels and the gutter. A box-filtered mip level ``l`` texel covers
``2**l x 2**l`` base texels; with box origins and sizes aligned to ``2**l`` no
level-``l`` texel mixes two boxes. Bilinear filtering at level ``l`` of a point
of the polygon (whose edge lies on the edge texel centres) reads level-``l``
texels reaching ``2**(l-1) + 1/2`` base texels beyond the tile edge, so the
exact bound is ``2**l <= 2 g + 1``. We keep one level of slack (trilinear blends
and anisotropic footprints reach further):

    levels = 1 + floor(log2(gutter))   (1 when gutter == 0: no mip chain)
    align  = 2 ** (levels - 1)          (box origins and box sizes)

(:func:`mip_levels`; tests/test_atlas.py checks that the rule never reads a
neighbour and that going past the exact bound does). Page sides are powers of
two, hence multiples of ``align``.

Packing is shelf packing sorted by box height (tallest first), vectorised per
run of equal boxes: the Python loop runs once per shelf and per size class,
never per tile (10 000 tiles pack in a few ms). A tile whose box is larger than
a page raises :class:`~iat.errors.BakeError` naming the tile (the patch when
``names`` is given) and its size; nothing is downscaled silently.

Orientation: pages are ``(n_pages, H, W, 3)``; the tile's row ``b`` lies on page
row ``y + b``, column ``a`` on page column ``x + a``; the texel centre of tile
texel ``(a, b)`` has atlas coordinates ``((x + a + 0.5) / W, (y + b + 0.5) / H)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iat.errors import BakeError

__all__ = ["Packing", "align_up", "blit", "blit_boxes", "mip_chain_texels", "mip_levels", "pack"]


def mip_levels(gutter: int, mipmaps: bool = True) -> int:
    """Mip levels whose bilinear footprint stays inside the gutter: ``1 + floor(log2 gutter)``."""
    if not mipmaps or gutter < 1:
        return 1
    return 1 + int(np.floor(np.log2(int(gutter))))


def mip_chain_texels(width: int, height: int, levels: int) -> int:
    """Texels of ``levels`` mip levels of a ``width x height`` image (sides halved, floor, min 1)."""
    return sum(max(1, width >> lv) * max(1, height >> lv) for lv in range(max(1, levels)))


def align_up(x, a: int):
    """Round up to a multiple of ``a`` (ints or int arrays)."""
    a = int(a)
    return (np.asarray(x) + a - 1) // a * a


@dataclass
class Packing:
    """Where the tiles went.

    placements : (k, 3) int64 ``[page, x, y]`` of each tile's texel (0, 0)
    boxes : (k, 2) int64 box size ``[bw, bh]`` (tile + gutters, aligned)
    n_pages, width, height : page count and page size in texels
    utilisation : tile texels / page texels, in (0, 1] (0 when empty)
    gutter, align : as packed
    """

    placements: np.ndarray
    boxes: np.ndarray
    n_pages: int
    width: int
    height: int
    utilisation: float
    gutter: int
    align: int


def _shelf(bw, bh, width, height):
    """Shelf-pack boxes (already sorted by height desc) into pages; returns (page, bx, by) or None."""
    k = len(bw)
    page = np.zeros(k, dtype=np.int64)
    bx = np.zeros(k, dtype=np.int64)
    by = np.zeros(k, dtype=np.int64)
    if k == 0:
        return page, bx, by, 0
    # runs of equal boxes
    change = np.flatnonzero((np.diff(bw) != 0) | (np.diff(bh) != 0)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [k]])
    pg, y, shelf_h, x = 0, 0, 0, 0
    for s, e in zip(starts.tolist(), ends.tolist(), strict=True):
        w, h = int(bw[s]), int(bh[s])
        i = s
        while i < e:
            if shelf_h == 0:
                if y + h > height:
                    pg, y = pg + 1, 0
                shelf_h, x = h, 0
            fit = (width - x) // w
            if fit <= 0:
                y, shelf_h = y + shelf_h, 0
                continue
            take = min(fit, e - i)
            page[i : i + take] = pg
            bx[i : i + take] = x + w * np.arange(take)
            by[i : i + take] = y
            x += take * w
            i += take
    return page, bx, by, pg + 1


def pack(
    sizes,
    page_size: int = 4096,
    gutter: int = 2,
    align: int = 1,
    shrink: bool = True,
    names=None,
) -> Packing:
    """Shelf-pack tiles into square pages of ``page_size`` texels.

    sizes : (k, 2) ints, tile ``[w, h]`` in texels
    page_size : page side (a power of two)
    gutter : texels of edge replication around every tile
    align : box origins and sizes are multiples of this (a power of two; see :func:`mip_levels`)
    shrink : when everything fits in one page, use the smallest power-of-two page
      (``S x S`` or ``S x S/2``) that holds it, instead of a full ``page_size`` page
    names : (k,) labels for error messages (patch indices); default the tile index

    Raises BakeError when a tile's box is larger than a page.
    """
    sizes = np.asarray(sizes, dtype=np.int64).reshape(-1, 2)
    k = len(sizes)
    page_size, gutter, align = int(page_size), int(gutter), max(1, int(align))
    boxes = align_up(sizes + 2 * gutter, align).astype(np.int64)
    if k == 0:
        return Packing(np.zeros((0, 3), np.int64), boxes, 0, 0, 0, 0.0, gutter, align)
    too_big = np.flatnonzero((boxes > page_size).any(axis=1))
    if len(too_big):
        q = int(too_big[0])
        name = q if names is None else np.asarray(names)[q]
        raise BakeError(
            f"texture of patch {name} is {sizes[q, 0]}x{sizes[q, 1]} texels "
            f"({boxes[q, 0]}x{boxes[q, 1]} with gutters), larger than the {page_size}x{page_size} "
            "atlas page; lower the scale, raise the threshold or use a larger page"
        )
    order = np.lexsort((-boxes[:, 0], -boxes[:, 1]))  # height desc, then width desc
    bw, bh = boxes[order, 0], boxes[order, 1]
    candidates = [(page_size, page_size)]
    if shrink:
        area = int((bw * bh).sum())
        s = max(int(align), int(2 ** np.ceil(np.log2(max(1, int(bw.max()), int(bh.max()))))))
        while s * s < area:
            s *= 2
        small = []
        while s <= page_size:
            if s // 2 >= bh.max():
                small.append((s, s // 2))
            if s < page_size:
                small.append((s, s))
            s *= 2
        candidates = small + candidates
    best = None
    for w, h in candidates:
        if (bw * bh).sum() > w * h and (w, h) != (page_size, page_size):
            continue
        page, bx, by, n_pages = _shelf(bw, bh, w, h)
        if n_pages == 1 or (w, h) == (page_size, page_size):
            best = (page, bx, by, n_pages, w, h)
            break
    page, bx, by, n_pages, w, h = best
    placements = np.empty((k, 3), dtype=np.int64)
    placements[order, 0] = page
    placements[order, 1] = bx + gutter
    placements[order, 2] = by + gutter
    util = float((sizes[:, 0] * sizes[:, 1]).sum()) / float(n_pages * w * h)
    return Packing(placements, boxes, int(n_pages), int(w), int(h), util, gutter, align)


def blit(pages: np.ndarray, tiles, placements, gutter: int, align: int = 1) -> np.ndarray:
    """Write tiles into pages with edge-replicated gutters; returns ``pages``.

    pages : (n_pages, H, W, C) array, written in place
    tiles : sequence of (h, w, C) arrays; placements : (k, 3) ``[page, x, y]`` of texel (0, 0)
    The ring of ``gutter`` texels (more on the far sides, up to the aligned box) repeats
    the nearest edge texel of the tile.
    """
    placements = np.asarray(placements, dtype=np.int64)
    g = int(gutter)
    for t, (p, x, y) in zip(tiles, placements.tolist(), strict=True):
        h, w = t.shape[:2]
        bw, bh = int(align_up(w + 2 * g, align)), int(align_up(h + 2 * g, align))
        x0, y0 = x - g, y - g
        x1, y1 = x0 + bw, y0 + bh
        pg = pages[p]
        pg[y : y + h, x : x + w] = t
        if g or bw > w or bh > h:
            pg[y0:y, x : x + w] = t[:1]
            pg[y + h : y1, x : x + w] = t[-1:]
            pg[y0:y1, x0:x] = pg[y0:y1, x : x + 1]
            pg[y0:y1, x + w : x1] = pg[y0:y1, x + w - 1 : x + w]
    return pages


def blit_boxes(pages: np.ndarray, boxes_data, placements, gutter: int) -> np.ndarray:
    """Write already padded boxes (``(bh, bw, C)`` with the tile at offset ``gutter``); returns ``pages``."""
    g = int(gutter)
    for t, (p, x, y) in zip(boxes_data, np.asarray(placements, dtype=np.int64).tolist(), strict=True):
        bh, bw = t.shape[:2]
        pages[p, y - g : y - g + bh, x - g : x - g + bw] = t
    return pages
