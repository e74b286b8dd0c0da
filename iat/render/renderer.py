"""The renderer: draws a Scene (preview), a Solution (mesh) or a Baked (IAT) with moderngl.

Shared by the viewer (a window context is passed in), the CLI, the tests and the
benchmark (headless: an EGL standalone context, Mesa llvmpipe here).

Modes
-----
``preview``  every patch of a :class:`~iat.io.scene.Scene` unlit: ``emission + 0.5 x albedo``
``mesh``     the solution's leaf triangles, one radiance per vertex, Gouraud-interpolated
``iat``      a Baked: its vertex-coloured mesh part plus one textured polygon per
             textured patch, the atlas pages in one texture array
``split``    mesh left of ``split x width``, IAT right of it (scissor)
``diff``     ``|mesh - iat| x diff_gain`` (both drawn to float targets, combined in a fullscreen pass)

In mesh, IAT and split modes glass (a solution's ``patch_transmission``) is drawn over the
opaque surfaces, multiplying what lies behind by its transmittance, and the sky given to
:meth:`Renderer.set_sky` fills the background (off by default: images compared with references
mask the sky out).

Solution sets (lighting states, e.g. times of day; :mod:`iat.lighting.solution_set`)
---------------------------------------------------------------------------
:meth:`Renderer.set_solution_set` (mesh mode) and :meth:`Renderer.set_baked_set`
(IAT mode) take several aligned solutions / a :class:`~iat.bake.baked.BakedSet`;
:meth:`Renderer.set_blend` picks the two neighbouring states ``a``, ``b`` and the
mix ``w``. IAT mode samples state a's and state b's page layers (all states sit in
one texture array, state k's page p at layer ``k * n_pages + p``) and mixes them
in one pass; mesh mode mixes two colour attributes per vertex. ``w = 0`` draws
state a exactly (the second lookup is skipped), so a blend at a key time equals
that solution's own image.

:meth:`Renderer.render` returns linear radiance as ``(h, w, 3) float32`` read
back from an RGBA32F framebuffer (exact, no tone map); :meth:`Renderer.draw`
draws into the bound framebuffer with exposure and sRGB encoding in the shader.

GL memory: every GL object the renderer creates is kept in one registry and
released by :meth:`Renderer.release`. Re-setting data writes buffers and
textures in place when the size allows (a buffer is orphaned with a new size
when the data grows, or shrinks below a quarter, keeping its name and its
vertex arrays), so re-baking every frame does not grow GL memory. Data that is a
prefix of a read-only array (the Baker's mesh parts) is written as the whole
array once, then drawn by count; the Baker's page arrays already on the GPU are
not written again. The page texture is kept when new pages fit in it (written into
its corner, texture coordinates scaled exactly; :meth:`iat.render.pages.PageTexture.size_for`),
so it may be larger than the bake's :class:`~iat.bake.memory.MemoryReport` counts:
:attr:`Renderer.page_texture` gives both.

Levels of detail (a Baked of ``BakePolicy(lod=True)``): :mod:`iat.render.lod` draws it (two quad-tree
levels blended per fragment, streaming); :meth:`Renderer.set_lod` switches, :meth:`Renderer.lod_info` reads.

Modules: :mod:`iat.render.gl` (shaders, programs, the GL object registry),
:mod:`iat.render.buffers` (buffers written in place, indexed geometry),
:mod:`iat.render.pages` (the page texture array); this one draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from iat.errors import RenderError
from iat.geometry.sides import twin_patches
from iat.radiosity.solution import drawn_mesh
from iat.render import gl
from iat.render.buffers import TWIN_KEY, Geometry, as_rows, check_indices, twin_keys, upload_buffer
from iat.render.gl import Registry
from iat.render.lod import LodDrawer
from iat.render.mesh_detail import mesh_detail
from iat.render.pages import PageTexture, gpu_pages

MODES = ("preview", "mesh", "iat", "split", "diff")
#: constant standing in for lighting in preview mode: colour = emission + PREVIEW_AMBIENT x albedo
PREVIEW_AMBIENT = 0.5
#: columns of the sky's equirectangular image drawn behind the model (0.7 degrees a texel)
SKY_WIDTH = 512


@dataclass
class _Target:
    """An offscreen framebuffer: RGBA32F colour (renderbuffer, or texture when sampled later) + depth."""

    size: tuple[int, int]
    color: Any
    depth: Any
    fbo: Any


class Renderer:
    """Draws preview / mesh / IAT images with moderngl.

    ctx : a moderngl context (the viewer's window context), or None to create an
          EGL standalone context (headless), which the renderer then owns and releases.
    """

    #: keep the page texture when new pages fit in it (:meth:`iat.render.pages.PageTexture.size_for`);
    #: False re-creates it whenever the pages' size changes (the benchmark's ``--no-reuse``, for comparison)
    reuse_pages = True

    def __init__(self, ctx=None):
        import moderngl

        self._moderngl = moderngl
        self._owns_ctx = ctx is None
        if ctx is None:
            try:
                ctx = moderngl.create_standalone_context(backend="egl")
            except Exception as e:  # moderngl raises plain Exception subclasses here
                raise RenderError(f"cannot create an EGL OpenGL context: {e}") from e
        self.ctx = ctx
        # where to return after offscreen work: moderngl rebinds "the bound framebuffer" whenever it
        # creates one, so our framebuffers must never stay bound once released
        self._home = ctx.fbo if ctx.fbo is not None else ctx.detect_framebuffer()
        self._reg = Registry()
        self._programs: dict[str, Any] = {}
        for name in ("mesh", "iat", "preview", "composite", "glass", "sky"):
            self._programs[name] = self._reg.add(gl.program(ctx, name))
        self._fullscreen = self._reg.add(ctx.vertex_array(self._programs["composite"], []))
        # on the detail unit when a draw has no detail texture (never the target: a diff-mode feedback loop)
        self._white = self._reg.add(ctx.texture((1, 1), 4, np.ones(4, np.float32).tobytes(), dtype="f4"))
        mesh, iat, preview = self._programs["mesh"], self._programs["iat"], self._programs["preview"]
        mesh_attrs = [("position", 3), ("color", 3), ("color_b", 3), ("detail_uv", 2), ("detail", 1)]
        self._solution, self._baked_mesh = Geometry(mesh, mesh_attrs), Geometry(mesh, mesh_attrs)
        self._scene = None  # the scene shown: its detail patches, for mesh mode (iat.render.mesh_detail)
        self._baked_tex = Geometry(
            iat, [("position", 3), ("uv", 2), ("layer", 1), ("detail_uv", 2), ("detail", 1)]
        )
        self._preview = Geometry(preview, [("position", 3), ("emission", 3), ("albedo", 3), ("uv", 2)])
        self._glass = Geometry(self._programs["glass"], [("position", 3), ("transmission", 3)])
        self._sky_quad = self._reg.add(ctx.vertex_array(self._programs["sky"], []))
        self._sky = None  # the sky's equirectangular texture, or None: a black background
        self._has = {"preview": False, "mesh": False, "iat": False}
        self._page_tex = PageTexture(ctx, self._reg)
        self._page_scale, self._lod_on = 1.0, True
        self._lod = LodDrawer(ctx, self._reg)  # a Baked with a LOD chain (iat.render.lod)
        self._baked_args: tuple | None = None
        # solution sets: per-state vertex colours (CPU) of the solution mesh and of the baked mesh
        # part, the (a, b) pair uploaded as color / color_b, the states and pages per state in IAT mode
        self._colors: dict[str, list[np.ndarray]] = {"mesh": [], "iat": []}
        self._colors_pair: dict[str, tuple[int, int]] = {"mesh": (0, 0), "iat": (0, 0)}
        self._iat_states = self._iat_pages = 1
        self.overlays: list = []  # drawn over the surfaces after the mode (iat.render.fault_tint)
        self._blend: tuple[int, int, float] = (0, 0, 0.0)
        self._detail: dict[str, dict[int, Any]] = {"iat": {}, "preview": {}}
        self._targets: dict[str, _Target] = {}
        self._last: dict[str, Any] = {"mode": None, "triangles": 0, "draw_calls": 0, "modes": {}}
        self._released = False

    # -- lifetime ---------------------------------------------------------------------------
    def release(self) -> None:
        """Release every GL object created by this renderer (and the context if it created it)."""
        if self._released:
            return
        if any(self.ctx.fbo is t.fbo for t in self._targets.values()):
            self._home.use()
        self._reg.release_all()
        self._detail = {"iat": {}, "preview": {}}
        self._targets.clear()
        self._page_tex.forget()
        if self._owns_ctx:
            self.ctx.release()
        self._released = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def gl_object_count(self) -> int:
        """How many GL objects this renderer holds now (constant across re-sets of same-shaped data)."""
        return len(self._reg)

    def _alive(self):
        if self._released:
            raise RenderError("renderer already released")

    # -- detail textures --------------------------------------------------------------------
    def _texture2d(self, old, data: np.ndarray):
        """(h, w, 3) float -> RGBA32F repeating, mipmapped texture; written in place when the size matches."""
        h, w = data.shape[:2]
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[..., :3] = data[..., :3]
        if old is not None and old.size == (w, h):
            old.write(rgba.tobytes())
            tex = old
        else:
            self._reg.release(old)
            tex = self._reg.add(self.ctx.texture((w, h), 4, rgba.tobytes(), dtype="f4"))
            tex.repeat_x = tex.repeat_y = True
            tex.filter = (self._moderngl.LINEAR_MIPMAP_LINEAR, self._moderngl.LINEAR)
        tex.build_mipmaps()
        return tex

    def _set_details(self, which: str, textures: dict[int, np.ndarray]) -> None:
        cur = self._detail[which]
        for m in list(cur):
            if m not in textures:
                self._reg.release(cur.pop(m))
        for m, img in textures.items():
            img = np.asarray(img, dtype=np.float32)
            if img.ndim != 3 or img.shape[2] < 3 or img.shape[0] == 0 or img.shape[1] == 0:
                raise RenderError(f"detail texture of material {m} has shape {img.shape}, expected (h, w, 3)")
            cur[int(m)] = self._texture2d(cur.get(int(m)), img)

    @property
    def page_texture(self) -> dict:
        """The IAT page texture: ``allocated`` ``(W, H, layers)`` and the ``used`` corner ``(w, h,
        layers)`` of the pages last set, and ``bytes`` allocated at level 0 (the bake's
        :class:`~iat.bake.memory.MemoryReport` counts what the pages need; the array may be larger, see
        :meth:`iat.render.pages.PageTexture.size_for`). Empty without pages."""
        return self._page_tex.info()

    @property
    def page_array(self):
        """The moderngl TextureArray holding the IAT pages (read-only; None before pages are set)."""
        return self._page_tex.texture

    @property
    def solution_geometry(self) -> Geometry:
        """The mesh-mode geometry (:class:`~iat.render.buffers.Geometry`; read-only: its buffers
        are rewritten in place by :meth:`set_solution`)."""
        return self._solution

    # -- data -------------------------------------------------------------------------------
    def set_scene(self, scene) -> None:
        """Preview geometry of a :class:`~iat.io.scene.Scene`: every patch, unlit albedo + emission.

        Quads become two triangles (0, 1, 2), (0, 2, 3); triangles one. Materials with a
        ``detail`` texture are drawn with it (one draw call per such material).
        """
        self._alive()
        corners = np.asarray(scene.corner_positions, dtype=np.float64).reshape(-1, 4, 3)
        p = len(corners)
        is_quad = np.asarray(scene.patch_corners)[:, 3] >= 0
        mat = np.asarray(scene.patch_material, dtype=np.int64).reshape(-1)
        materials = scene.materials
        albedo = np.array([m.albedo for m in materials], dtype=np.float64).reshape(-1, 3)
        emission = np.array([m.emission for m in materials], dtype=np.float64).reshape(-1, 3)
        if p and (mat.min() < 0 or mat.max() >= len(materials)):
            raise RenderError(f"scene patch_material refers to material {int(mat.max())} of {len(materials)}")
        uv = scene.patch_uv if scene.patch_uv is not None else np.zeros((p, 4, 2))
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 4, 2)
        base = 4 * np.arange(p, dtype=np.uint32)
        t1 = np.stack([base, base + 1, base + 2], axis=1)
        t2 = np.stack([base, base + 2, base + 3], axis=1)[is_quad]
        indices = np.concatenate([t1, t2])
        tri_patch = np.concatenate([np.arange(p), np.nonzero(is_quad)[0]])
        details = {i: m.detail for i, m in enumerate(materials) if getattr(m, "detail", None) is not None}
        detail_mat = np.array(sorted(details), dtype=np.int64)
        tri_mat = mat[tri_patch]
        tri_key = np.where(np.isin(tri_mat, detail_mat), tri_mat, -1)
        self._set_details("preview", details)
        self._scene = scene
        self._preview.upload(
            self.ctx,
            self._reg,
            {
                "position": corners.reshape(-1, 3),
                "emission": np.repeat(emission[mat], 4, axis=0),
                "albedo": np.repeat(albedo[mat], 4, axis=0),
                "uv": uv.reshape(-1, 2),
            },
            indices,
            tri_key,
        )
        self._has["preview"] = True

    def set_solution(self, solution) -> None:
        """Mesh-mode geometry of a Solution: vertex-coloured leaf triangles (Gouraud).

        Uses ``max_depth, patch_corners (P,4,3), patch_is_quad (P,), vert_key (V,) int64,
        vert_radiance (V,3), tri_vertices (T,3)``; vertex positions come from the lattice keys.
        """
        self.set_solution_set([solution])

    def set_solution_set(self, solutions) -> None:
        """Mesh-mode geometry of aligned solutions (same vertex keys and triangles: solved on one
        mesh, :mod:`iat.lighting.solution_set`), one radiance per vertex and state; :meth:`set_blend` mixes
        two of them. Positions and triangles come from the first."""
        self._alive()
        solutions = list(solutions)
        if not solutions:
            raise RenderError("set_solution_set needs at least one solution")
        solution = solutions[0]
        key = np.asarray(solution.vert_key, dtype=np.int64).reshape(-1)
        m = 2 ** int(solution.max_depth) + 1
        corners = np.asarray(solution.patch_corners, dtype=np.float64).reshape(-1, 4, 3)
        if key.size and (key.min() < 0 or (key // (m * m)).max() >= len(corners)):
            raise RenderError(
                f"solution vertex keys refer to patch {int((key // (m * m)).max())} of {len(corners)}"
            )
        tris = np.asarray(solution.tri_vertices, dtype=np.int64).reshape(-1, 3)
        check_indices(tris, len(key), "solution tri_vertices")
        drawn = drawn_mesh(solution)  # panel cells' triangles cut to their surface
        pos, tris = drawn.position, drawn.triangles
        md = mesh_detail(solution, drawn, self._scene)  # detail vertices hold incoming light
        duv, dflag, divisor, tri_key = md or (np.zeros((len(pos), 2)), np.zeros(len(pos)), 1.0, None)
        twin = twin_patches(corners, solution.patch_is_quad)
        tri_key = twin_keys(tri_key, twin[drawn.patch[tris[:, 0]]] if len(tris) else np.zeros(0, bool))
        colors = []
        for k, sol in enumerate(solutions):
            rad = as_rows(sol.vert_radiance, 3, "vert_radiance")
            if len(rad) != len(key):
                raise RenderError(f"solution has {len(key)} vertex keys but {len(rad)} radiance values")
            if k and (
                not np.array_equal(np.asarray(sol.vert_key).reshape(-1), key)
                or not np.array_equal(np.asarray(sol.tri_vertices).reshape(-1, 3), solution.tri_vertices)
            ):
                raise RenderError(f"solution {k} of the set is not on the same mesh as solution 0")
            colors.append(np.ascontiguousarray(drawn.radiance(rad) * divisor, dtype=np.float32))
        self._colors["mesh"] = colors
        a, b = self._pair("mesh")
        arrays = {"position": pos, "color": colors[a], "color_b": colors[b], "detail_uv": duv}
        self._solution.upload(self.ctx, self._reg, {**arrays, "detail": dflag}, tris, tri_key)
        self._colors_pair["mesh"] = (a, b)
        self._has["mesh"] = True
        self._set_glass(solution)

    def _set_glass(self, solution) -> None:
        """The glass patches of ``solution`` (``patch_transmission > 0``) as triangles."""
        tau = np.asarray(getattr(solution, "patch_transmission", np.zeros(0)), dtype=np.float32).reshape(-1)
        corners = np.asarray(solution.patch_corners, dtype=np.float32).reshape(-1, 4, 3)
        glass = np.nonzero(tau > 0)[0] if len(tau) == len(corners) else np.zeros(0, np.int64)
        is_quad = np.asarray(solution.patch_is_quad, dtype=bool).reshape(-1)[glass]
        base = 4 * np.arange(len(glass), dtype=np.uint32)
        tris = np.concatenate(
            [np.stack([base, base + 1, base + 2], 1), np.stack([base, base + 2, base + 3], 1)[is_quad]]
        )
        self._glass.upload(
            self.ctx,
            self._reg,
            {
                "position": corners[glass].reshape(-1, 3),
                "transmission": np.repeat(np.repeat(tau[glass], 4)[:, None], 3, axis=1),
            },
            tris.reshape(-1, 3),
        )

    def set_sky(self, sky) -> None:
        """Draw ``sky`` (an :class:`iat.io.scene.Sky`, or None for black) behind the model in
        mesh, IAT and split modes; its radiance from :func:`iat.radiosity.sky.sky_equirect`."""
        from iat.radiosity.sky import sky_equirect

        self._alive()
        if self._sky is not None:
            self._reg.release(self._sky)
            self._sky = None
        if sky is None:
            return
        img = np.ascontiguousarray(sky_equirect(sky, SKY_WIDTH))
        tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
        tex.repeat_x, tex.repeat_y = True, False
        tex.filter = (self._moderngl.LINEAR, self._moderngl.LINEAR)
        self._sky = self._reg.add(tex)

    # -- blending -----------------------------------------------------------------------------
    def set_blend(self, a: int, b: int | None = None, w: float = 0.0) -> None:
        """Show state ``a`` mixed with state ``b`` by ``w`` in [0, 1] (linear radiance):
        ``(1 - w) a + w b``; ``w = 0`` draws ``a`` exactly. Indices beyond a set's size are
        clamped to its last state (a single solution is a set of one).
        See :func:`iat.lighting.solution_set.blend_weights` for the pair and weight of a time."""
        a = int(a)
        b = a if b is None else int(b)
        w = float(w)
        if a < 0 or b < 0:
            raise RenderError(f"blend states must be >= 0, got {a}, {b}")
        if not (0.0 <= w <= 1.0):
            raise RenderError(f"blend weight must be in [0, 1], got {w}")
        self._blend = (a, b, w)
        for which, geo in (("mesh", self._solution), ("iat", self._baked_mesh)):
            pair = self._pair(which)
            colors = self._colors[which]
            if colors and geo.buffers and pair != self._colors_pair[which]:
                for name, state in (("color", pair[0]), ("color_b", pair[1])):
                    geo.buffers[name] = upload_buffer(self.ctx, self._reg, geo.buffers[name], colors[state])
                self._colors_pair[which] = pair

    @property
    def blend(self) -> tuple[int, int, float]:
        """(a, b, w) as last set by :meth:`set_blend`."""
        return self._blend

    def n_states(self, mode: str = "iat") -> int:
        """States (solutions) uploaded for ``mode`` "mesh" or "iat" (1 for a single solution)."""
        if mode == "iat":
            return int(self._iat_states) if self._has["iat"] else 0
        return len(self._colors["mesh"])

    def _pair(self, which: str) -> tuple[int, int]:
        n = max(len(self._colors[which]), 1) if which == "mesh" else max(self._iat_states, 1)
        a, b, _ = self._blend
        return min(a, n - 1), min(b, n - 1)

    def set_baked(self, baked) -> None:
        """IAT-mode data of a Baked: its vertex-coloured mesh part and its textured part.

        The textured part is drawn in one call for the patches without detail texture and
        one call per detail material (``baked.detail_textures: {material: (h,w,3)}``,
        applied where ``tex_detail`` is 1, or on every vertex of that material when the
        field is absent). Pages go into one texture array, rewritten in place when they fit
        in it with the same ``policy.pixel_format`` and mip levels (into its corner when
        smaller, see :meth:`iat.render.pages.PageTexture.size_for`), mipmapped when ``policy.mipmaps``:
        ``baked.gpu_form()`` (the Baker's pages in their GPU dtype) is written as it is and not
        at all when the texture already holds that very array; other Baked-likes' float
        ``pages`` are converted (:func:`iat.bake.formats.to_gpu`). rgba8 pages are GL_SRGB8_ALPHA8,
        rgb9e5 pages GL_RGB9_E5 (4 bytes a texel, as the memory report counts).
        """
        self._set_baked(baked, [baked.mesh_radiance], None, 1)

    def set_baked_set(self, baked_set) -> None:
        """IAT-mode data of a :class:`~iat.bake.baked.BakedSet`: the shared geometry once, every state's
        pages in one texture array (state k's page p at layer ``k * n_pages + p``) and every
        state's mesh-part colours; :meth:`set_blend` picks and mixes two states."""
        pages = np.asarray(baked_set.pages)
        if pages.ndim != 5:
            raise RenderError(
                f"baked set pages have shape {pages.shape}, expected (n_states, n_pages, H, W, 3)"
            )
        n = int(pages.shape[0])
        rad = np.asarray(baked_set.mesh_radiance)
        if rad.ndim != 3 or rad.shape[0] != n:
            raise RenderError(f"baked set mesh_radiance has shape {rad.shape}, expected ({n}, M, 3)")
        self._set_baked(baked_set, list(rad), pages.reshape(-1, *pages.shape[2:]), n)

    def _set_baked(self, baked, mesh_colors: list, all_pages: np.ndarray | None, n_states: int) -> None:
        """all_pages : (n_states x n_pages, H, W, 3) float pages, or None: ``baked``'s own (its
        GPU form when it has one)."""
        self._alive()
        self._baked_args = (baked, mesh_colors, all_pages, n_states)
        lod = getattr(baked, "lod", None) is not None and n_states == 1 and self._lod_on
        policy = getattr(baked, "policy", None)
        pixel_format = str(getattr(policy, "pixel_format", "rgba16f") or "rgba16f")
        mipmaps = bool(getattr(policy, "mipmaps", False))

        mpos = as_rows(baked.mesh_positions, 3, "mesh_positions")
        colors = [np.ascontiguousarray(as_rows(c, 3, "mesh_radiance")) for c in mesh_colors]
        midx = np.asarray(baked.mesh_indices, dtype=np.int64).reshape(-1, 3)
        for mrad in colors:
            if len(mpos) != len(mrad):
                raise RenderError(
                    f"baked mesh part has {len(mpos)} positions but {len(mrad)} radiance values"
                )
        check_indices(midx, len(mpos), "baked mesh_indices")

        tpos = as_rows(baked.tex_positions, 3, "tex_positions")
        k = len(tpos)
        tuv = as_rows(baked.tex_uv, 2, "tex_uv")
        tlayer = as_rows(baked.tex_layer, 1, "tex_layer")
        tduv = getattr(baked, "tex_detail_uv", None)
        tduv = np.zeros((k, 2), np.float32) if tduv is None else as_rows(tduv, 2, "tex_detail_uv")
        tmat = getattr(baked, "tex_material", None)
        tmat = np.full(k, -1, np.int64) if tmat is None else np.asarray(tmat, dtype=np.int64).reshape(-1)
        tidx = np.asarray(baked.tex_indices, dtype=np.int64).reshape(-1, 3)
        rows = {"tex_uv": tuv, "tex_layer": tlayer, "tex_detail_uv": tduv, "tex_material": tmat}
        for name, a in rows.items():
            if len(a) != k:
                raise RenderError(f"baked {name} has {len(a)} rows but tex_positions has {k}")
        check_indices(tidx, k, "baked tex_indices")

        details = dict(getattr(baked, "detail_textures", None) or {})
        tdetail = getattr(baked, "tex_detail", None)
        if tdetail is None:
            tdetail = np.isin(tmat, list(details)).astype(np.float32)
        else:
            tdetail = np.asarray(tdetail, dtype=np.float32).reshape(-1)
            if len(tdetail) != k:
                raise RenderError(f"baked tex_detail has {len(tdetail)} rows but tex_positions has {k}")
        # a triangle goes to its material's detail draw call when its first vertex asks for detail
        tri_key = np.full(len(tidx), -1, np.int64)
        if len(tidx) and details:
            v0 = tidx[:, 0]
            use = (tdetail[v0] > 0.5) & np.isin(tmat[v0], list(details))
            tri_key[use] = tmat[v0][use]

        per_state = 0
        self._lod.clear()
        if len(tidx) and lod:  # levels of detail: the chain's pages and its own textured geometry
            self._lod.set(baked, self._page_tex, self.reuse_pages, tpos, tduv, tdetail, tidx, tri_key)
            self._page_scale, per_state = float(getattr(baked, "page_scale", 1.0) or 1.0), 1
        elif len(tidx):
            # rgba8: GPU texel = sRGB8(page / scale); the shader multiplies back
            pages, scale = gpu_pages(baked, all_pages, pixel_format)
            per_state = pages.shape[0] // max(n_states, 1)
            if pages.shape[0] == 0:
                raise RenderError(f"baked has textured triangles but its pages have shape {pages.shape}")
            if tlayer.size and (tlayer.min() < 0 or tlayer.max() > per_state - 1):
                raise RenderError(f"baked tex_layer refers to page {int(tlayer.max())} of {per_state}")
            mip_levels = getattr(baked, "mip_levels", None)
            self._page_tex.upload(pages, pixel_format, mipmaps, mip_levels, self.reuse_pages)
            self._page_scale = scale
        self._set_details("iat", {int(m): v for m, v in details.items()})
        self._iat_states, self._iat_pages = int(n_states), max(int(per_state), 1)
        self._colors["iat"] = colors
        a, b = self._pair("iat")
        n = len(colors[a])  # the mesh part holds radiance: no detail
        arrays = {"position": mpos, "color": colors[a], "color_b": colors[b], "detail_uv": np.zeros((n, 2))}
        # patches with a twin (Baked.patch_twin): their calls cull back faces
        twin = np.asarray(getattr(baked, "patch_twin", np.zeros(0, bool)), dtype=bool).reshape(-1)
        mkey = None
        if twin.any():
            mpatch = np.asarray(baked.mesh_patch, dtype=np.int64).reshape(-1)
            tpatch = np.asarray(baked.tex_patch, dtype=np.int64).reshape(-1)
            if len(midx) and len(mpatch) == len(mpos):
                mkey = twin_keys(None, twin[mpatch[midx[:, 0]]])
            if len(tidx) and len(tpatch) == k:
                tri_key = twin_keys(tri_key, twin[tpatch[tidx[:, 0]]])
        self._baked_mesh.upload(self.ctx, self._reg, {**arrays, "detail": np.zeros(n)}, midx, mkey)
        self._colors_pair["iat"] = (a, b)
        if len(tidx):
            tuv = self._page_tex.scale_uv(tuv)
        self._baked_tex.upload(
            self.ctx,
            self._reg,
            {"position": tpos, "uv": tuv, "layer": tlayer, "detail_uv": tduv, "detail": tdetail},
            tidx,
            tri_key,
        )
        self._has["iat"] = True

    # -- levels of detail ---------------------------------------------------------------------
    def set_lod(self, enabled=None, from_bake: bool = False, **options) -> None:
        """Level-of-detail switches for a Baked baked with ``BakePolicy(lod=True)`` (or ``lod_stream``):
        ``enabled`` False draws the finest textures as without LOD; ``options``: ``bias``, ``stream``,
        ``budget_mb``, ``cull``, ``show``, ``snap`` (:meth:`iat.render.lod.LodDrawer.configure`), and
        ``from_bake`` drops earlier ``stream`` / ``budget_mb`` settings. A change of ``enabled``,
        ``stream`` or ``budget_mb`` re-sets the last Baked."""
        again = self._lod.configure(from_bake=from_bake, **options)
        if enabled is not None and bool(enabled) != self._lod_on:
            self._lod_on, again = bool(enabled), True
        if again and self._baked_args is not None:
            self._set_baked(*self._baked_args)

    def lod_info(self) -> dict:
        """The levels in use (:meth:`iat.render.lod.LodDrawer.info`): tiles per finest resident
        (and needed) tree level, resident against total texture bytes, page uploads, the memory
        report of now; empty when the Baked shown has no LOD chain or LOD is off."""
        return self._lod.info() if self._lod.active else {}

    # -- drawing ----------------------------------------------------------------------------
    def _target(self, name: str, size: tuple[int, int], sampled: bool) -> _Target:
        t = self._targets.get(name)
        if t is not None and t.size == size:
            return t
        if t is not None:
            if self.ctx.fbo is t.fbo:
                self._home.use()
            for o in (t.fbo, t.color, t.depth):
                self._reg.release(o)
        ctx = self.ctx
        if sampled:
            color = self._reg.add(ctx.texture(size, 4, dtype="f4"))
            color.filter = (self._moderngl.NEAREST, self._moderngl.NEAREST)
        else:
            color = self._reg.add(ctx.renderbuffer(size, 4, dtype="f4"))
        depth = self._reg.add(ctx.depth_renderbuffer(size))
        fbo = self._reg.add(ctx.framebuffer(color_attachments=[color], depth_attachment=depth))
        t = self._targets[name] = _Target(size, color, depth, fbo)
        return t

    def _need(self, mode: str) -> None:
        what = {"preview": "set_scene", "mesh": "set_solution", "iat": "set_baked"}
        for m in {"split": ("mesh", "iat"), "diff": ("mesh", "iat")}.get(mode, (mode,)):
            if not self._has[m]:
                raise RenderError(f"mode {mode!r} needs {what[m]}() first")

    @staticmethod
    def _uniforms(prog, values: dict) -> None:
        for name, v in values.items():
            if prog.get(name, None) is not None:
                if name == "clip_from_world":
                    prog[name].write(v)
                else:
                    prog[name].value = v

    def _draw_mode(self, mode: str, clip: bytes, exposure: float, tonemap: bool, stats: dict) -> None:
        """Draw one of preview / mesh / iat into the bound framebuffer, counting triangles and calls."""
        common = {"clip_from_world": clip, "exposure": float(exposure), "tonemap": bool(tonemap)}
        tris = calls = 0
        w = float(self._blend[2])
        if mode == "mesh" or mode == "iat":
            g = self._solution if mode == "mesh" else self._baked_mesh
            pa, pb = self._pair(mode)
            if g.n_triangles:
                self._uniforms(g.program, {**common, "blend": w if pa != pb else 0.0, "detail": 1})
                for key, first, count in g.calls():  # mesh mode: one call per detail material
                    key = self._cull_twins(key)
                    tex = self._detail["preview"].get(key) if mode == "mesh" else None
                    (tex if tex is not None else self._white).use(1)
                    self._uniforms(g.program, {"use_detail": tex is not None})
                    g.render_range(first, count)
                    tris, calls = tris + count // 3, calls + 1
        if mode == "iat" and self._lod.active:
            self._uniforms(self._lod.program, {**common, "layer_a": 0.0, "page_scale": self._page_scale})
            t, c = self._lod.draw(self._uniforms, self._page_tex, self._detail["iat"], self._white)
            tris, calls = tris + t, calls + c
        elif mode == "iat" and self._baked_tex.n_triangles:
            g = self._baked_tex
            self._page_tex.texture.use(0)
            pa, pb = self._pair("iat")
            blend = {
                "layer_a": float(pa * self._iat_pages),
                "layer_b": float(pb * self._iat_pages),
                "blend": w if pa != pb else 0.0,
            }
            pages = {"pages": 0, "detail": 1, "page_scale": self._page_scale}
            self._uniforms(g.program, {**common, **blend, **pages})
            for key, first, count in g.calls():
                key = self._cull_twins(key)
                tex = self._detail["iat"].get(key)
                (tex if tex is not None else self._white).use(1)
                self._uniforms(g.program, {"use_detail": tex is not None})
                g.render_range(first, count)
                tris, calls = tris + count // 3, calls + 1
        if mode == "preview" and self._preview.n_triangles:
            g = self._preview
            self._uniforms(g.program, {**common, "detail": 1, "ambient": PREVIEW_AMBIENT})
            for key, first, count in g.calls():
                tex = self._detail["preview"].get(key)
                (tex if tex is not None else self._white).use(1)
                self._uniforms(g.program, {"use_detail": tex is not None})
                g.render_range(first, count)
                tris, calls = tris + count // 3, calls + 1
        self.ctx.disable(self._moderngl.CULL_FACE)
        s = stats.setdefault(mode, {"triangles": 0, "draw_calls": 0})
        s["triangles"] += tris
        s["draw_calls"] += calls

    def _cull_twins(self, key: int) -> int:
        """A draw call's material key (-1: none); culls back faces for a call of twin triangles
        (:data:`TWIN_KEY`) and draws both faces otherwise: a patch with a twin shows only its front,
        its twin shows the other side's light; a one-sided patch seen from behind shows its front's."""
        if key >= TWIN_KEY // 2:
            self.ctx.enable(self._moderngl.CULL_FACE)
            return key - TWIN_KEY
        self.ctx.disable(self._moderngl.CULL_FACE)
        return key

    def _draw_sky_and_glass(self, camera, aspect: float, clip: bytes, exposure: float, tonemap: bool) -> None:
        """The sky where nothing was drawn (depth still 1), then glass over everything."""
        ctx, mgl = self.ctx, self._moderngl
        if self._sky is not None:
            m = np.asarray(camera.clip_from_world(aspect), dtype=np.float64)
            inv = np.linalg.inv(m).T.astype("f4").tobytes()
            self._sky.use(0)
            prog = self._programs["sky"]
            prog["world_from_clip"].write(inv)
            self._uniforms(prog, {"sky": 0, "exposure": float(exposure), "tonemap": bool(tonemap)})
            ctx.depth_func = "<="
            self._sky_quad.render(mgl.TRIANGLES, vertices=3)
            ctx.depth_func = "<"
        if self._glass.n_triangles:
            ctx.enable(mgl.BLEND)
            ctx.blend_func = (mgl.ZERO, mgl.SRC_COLOR)
            ctx.depth_mask = False
            try:
                self._uniforms(self._glass.program, {"clip_from_world": clip, "tonemap": bool(tonemap)})
                for _, first, count in self._glass.calls():
                    self._glass.render_range(first, count)
            finally:
                ctx.depth_mask = True
                ctx.disable(mgl.BLEND)
                ctx.blend_func = mgl.DEFAULT_BLENDING

    def _frame(self, target, viewport, camera, mode, exposure, tonemap, split, diff_gain, clear) -> None:
        if mode not in MODES:
            raise RenderError(f"unknown render mode {mode!r} (known: {', '.join(MODES)})")
        self._alive()
        self._need(mode)
        ctx, mgl = self.ctx, self._moderngl
        x, y, w, h = (int(v) for v in viewport)
        if w <= 0 or h <= 0:
            raise RenderError(f"empty viewport {tuple(viewport)}")
        clip_m = np.asarray(camera.clip_from_world(w / h), dtype=np.float64)
        clip = clip_m.T.astype("f4").tobytes()
        if mode in ("iat", "split", "diff") and self._lod.active:  # streaming: this view's levels
            self._lod.update(clip_m, (w, h), self._page_tex, self.reuse_pages, getattr(camera, "znear", 1e-3))
        stats: dict[str, dict] = {}
        ctx.enable(mgl.DEPTH_TEST)
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        try:
            if mode == "diff":
                for name, sub in (("diff_a", "mesh"), ("diff_b", "iat")):
                    t = self._target(name, (w, h), sampled=True)
                    t.fbo.use()
                    t.fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
                    self._draw_mode(sub, clip, 1.0, False, stats)
                target.use()
                ctx.viewport = (x, y, w, h)
                ctx.disable(mgl.DEPTH_TEST)
                self._targets["diff_a"].color.use(0)
                self._targets["diff_b"].color.use(1)
                prog = self._programs["composite"]
                self._uniforms(
                    prog,
                    {
                        "image_a": 0,
                        "image_b": 1,
                        "offset": (x, y),
                        "gain": float(diff_gain),
                        "exposure": float(exposure),
                        "tonemap": bool(tonemap),
                    },
                )
                self._fullscreen.render(mgl.TRIANGLES, vertices=3)
            else:
                target.use()
                ctx.viewport = (x, y, w, h)
                if clear:
                    target.clear(0.0, 0.0, 0.0, 1.0, depth=1.0, viewport=(x, y, w, h))
                if mode == "split":
                    sw = int(round(min(max(float(split), 0.0), 1.0) * w))
                    ctx.scissor = (x, y, sw, h)
                    self._draw_mode("mesh", clip, exposure, tonemap, stats)
                    ctx.scissor = (x + sw, y, w - sw, h)
                    self._draw_mode("iat", clip, exposure, tonemap, stats)
                    ctx.scissor = None
                else:
                    self._draw_mode(mode, clip, exposure, tonemap, stats)
                for o in self.overlays:  # over the surfaces, under the sky and glass
                    o.draw(clip, tonemap)
                if mode != "preview":
                    self._draw_sky_and_glass(camera, w / h, clip, exposure, tonemap)
        finally:
            ctx.disable(mgl.DEPTH_TEST)
        self._last = {
            "mode": mode,
            "triangles": sum(s["triangles"] for s in stats.values()),
            "draw_calls": sum(s["draw_calls"] for s in stats.values()) + (mode == "diff"),
            "modes": stats,
        }

    def render(
        self,
        camera,
        size: tuple[int, int] = (640, 480),
        mode: str = "mesh",
        exposure: float | None = None,
        split: float = 0.5,
        diff_gain: float = 1.0,
    ) -> np.ndarray:
        """Draw offscreen and return ``(h, w, 3) float32`` linear radiance, row 0 at the top.

        camera : anything with ``clip_from_world(aspect) -> (4, 4)`` (a :class:`~iat.camera.Camera`)
        size : (w, h) pixels; the aspect ratio is w / h
        mode : "mesh" | "iat" | "preview" | "split" | "diff"
        exposure : None (radiance as is) or a multiplier applied in the shader; never a tone map
        split : fraction of the width drawn in mesh mode (split mode)
        diff_gain : multiplier on |mesh - iat| (diff mode)
        """
        self._alive()
        w, h = (int(v) for v in size)
        if w <= 0 or h <= 0:
            raise RenderError(f"bad image size {size}")
        prev = self.ctx.fbo
        if prev is None or isinstance(prev.mglo, self._moderngl.InvalidObject):  # none, or released
            prev = self._home
        t = self._target("out", (w, h), sampled=False)
        e = 1.0 if exposure is None else float(exposure)
        try:
            self._frame(t.fbo, (0, 0, w, h), camera, mode, e, False, split, diff_gain, True)
            self.ctx.finish()
            raw = t.fbo.read(viewport=(0, 0, w, h), components=3, dtype="f4", alignment=1)
        finally:
            prev.use()  # leave the caller's framebuffer (and its viewport) bound
        return np.frombuffer(raw, dtype=np.float32).reshape(h, w, 3)[::-1].copy()

    def draw(
        self,
        camera,
        mode: str,
        viewport: tuple[int, int, int, int],
        exposure: float = 1.0,
        tonemap: bool = True,
        split: float = 0.5,
        diff_gain: float = 1.0,
        clear: bool = True,
        target=None,
    ) -> None:
        """Draw into ``target`` (default: the bound framebuffer, ``ctx.fbo``) inside ``viewport``.

        viewport : (x, y, w, h) in the target's pixels (GL convention, y up)
        tonemap : True for a display framebuffer (exposure, clamp, sRGB encode in the shader);
                  False writes exposure x linear radiance (float targets)
        clear : clear colour (black) and depth inside the viewport first
        """
        self._alive()
        target = target if target is not None else self.ctx.fbo
        if target is None:
            raise RenderError("draw() needs a bound framebuffer (or target=); use render() headless")
        self._frame(target, viewport, camera, mode, exposure, tonemap, split, diff_gain, clear)

    def stats(self) -> dict:
        """Counts of the last frame: ``{"mode", "triangles", "draw_calls", "modes": {mode: {"triangles",
        "draw_calls"}}, "gl_objects"}`` (split and diff list both mesh and iat under "modes")."""
        out = dict(self._last)
        out["modes"] = {k: dict(v) for k, v in self._last["modes"].items()}
        out["gl_objects"] = len(self._reg)
        return out
