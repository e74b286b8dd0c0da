"""Vertex and index buffers written in place, and the indexed geometry drawn from them.

A buffer is re-written rather than re-created when the data fits (orphaned with a new size when it
grows, or shrinks below a quarter, keeping its name and its vertex arrays); a prefix of a read-only
array (the Baker's mesh parts) is written as the whole array once, then drawn by count.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iat.errors import RenderError
from iat.render.gl import Registry

_MIN_BUFFER = 64  # bytes; GL buffers are never created empty


def _frozen_root(raw: np.ndarray) -> np.ndarray | None:
    """The read-only, contiguous array ``raw`` is a prefix of (same dtype, same start), or None."""
    root = raw.base
    if (
        isinstance(root, np.ndarray)
        and not root.flags.writeable
        and root.flags.c_contiguous
        and root.dtype == raw.dtype
        and raw.nbytes <= root.nbytes
        and raw.__array_interface__["data"][0] == root.__array_interface__["data"][0]
    ):
        return root
    return None


def upload_buffer(ctx, reg: Registry, buf, data: np.ndarray):
    """Write ``data`` into ``buf`` in place; orphan it with a new size when the data grows
    (or shrinks below a quarter). Creates the buffer when ``buf`` is None. Returns the buffer.

    A prefix of a read-only array (the Baker's mesh parts are prefixes of one depth-sorted mesh)
    is written as the whole array, once: while the buffer holds that array, later prefixes of it
    write nothing (the draw call's count selects the prefix). Written from the array's memory
    (no ``tobytes`` copy)."""
    raw = np.ascontiguousarray(data)
    root = _frozen_root(raw)
    src = raw if root is None else root
    if buf is not None and root is not None and getattr(buf, "iat_source", None) is root:
        return buf  # already holds the whole frozen array
    nbytes = src.nbytes
    if buf is None:
        buf = reg.add(ctx.buffer(reserve=max(nbytes, _MIN_BUFFER), dynamic=True))
    elif nbytes > buf.size or (buf.size > _MIN_BUFFER and nbytes < buf.size // 4):
        buf.orphan(max(nbytes, _MIN_BUFFER))
    if nbytes:
        buf.write(memoryview(src.reshape(-1)).cast("B"))
    buf.iat_source = root  # the frozen array it now holds whole (None: anything else)
    return buf


@dataclass
class Geometry:
    """Indexed triangles with per-vertex attributes, drawn by ranges (one range per draw call).

    attrs : (name, components) of the float attributes, in the program's ``in_<name>``
    ranges : [(key, first_index, index_count)]: key -1 = plain, else a material with a detail texture
    """

    program: Any
    attrs: list[tuple[str, int]]
    buffers: dict[str, Any] = field(default_factory=dict)
    index_buffer: Any = None
    vao: Any = None
    n_triangles: int = 0
    ranges: list[tuple[int, int, int]] = field(default_factory=list)

    def upload(
        self,
        ctx,
        reg: Registry,
        arrays: dict[str, np.ndarray],
        indices: np.ndarray,
        tri_key: np.ndarray | None = None,
    ) -> None:
        """arrays : name -> (n, components) float32; indices : (t, 3) uint32;
        tri_key : (t,) int, -1 for plain triangles, else the detail material (one draw call per key)."""
        indices = np.asarray(indices, dtype=np.uint32).reshape(-1, 3)
        ranges = [(-1, 0, 3 * len(indices))]
        if tri_key is not None and len(indices):
            tri_key = np.asarray(tri_key, dtype=np.int64).reshape(-1)
            order = np.argsort(tri_key, kind="stable")
            indices = indices[order]
            keys, starts, counts = np.unique(tri_key[order], return_index=True, return_counts=True)
            ranges = [(int(k), 3 * int(s), 3 * int(c)) for k, s, c in zip(keys, starts, counts, strict=True)]
        for name, comps in self.attrs:
            a = np.asarray(arrays[name], dtype=np.float32).reshape(-1, comps)
            self.buffers[name] = upload_buffer(ctx, reg, self.buffers.get(name), a)
        self.index_buffer = upload_buffer(ctx, reg, self.index_buffer, indices)
        if self.vao is None:
            content = [(self.buffers[name], f"{comps}f", f"in_{name}") for name, comps in self.attrs]
            self.vao = reg.add(
                ctx.vertex_array(self.program, content, index_buffer=self.index_buffer, index_element_size=4)
            )
        self.n_triangles = len(indices)
        self.ranges = [r for r in ranges if r[2] > 0]

    def calls(self):
        """(key, first_index, index_count) of each draw call."""
        return list(self.ranges)

    def render_range(self, first: int, count: int) -> None:
        import moderngl

        self.vao.render(moderngl.TRIANGLES, vertices=count, first=first)

    def release(self, reg: Registry) -> None:
        reg.release(self.vao)
        for b in self.buffers.values():
            reg.release(b)
        reg.release(self.index_buffer)
        self.buffers.clear()
        self.vao = self.index_buffer = None
        self.n_triangles = 0
        self.ranges = []


#: added to the draw-call key of triangles whose patch has a twin (a back face of its own,
#: :mod:`iat.geometry.sides`): those calls cull back faces, so each side shows its own light
TWIN_KEY = 1 << 40


def twin_keys(tri_key: np.ndarray | None, tri_twin: np.ndarray) -> np.ndarray | None:
    """Draw-call keys (t,) with :data:`TWIN_KEY` added where ``tri_twin`` (t,) bool; None when no
    triangle has a twin (keys unchanged)."""
    if not tri_twin.any():
        return tri_key
    base = np.full(len(tri_twin), -1, np.int64) if tri_key is None else np.asarray(tri_key, np.int64)
    return np.where(tri_twin, base + TWIN_KEY, base)


def as_rows(a, n: int, name: str, dtype=np.float32) -> np.ndarray:
    """``a`` as (k, n) rows of ``dtype``; :class:`RenderError` naming ``name`` when it does not split."""
    a = np.asarray(a, dtype=dtype)
    if a.size % n:
        raise RenderError(f"{name} has {a.size} values, not a multiple of {n}")
    return a.reshape(-1, n)


def check_indices(indices: np.ndarray, n_vertices: int, name: str) -> None:
    """:class:`RenderError` naming ``name`` when ``indices`` reach outside ``n_vertices`` vertices."""
    if indices.size and (indices.min() < 0 or indices.max() >= n_vertices):
        raise RenderError(f"{name} refer to vertex {int(indices.max())} but there are {n_vertices} vertices")
