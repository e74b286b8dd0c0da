"""Steps the viewer's GUI tests share, driving the real app through imgui-bundle's test engine."""

from __future__ import annotations

import numpy as np

from tests.conftest import wait_until


def settle(ctx, app, seconds: float, frames: int = 3) -> None:
    """Yield frames until the viewer ``app``'s background work is done (re-bake, opening, relight,
    day-cycle solve, a relit solution not yet shown), failing after ``seconds``; then ``frames`` more."""
    s = app.state

    def idle() -> bool:
        busy = s.jobs.rebaking or s.jobs.opening or s.lighting.relighting or s.lighting.solving_day_cycle
        return not busy and app.pending_relit is None

    wait_until(ctx, idle, seconds, "the background work")
    ctx.yield_(frames)


def screenshot(ctx, app, name: str) -> np.ndarray:
    """Press F12 and read back the screenshot the viewer writes: (h, w, 3) float64, 8-bit levels
    (0-255) of its 3D view; ``name`` labels the wait."""
    from imgui_bundle import imgui
    from PIL import Image

    s = app.state
    s.messages.last_screenshot = ""
    ctx.key_press(imgui.Key.f12)
    wait_until(ctx, lambda: s.messages.last_screenshot, 10, f"the {name} screenshot")
    return np.asarray(Image.open(s.messages.last_screenshot).convert("RGB")).astype(np.float64)
