"""IAT mode with levels of detail (report §6.2.2): the textured part drawn from a Baked's
:class:`~iat.bake.lod.LodChain`, two levels blended per fragment in one pass, and (streaming)
only the levels the view needs resident on the GPU.

:class:`LodDrawer` holds the LOD program (``shaders/iat.glsl`` compiled with ``#define LOD``), the
textured geometry with per-vertex lattice coordinates ``st`` and tile row, and the table texture
(:class:`~iat.bake.lod.LodPages` ``table``: per tile a header and per level its place in the pages).
The pages go into the renderer's own :class:`~iat.render.pages.PageTexture` (no hardware mip
levels: the chain replaces them). With streaming, :meth:`LodDrawer.update` runs before each frame:
:func:`~iat.bake.lod.needed_levels` for the camera, :func:`~iat.bake.lod.resident_levels` (with
hysteresis), and when the resident set changed, :func:`~iat.bake.lod.fit_pages` (the budget caps the
resident pages) and one upload of pages and table.
"""

from __future__ import annotations

import numpy as np

from iat.bake.lod import LodChain, LodPages, fit_pages, needed_levels, resident_levels
from iat.bake.memory import MIB, lod_report
from iat.errors import RenderError
from iat.render import gl
from iat.render.buffers import Geometry

#: table rows per column block (tiles beyond wrap into the next block of columns)
TABLE_ROWS = 8192


def lod_program(ctx):
    """``shaders/iat.glsl`` compiled with ``#define LOD`` (the plain program stays as it was)."""

    def src(stage: str) -> str:
        s = gl.shader_source("iat", stage)
        head, rest = s.split("\n", 1)
        return f"{head}\n#define LOD\n{rest}"

    try:
        return ctx.program(vertex_shader=src("VERTEX_SHADER"), fragment_shader=src("FRAGMENT_SHADER"))
    except Exception as e:  # moderngl raises plain Exception subclasses
        raise RenderError(f"shader iat.glsl (LOD) does not compile: {e}") from e


def table_image(table: np.ndarray) -> np.ndarray:
    """(T, L + 1, 4) table -> ``(rows, blocks x (L + 1), 4)`` float32 image: tile ``t`` on row
    ``t % rows`` of column block ``t // rows`` (rows = min(T, :data:`TABLE_ROWS`))."""
    T, C = table.shape[:2]
    rows = max(1, min(T, TABLE_ROWS))
    blocks = max(1, -(-T // rows))
    img = np.zeros((rows, blocks * C, 4), np.float32)
    t = np.arange(T)
    img[(t % rows)[:, None], (t // rows)[:, None] * C + np.arange(C)[None]] = table
    return img


class LodDrawer:
    """The LOD textured part of one renderer (see the module docstring).

    Attributes: ``chain`` (the :class:`~iat.bake.lod.LodChain` set, or None), ``current`` (the
    :class:`~iat.bake.lod.LodPages` resident), ``stream`` (streaming on), ``budget_mb`` (cap on the
    resident pages, streaming only), ``bias`` (added to lambda), ``hysteresis`` (levels a tile may
    stay finer than it needs), ``drop_fraction`` (levels no longer needed are dropped, i.e. the pages
    re-packed, when a load happens anyway or when dropping them leaves at most this fraction of the
    resident bytes: fewer re-packs as the camera moves), ``cull_margin`` (None: streaming by
    distance alone; a fraction: patches outside the frustum widened by it keep only their coarsest
    level; fewer resident, more re-packs as the view turns), ``stats`` (``updates``: uploads of pages;
    ``frames``).
    """

    def __init__(self, ctx, reg):
        self._ctx, self._reg = ctx, reg
        self.program = reg.add(lod_program(ctx))
        self.geometry = Geometry(
            self.program, [("position", 3), ("st", 2), ("tile", 1), ("detail_uv", 2), ("detail", 1)]
        )
        self._table = None
        self.chain: LodChain | None = None
        self.current: LodPages | None = None
        self.stream = False
        self.budget_mb: float | None = None
        self.bias = 0.0
        self.hysteresis = 1
        self.drop_fraction = 0.75
        self.cull_margin: float | None = None  # frustum culling margin of needed_levels (None: off)
        self.show = False
        self.snap = False
        self.overrides: dict = {}  # "stream", "budget_mb" set by Renderer.set_lod over the bake's
        self._memory = None
        self._need: np.ndarray | None = None
        self._fresh = False
        self._wanted: np.ndarray | None = None
        self.stats = {"updates": 0, "frames": 0}

    @property
    def active(self) -> bool:
        return self.chain is not None and self.geometry.n_triangles > 0

    def clear(self) -> None:
        """Draw without LOD (the next :meth:`set` turns it on again)."""
        self.chain, self.current, self._need = None, None, None
        self.geometry.n_triangles = 0

    def set(self, baked, page_tex, reuse: bool, tpos, tduv, tdetail, tidx, tri_key) -> None:
        """Upload the LOD textured part of ``baked`` (``baked.lod``), all levels resident (streaming
        replaces them at the first :meth:`update`). tpos, tduv, tdetail, tidx, tri_key: the
        textured part's arrays as the renderer checked them."""
        chain: LodChain = baked.lod
        policy = getattr(baked, "policy", None)
        self.chain = chain
        self.stream = bool(self.overrides.get("stream", getattr(policy, "lod_stream", False)))
        self.budget_mb = getattr(policy, "budget_mb", None) if self.stream else None
        self.budget_mb = self.overrides.get("budget_mb", self.budget_mb)
        self._memory = getattr(baked, "memory", None)
        st, tile = chain.tile_st(np.asarray(baked.tex_patch), np.asarray(baked.tex_uv))
        self.geometry.upload(
            self._ctx,
            self._reg,
            {"position": tpos, "st": st, "tile": tile, "detail_uv": tduv, "detail": tdetail},
            tidx,
            tri_key,
        )
        self._need = None
        self.stats["updates"] = 0
        self._upload(chain.pages(), page_tex, reuse)
        self._fresh, self._wanted = True, None  # the first view streams what it needs, no hysteresis

    def configure(
        self, bias=None, stream=None, budget_mb=..., cull=..., show=None, snap=None, from_bake=False
    ) -> bool:
        """Set the switches (None / ``...``: unchanged); True when the Baked must be set again.

        bias : added to lambda (negative: finer levels)
        stream : keep only the levels the view needs resident (overrides the bake's ``lod_stream``)
        budget_mb : cap on the resident pages when streaming (None: no cap; overrides the bake's)
        cull : frustum margin of :func:`~iat.bake.lod.needed_levels` (None: by distance alone)
        show : IAT mode writes ``(lambda, level, weight)`` per textured pixel instead of radiance
          (a readout for tests and overlays); snap : the nearest level alone (no blend: it pops)
        from_bake : first drop earlier ``stream`` / ``budget_mb`` settings (the bake's apply again)
        """
        for name, v, kind in (("bias", bias, float), ("show", show, bool), ("snap", snap, bool)):
            if v is not None:
                setattr(self, name, kind(v))
        if cull is not ...:
            self.cull_margin = None if cull is None else float(cull)
        again = bool(from_bake and self.overrides)
        if from_bake:
            self.overrides.clear()
        if stream is not None and self.overrides.get("stream") != bool(stream):
            self.overrides["stream"], again = bool(stream), True
        if budget_mb is not ... and self.overrides.get("budget_mb", ...) != budget_mb:
            self.overrides["budget_mb"], again = budget_mb, True
        return again

    def _upload(self, pages: LodPages, page_tex, reuse: bool) -> None:
        if pages.gpu.shape[0]:
            page_tex.upload(pages.gpu, self.chain.pixel_format, False, 1, reuse)
        img = table_image(pages.table)
        h, w = img.shape[:2]
        if self._table is not None and self._table.size == (w, h):
            self._table.write(img.tobytes())
        else:
            import moderngl

            self._reg.release(self._table)
            self._table = self._reg.add(self._ctx.texture((w, h), 4, img.tobytes(), dtype="f4"))
            self._table.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._rows, self._columns = (h, pages.table.shape[1])
        self.current = pages
        self.stats["updates"] += 1

    def update(
        self, clip_from_world: np.ndarray, size: tuple[int, int], page_tex, reuse: bool, znear: float = 1e-3
    ) -> bool:
        """Before a frame: the finest level each patch can show in this view (:meth:`info`) and, when
        streaming, those levels made resident (True when the pages changed)."""
        self.stats["frames"] += 1
        if self.chain is None or self.chain.n_tiles == 0:
            return False
        need = needed_levels(self.chain, clip_from_world, size, self.bias, znear, self.cull_margin)
        self._need = need  # the readout's finest levels this view can use, streaming or not
        if not self.stream:
            return False
        cur = self.current.resident if self.current is not None else None
        fresh, self._fresh = self._fresh, False
        want = None if fresh else self._wanted
        res = resident_levels(self.chain, need, None, want, self.hysteresis)
        if want is not None and not (res < want).any():  # nothing to load: drop only when it pays
            eb = self.chain.entry_bytes()
            L = np.arange(self.chain.max_levels)[None, :]
            now, then = eb[L >= want[:, None]].sum(), eb[L >= res[:, None]].sum()
            if then > self.drop_fraction * now:
                return False
        self._wanted = res  # before the budget: what the view asks for
        budget = None if self.budget_mb is None else float(self.budget_mb) * MIB
        pages = fit_pages(self.chain, res, budget)
        if not fresh and cur is not None and np.array_equal(pages.resident, cur):
            return False
        self._upload(pages, page_tex, reuse)
        return True

    def draw(self, uniforms, page_tex, details: dict, white) -> tuple[int, int]:
        """Draw the textured part (``uniforms(program, values)`` sets uniforms); returns
        ``(triangles, draw calls)``."""
        g = self.geometry
        page_tex.texture.use(0)
        self._table.use(2)
        aw, ah = page_tex.info()["allocated"][:2]
        values = {
            "pages": 0,
            "detail": 1,
            "lod_table": 2,
            "lod_rows": int(self._rows),
            "lod_columns": int(self._columns),
            "atlas_size": (float(aw), float(ah)),
            "lod_bias": float(self.bias),
            "lod_show": bool(self.show),
            "lod_snap": bool(self.snap),
        }
        uniforms(g.program, values)
        tris = calls = 0
        for key, first, count in g.calls():
            tex = details.get(key)
            (tex if tex is not None else white).use(1)
            uniforms(g.program, {"use_detail": tex is not None})
            g.render_range(first, count)
            tris, calls = tris + count // 3, calls + 1
        return tris, calls

    def info(self) -> dict:
        """The readout of the levels in use: ``enabled``, ``streaming``, ``tiles``, ``max_levels``,
        ``resident_levels`` / ``needed_levels`` (``{tree level: tiles}`` of each tile's finest level
        resident / the finest the last view can use), ``resident_bytes``,
        ``total_bytes`` (packed pages), ``resident_texel_bytes``, ``total_texel_bytes`` (the boxes
        themselves, without the pages' power-of-two rounding), ``updates``, ``memory`` (the bake's
        :class:`~iat.bake.memory.MemoryReport` with the resident bytes of now). Empty without LOD."""
        if self.chain is None or self.current is None:
            return {}
        ch = self.chain

        def hist(levels: np.ndarray | None) -> dict:
            if levels is None or not len(levels):
                return {}
            tree = ch.tree_level[np.arange(ch.n_tiles), np.clip(levels, 0, ch.max_levels - 1)]
            u, c = np.unique(tree, return_counts=True)
            return {int(a): int(b) for a, b in zip(u.tolist(), c.tolist(), strict=True)}

        total = ch.pages().bytes
        eb = ch.entry_bytes()
        keep = np.arange(ch.max_levels)[None, :] >= self.current.resident[:, None]
        mem = None
        if self._memory is not None:
            mem = lod_report(self._memory, ch.max_levels, total, self.current.bytes, self.budget_mb)
        return {
            "enabled": True,
            "streaming": self.stream,
            "tiles": ch.n_tiles,
            "max_levels": ch.max_levels,
            "resident_levels": hist(self.current.resident),
            "needed_levels": hist(self._need),
            "resident_bytes": int(self.current.bytes),
            "total_bytes": int(total),
            "resident_texel_bytes": int(eb[keep].sum()),
            "total_texel_bytes": int(eb.sum()),
            "updates": int(self.stats["updates"]),
            "memory": mem,
        }


__all__ = ["TABLE_ROWS", "LodDrawer", "lod_program", "table_image"]
