"""Ray-traced visibility between points, with Embree 4.

The scene's surface as triangles (:meth:`iat.io.scene.Scene.world_triangles`: a patch's one
or two, a panel cell's clip triangles) becomes one float32 Embree scene of its opaque triangles
and one of its glass. Two backends answer alike, ray for ray (``tests/test_embree_c.py``):

- ``"c"`` (the default where the library loads, :mod:`iat.radiosity.embree`): Embree's C API
  called from numba kernels that release the GIL and spread the rays over the ray threads
  (``prange``); the gathers trace their own rays through the same kernels
  (:meth:`Visibility.embree_args`).
- ``"embreex"`` (the fallback, or ``IAT_EMBREE_C=0``): embreex's ``run`` in chunks, spread over a
  Python thread pool (embreex releases the GIL during a query).

Callers offset their ray origins off the surfaces (see the solver).
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np
from numba import get_num_threads, set_num_threads

from iat.radiosity import embree

#: rays per embreex call
CHUNK = 1 << 16
#: environment variable: the worker threads of ray queries when none are given (default min(2, cores))
RAY_THREADS_ENV = "IAT_RAY_THREADS"


class Visibility:
    """Occlusion queries against the scene's surface.

    triangles : (T, 3, 3) float64 world triangles
    transmission : (T,) float transmittance of each triangle (glass), or None (all opaque)
    threads : ray threads for large queries (default: ``$IAT_RAY_THREADS``, else min(2, CPU count))
    backend : ``"c"``, ``"embreex"`` or None (``"c"`` where :func:`.embree.available`); see the
      module docstring

    ``rays`` counts the rays traced so far and ``seconds`` the time spent tracing them (with the
    ``"c"`` backend, a gather that traces its own rays counts the whole of its kernel).
    Transmissive triangles do not occlude; :meth:`visible` multiplies by the transmittance
    of the first one a ray crosses (one pane: double glazing counts once).
    """

    def __init__(
        self,
        triangles: np.ndarray,
        transmission: np.ndarray | None = None,
        threads: int | None = None,
        backend: str | None = None,
    ):
        tris = np.asarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
        tau = np.zeros(len(tris)) if transmission is None else np.asarray(transmission, dtype=np.float64)
        glass = tau > 0
        if backend is None:
            backend = "c" if embree.available() else "embreex"
        if backend not in ("c", "embreex"):
            raise ValueError(f"unknown ray backend {backend!r}")
        #: ``"c"`` or ``"embreex"``
        self.backend = backend
        #: (T_opaque,) int64 index into ``triangles`` of each opaque triangle (what :meth:`first_hit` numbers)
        self.opaque = np.flatnonzero(~glass)
        self._n_tris = len(self.opaque)
        self._glass_tau = np.ascontiguousarray(tau[glass]) if glass.any() else np.ones(1)
        self._has_glass = bool(glass.any())
        self._c = self._c_glass = None
        self._glass = self._scene = None
        if backend == "c":
            self._c = embree.EmbreeScene(tris[~glass])
            self._c_glass = embree.EmbreeScene(tris[glass]) if self._has_glass else None
        else:
            from embreex import rtcore_scene as rtcs
            from embreex.mesh_construction import TriangleMesh

            if self._has_glass:
                self._glass = rtcs.EmbreeScene()
                gv = np.ascontiguousarray(tris[glass].reshape(-1, 3))
                self._glass_mesh = TriangleMesh(
                    self._glass, gv, np.arange(len(gv), dtype=np.int32).reshape(-1, 3)
                )
            self._scene = rtcs.EmbreeScene()
            if self._n_tris:
                verts = np.ascontiguousarray(tris[~glass].reshape(-1, 3))
                faces = np.arange(len(verts), dtype=np.int32).reshape(-1, 3)
                self._mesh = TriangleMesh(self._scene, verts, faces)
        if threads is None:
            threads = int(os.environ.get(RAY_THREADS_ENV, "0") or 0) or min(2, os.cpu_count() or 1)
        self.threads = max(1, int(threads))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 and backend == "embreex" else None
        self._lock = threading.Lock()
        self._local = threading.local()
        self.rays = 0
        self.seconds = 0.0

    @classmethod
    def of_scene(cls, scene, threads: int | None = None, backend: str | None = None) -> Visibility:
        """The visibility of a :class:`~iat.io.scene.Scene`'s surface, its glass transmissive."""
        tau = scene.patch_transmission[scene.world_triangle_patch()]
        return cls(scene.world_triangles(), tau, threads, backend)

    def close(self) -> None:
        """Stop the worker threads and release the Embree scenes (also done when the object is
        collected); no query may follow."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        for sc in (self._c, self._c_glass):
            if sc is not None:
                sc.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @contextmanager
    def on_this_thread(self) -> Iterator[None]:
        """Queries made by this thread inside are traced on it, not spread over the threads (for
        callers that trace from several threads at once)."""
        self._local.serial = True
        try:
            yield
        finally:
            self._local.serial = False

    def ray_threads(self) -> int:
        """The threads a query made now on this thread spreads over: 1 inside
        :meth:`on_this_thread`, else :attr:`threads`, at most numba's thread count here."""
        if getattr(self._local, "serial", False):
            return 1
        return max(1, min(self.threads, get_num_threads()))

    @contextmanager
    def kernel_threads(self) -> Iterator[None]:
        """numba kernels called inside run on :meth:`ray_threads` threads."""
        before = get_num_threads()
        want = 1 if getattr(self._local, "serial", False) else max(1, min(self.threads, before))
        if want == before:  # (numba's set_num_threads costs microseconds a call: skipped if a no-op)
            yield
            return
        set_num_threads(want)
        try:
            yield
        finally:
            set_num_threads(before)

    def embree_args(self) -> tuple | None:
        """With the ``"c"`` backend, what a kernel that traces its own rays takes
        (:func:`.embree.visible8`): ``(occluded8, intersect1, scene, glass, glass_tau)``, the entry
        points' addresses and the scenes' handles as int64 (glass 0 when there is none) and the
        glass triangles' transmittances (float64); None with embreex."""
        if self._c is None:
            return None
        glass = self._c_glass.handle if self._c_glass is not None else np.int64(0)
        return (self._c.entry.occluded8, self._c.entry.intersect1, self._c.handle, glass, self._glass_tau)

    def _opaque_args(self) -> tuple:
        """:meth:`embree_args` without the glass: what :func:`.embree.trace_visible` takes to answer
        only whether something opaque lies on each ray (0: it does, 1: it does not)."""
        return (self._c.entry.occluded8, np.int64(0), self._c.handle, np.int64(0), self._glass_tau)

    def count(self, rays: int, seconds: float) -> None:
        """Add rays traced elsewhere (a kernel given :meth:`embree_args`) to ``rays`` and ``seconds``."""
        with self._lock:
            self.rays += int(rays)
            self.seconds += seconds

    def occluded_chunk(self, o: np.ndarray, d: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The backend's raw answer for one chunk of rays, on the calling thread and not counted in
        ``rays``: (n,) int, 0 where something lies before ``t`` (embreex's convention). o, d :
        (n, 3) float32 contiguous; t : (n,) float32."""
        if self._c is None:
            return self._scene.run(o, d, dists=t, query="OCCLUDED")
        out = np.empty(len(o))
        before = get_num_threads()
        set_num_threads(1)
        try:
            embree.trace_visible(*self._opaque_args(), o, d, t, out)
        finally:
            set_num_threads(before)
        return (out > 0).astype(np.int32)

    @staticmethod
    def _rays(origins, dirs, tfar) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        o = np.ascontiguousarray(origins, dtype=np.float32).reshape(-1, 3)
        d = np.ascontiguousarray(dirs, dtype=np.float32).reshape(-1, 3)
        t = np.ascontiguousarray(tfar, dtype=np.float32).reshape(-1)
        return o, d, t

    def _kernel(self, kernel, *args, n: int) -> None:
        """``kernel(*args)`` on :meth:`ray_threads` threads, its ``n`` rays counted."""
        t0 = time.perf_counter()
        with self.kernel_threads():
            kernel(*args)
        self.count(n, time.perf_counter() - t0)

    def _traced(self, query, origins, dirs, tfar, fill, out: np.ndarray | None = None) -> np.ndarray:
        """``query(o, d, t)`` (one embreex call) over chunks of the rays, spread over the threads
        and counted in ``rays`` and ``seconds``; its answers in ``out`` (default (n,) int64),
        ``fill`` where there is no scene."""
        n = len(origins)
        if out is None:
            out = np.empty(n, dtype=np.int64)
        out[...] = fill
        if n == 0 or self._n_tris == 0:
            self.count(n, 0.0)
            return out
        o, d, t = self._rays(origins, dirs, tfar)
        t0 = time.perf_counter()
        c = max(4096, min(CHUNK, -(-n // self.threads)))
        bounds = list(range(0, n, c))
        if self._pool is None or len(bounds) == 1 or getattr(self._local, "serial", False):
            for a in bounds:
                out[a : a + c] = query(o[a : a + c], d[a : a + c], t[a : a + c])
        else:
            futs = [(a, self._pool.submit(query, o[a : a + c], d[a : a + c], t[a : a + c])) for a in bounds]
            for a, f in futs:
                out[a : a + c] = f.result()
        self.count(n, time.perf_counter() - t0)
        return out

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """(n,) bool: True where something lies on the ray before ``tfar``.

        origins : (n, 3) ray origins (already offset off the surface)
        dirs : (n, 3) unit directions
        tfar : (n,) distances along the ray beyond which hits are ignored
        """
        if self._c is None:
            return self._traced(self.occluded_chunk, origins, dirs, tfar, 1) == 0
        o, d, t = self._rays(origins, dirs, tfar)
        out = np.empty(len(o))
        self._kernel(embree.trace_visible, *self._opaque_args(), o, d, t, out, n=len(o))
        return out == 0

    def first_hit(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """(n,) int64 the opaque triangle each ray meets first before ``tfar`` (an index into
        :attr:`opaque`), -1 where none; arguments as :meth:`occluded`."""
        if self._c is None:
            return self._traced(lambda o, d, t: self._scene.run(o, d, dists=t), origins, dirs, tfar, -1)
        return self.first_hits(origins, dirs, tfar)[0]

    def first_hits(self, origins, dirs, tfar) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`first_hit` with where on the triangle: (n,) int64 opaque triangle (-1: none) and
        (n, 2) float64 its barycentric coordinates (b1, b2) of the hit, ``(1 - b1 - b2) v0 + b1 v1
        + b2 v2``."""
        if self._c is not None:
            o, d, t = self._rays(origins, dirs, tfar)
            prim, bary = np.empty(len(o), dtype=np.int64), np.empty((len(o), 2))
            entry, handle = self._c.entry.intersect8, self._c.handle
            self._kernel(embree.trace_first_hits, entry, handle, o, d, t, prim, bary, n=len(o))
            return prim, bary

        def query(o, d, t):
            r = self._scene.run(o, d, dists=t, output=1)
            prim = np.where(np.asarray(r["geomID"]) < 0, -1, np.asarray(r["primID"]))
            return np.stack([prim, r["u"], r["v"]], axis=1)

        out = self._traced(query, origins, dirs, tfar, -1.0, np.empty((len(origins), 3)))
        return out[:, 0].astype(np.int64), out[:, 1:]

    def visible(self, origins: np.ndarray, dirs: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """(n,) float64 what of each ray's light gets through before ``tfar``: 0 when something
        opaque lies on it, else the transmittance of the first glass it crosses (1 if none)."""
        if self._c is not None:
            o, d, t = self._rays(origins, dirs, tfar)
            out = np.empty(len(o))
            occ, isect, scene, glass, tau = self.embree_args()
            t0 = time.perf_counter()
            with self.kernel_threads():
                through = embree.trace_visible(occ, isect, scene, glass, tau, o, d, t, out)
            self.count(len(o) + through, time.perf_counter() - t0)  # the glass's rays counted, as embreex's
            return out
        out = (~self.occluded(origins, dirs, tfar)).astype(np.float64)
        if self._glass is None or not out.any():
            return out
        free = np.flatnonzero(out > 0)
        o = np.ascontiguousarray(np.asarray(origins, dtype=np.float32).reshape(-1, 3)[free])
        d = np.ascontiguousarray(np.asarray(dirs, dtype=np.float32).reshape(-1, 3)[free])
        t = np.ascontiguousarray(np.asarray(tfar, dtype=np.float32).reshape(-1)[free])
        t0 = time.perf_counter()
        prim = np.concatenate(
            [
                self._glass.run(o[a : a + CHUNK], d[a : a + CHUNK], dists=t[a : a + CHUNK])
                for a in range(0, len(o), CHUNK)
            ]
        )
        self.count(len(o), time.perf_counter() - t0)
        hit = prim >= 0
        out[free[hit]] = self._glass_tau[prim[hit]]
        return out
