"""iat.atlas: shelf packing, gutters, mip rule."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from iat.bake.atlas import align_up, blit, blit_boxes, mip_chain_texels, mip_levels, pack
from iat.errors import BakeError


def occupancy(packing, sizes):
    """Per-page count of boxes covering each texel; also checks bounds and alignment."""
    occ = np.zeros((packing.n_pages, packing.height, packing.width), dtype=np.int32)
    g, a = packing.gutter, packing.align
    for (p, x, y), (bw, bh) in zip(packing.placements, packing.boxes, strict=True):
        x0, y0 = x - g, y - g
        assert 0 <= p < packing.n_pages
        assert x0 >= 0 and y0 >= 0 and x0 + bw <= packing.width and y0 + bh <= packing.height
        assert x0 % a == 0 and y0 % a == 0 and bw % a == 0 and bh % a == 0
        occ[p, y0 : y0 + bh, x0 : x0 + bw] += 1
    return occ


@settings(max_examples=60, deadline=None)
@given(
    sides=st.lists(st.tuples(st.integers(1, 40), st.integers(1, 40)), min_size=1, max_size=60),
    gutter=st.integers(0, 4),
    align=st.sampled_from([1, 2, 4]),
    page=st.sampled_from([64, 128]),
    shrink=st.booleans(),
)
def test_no_overlaps_property(sides, gutter, align, page, shrink):
    sizes = np.array(sides)
    boxes = align_up(sizes + 2 * gutter, align)
    if (boxes > page).any():
        with pytest.raises(BakeError, match="larger than"):
            pack(sizes, page, gutter, align, shrink)
        return
    pk = pack(sizes, page, gutter, align, shrink)
    occ = occupancy(pk, sizes)
    assert occ.max() <= 1
    assert 0 < pk.utilisation <= 1
    assert pk.utilisation == pytest.approx(
        (sizes[:, 0] * sizes[:, 1]).sum() / (pk.n_pages * pk.width * pk.height)
    )
    assert pk.width <= page and pk.height <= page
    if pk.n_pages > 1:
        assert (pk.width, pk.height) == (page, page)


def test_ten_thousand_tiles_pack_without_overlap():
    rng = np.random.default_rng(0)
    n = (1 << rng.integers(0, 6, 10_000)) + 1
    sizes = np.stack([n, n], axis=1)
    pk = pack(sizes, 4096, 2, 2)
    assert occupancy(pk, sizes).max() <= 1
    assert 0 < pk.utilisation <= 1


def test_shrinks_a_single_page_to_a_small_power_of_two():
    pk = pack([[5, 5], [5, 5]], page_size=2048, gutter=2, align=2)
    # boxes 10 x 10: 16 x 16 holds only one shelf of one, 32 x 16 holds both
    assert (pk.n_pages, pk.width, pk.height) == (1, 32, 16)
    assert pk.utilisation == pytest.approx(50 / 512)
    full = pack([[5, 5], [5, 5]], page_size=2048, gutter=2, align=2, shrink=False)
    assert (full.width, full.height) == (2048, 2048)


def test_tile_larger_than_page_names_patch_and_size():
    with pytest.raises(BakeError, match=r"patch 17 is 70x70 texels \(74x74 with gutters\)"):
        pack([[5, 5], [70, 70]], page_size=64, gutter=2, names=[3, 17])


def test_empty():
    pk = pack(np.zeros((0, 2), int))
    assert pk.n_pages == 0 and pk.utilisation == 0.0


def test_blit_replicates_edges_into_the_gutter():
    rng = np.random.default_rng(1)
    tiles = [rng.random((5, 5, 3)).astype(np.float32), rng.random((3, 3, 3)).astype(np.float32)]
    g, a = 2, 2
    pk = pack([[5, 5], [3, 3]], page_size=64, gutter=g, align=a)
    pages = np.full((pk.n_pages, pk.height, pk.width, 3), -1.0, dtype=np.float32)
    blit(pages, tiles, pk.placements, g, a)
    for t, (p, x, y), (bw, bh) in zip(tiles, pk.placements, pk.boxes, strict=True):
        h, w = t.shape[:2]
        box = pages[p, y - g : y - g + bh, x - g : x - g + bw]
        # every box texel = the nearest tile texel (edge clamp), gutter >= g on every side
        r = np.clip(np.arange(bh) - g, 0, h - 1)
        c = np.clip(np.arange(bw) - g, 0, w - 1)
        np.testing.assert_array_equal(box, t[r][:, c])
    # the same through pre-padded boxes
    pages2 = np.full_like(pages, -1.0)
    padded = []
    for t, (bw, bh) in zip(tiles, pk.boxes, strict=True):
        h, w = t.shape[:2]
        padded.append(np.pad(t, ((g, bh - h - g), (g, bw - w - g), (0, 0)), mode="edge"))
    blit_boxes(pages2, padded, pk.placements, g)
    np.testing.assert_array_equal(pages2, pages)


def test_mip_rule():
    assert [mip_levels(g) for g in (0, 1, 2, 3, 4, 7, 8)] == [1, 1, 2, 2, 3, 3, 4]
    assert mip_levels(4, mipmaps=False) == 1
    assert mip_chain_texels(32, 16, 1) == 512
    assert mip_chain_texels(32, 16, 2) == 512 + 128
    assert mip_chain_texels(4, 2, 4) == 8 + 2 + 1 + 1


def _foreign_taps(g: int, levels: int) -> int:
    """Bilinear taps at the coarsest level, at every polygon corner, that read another tile's texels."""
    a = 1 << (levels - 1)
    tiles = [
        np.full((5, 5, 3), 1.0, np.float32),
        np.full((9, 9, 3), 7.0, np.float32),
        np.full((3, 3, 3), 3.0, np.float32),
    ]
    pk = pack([[5, 5], [9, 9], [3, 3]], page_size=64, gutter=g, align=a)
    pages = np.zeros((pk.n_pages, pk.height, pk.width, 3), np.float32)
    blit(pages, tiles, pk.placements, g, a)
    f = 1 << (levels - 1)
    coarse = pages[0].reshape(pk.height // f, f, pk.width // f, f, 3).mean(axis=(1, 3))
    bad = 0
    for t, (_, x, y) in zip(tiles, pk.placements, strict=True):
        n = t.shape[0]
        for cx in (x + 0.5, x + n - 0.5):  # polygon corners = texel centres, in base texels
            for cy in (y + 0.5, y + n - 0.5):
                ix, iy = int(np.floor(cx / f - 0.5)), int(np.floor(cy / f - 0.5))
                rows = np.clip([iy, iy + 1], 0, coarse.shape[0] - 1)  # clamp-to-edge
                cols = np.clip([ix, ix + 1], 0, coarse.shape[1] - 1)
                bad += int(not np.all(coarse[rows][:, cols] == t[0, 0]))
    return bad


def test_gutter_covers_the_coarsest_mip_footprint():
    """Mip levels allowed by the rule: bilinear taps near a tile's corners read only its own texels."""
    for g in (1, 2, 3, 4):
        assert _foreign_taps(g, mip_levels(g)) == 0
    # the rule is one level conservative (exact bilinear bound: 2**l <= 2 g + 1), and beyond it taps bleed
    assert _foreign_taps(1, 3) > 0
    assert _foreign_taps(2, 4) > 0
