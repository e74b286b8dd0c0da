"""Draw the docked panels only when they changed (a software rasteriser's frame rate).

On llvmpipe a frame's cost is mostly pixels: imgui drawing the docked panels (the dock space's
background and about 0.5 Mpixel of blended, textured quads and text) took 6-9 ms of CPU in a
frame, as much as drawing the house. The window's back buffer keeps its pixels across a buffer
swap there (the swap copies it to the X window), so what looks as in the last frame need not be
drawn again: the 3D view (its rectangle, rewritten every frame: drawn or copied; with nothing
open kept too while nothing was drawn over it, :attr:`PanelCache.keeps_view`) and any floating
window are drawn, the panels' pixels stay. :class:`PanelCache` decides just before
``ImGui::Render``, per part of the window: each docked panel, and the frame around them (the
dock space's host with its tab bars and splitters, the menu bar):

- a part is drawn when its draw lists differ from those it last drew (a digest of their
  vertices); the frame changed: everything is drawn;
- everything is drawn for a few frames after the layout changed (window or view size, a docked
  window's place or size, a floating window's), and while a floating window (error, tooltip, a
  window undocked) reaches outside the 3D view or imgui draws the mouse cursor itself (the test
  engine's): each blends over the panels, and drawn over their kept pixels it would darken a
  little more every frame;
- else the part's draw lists are emptied: imgui still ran its widgets (inputs, layout, the test
  engine's item queries), nothing is drawn.

When nothing changed and nothing can (no input, the mouse not over a panel, nothing active, see
:meth:`PanelCache.panel`), the next frames do not even run the panels' widgets (a *lean* frame),
for at most ``refresh_s``: then they run again (the Stats panel's numbers, progress bars,
messages) and what changed is drawn. Windows get an opaque background
(:func:`opaque_window_background`): a panel drawn again shows nothing of its last pixels through.

Whether the back buffer is kept is not promised by OpenGL (a GPU driver may flip between buffers),
so it is measured first: for a few frames one pixel is set to a marked colour just before the swap
and read back at the start of the next frame; unless every mark came back, every frame is drawn
in full. ``IAT_VIEWER_PANEL_CACHE=0`` turns the cache off (every frame in full).
"""

from __future__ import annotations

import ctypes
import os
import time

from imgui_bundle import imgui

#: frames drawn in full after the window opens (layout settles) and after any change
SETTLE_FRAMES = 5
#: frames whose back buffer is checked (a mark set before the swap must be there after it)
PROBE_FRAMES = 3
#: the first probed frame
PROBE_START = 6
_MENU_BAR = "##MainMenuBar"
_FALLBACK = "Debug##Default"  # imgui's implicit window: active until the frame ends, drawn if used
_MAIN_HOST = "MainDockSpace"  # hello_imgui's full-screen dock space window
_FRAME = "(frame)"  # the part of the window around the panels: dock space host, tab bars, menu bar
_VERT_BYTES = 20  # sizeof(ImDrawVert): pos, uv (2 floats each), col (4 bytes)


def enabled_by_env() -> bool:
    return os.environ.get("IAT_VIEWER_PANEL_CACHE", "1").strip().lower() not in ("0", "off", "false", "no")


class PanelCache:
    """Per-frame decision whether the docked panels are drawn (see the module docstring).

    refresh_s : the longest time the panels go undrawn while nothing happens in them
    enabled : False draws every frame in full (as without the cache)
    """

    def __init__(self, refresh_s: float = 0.2, enabled: bool | None = None):
        self.refresh_s = float(refresh_s)
        self.enabled = enabled_by_env() if enabled is None else bool(enabled)
        self.preserved: bool | None = None  # does the back buffer keep its pixels? (None: not known yet)
        self.full_frames = 0
        self.skipped_frames = 0
        self._frame = 0
        self._last_full = -1e9
        self._signature = None
        self._settle = SETTLE_FRAMES
        self._probe_value = None  # (mark, original) of the pixel marked before the last swap
        self._probes_ok = 0
        self.last_full = True  # the last frame drew the panels
        self.lean_frames = 0  # frames whose panels ran no widgets (see :meth:`panel`)
        self.partial_frames = 0  # frames that drew only the panels that changed
        self._drawn: dict[str, int] = {}  # each part's digest as last drawn
        self._drawn_at: dict[str, float] = {}  # and when
        self._last_content = -1e9  # when the panels' widgets last ran
        self._quiet = False  # the last frame's decision found nothing going on in the panels
        self._lean = (-1, False)  # (imgui frame, this frame's panels run no widgets)
        self._sizes: dict[str, tuple[float, float]] = {}  # each panel's content size when it last ran
        self._display = None
        self._overlaid = True  # the last frame drew windows (or a software cursor) anywhere

    # -- the back buffer check ---------------------------------------------------------------------------
    def frame_start(self, ctx) -> None:
        """At the start of the frame's drawing (before the 3D view): read the mark set before the
        last swap, and put the pixel back; windows get an opaque background (hello_imgui applies its
        theme after the app's setup)."""
        self._frame += 1
        if self.enabled and self._frame <= PROBE_START:
            opaque_window_background()
        if self._probe_value is None or ctx is None:
            return
        mark, original = self._probe_value
        self._probe_value = None
        try:
            got = tuple(ctx.screen.read(viewport=(0, 0, 1, 1), components=3, alignment=1))
            _set_pixel(ctx, original)
        except Exception:
            self.preserved = False
            return
        if all(abs(int(a) - int(b)) <= 1 for a, b in zip(got, mark, strict=True)):
            self._probes_ok += 1
            if self._probes_ok >= PROBE_FRAMES:
                self.preserved = True
        else:
            self.preserved = False

    def before_swap(self, ctx) -> None:
        """Mark one pixel before the swap while the check runs."""
        if not self.enabled or self.preserved is not None or ctx is None or self._frame < PROBE_START:
            return
        try:
            original = tuple(
                int(v) for v in ctx.screen.read(viewport=(0, 0, 1, 1), components=3, alignment=1)
            )
            mark = tuple((v + 97 + 31 * k) % 256 for k, v in enumerate(original))
            _set_pixel(ctx, mark)
        except Exception:
            self.preserved = False
            return
        self._probe_value = (mark, original)

    # -- the decision --------------------------------------------------------------------------------------
    def before_render(self, view_rect, dock_space_id: int | None) -> bool:
        """Just before ``ImGui::Render``: empty the panels' draw lists unless they must be drawn.
        Returns True when this frame draws them."""
        full = self._decide(view_rect, dock_space_id)
        self.last_full = full
        if full:
            self.full_frames += 1
            self._last_full = time.perf_counter()
        else:
            self.skipped_frames += 1
        return full

    @property
    def keeps_view(self) -> bool:
        """The window keeps its pixels and the last frame drew nothing over the 3D view but the
        app's own overlay (no floating window, no software cursor): an unchanged empty view need
        not be cleared (:meth:`viewer.view3d.View3D.draw`)."""
        return bool(self.enabled and self.preserved and not self._overlaid)

    def _decide(self, view_rect, dock_space_id) -> bool:
        self._quiet = False
        self._overlaid = True
        # a software cursor (the imgui test engine's) is drawn over kept pixels every frame
        if not self.enabled or not self.preserved or imgui.get_io().mouse_draw_cursor:
            return True
        g = imgui.get_current_context()
        panels, floating = _windows(g, dock_space_id)
        self._overlaid = bool(floating)
        roots = [w for n, w in panels.items() if w.root_window.name == n]
        layout = tuple((w.name, w.pos.x, w.pos.y, w.size.x, w.size.y) for w in roots)
        io = imgui.get_io()
        sig = ((io.display_size.x, io.display_size.y), tuple(view_rect), layout, tuple(floating))
        if sig != self._signature:  # a new layout: every window drawn for a few frames
            self._signature, self._settle = sig, SETTLE_FRAMES
            self._drawn.clear()
        if self._lean == (imgui.get_frame_count(), True):
            # the panels ran no widgets: drawn they would be empty (a change shows next frame)
            self.lean_frames += 1
            self._reset(panels.values())
            self._quiet = self._settle == 0
            return False
        self._last_content = time.perf_counter()
        digests = _digests(panels, self._frame_windows(dock_space_id, panels))
        opaque = imgui.get_style().color_(imgui.Col_.window_bg).w >= 1.0
        if self._settle > 0 or not opaque or any(_outside(r, view_rect) for r in floating):
            self._settle = max(self._settle - 1, 0)
            self._drawn = digests
            self._drawn_at = dict.fromkeys(digests, self._last_content)
            return True
        busy = _busy(g)
        self._quiet = not busy
        now = self._last_content
        changed = {  # without input a part shows its changes (numbers, progress) every refresh_s
            k
            for k, d in digests.items()
            if self._drawn.get(k) != d and (busy or now - self._drawn_at.get(k, -1e9) >= self.refresh_s)
        }
        if _FRAME in changed:  # the dock space's tab bars and splitters, the menu bar: all of it
            self._drawn = digests
            self._drawn_at = dict.fromkeys(digests, now)
            return True
        for w in panels.values():
            if _group(w, panels) not in changed:
                w.draw_list._reset_for_new_frame()
        if not changed:
            return False
        self.partial_frames += 1
        _clear_behind([panels[k] for k in changed if k in panels])
        for k in changed:
            self._drawn[k], self._drawn_at[k] = digests[k], now
        return True

    def _frame_windows(self, dock_space_id, panels) -> set:
        return {n for n in panels if n in (_MENU_BAR, _host_name(dock_space_id))}

    @staticmethod
    def _reset(windows) -> None:
        for w in windows:
            w.draw_list._reset_for_new_frame()

    # -- lean frames: the panels' widgets not run ------------------------------------------------------------
    def panel(self, name: str, draw) -> None:
        """Run a docked panel's widgets (``draw()``), or, on a frame that will not draw the panels
        and where nothing can happen in them, only reserve the space they took when they last ran
        (the panel's scroll range stays). Nothing can happen in them when the last frame found them
        quiet, no input arrived this frame, the mouse is not over a panel, no widget is active or
        keyboard-focused, no popup is open and the periodic refresh is not due; never while the
        imgui test engine runs (its queries need the widgets)."""
        if self._lean_now():
            size = self._sizes.get(name)
            if size is not None and size[0] > 0 and size[1] > 0:
                imgui.dummy(imgui.ImVec2(*size))
            return
        draw()
        dc = imgui.internal.get_current_window().dc
        self._sizes[name] = (
            dc.cursor_max_pos.x - dc.cursor_start_pos.x,
            dc.cursor_max_pos.y - dc.cursor_start_pos.y,
        )

    def _lean_now(self) -> bool:
        frame = imgui.get_frame_count()
        if self._lean[0] != frame:
            self._lean = (frame, self._can_be_lean())
        return self._lean[1]

    def _can_be_lean(self) -> bool:
        io = imgui.get_io()
        display = (float(io.display_size.x), float(io.display_size.y))
        same_size, self._display = display == self._display, display
        if not (self.enabled and self.preserved and self._quiet and same_size):
            return False
        if time.perf_counter() - self._last_content >= self.refresh_s:
            return False
        try:
            from imgui_bundle import hello_imgui

            if hello_imgui.get_runner_params().use_imgui_test_engine:
                return False
        except Exception:
            return False
        return not _busy(imgui.get_current_context())


def _busy(g) -> bool:
    """Something may be happening in the panels: input arrived this frame, the mouse is over a
    window (over the 3D view the dock space lets it through: none), a widget is active, a popup
    open, a window moving, a drag and drop or keyboard navigation under way."""
    if (
        g.input_events_trail.size()
        or g.active_id
        or g.open_popup_stack.size()
        or g.hovered_window is not None
    ):
        return True
    return bool(
        g.moving_window is not None
        or g.drag_drop_active
        or g.nav_cursor_visible
        or imgui.get_io().want_text_input
    )


def _windows(g, dock_space_id):
    """``({name: window}`` of the visible windows drawn from the main dock space (its host and the
    windows docked in it, children included) and from the main menu bar, ``[(x, y, w, h)]`` of the
    other visible root windows)."""
    host = _host_name(dock_space_id)
    panels, floating = {}, []
    for w in g.windows:
        if not w.active or w.hidden:
            continue
        root = w.root_window_dock_tree
        rname = root.name if root is not None else w.name
        if rname in (host, _MENU_BAR):
            panels[w.name] = w
        elif rname == w.name and (w.name != _FALLBACK or w.write_accessed):  # (the unused "Debug" window)
            floating.append((float(w.pos.x), float(w.pos.y), float(w.size.x), float(w.size.y)))
    return panels, floating


def _host_name(dock_space_id) -> str:
    """The name of the root window holding the main dock space (hello_imgui's "MainDockSpace")."""
    if dock_space_id is not None:
        node = imgui.internal.dock_builder_get_node(dock_space_id)
        hw = node.host_window if node is not None else None
        if hw is not None and hw.root_window_dock_tree is not None:
            return hw.root_window_dock_tree.name
    return _MAIN_HOST


def _group(w, panels) -> str:
    """The part of the window a window's pixels belong to: its docked panel, or :data:`_FRAME`
    (the dock space's host, its tab bars and splitters, the menu bar)."""
    root = w.root_window.name
    return _FRAME if root not in panels or root == _MENU_BAR or w.root_window_dock_tree.name == root else root


def _digests(panels, frame: set) -> dict:
    """``{group: digest}`` of what each part's draw lists would draw (their vertices: positions, uvs
    and colours; index and command counts)."""
    parts: dict[str, list] = {}
    for name in sorted(panels):
        w = panels[name]
        dl = w.draw_list
        n = dl.vtx_buffer.size()
        data = ctypes.string_at(dl.vtx_buffer.data_address(), n * _VERT_BYTES) if n else b""
        key = _FRAME if name in frame else _group(w, panels)
        parts.setdefault(key, []).append((name, n, dl.idx_buffer.size(), dl.cmd_buffer.size(), hash(data)))
    return {k: hash(tuple(v)) for k, v in parts.items()}


def _clear_behind(windows) -> None:
    """A docked window's background is drawn by its dock space's host (the frame part): a panel
    drawn without it gets its background here, first (the viewport's background draw list goes
    under every window), where and as the host draws it."""
    dl = imgui.get_background_draw_list()
    c = imgui.get_style().color_(imgui.Col_.window_bg)
    col = imgui.get_color_u32(imgui.ImVec4(c.x, c.y, c.z, 1.0))
    for w in windows:
        x, y = float(w.pos.x), float(w.pos.y)
        dl.add_rect_filled(
            imgui.ImVec2(x, y + float(w.title_bar_height)), imgui.ImVec2(x + w.size.x, y + w.size.y), col
        )


def opaque_window_background() -> None:
    """Make windows' background opaque (the theme's is 86.5 %): a panel drawn again over its own
    last pixels then shows none of them through."""
    st = imgui.get_style()
    c = st.color_(imgui.Col_.window_bg)
    st.set_color_(imgui.Col_.window_bg, imgui.ImVec4(c.x, c.y, c.z, 1.0))


def _outside(r, view_rect) -> bool:
    x, y, w, h = r
    vx, vy, vw, vh = view_rect
    return x < vx or y < vy or x + w > vx + vw or y + h > vy + vh


def _set_pixel(ctx, rgb) -> None:
    ctx.screen.use()
    old = ctx.scissor
    ctx.scissor = (0, 0, 1, 1)
    ctx.clear(*(v / 255.0 for v in rgb), 1.0)
    ctx.scissor = old
