"""The gather kernels' arguments in typed bundles (:class:`ShooterArrays`, :class:`ReceiverRows`,
:class:`Samples`, :class:`ShotField`), and the calls of :mod:`iat.radiosity.kernels` (and
:mod:`iat.radiosity.traced`) that take them: a gather passes four bundles where the kernels take 19
to 36 plain arrays and flags."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from iat.radiosity import kernels, traced


class ShooterArrays(NamedTuple):
    """One shooter as the gather kernels take it (:meth:`iat.radiosity.sampling.Shooter.kernel_args`):
    ``geom`` (16, 3) and ``uvc`` (3, 2) (:mod:`iat.radiosity.kernels`), its edges' outward normals and
    points ``poly_n, poly_o`` (k, 3), the inside test's slack ``tol``, ``is_quad``, ``para`` (a
    parallelogram), ``linear_uv`` (the (u, v) inverse is linear), its lattice ``area``, a panel
    cell's coverage ``mask`` (r, r) bool (used when ``has_mask``), the float32 ray-target terms
    ``t32`` (4, 3) (``base, k e1, k e2, k e3``) and ``half_eps`` (taken off the rays' length)."""

    geom: np.ndarray
    uvc: np.ndarray
    poly_n: np.ndarray
    poly_o: np.ndarray
    tol: float
    is_quad: bool
    para: bool
    linear_uv: bool
    area: float
    mask: np.ndarray
    has_mask: bool
    t32: np.ndarray
    half_eps: np.float32


class ReceiverRows(NamedTuple):
    """A block of b receivers as :func:`~iat.radiosity.kernels.block_inputs` gives them: ``rot``
    (b, 4) their pattern rotations, points ``x`` and normals ``nr`` (b, 3), tangents ``t1, t2``
    (b, 3), ``near`` (b,) bool (direction samples too), float32 ray origins ``o32`` (b, 3) and
    ``patch`` (b,)."""

    rot: np.ndarray
    x: np.ndarray
    nr: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    near: np.ndarray
    o32: np.ndarray
    patch: np.ndarray


class Samples(NamedTuple):
    """A block's samples as :func:`~iat.radiosity.kernels.gather_rays` returns them: ``off``
    (b + 1,), ``wsum`` (b,), per sample ``w, u, v`` (k,) and its ray ``o, d`` (k, 3) float32,
    ``tfar`` (k,) float32."""

    off: np.ndarray
    wsum: np.ndarray
    w: np.ndarray
    u: np.ndarray
    v: np.ndarray
    o: np.ndarray
    d: np.ndarray
    tfar: np.ndarray


class ShotField(NamedTuple):
    """What a gather weighs its samples with: ``flat`` ((nl+1)**2, 3) the shooter's radiance on
    its lattice of ``nl`` cells a side and its area mean ``mean`` (3,) when ``has_field`` (else a
    (1, 3) zero placeholder), whether results are clamped to >= 0 / <= 0, and ``imp`` the tables
    its area samples are drawn by (:func:`~iat.radiosity.sampling.field_importance`; one row:
    uniformly)."""

    flat: np.ndarray
    nl: int
    mean: np.ndarray
    has_field: bool
    clamp_lo: bool
    clamp_hi: bool
    imp: np.ndarray


def receiver_rows(
    ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32
) -> ReceiverRows:
    """:func:`~iat.radiosity.kernels.block_inputs` as a :class:`ReceiverRows`."""
    return ReceiverRows(
        *kernels.block_inputs(ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32)
    )


def sample_rays(pat, rows: ReceiverRows, sh: ShooterArrays, imp, scratch) -> Samples:
    """:func:`~iat.radiosity.kernels.gather_rays` of a block: pattern ``pat`` (S, 2), the block's
    ``rows``, the shooter ``sh``, the importance tables ``imp`` (:class:`ShotField`'s) and the
    thread's ``scratch`` (buf, ro, rd, rt)."""
    return Samples(
        *kernels.gather_rays(
            pat,
            rows.rot,
            rows.x,
            rows.nr,
            rows.t1,
            rows.t2,
            rows.near,
            rows.o32,
            sh.geom,
            sh.uvc,
            sh.poly_n,
            sh.poly_o,
            sh.tol,
            sh.is_quad,
            sh.para,
            sh.linear_uv,
            sh.area,
            sh.mask,
            sh.has_mask,
            imp,
            sh.t32,
            sh.half_eps,
            *scratch,
        )  # fmt: skip
    )


def finish_rows(smp: Samples, vis, fb, rows: ReceiverRows, sh: ShooterArrays, fld: ShotField):
    """:func:`~iat.radiosity.kernels.gather_finish` of a block: its samples, what each ray let
    through ``vis`` (k,), the rows' form factors ``fb`` (b,); returns ``(out (b, 3), seen (b,))``."""
    return kernels.gather_finish(
        smp.off, smp.w, vis, smp.u, smp.v, fb, smp.wsum, fld.has_field, fld.flat, fld.nl, rows.x, sh.geom,
        sh.uvc, sh.linear_uv, sh.is_quad, sh.para, fld.mean, fld.clamp_lo, fld.clamp_hi,
    )  # fmt: skip


def traced_rows(
    embree_args: tuple, ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32,
    pat, sh: ShooterArrays, fld: ShotField,
):  # fmt: skip
    """:func:`~iat.radiosity.traced.gather_traced` of a receiver set: ``embree_args``
    (:meth:`~iat.radiosity.visibility.Visibility.embree_args`), the rows as :func:`receiver_rows`
    takes them, the pattern ``pat``, the shooter ``sh`` and the field ``fld``; returns ``(out (b, 3),
    seen (b,), rays (b,), glass rays)``."""
    return traced.gather_traced(
        *embree_args, ii, key, salt, correlated, ff, normal, patch, tangent, f, f_direction, origin32,
        pat, sh.geom, sh.uvc, sh.poly_n, sh.poly_o, sh.tol, sh.is_quad, sh.para, sh.linear_uv, sh.area,
        sh.mask, sh.has_mask, fld.imp, sh.t32, sh.half_eps, fld.has_field, fld.flat, fld.nl, fld.mean,
        fld.clamp_lo, fld.clamp_hi,
    )  # fmt: skip
