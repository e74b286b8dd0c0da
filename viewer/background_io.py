"""The viewer's file writes that run beside the UI: Export GLB, save the solution, save the lights.

Each runs on its own thread and reports through the app's message queue (``app._messages``): the
state is changed on the UI thread only.
"""

from __future__ import annotations

import threading

from viewer.jobs import error_text


def in_background(app, done: str, fn) -> None:
    """Run ``fn()`` on a thread; ``done`` is the status shown when it returns, else its error."""

    def run():
        try:
            fn()
            app._messages.append(("status", done))
        except Exception as e:
            app._messages.append(("error", error_text(e)))

    t = threading.Thread(target=run, name="iat-io", daemon=True)
    app._bg_threads = [b for b in app._bg_threads if b.is_alive()] + [t]
    t.start()


def export(app, path: str) -> None:
    """Export the bake on screen to ``path`` (``export_glb``'s defaults: as ``iat bake`` writes it);
    in the day cycle, the moment on screen."""
    from iat.bake.baked import BakedSet
    from iat.export.gltf import export_glb

    s = app.state
    if s.model.baked is None:
        s.messages.set_error("nothing baked to export yet")
        return
    baked, scene = s.model.baked, s.model.scene
    if isinstance(baked, BakedSet):
        baked = baked.blend(*s.lighting.day_blend())
    in_background(app, f"exported the bake to {path}", lambda: export_glb(baked, path, scene))
