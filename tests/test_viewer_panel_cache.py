"""The panel cache (:mod:`viewer.panel_cache`) against the window drawn in full, in the real app
under imgui-bundle's test engine (needs a display; runs alone in a child process, see
tests/conftest.py).

The cache keeps the docked panels' pixels in the back buffer and draws only what changed, so a
frame it kept must look exactly like a frame drawn in full: after a hover comes and goes, after a
panel's text changes (the exposure set from outside the panel, as auto exposure does), and in the
empty 3D view beside them. The whole window is read back
just before the buffer swap, once on a frame that drew nothing of the panels (kept) and once on
the next frame with the cache turned off (everything drawn); the two must match. Each change must
also show in the pixels (so a cache that kept the old ones would fail), and be drawn by the
cache's partial drawing (one panel alone). A tooltip that reached over the panels and the view
must leave nothing behind. With nothing open the empty 3D view keeps its pixels too (it is not
cleared every frame): the same comparison covers it. The Stats panel is hidden: its frame times
change every frame, so a kept frame may rightly show numbers up to ``refresh_s`` old. The test
engine's software cursor is turned off (the cache draws every frame in full under it).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.conftest import run_gui, wait_until

# Tolerances over the 1280 x 800 window, in 8-bit levels. A kept frame and a full one come from the
# same draw lists over opaque window backgrounds: measured equal (0 pixels differ). A panel drawn
# alone gets its background from the cache, not from the dock space's host: a few pixels of
# anti-aliased edge may differ by a little, nothing more. What the checks catch differs by far
# more: a hover not drawn, 441 pixels by up to 136 levels; a new value, 449 by 192; a label
# drawn again over its kept pixels, 550 by 214; a panel drawn alone without its background, 28 000;
# the empty view kept after a tooltip lay over it, 7 700 by 204.
MAX_LEVEL = 8  # no pixel differs by more
MAX_PIXELS = 50  # pixels that differ at all
CHANGE_PIXELS = 100  # a hover or a new value changes at least this many pixels of the panel


def differing(a: np.ndarray, b: np.ndarray) -> tuple[int, int]:
    """(pixels that differ, the largest difference in levels) of two (h, w, 3) uint8 images."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=2)
    return int((d > 0).sum()), int(d.max())


def crop(img: np.ndarray, rect) -> np.ndarray:
    x, y, w, h = (int(v) for v in rect)
    return img[y : y + h, x : x + w]


@pytest.mark.gui
def test_kept_panels_match_a_full_drawing(gui_child):
    if gui_child():
        return
    from imgui_bundle import ImVec2, hello_imgui, imgui

    from viewer.app import ViewerApp

    class Reading(ViewerApp):
        """The viewer, reading its whole window back before the swap of a kept frame (one that drew
        none of the panels) or of a full one (the cache off, from a blank window) when asked."""

        want: str | None = None
        fresh = -1  # the frame that started from a blank window
        images: dict = {}

        def runner_params(self):
            rp = super().runner_params()
            own_background, own_swap = rp.callbacks.custom_background, rp.callbacks.before_swap

            def background():
                if self.want == "full" and not self.panel_cache.enabled:
                    self.ctx.screen.use()
                    self.ctx.clear(1.0, 0.0, 1.0)  # any pixel the full frame does not draw shows
                    self.fresh = imgui.get_frame_count()
                own_background()

            def before_swap():
                own_swap()
                last_full = self.panel_cache.last_full
                full = last_full and self.fresh == imgui.get_frame_count()
                if self.want == "full" and full or self.want == "kept" and not last_full:
                    w, h = (int(v) for v in imgui.get_io().display_size)
                    raw = self.ctx.screen.read(viewport=(0, 0, w, h), components=3, alignment=1)
                    img = np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()
                    self.images[self.want] = (img, self.state.view.kept)
                    self.want = None

            rp.callbacks.custom_background = background
            rp.callbacks.before_swap = before_swap
            return rp

    app = Reading(None, size=(1280, 800), idle=False)
    pc = app.panel_cache
    got: dict = {}

    def grab(ctx, kind: str):
        app.want = kind
        wait_until(ctx, lambda: app.want is None, 10, f"a {kind} frame")
        return app.images.pop(kind)

    def step(ctx, name: str, act) -> None:
        """``act(ctx)``; then a kept frame, and the next frame drawn in full (the cache off for it).
        The frames that drew panels alone meanwhile are counted."""
        partial = pc.partial_frames
        act(ctx)
        t0 = time.monotonic()
        ctx.yield_(10)  # a change is drawn at once with input, at most refresh_s late without
        wait_until(ctx, lambda: time.monotonic() - t0 > 3 * pc.refresh_s, 10, "the panels' refresh")
        got[name], got[f"{name} view kept"] = grab(ctx, "kept")
        pc.enabled = False
        got[f"{name} full"], _ = grab(ctx, "full")
        pc.enabled = True
        got[f"{name} partial"] = pc.partial_frames - partial

    def away(ctx) -> None:
        x, y, w, h = app.state.view.rect  # over the empty 3D view: no window hovered
        ctx.mouse_move_to_pos(ImVec2(x + 0.5 * w, y + 0.5 * h))

    def tooltip(ctx) -> None:
        """Hover the "(?)" after the Budget checkbox's label until its tooltip shows, then leave."""
        r = ctx.item_info("//Tuning/Budget").rect_full
        x = r.max.x + imgui.get_style().item_spacing.x + 8
        ctx.mouse_move_to_pos(ImVec2(x, 0.5 * (r.min.y + r.max.y)))
        wait_until(ctx, lambda: _shown("##Tooltip_00"), 10, "the tooltip")
        ctx.yield_(5)  # (its size fits its text from the second frame on)
        t = imgui.internal.find_window_by_name("##Tooltip_00")
        got["tooltip"] = (t.pos.x, t.pos.y, t.size.x, t.size.y) if _shown("##Tooltip_00") else None
        away(ctx)

    def change(ctx) -> None:  # from outside the panel, as auto exposure (key X) does
        app.state.tuning.exposure = 2.5

    def drive(ctx) -> None:
        imgui.test_engine.get_io(hello_imgui.get_imgui_test_engine()).config_mouse_draw_cursor = False
        imgui.get_io().mouse_draw_cursor = False
        wait_until(ctx, lambda: pc.preserved is not None, 10, "the back buffer check")
        got["preserved"] = pc.preserved
        if not pc.preserved:
            return
        hello_imgui.get_runner_params().docking_params.dockable_window_of_name("Stats").is_visible = False
        away(ctx)
        ctx.yield_(10)
        w = imgui.internal.find_window_by_name("Tuning")
        got["tuning"] = (w.pos.x, w.pos.y, w.size.x, w.size.y)
        got["view"] = app.state.view.rect
        step(ctx, "still", lambda c: None)
        step(ctx, "hovered", lambda c: c.mouse_move("//Tuning/Budget"))  # the checkbox lights up
        step(ctx, "unhovered", away)
        step(ctx, "after a tooltip", tooltip)
        step(ctx, "changed", change)

    run_gui(app, drive)
    if not got.get("preserved"):
        pytest.skip("this GL driver does not keep the back buffer across a swap: the cache is off")
    assert got["tooltip"] is not None, "the tooltip went before it was measured"
    tx, _, tw, _ = got["tooltip"]  # it lay over the Tuning panel and over the view
    assert tx < got["view"][0] < tx + tw, (got["tooltip"], got["view"])
    steps = ("still", "hovered", "unhovered", "after a tooltip", "changed")
    for name in steps:
        n, level = differing(got[name], got[f"{name} full"])
        assert level <= MAX_LEVEL and n <= MAX_PIXELS, f"{name}: {n} pixels differ, by up to {level} levels"
        assert got[f"{name} view kept"], f"{name}: the empty view was cleared and labelled again"
    for name in ("hovered", "unhovered", "changed"):
        assert got[f"{name} partial"] >= 1, f"{name}: no panel was drawn alone"
    for before, after in (("still", "hovered"), ("hovered", "unhovered"), ("still", "changed")):
        n, _ = differing(crop(got[before], got["tuning"]), crop(got[after], got["tuning"]))
        assert n >= CHANGE_PIXELS, f"{before} -> {after}: only {n} pixels of the Tuning panel changed"


def _shown(name: str) -> bool:
    from imgui_bundle import imgui

    w = imgui.internal.find_window_by_name(name)
    return w is not None and w.active
