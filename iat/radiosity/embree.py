"""Embree 4 through its C API, called from numba kernels (issue 41).

The library is the one embreex bundles (``embreex.libs/libembree4*.so*``), else a system
``libembree4``; ``$IAT_EMBREE_LIB`` names another, and ``IAT_EMBREE_C=0`` turns this path off
(:func:`available` is then False and :class:`~iat.radiosity.visibility.Visibility` uses embreex).

:class:`EmbreeScene` builds a device and a scene of (T, 3, 3) triangles with ctypes and keeps both
handles until :meth:`EmbreeScene.close`. The kernels take the scene's handle and the addresses of
the query entry points as int64 arguments (:class:`Entry`) and call them through :func:`call3` /
:func:`call4`, ``@intrinsic`` s that call a function pointer given as an integer: no address is
compiled into the code as a constant, so the kernels stay ``cache=True`` (an address changes from
one process to the next).

The solver's rays go to Embree in packets of ``PACKET`` = 8 (``rtcOccluded8``, ``rtcIntersect8``;
:func:`visible8`, :func:`trace_first_hits`): a gather's rays from one receiver to neighbouring
points of a shooter, a vertex's sky directions in neighbouring strata, consecutive rays of an
array. Embree traverses a packet's rays together, 1.3-1.5x as fast a ray as one at a time on these
rays, with the same answers ray for ray (``tests/test_embree_c.py``). ``rtcOccluded1`` stays for
bare Embree's measure (:func:`trace_occluded`) and ``rtcIntersect1`` for the glass.

Embree 4's single-ray records (``rtcore_ray.h``), 16-byte aligned (a packet's are the same words,
each a row of 8 lanes, 32-byte aligned): ``RTCRay`` is 12 words, ``org``
(0-2), ``tnear`` 3, ``dir`` (4-6), ``time`` 7, ``tfar`` 8, ``mask`` 9, ``id`` 10, ``flags`` 11
(48 bytes); ``RTCRayHit`` is that ray then ``RTCHit``: ``Ng`` (12-14), ``u`` 15, ``v`` 16, ``primID``
17, ``geomID`` 18, ``instID[1]`` 19 and, when the library is built with instance arrays,
``instPrimID[1]`` 20 (80 or 96 bytes: :func:`ray_record` gives 96). The query arguments
(``RTCOccludedArguments``, ``RTCIntersectArguments``) are passed as NULL: Embree's defaults, as
embreex passes them, so both answer ray for ray alike. ``rtcOccluded1`` sets ``tfar`` to -inf on a
hit; ``rtcIntersect1`` sets ``tfar``, ``u, v``, ``primID`` and ``geomID`` (left at
``RTC_INVALID_GEOMETRY_ID`` on a miss). Scenes are built with ``RTC_SCENE_FLAG_ROBUST``, as embreex
4.4 builds its own (without it, Embree's faster triangle test gives other ``tfar, u, v`` in the last
bits on 6 % of the hits, and may answer differently on an edge).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import threading
from pathlib import Path
from typing import NamedTuple

import numpy as np
from llvmlite import ir

# as iat.radiosity.kernels: numba's OpenMP workers wait passively between parallel loops
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

from numba import njit, prange, types  # noqa: E402
from numba.core import cgutils  # noqa: E402
from numba.extending import intrinsic  # noqa: E402

#: environment variable: "0" turns the C API path off (embreex traces instead)
EMBREE_C_ENV = "IAT_EMBREE_C"
#: environment variable: the path of a libembree4 to load instead of embreex's
EMBREE_LIB_ENV = "IAT_EMBREE_LIB"
#: rays per parallel task of the tracing kernels (one ray record each)
RAY_BLOCK = 2048
#: rays per Embree packet (``rtcOccluded8``, :func:`visible8`): rays from one point to neighbouring
#: targets traverse the scene together, 1.5x as fast a ray as one at a time (docs/benchmarks.md)
PACKET = 8
#: workers of a tracing kernel's ``prange`` (:func:`workers`): at least the most threads it runs on
WORKERS = 256

_INVALID = 0xFFFFFFFF
_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_SCENE_FLAG_ROBUST = 1 << 2
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_FLOAT3 = 0x5003, 0x9003

_LOCK = threading.Lock()
_LIB: list = []  # [CDLL or None] once looked for


def library_path() -> str | None:
    """The path of the libembree4 to load (``$IAT_EMBREE_LIB``, embreex's, a system one), or None."""
    env = os.environ.get(EMBREE_LIB_ENV)
    if env:
        return env
    try:
        import embreex

        found = sorted(glob.glob(str(Path(embreex.__path__[0]).parent / "embreex.libs" / "libembree4*.so*")))
        if found:
            return found[0]
    except ImportError:
        pass
    return ctypes.util.find_library("embree4")


def _load():
    """The library with the signatures used here, or None when there is none (or it fails to load)."""
    path = library_path()
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    vp, size, uint, cint = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int
    sigs = {
        "rtcNewDevice": (vp, [ctypes.c_char_p]),
        "rtcReleaseDevice": (None, [vp]),
        "rtcGetDeviceError": (cint, [vp]),
        "rtcNewScene": (vp, [vp]),
        "rtcReleaseScene": (None, [vp]),
        "rtcCommitScene": (None, [vp]),
        "rtcSetSceneFlags": (None, [vp, cint]),
        "rtcNewGeometry": (vp, [vp, cint]),
        "rtcSetNewGeometryBuffer": (vp, [vp, cint, uint, cint, size, size]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (uint, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
    }
    try:
        for name, (res, args) in sigs.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
        lib.rtcOccluded1, lib.rtcIntersect1, lib.rtcOccluded8, lib.rtcIntersect8  # noqa: B018 (the entry points exist)
    except AttributeError:
        return None
    return lib


def library():
    """The loaded library (ctypes), or None (looked for once per process)."""
    with _LOCK:
        if not _LIB:
            _LIB.append(_load())
        return _LIB[0]


def available() -> bool:
    """Whether the C API path is on (not ``IAT_EMBREE_C=0``) and the library loads."""
    if os.environ.get(EMBREE_C_ENV, "1").strip() in ("0", "false", "no", "off"):
        return False
    return library() is not None


class Entry(NamedTuple):
    """The entry points' addresses, as the kernels take them (int64)."""

    occluded1: int
    intersect1: int
    occluded8: int
    intersect8: int


def entry_points() -> Entry:
    """The addresses of ``rtcOccluded1``, ``rtcIntersect1``, ``rtcOccluded8`` and ``rtcIntersect8`` in
    the loaded library."""
    lib = library()
    if lib is None:
        raise RuntimeError("libembree4 not found")
    names = ("rtcOccluded1", "rtcIntersect1", "rtcOccluded8", "rtcIntersect8")
    addr = [ctypes.cast(getattr(lib, n), ctypes.c_void_p).value for n in names]
    return Entry(*(np.int64(a) for a in addr))


class EmbreeScene:
    """A device and a static scene of one triangle geometry, built through the C API.

    triangles : (T, 3, 3) vertices (stored float32, as embreex stores them); T may be 0.
    ``handle`` is the scene's address (int64, 0 when there are no triangles: nothing to hit) and
    ``entry`` the query entry points, both as the kernels take them. :meth:`close` (also on
    collection) releases the scene and the device; the kernels must not be called after it."""

    def __init__(self, triangles: np.ndarray):
        lib = library()
        if lib is None:
            raise RuntimeError("libembree4 not found")
        self._lib = lib
        self.entry = entry_points()
        self.n_triangles = 0
        self._device = self._scene = None
        self.handle = np.int64(0)
        verts = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 3)
        if len(verts) == 0:
            return
        self._device = lib.rtcNewDevice(None)
        if not self._device:
            raise RuntimeError("rtcNewDevice failed")
        self._scene = lib.rtcNewScene(self._device)
        lib.rtcSetSceneFlags(self._scene, _RTC_SCENE_FLAG_ROBUST)  # as embreex builds its scenes
        geom = lib.rtcNewGeometry(self._device, _RTC_GEOMETRY_TYPE_TRIANGLE)
        n = len(verts)
        vbuf = lib.rtcSetNewGeometryBuffer(geom, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3, 12, n)
        ibuf = lib.rtcSetNewGeometryBuffer(geom, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3, 12, n // 3)
        if not (vbuf and ibuf):
            lib.rtcReleaseGeometry(geom)
            self.close()
            raise RuntimeError(f"Embree buffers not made (error {lib.rtcGetDeviceError(self._device)})")
        ctypes.memmove(vbuf, verts.ctypes.data, verts.nbytes)
        index = np.arange(n, dtype=np.uint32)
        ctypes.memmove(ibuf, index.ctypes.data, index.nbytes)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(self._scene, geom)
        lib.rtcReleaseGeometry(geom)  # the scene holds it
        lib.rtcCommitScene(self._scene)
        err = lib.rtcGetDeviceError(self._device)
        if err:
            self.close()
            raise RuntimeError(f"Embree scene not built (error {err})")
        self.n_triangles = n // 3
        self.handle = np.int64(self._scene)

    def close(self) -> None:
        """Release the scene and the device (idempotent)."""
        lib = getattr(self, "_lib", None)
        if lib is None:
            return
        if self._scene:
            lib.rtcReleaseScene(self._scene)
        if self._device:
            lib.rtcReleaseDevice(self._device)
        self._scene = self._device = None
        self.handle = np.int64(0)

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


# -- calling the entry points from numba ------------------------------------------------------
def _pointer_call(n: int):
    """The codegen of :func:`call3` / :func:`call4`: ``args[0]`` called as ``void f(void *, ...)`` with
    the n other arguments (integers) as its pointers."""

    def codegen(context, builder, signature, args):
        ptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [ptr] * n)
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [builder.inttoptr(x, ptr) for x in args[1:]])
        return context.get_dummy_value()

    return codegen


@intrinsic
def call3(typingctx, fn, a, b, c):
    """``fn(a, b, c)`` for a C function ``void fn(void *, void *, void *)`` whose address is the
    integer ``fn``, the three pointers given as integers (0: NULL)."""
    if not all(isinstance(x, types.Integer) for x in (fn, a, b, c)):
        return None
    return types.void(fn, a, b, c), _pointer_call(3)


@intrinsic
def call4(typingctx, fn, a, b, c, d):
    """``fn(a, b, c, d)`` for a C function ``void fn(void *, void *, void *, void *)``, as :func:`call3`."""
    if not all(isinstance(x, types.Integer) for x in (fn, a, b, c, d)):
        return None
    return types.void(fn, a, b, c, d), _pointer_call(4)


@intrinsic
def fetch_add(typingctx, arr, idx, val):
    """Atomically ``arr[idx] += val`` (arr an int64 array); returns the value before."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64 and isinstance(idx, types.Integer)):
        return None
    sig = types.int64(arr, idx, val)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]])
        v = context.cast(builder, args[2], signature.args[2], types.int64)
        return builder.atomic_rmw("add", ptr, v, "seq_cst")

    return sig, codegen


@njit(cache=True, nogil=True)
def workers():
    """The workers of a kernel's ``prange`` (``WORKERS``) and the shared counter (1,) int64 they take
    their tasks from with :func:`fetch_add`, so that tasks go to whichever thread is free: a static
    split of the range leaves a core idle when the costly tasks bunch, or while another process
    holds the other core. The range splits into one run of workers a thread; a thread's first
    worker takes tasks until none is left, the others find none. Each task's result does not
    depend on who runs it. (The thread count is not asked for: ``numba.get_num_threads`` in a
    kernel would keep it from numba's cache.)"""
    return WORKERS, np.zeros(1, dtype=np.int64)


@njit(cache=True, nogil=True)
def ray_record():
    """A 96-byte, 16-byte aligned ``RTCRayHit`` (or ``RTCRay``: its first 48 bytes): (24,) float32
    and the same memory as (24,) uint32."""
    buf = np.empty(28, np.float32)
    a = ((16 - buf.ctypes.data % 16) % 16) // 4
    rec = buf[a : a + 24]
    return rec, rec.view(np.uint32)


@njit(cache=True, nogil=True, inline="always")
def _set_ray(rec, bits, ox, oy, oz, dx, dy, dz, tfar):
    rec[0], rec[1], rec[2], rec[3] = ox, oy, oz, 0.0
    rec[4], rec[5], rec[6], rec[7] = dx, dy, dz, 0.0
    rec[8] = tfar
    bits[9], bits[10], bits[11] = _INVALID, 0, 0  # mask (all), id, flags


@njit(cache=True, nogil=True)
def occluded1(fn, scene, rec, bits, ox, oy, oz, dx, dy, dz, tfar):
    """True when ``rtcOccluded1`` (address ``fn``) finds a hit in ``scene`` on the ray before tfar
    (float32 arguments, as embreex takes them); rec, bits: a :func:`ray_record`."""
    if scene == 0:
        return False
    _set_ray(rec, bits, ox, oy, oz, dx, dy, dz, tfar)
    call3(fn, scene, rec.ctypes.data, 0)
    return rec[8] < 0  # tfar is -inf after a hit


@njit(cache=True, nogil=True)
def intersect1(fn, scene, rec, bits, ox, oy, oz, dx, dy, dz, tfar):
    """The triangle ``rtcIntersect1`` (address ``fn``) finds first in ``scene`` on the ray before
    tfar (-1: none); the hit's ``u, v`` are then ``rec[15], rec[16]``."""
    if scene == 0:
        return -1
    _set_ray(rec, bits, ox, oy, oz, dx, dy, dz, tfar)
    bits[17], bits[18], bits[19] = _INVALID, _INVALID, _INVALID  # primID, geomID, instID
    call3(fn, scene, rec.ctypes.data, 0)
    if bits[18] == _INVALID:
        return -1
    return np.int64(bits[17])


@njit(cache=True, nogil=True)
def packet_record():
    """An 8-ray packet's scratch, ``(rec, bits, valid, vis, rec1, bits1)``: ``RTCRayHit8`` (structure
    of arrays: the 24 words of a :func:`ray_record` as rows of 8 lanes, 64-byte aligned; its first 12
    rows are ``RTCRay8``) as (24, 8) float32 and the same memory as uint32; its valid mask (8,) int32
    (64-byte aligned); ``vis`` (8,) float64, what of each lane's ray gets through (:func:`visible8`);
    a :func:`ray_record` for the glass."""
    buf = np.empty(192 + 16, np.float32)
    a = ((64 - buf.ctypes.data % 64) % 64) // 4
    rec = buf[a : a + 192].reshape(24, 8)
    vbuf = np.empty(8 + 16, np.int32)
    av = ((64 - vbuf.ctypes.data % 64) % 64) // 4
    rec1, bits1 = ray_record()
    return rec, rec.view(np.uint32), vbuf[av : av + 8], np.empty(PACKET), rec1, bits1


@njit(cache=True, nogil=True, inline="always")
def set_lane(pk, lane, ox, oy, oz, dx, dy, dz, tfar):
    """Lane ``lane`` of the packet pk (:func:`packet_record`) the ray from (ox, oy, oz) along (dx, dy,
    dz) before tfar (float32), as :func:`occluded1` sets its record."""
    rec, bits = pk[0], pk[1]
    rec[0, lane], rec[1, lane], rec[2, lane], rec[3, lane] = ox, oy, oz, 0.0
    rec[4, lane], rec[5, lane], rec[6, lane], rec[7, lane] = dx, dy, dz, 0.0
    rec[8, lane] = tfar
    bits[9, lane], bits[10, lane], bits[11, lane] = _INVALID, 0, 0


@njit(cache=True, nogil=True, inline="always")
def _load_lanes(pk, o, d, t, a, n):
    """Lanes 0 .. n-1 of the packet pk the rays a .. a+n-1 of the arrays o, d (m, 3), t (m,)."""
    for lane in range(n):
        i = a + lane
        set_lane(pk, lane, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], t[i])


@njit(cache=True, nogil=True, inline="always")
def _valid(pk, n):
    """The packet pk's valid mask with lanes 0 .. n-1 on."""
    valid = pk[2]
    for lane in range(PACKET):
        valid[lane] = -1 if lane < n else 0
    return valid


@njit(cache=True, nogil=True)
def intersect8(fn8, scene, pk, n):
    """``rtcIntersect8`` (address ``fn8``) of the rays in lanes 0 .. n-1 of the packet pk
    (:func:`set_lane`): lane l's first hit in ``scene`` is then triangle ``bits[17, l]`` at ``u, v =
    rec[15, l], rec[16, l]``, none where ``bits[18, l]`` (geomID) is ``RTC_INVALID_GEOMETRY_ID``."""
    rec, bits = pk[0], pk[1]
    for lane in range(PACKET):
        bits[17, lane], bits[18, lane], bits[19, lane] = _INVALID, _INVALID, _INVALID
    valid = _valid(pk, n)
    if scene != 0:
        call4(fn8, valid.ctypes.data, scene, rec.ctypes.data, 0)


@njit(cache=True, nogil=True)
def visible8(occ8, isect, scene, glass, glass_tau, pk, n):
    """What of the light of each ray in lanes 0 .. n-1 of the packet pk (:func:`set_lane`) gets
    through before its tfar, into pk's ``vis`` (``pk[3]``, float64): 0 when something opaque in
    ``scene`` lies on it, else the transmittance ``glass_tau`` of the first triangle of ``glass`` it
    crosses (1 if none). The lanes are traced together by ``rtcOccluded8`` (address ``occ8``; the
    answers of ``rtcOccluded1`` ray for ray), the free ones then one by one against the glass.
    Returns how many were traced against the glass."""
    rec, vis, rec1, bits1 = pk[0], pk[3], pk[4], pk[5]
    valid = _valid(pk, n)
    if scene != 0:
        call4(occ8, valid.ctypes.data, scene, rec.ctypes.data, 0)
    through = 0
    for lane in range(n):
        if scene != 0 and rec[8, lane] < 0:  # tfar is -inf after a hit
            vis[lane] = 0.0
        elif glass == 0:
            vis[lane] = 1.0
        else:
            p = intersect1(isect, glass, rec1, bits1, rec[0, lane], rec[1, lane], rec[2, lane],
                           rec[4, lane], rec[5, lane], rec[6, lane], rec[8, lane])  # fmt: skip
            vis[lane] = 1.0 if p < 0 else glass_tau[p]
            through += 1
    return through


@njit(cache=True, nogil=True, inline="always")
def take_tasks(nxt, n_tasks, task, scratch, scratch_args, args):
    """One worker of a kernel's ``prange`` (:func:`workers`): takes tasks k < n_tasks from the shared
    counter nxt (:func:`fetch_add`) until none is left and runs ``task(k, s, *args)``; makes its
    scratch ``s = scratch(*scratch_args)`` (e.g. :func:`ray_record`) once, with its first task.
    Inlined, with task and scratch global functions: a function passed on as a value would keep the
    kernel from numba's cache; args, a flat tuple built in the ``prange`` body."""
    k = fetch_add(nxt, 0, 1)
    if k < n_tasks:
        s = scratch(*scratch_args)
        while k < n_tasks:
            task(k, s, *args)
            k = fetch_add(nxt, 0, 1)


# -- queries over arrays of rays (blocks of RAY_BLOCK rays, taken by the threads as they come free) --
@njit(cache=True, nogil=True)
def ray_blocks(n):
    """How many blocks of RAY_BLOCK rays n rays make."""
    return (n + RAY_BLOCK - 1) // RAY_BLOCK


@njit(cache=True, parallel=True, nogil=True)
def trace_occluded(fn, scene, o, d, t, out):
    """``out[i]`` (n,) bool: whether ``rtcOccluded1`` finds a hit on ray i (o, d (n, 3), t (n,)
    float32) before t[i], one ray at a time (bare Embree, ``benchmarks/ray_budget.py``'s measure)."""
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, ray_blocks(o.shape[0]), _occluded_block, ray_record, (), (fn, scene, o, d, t, out))


@njit(cache=True, nogil=True)
def _occluded_block(b, s, fn, scene, o, d, t, out):
    rec, bits = s
    for i in range(b * RAY_BLOCK, min(o.shape[0], (b + 1) * RAY_BLOCK)):
        out[i] = occluded1(fn, scene, rec, bits, o[i, 0], o[i, 1], o[i, 2], d[i, 0], d[i, 1], d[i, 2], t[i])


@njit(cache=True, parallel=True, nogil=True)
def trace_visible(occ8, isect, scene, glass, glass_tau, o, d, t, out):
    """``out[i]`` (n,) float64: what of ray i gets through (:func:`visible8`), in packets of
    consecutive rays. Returns how many rays were traced against the glass."""
    nb = ray_blocks(o.shape[0])
    through = np.zeros(nb, dtype=np.int64)
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, nb, _visible_block, packet_record, (),
                   (occ8, isect, scene, glass, glass_tau, o, d, t, out, through))  # fmt: skip
    return through.sum()


@njit(cache=True, nogil=True)
def _visible_block(b, pk, occ8, isect, scene, glass, glass_tau, o, d, t, out, through):
    """Block b of :func:`trace_visible`."""
    end = min(o.shape[0], (b + 1) * RAY_BLOCK)
    vis = pk[3]
    for a in range(b * RAY_BLOCK, end, PACKET):
        n = min(PACKET, end - a)
        _load_lanes(pk, o, d, t, a, n)
        through[b] += visible8(occ8, isect, scene, glass, glass_tau, pk, n)  # 0 without glass
        for lane in range(n):
            out[a + lane] = vis[lane]


@njit(cache=True, parallel=True, nogil=True)
def trace_first_hits(fn8, scene, o, d, t, prim, bary):
    """``prim[i]`` (n,) int64 the triangle ray i meets first before t[i] (-1: none) and ``bary[i]``
    (n, 2) float64 the hit's (u, v) (0 where none), by ``rtcIntersect8`` (address ``fn8``) in packets
    of consecutive rays."""
    nw, nxt = workers()
    for _ in prange(nw):
        take_tasks(nxt, ray_blocks(o.shape[0]), _first_hit_block, packet_record, (),
                   (fn8, scene, o, d, t, prim, bary))  # fmt: skip


@njit(cache=True, nogil=True)
def _first_hit_block(b, pk, fn8, scene, o, d, t, prim, bary):
    rec, bits = pk[0], pk[1]
    end = min(o.shape[0], (b + 1) * RAY_BLOCK)
    for a in range(b * RAY_BLOCK, end, PACKET):
        n = min(PACKET, end - a)
        _load_lanes(pk, o, d, t, a, n)
        intersect8(fn8, scene, pk, n)  # geomID left invalid when there is no scene
        for lane in range(n):
            i = a + lane
            if bits[18, lane] != _INVALID:
                prim[i] = np.int64(bits[17, lane])
                bary[i, 0], bary[i, 1] = rec[15, lane], rec[16, lane]
            else:
                prim[i] = -1
                bary[i, 0], bary[i, 1] = 0.0, 0.0
