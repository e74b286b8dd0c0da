"""Per-shooter bookkeeping kept compact, since a large building has ~10^5 patches and shooters:
the culling counts (:class:`CullCounts`, sparse: the patches a shooter's rays reached) and
bit-packed (P,) masks (:func:`pack`, :func:`unpack`)."""

from __future__ import annotations

import numpy as np

from iat.radiosity.options import CULL_RAYS


def pack(mask: np.ndarray) -> np.ndarray:
    """(ceil(P / 8),) uint8 of a (P,) bool mask."""
    return np.packbits(mask)


def unpack(bits: np.ndarray, n: int) -> np.ndarray:
    """(n,) bool of :func:`pack`'s bits."""
    return np.unpackbits(bits, count=n).view(bool)


class CullCounts:
    """Per shooter, the rays its gathers traced to each receiver patch and how many got through,
    over all its shots: ``rows[s] = (patch (k,) int32 sorted, rays (k,) float64, seen (k,)
    float64)`` for the k patches its rays reached (a room's, not the building's). Not thread-safe:
    the caller holds its lock."""

    def __init__(self):
        self.rows: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def __contains__(self, s: int) -> bool:
        return s in self.rows

    def add(self, s: int, patch: np.ndarray, rays: np.ndarray, seen: np.ndarray) -> None:
        """Count one gather of s: per receiver (n,) its patch, rays traced and rays that got through."""
        if len(patch) == 0:
            return
        ids, inv = np.unique(patch, return_inverse=True)
        r, v = np.bincount(inv, weights=rays), np.bincount(inv, weights=seen)
        old = self.rows.get(s)
        if old is not None:
            both = np.union1d(old[0], ids)
            a, b = np.searchsorted(both, old[0]), np.searchsorted(both, ids)
            r2, v2 = np.zeros(len(both)), np.zeros(len(both))
            r2[a], v2[a] = old[1], old[2]
            r2[b] += r
            v2[b] += v
            ids, r, v = both, r2, v2
        self.rows[s] = (ids.astype(np.int32), r, v)

    def hidden(self, s: int) -> np.ndarray:
        """(h,) int32 receiver patches of s found fully occluded: ``CULL_RAYS`` rays or more, none
        through."""
        ids, r, v = self.rows[s]
        return ids[(r >= CULL_RAYS) & (v == 0)]
