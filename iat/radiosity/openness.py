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


def kept_fraction(patches, vis, seed: int = 0) -> np.ndarray:
    """(P,) float64 in [0, 1]: the share of cosine-distributed rays from points spread over each
    patch's front (:data:`OPENNESS_RAYS`, stratified in the patch's lattice and over the disc, one
    direction a point) that meet an opaque surface of ``vis`` within 4 scene diagonals; all 1 when
    every patch keeps :data:`CLOSED_SHARE` or more (a closed scene: rays lost at seams change nothing).

    patches : :class:`~iat.radiosity.patches.Patches`; vis : their
    :class:`~iat.radiosity.visibility.Visibility`.
    """
    P = patches.n_patches
    if P == 0:
        return np.ones(0)
    m = int(round(np.sqrt(OPENNESS_RAYS)))
    k = m * m
    rng = np.random.default_rng(seed)
    # points: a jittered m x m grid of the lattice; directions: the disc's m x m cells, shuffled
    j = np.arange(k)
    gu, gv = (j % m + rng.random((P, k))) / m, (j // m + rng.random((P, k))) / m
    perm = rng.permuted(np.tile(j, (P, 1)), axis=1)
    du, dv = (perm % m + rng.random((P, k))) / m, (perm // m + rng.random((P, k))) / m
    c = patches.corners  # (P, 4, 3); a triangle repeats corner 2 in slot 3
    quad = patches.is_quad[:, None, None]
    u, v = gu[..., None], gv[..., None]
    bil = (1 - u) * (1 - v) * c[:, None, 0] + u * (1 - v) * c[:, None, 1] + u * v * c[:, None, 2]
    bil = bil + (1 - u) * v * c[:, None, 3]
    fold = u + v > 1.0  # a triangle: the square folded onto it
    tu, tv = np.where(fold, 1.0 - v, u), np.where(fold, 1.0 - u, v)
    tri = (1 - tu - tv) * c[:, None, 0] + tu * c[:, None, 1] + tv * c[:, None, 2]
    points = np.where(quad, bil, tri)
    dx, dy = concentric_disk(du, dv)
    dz = np.sqrt(np.maximum(0.0, 1.0 - dx * dx - dy * dy))
    t1, t2, n = patches.tangent[:, 0], patches.tangent[:, 1], patches.normal
    dirs = dx[..., None] * t1[:, None] + dy[..., None] * t2[:, None] + dz[..., None] * n[:, None]
    origins = points + patches.eps_ray * n[:, None]
    tfar = np.full(P * k, 4.0 * patches.scale, dtype=np.float32)
    hit, _ = vis.first_hits(
        np.ascontiguousarray(origins.reshape(-1, 3), dtype=np.float32),
        np.ascontiguousarray(dirs.reshape(-1, 3), dtype=np.float32),
        tfar,
    )
    kept = (hit.reshape(P, k) >= 0).mean(axis=1)
    return np.ones(P) if kept.min() >= CLOSED_SHARE else kept
