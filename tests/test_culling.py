"""The solver's compact per-shooter bookkeeping (issue 41: a large building's solve held a (P,)
array per shooter and grew to 8.5 GB): sparse culling counts that decide as the dense ones did,
bit-packed masks, and the C heap's mmap threshold."""

from __future__ import annotations

import platform

import numpy as np
import pytest

from iat.radiosity.culling import CullCounts, pack, unpack
from iat.radiosity.options import CULL_RAYS


def test_sparse_counts_hide_what_dense_counts_hide():
    """Gathers of three shooters over 1 000 patches, some receivers of a patch seeing, some not:
    the patches hidden per shooter are those of the dense sums (rays >= CULL_RAYS, none seen), and a
    shooter keeps rows only for the patches its rays reached."""
    rng = np.random.default_rng(7)
    P = 1000
    counts = CullCounts()
    dense = {s: (np.zeros(P), np.zeros(P)) for s in range(3)}
    for _ in range(40):
        s = int(rng.integers(3))
        patch = np.sort(rng.integers(100 * s, 100 * s + 150, size=int(rng.integers(0, 60))))
        rays = rng.integers(1, 40, size=len(patch)).astype(np.float64)
        seen = np.where(rng.random(len(patch)) < 0.3, rays * rng.random(len(patch)), 0.0)
        counts.add(s, patch, rays, seen)
        np.add.at(dense[s][0], patch, rays)
        np.add.at(dense[s][1], patch, seen)
    hidden_any = 0
    for s, (r, v) in dense.items():
        want = np.flatnonzero((r >= CULL_RAYS) & (v == 0))
        np.testing.assert_array_equal(np.sort(counts.hidden(s)), want)
        assert set(counts.rows[s][0].tolist()) == set(np.flatnonzero(r > 0).tolist())
        hidden_any += len(want)
    assert hidden_any > 0  # the case tests something


@pytest.mark.parametrize("n", [1, 7, 8, 9, 1001])
def test_packed_masks_come_back(n):
    mask = np.random.default_rng(n).random(n) < 0.4
    bits = pack(mask)
    assert bits.nbytes == -(-n // 8)
    back = unpack(bits, n)
    assert back.dtype == bool
    np.testing.assert_array_equal(back, mask)


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_the_mmap_threshold_is_fixed_on_glibc():
    from iat.radiosity.heap import fix_mmap_threshold

    assert fix_mmap_threshold() is True
