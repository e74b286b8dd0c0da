"""What share of each patch's light stays in the scene (:func:`kept_fraction`), by which a shot's
share of the light is judged (``SolveRun.samples_by_power``).

In an open scene much of the light the surfaces receive leaves it at the next bounce: a roof in the
sun reflects it to the sky. Measured against all the power the scene received, a room's own shots
(its ceiling's, its walls') are a tiny share and got one sample; one pattern serves all of a shot's
receivers, so such a shot threw its light from one point onto the whole room, and with more shots
the errors added up instead of averaging. Measured against the received power weighted by this
share (``power_kept``), they are what they are to the room; a closed scene weighs every patch 1, so
its solves are unchanged to the bit.
"""

from __future__ import annotations

import numpy as np

from iat.radiosity.sampling import concentric_disk

#: rays per patch (a square number: stratified over the patch and the hemisphere at once)
OPENNESS_RAYS = 64
#: a scene whose patches all keep at least this share is closed: every patch weighs 1
CLOSED_SHARE = 0.99
#: patches a block of rays (bounds the temporaries: a million-triangle model holds 0.5 M patches)
OPENNESS_BLOCK = 8192


def kept_fraction(patches, vis, seed: int = 0) -> np.ndarray:
    """(P,) float64 in [0, 1]: the share of cosine-distributed rays from points spread over each
    patch's front (:data:`OPENNESS_RAYS`, stratified in the patch's lattice and over the disc, one
    direction a point) that meet an opaque surface of ``vis`` within 4 scene diagonals; all 1 when
    every patch keeps :data:`CLOSED_SHARE` or more (a closed scene: rays lost at seams change nothing).

    patches : :class:`~iat.radiosity.patches.Patches`; vis : their
    :class:`~iat.radiosity.visibility.Visibility`.
    """
    P = patches.n_patches
    m = int(round(np.sqrt(OPENNESS_RAYS)))
    rng = np.random.default_rng(seed)
    kept = np.ones(P)
    for a in range(0, P, OPENNESS_BLOCK):
        sl = slice(a, min(a + OPENNESS_BLOCK, P))
        origins, dirs = _rays(patches, sl, m, rng)
        tfar = np.full(len(origins), 4.0 * patches.scale, dtype=np.float32)
        hit, _ = vis.first_hits(origins, dirs, tfar)
        kept[sl] = (hit.reshape(sl.stop - sl.start, m * m) >= 0).mean(axis=1)
    return kept if P and kept.min() < CLOSED_SHARE else np.ones(P)


def _rays(patches, sl: slice, m: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Origins and directions ((b m^2, 3) float32 each) of patches ``sl``: a jittered m x m grid of
    each patch's lattice, each point with a cosine-distributed direction from the disc's m x m cells
    in shuffled order, the origins lifted by ``eps_ray`` off the front."""
    b, k = sl.stop - sl.start, m * m
    j = np.arange(k)
    gu, gv = (j % m + rng.random((b, k))) / m, (j // m + rng.random((b, k))) / m
    perm = rng.permuted(np.tile(j, (b, 1)), axis=1)
    du, dv = (perm % m + rng.random((b, k))) / m, (perm // m + rng.random((b, k))) / m
    c = patches.corners[sl]  # (b, 4, 3); a triangle repeats corner 2 in slot 3
    u, v = gu[..., None], gv[..., None]
    bil = (1 - u) * (1 - v) * c[:, None, 0] + u * (1 - v) * c[:, None, 1] + u * v * c[:, None, 2]
    bil = bil + (1 - u) * v * c[:, None, 3]
    fold = u + v > 1.0  # a triangle: the square folded onto it
    tu, tv = np.where(fold, 1.0 - v, u), np.where(fold, 1.0 - u, v)
    tri = (1 - tu - tv) * c[:, None, 0] + tu * c[:, None, 1] + tv * c[:, None, 2]
    points = np.where(patches.is_quad[sl, None, None], bil, tri)
    dx, dy = concentric_disk(du, dv)
    dz = np.sqrt(np.maximum(0.0, 1.0 - dx * dx - dy * dy))
    t1, t2, n = patches.tangent[sl, 0], patches.tangent[sl, 1], patches.normal[sl]
    dirs = dx[..., None] * t1[:, None] + dy[..., None] * t2[:, None] + dz[..., None] * n[:, None]
    origins = points + patches.eps_ray * n[:, None]
    f32 = np.float32
    return np.ascontiguousarray(origins.reshape(-1, 3), f32), np.ascontiguousarray(dirs.reshape(-1, 3), f32)
