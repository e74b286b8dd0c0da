"""The compiled kernels (iat.radiosity.kernels) against closed forms and the numpy definitions
they replaced: Gauss rule vs contour integral, the MIS weights' rays, the visible fraction of
an unoccluded shooter, the field integral of a linear field, thread-count independence."""

import numba
import numpy as np
import pytest

from iat.radiosity import bundles, kernels
from iat.radiosity.sampling import (
    GAUSS_QUAD,
    NO_IMPORTANCE,
    Shooter,
    concentric_disk,
    disk_to_hemisphere,
    field_importance,
    sample_lattice,
)

SQUARE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
UP = np.array([0.0, 0.0, 1.0])


def shooter(corners=SQUARE, is_quad=True):
    normal = UP
    area = float(np.linalg.norm(np.cross(corners[1] - corners[0], corners[3] - corners[0])))
    return Shooter(corners, is_quad, normal, area if is_quad else 0.5 * area, 1e-4)


def receivers(n=64, seed=3, height=(0.3, 3.0)):
    """Receivers in front of the square (z > 0) facing it (unit normals tilted a little)."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-1, 2, n), rng.uniform(-1, 2, n), rng.uniform(*height, n)])
    nr = np.column_stack([rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), -np.ones(n)])
    return x, nr / np.linalg.norm(nr, axis=1, keepdims=True)


def test_point_polygon_unit_square_corner():
    # receiver under a corner of a unit square at height 1, facing it: the closed form
    f = kernels.point_polygon(np.array([[0.0, 0.0, -1.0]]), np.array([UP]), SQUARE)[0]
    a = 1.0 / np.sqrt(2.0)  # parallel unit square, receiver under a corner: 2 a atan(a) / (2 pi)
    exact = 2 * a * np.arctan(a) / (2 * np.pi)
    assert f == pytest.approx(exact, rel=1e-12)


def test_gauss_rule_agrees_with_contour_far_away():
    sh = shooter()
    ka = sh.kernel_args()
    x, nr = receivers(height=(4.5, 8.0))
    (gu, gv), gw = GAUSS_QUAD
    exact = kernels.point_polygon(x, nr, SQUARE)
    args = (ka.geom, ka.para, ka.area, gu.ravel(), gv.ravel(), gw)
    far = kernels.patch_form_factors(x, nr, SQUARE, SQUARE.mean(axis=0), 4.0, *args)
    near = kernels.patch_form_factors(x, nr, SQUARE, SQUARE.mean(axis=0), 1e9, *args)
    np.testing.assert_array_equal(near, exact)  # nothing far: the contour integral itself
    assert np.all(exact > 0)
    np.testing.assert_allclose(far, exact, rtol=5e-3)


def block(sh, n=200, m=6, near_share=0.5, seed=5):
    """A gather block's inputs: receivers in front of the shooter (+z), facing it."""
    x, nr = receivers(n, seed)
    rng = np.random.default_rng(seed)
    a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    pat = np.stack([(a.ravel() + rng.random(m * m)) / m, (b.ravel() + rng.random(m * m)) / m], axis=1)
    rot = rng.random((n, 4))
    t1 = np.cross(nr, [1.0, 0.0, 0.0])
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nr, t1)
    near = rng.random(n) < near_share
    o32 = (x + 1e-4 * nr).astype(np.float32)
    return pat, rot, x, nr, t1, t2, near, o32


def rays(sh, inputs, imp=NO_IMPORTANCE):
    ka = sh.kernel_args()
    pat, rot, x, nr, t1, t2, near, o32 = inputs
    n = 2 * len(x) * len(pat)
    buf = (
        np.empty((6, n)),
        np.empty((n, 3), np.float32),
        np.empty((n, 3), np.float32),
        np.empty(n, np.float32),
    )
    rows = bundles.ReceiverRows(rot, x, nr, t1, t2, near, o32, np.zeros(len(x), np.int64))
    out = bundles.sample_rays(pat, rows, ka, imp, buf)
    return [np.array(a) for a in out]


def finish(sh, inputs, r, vis, fb, flat=None, mean=None):
    ka = sh.kernel_args()
    off, wsum, w, u, v = r[:5]
    has = flat is not None
    flat = np.zeros((1, 3)) if flat is None else flat
    nl = int(round(np.sqrt(len(flat)))) - 1
    rows = bundles.ReceiverRows(*inputs[1:], np.zeros(len(inputs[2]), np.int64))
    smp = bundles.Samples(off, wsum, w, u, v, *r[5:])
    fld = bundles.ShotField(flat, nl, np.zeros(3) if mean is None else mean, has, False, False, NO_IMPORTANCE)
    return bundles.finish_rows(smp, vis, fb, rows, ka, fld)


@pytest.mark.parametrize("is_quad", [True, False])
def test_rays_end_on_the_shooter(is_quad):
    sh = shooter(is_quad=is_quad)
    inputs = block(sh)
    off, wsum, w, u, v, o, d, tfar = rays(sh, inputs)
    assert off[-1] == len(w) > 0 and np.all(w > 0)
    assert np.all(np.diff(off) <= 2 * len(inputs[0]))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    # origin + (tfar + eps/2) d is the target of (u, v): on the square (pulled in by <= eps), eps above it
    end = o + (tfar + sh.kernel_args().half_eps)[:, None] * d
    target = sh.origin + u[:, None] * sh.e1 + v[:, None] * sh.e2
    np.testing.assert_allclose(end[:, :2], target[:, :2], atol=2e-4)
    np.testing.assert_allclose(end[:, 2], 1e-4, atol=1e-5)
    if not is_quad:
        assert np.all(u + v <= 1 + 1e-9)
    # each row's weights add up to its wsum
    np.testing.assert_allclose(np.add.reduceat(w, off[:-1])[np.diff(off) > 0], wsum[np.diff(off) > 0])


def test_unoccluded_gather_is_the_form_factor():
    sh = shooter()
    inputs = block(sh)
    r = rays(sh, inputs)
    fb = kernels.point_polygon(inputs[2], inputs[3], SQUARE)
    vis = np.ones(len(r[2]))
    out, seen = finish(sh, inputs, r, vis, fb)
    hit = np.diff(r[0]) > 0
    np.testing.assert_allclose(out[hit, 0], fb[hit], rtol=1e-12)
    np.testing.assert_array_equal(seen, np.diff(r[0]))
    # half the rays blocked, in every row: between 0 and F
    vis[::2] = 0.0
    part, _ = finish(sh, inputs, r, vis, fb)
    assert np.all(part[:, 0] <= fb + 1e-15) and part[hit, 0].sum() < fb[hit].sum()
    # a constant field c: F c
    c = np.array([1.0, 2.0, 0.5])
    n = 9
    flat = np.tile(c, ((n + 1) ** 2, 1))
    val, _ = finish(sh, inputs, r, np.ones(len(r[2])), fb, flat, c)
    np.testing.assert_allclose(val[hit], fb[hit, None] * c, rtol=1e-9)


def test_field_integral_of_a_linear_field():
    """A field linear in u: the control variate plus the MIS estimate of the rest is the
    kernel-weighted mean of the field, so it lies between the field's extremes times F."""
    sh = shooter()
    inputs = block(sh, n=100, m=12)
    r = rays(sh, inputs)
    fb = kernels.point_polygon(inputs[2], inputs[3], SQUARE)
    n = 8
    g = np.arange(n + 1) / n
    uu, _ = np.meshgrid(g, g, indexing="ij")
    flat = np.repeat((1.0 + uu.ravel())[:, None], 3, axis=1)
    val, _ = finish(sh, inputs, r, np.ones(len(r[2])), fb, flat, np.full(3, 1.5))
    hit = np.diff(r[0]) > 0
    mean = val[hit, 0] / fb[hit]
    assert np.all(mean > 0.95) and np.all(mean < 2.05)
    # sample_lattice (numpy) and the kernel read the same field
    u = np.random.default_rng(0).random(50)
    np.testing.assert_allclose(sample_lattice(flat, n, u, 0 * u)[:, 0], 1.0 + u, rtol=1e-12)


def test_importance_warp_draws_by_the_density():
    """Uniform points warped by :func:`field_importance`'s tables fall in each cell in proportion to
    its density, and the density returned is the cell's."""
    n = 8
    field = np.ones((n + 1, n + 1, 3))
    field[6:, :3] = 40.0  # a bright corner
    imp = field_importance(field, True, 16, 0.5)
    g = (imp.shape[0] - 1) // 2
    assert g == n and np.mean(imp[g + 1 :, :g]) == pytest.approx(1.0)
    rng = np.random.default_rng(1)
    out = np.array([kernels.importance_warp(a, b, imp) for a, b in rng.random((40_000, 2))])
    cells = np.minimum((out[:, :2] * g).astype(int), g - 1)
    np.testing.assert_array_equal(out[:, 2], imp[g + 1 + cells[:, 0], cells[:, 1]])
    share = np.bincount(cells[:, 0] * g + cells[:, 1], minlength=g * g).reshape(g, g) / len(out)
    np.testing.assert_allclose(share, imp[g + 1 :, :g] / g**2, atol=0.004)
    assert share[7, 0] > 5 * share[0, 7]  # the bright corner drew its points
    for u, v in rng.random((50, 2)) * 0.5:  # the density at a triangle's point is its square point's
        s, t = (u + v) ** 2, v / (u + v)
        i, j = int(s * g), int(t * g)
        assert kernels.importance_density(u, v, False, imp) == imp[g + 1 + i, j]


@pytest.mark.parametrize("is_quad", [True, False])
def test_importance_gather_of_a_peaked_field(is_quad):
    """A field 60x brighter on a corner sixteenth of the shooter (a sun patch): drawn by its light
    (:func:`field_importance`), a gather of 8 x 8 samples keeps the estimate unbiased and comes
    closer to uniform 64 x 64 gathers (the mean of 4) than uniform 8 x 8 samples do."""
    sh = shooter(SQUARE, is_quad)
    n = 16
    field = np.ones((n + 1, n + 1, 3))
    field[12:, :4] = 60.0
    flat = field.reshape(-1, 3)
    mean = flat.mean(axis=0)
    x, nr = receivers(120, 7)
    fb = kernels.point_polygon(x, nr, SQUARE if is_quad else SQUARE[[0, 1, 3]])

    def gathered(m, imp, seed):
        inputs = block(sh, n=120, m=m, seed=seed)
        inputs = (*inputs[:2], x, nr, *inputs[4:])
        r = rays(sh, inputs, imp)
        return finish(sh, inputs, r, np.ones(len(r[2])), fb, flat, mean)[0][:, 0]

    ref = np.mean([gathered(64, NO_IMPORTANCE, seed) for seed in (100, 200, 300, 400)], axis=0)
    imp = field_importance(field, is_quad, 16, 0.5)
    ok = fb > 1e-3
    err = {}
    for name, tables in (("uniform", NO_IMPORTANCE), ("drawn", imp)):
        runs = np.array([gathered(8, tables, seed) for seed in range(2, 26)])
        rel = (runs[:, ok] - ref[ok]) / ref[ok]
        err[name] = float(np.sqrt(np.mean(rel**2)))
        bias = float(np.mean(runs[:, ok].sum(axis=1) / ref[ok].sum() - 1))  # seeds' spread ~0.4 %
        assert abs(bias) < 0.015, (name, bias)
    assert err["drawn"] < 0.75 * err["uniform"], err  # 0.14 against 0.20 (quad), 0.12 against 0.22


def test_results_do_not_depend_on_the_thread_count():
    sh = shooter()
    inputs = block(sh, n=300)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = rays(sh, inputs)
        ff1 = kernels.point_polygon(inputs[2], inputs[3], SQUARE)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = rays(sh, inputs)
        ffn = kernels.point_polygon(inputs[2], inputs[3], SQUARE)
    finally:
        numba.set_num_threads(before)
    for a, b in zip(one, many, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ff1, ffn)


def splitmix64_uniform(keys, salt, k):
    """The definition :func:`kernels.hash_keys` compiles: k splitmix64 hashes of (key, salt), numpy."""
    z = np.asarray(keys, dtype=np.int64).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    z ^= np.uint64(salt & 0xFFFFFFFFFFFFFFFF)
    out = []
    for _ in range(k):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        x = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
        out.append((x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53)))
    return np.stack(out, axis=1)


@pytest.mark.parametrize("salt", [0, 17, 1234567891234567, (1 << 64) - 5])
def test_hash_uniform_is_splitmix64(salt):
    from iat.radiosity.sampling import hash_uniform

    keys = np.array([0, 1, 5, 123456789012345, 2**62 + 7], dtype=np.int64)
    np.testing.assert_array_equal(hash_uniform(keys, salt, 4), splitmix64_uniform(keys, salt, 4))
    assert hash_uniform(keys, salt).shape == (5, 2)


def test_block_inputs_hash_as_hash_uniform():
    """The compiled per-row inputs: the rotations are splitmix64's (bit for bit), the rest rows
    of the receiver arrays; correlated rows all take key 0's rotation."""
    hash_uniform = splitmix64_uniform

    rng = np.random.default_rng(7)
    n, P = 50, 4
    key = rng.integers(0, 2**62, n)
    ff, normal = rng.random((n, 3)), rng.random((n, 3))
    patch = rng.integers(0, P, n)
    tangent = rng.random((P, 2, 3))
    origin32 = rng.random((n, 3)).astype(np.float32)
    ii = np.array([3, 0, 49, 7])
    f = np.array([0.01, 0.5, 0.02, 0.0])
    salt = (1 << 64) - 12345
    rot, x, nr, t1, t2, near, o32, rp = kernels.block_inputs(
        ii, key, np.uint64(salt), False, ff, normal, patch, tangent, f, 0.02, origin32
    )
    np.testing.assert_array_equal(rot, hash_uniform(key[ii], salt, 4))
    np.testing.assert_array_equal(x, ff[ii])
    np.testing.assert_array_equal(nr, normal[ii])
    np.testing.assert_array_equal(t1, tangent[patch[ii], 0])
    np.testing.assert_array_equal(t2, tangent[patch[ii], 1])
    np.testing.assert_array_equal(o32, origin32[ii])
    np.testing.assert_array_equal(near, [False, True, True, False])
    np.testing.assert_array_equal(rp, patch[ii])
    args = (ff, normal, patch, tangent, f, 0.02, origin32)
    rot_c = kernels.block_inputs(ii, key, np.uint64(salt), True, *args)[0]
    np.testing.assert_array_equal(rot_c, np.repeat(hash_uniform(np.zeros(1, np.int64), salt, 4), 4, axis=0))


def test_rows_product_is_scipys_product_on_those_rows():
    from scipy import sparse

    rng = np.random.default_rng(11)
    a = sparse.random(40, 30, density=0.2, random_state=3, format="csr")
    x = rng.random((30, 3)) - 0.5
    rows = np.array([1, 5, 6, 39])
    for absolute, xx in ((False, x), (True, np.abs(x))):
        got = kernels.rows_product(a.indptr, a.indices, a.data, x, rows, absolute)
        np.testing.assert_array_equal(got, (a @ xx)[rows])


def test_patch_point_is_the_numpy_blend():
    """The compiled patch_point gives the bits of its numpy expressions (bilinear on quads,
    barycentric on triangles)."""
    from iat.geometry import quadtree as qt

    rng = np.random.default_rng(5)
    corners = rng.normal(size=(7, 4, 3)) * 10
    is_quad = np.array([True, False, True, False, False, True, True])
    patch = rng.integers(0, 7, 500)
    u, v = rng.random(500), rng.random(500)
    c = corners[patch]
    uu, vv = u[:, None], v[:, None]
    quad = (
        (1 - uu) * (1 - vv) * c[:, 0] + uu * (1 - vv) * c[:, 1] + uu * vv * c[:, 2] + (1 - uu) * vv * c[:, 3]
    )
    tri = c[:, 0] + uu * (c[:, 1] - c[:, 0]) + vv * (c[:, 2] - c[:, 0])
    want = np.where(is_quad[patch][:, None], quad, tri)
    np.testing.assert_array_equal(qt.patch_point(corners, is_quad, patch, u, v), want)


def test_leaf_corner_lattice_of_quads_and_both_triangles():
    from iat.geometry import quadtree as qt

    f = qt.roots(np.array([True, False]), 4)
    f = qt.split(f, np.ones(f.n_leaves, dtype=bool))  # a triangle splits into up and down ones
    c = qt.leaf_corner_lattice(f)
    s = f.leaf_size[:, None]
    base = np.stack([f.leaf_i, f.leaf_j], axis=1)[:, None, :]
    for k in range(f.n_leaves):
        if f.leaf_is_quad[k]:
            off = qt.QUAD_CORNERS
        else:
            off = qt.DOWN_CORNERS if f.leaf_flip[k] else qt.UP_CORNERS
            off = np.vstack([off, off[2:]])
        np.testing.assert_array_equal(c[k], base[k] + off * s[k])
    assert f.leaf_flip.any() and (~f.leaf_flip & ~f.leaf_is_quad).any()


def test_merge_keys_is_the_sorted_union():
    from iat.geometry import quadtree as qt

    rng = np.random.default_rng(8)
    keys = np.unique(rng.integers(0, 10**6, 5000))
    more = rng.integers(0, 10**6, (300, 4))
    np.testing.assert_array_equal(qt.merge_keys(keys, more), np.unique(np.concatenate([keys, more.ravel()])))
    np.testing.assert_array_equal(qt.merge_keys(keys[:0], more[:0]), keys[:0])


def test_cosine_rays_are_disk_to_hemisphere_bit_for_bit():
    # the ambient term's rays: the numpy lift of the disc points, and its float32 rounding for embreex
    from iat.radiosity.ambient_kernels import cosine_rays

    rng = np.random.default_rng(5)
    dx, dy = concentric_disk(rng.random(16), rng.random(16))
    normal = rng.normal(size=(7, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    t1 = np.cross(normal, [0.3, 0.5, 0.8])
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    origin32 = rng.normal(size=(7, 3)).astype(np.float32)
    w, o, d = np.empty((112, 3)), np.empty((112, 3), np.float32), np.empty((112, 3), np.float32)
    cosine_rays(dx, dy, t1, t2, normal, origin32, w, o, d)
    ref = disk_to_hemisphere(dx[None], dy[None], t1, t2, normal).reshape(-1, 3)
    assert np.array_equal(w, ref)
    assert np.array_equal(d, ref.astype(np.float32))
    assert np.array_equal(o, np.repeat(origin32, 16, axis=0))
    assert np.allclose(
        np.einsum("ic,ic->i", w, np.repeat(normal, 16, axis=0)), np.sqrt(1 - np.tile(dx**2 + dy**2, 7))
    )


def test_shot_power_sums_what_the_vertices_received_and_reflect():
    """kernels.shot_power against numpy: each channel's power the rows received (|dv| / rho, 0
    where rho is 0) and reflect (dv, signed), weighted by the vertices' power."""
    rng = np.random.default_rng(3)
    rho = rng.random((40, 3))
    rho[5] = 0.0
    rho[7, 1] = 0.0
    vertex_power = rng.random(40)
    rows = np.array([2, 5, 7, 11, 30])
    dv = rng.normal(size=(5, 3))
    got, reflected = kernels.shot_power(rows, dv, rho, vertex_power)
    r = rho[rows]
    want = vertex_power[rows] @ np.where(r > 0, np.abs(dv) / np.where(r > 0, r, 1.0), 0.0)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    np.testing.assert_allclose(reflected, vertex_power[rows] @ dv, rtol=1e-12)
