"""``iat render MODEL|SOL --faults``: the patches that carry a fault the loader found, tinted.

The view is drawn in ``--mode`` at the exposure ``iat render`` would
pick (or ``--exposure``), the faulty patches tinted in their kind's colour
(:mod:`iat.render.fault_tint`: inside-out solids turned, open sheets given a back face, faces cut by a
crossing element, faces a dropped repeat coincided with) and, in a PNG, a legend of the kinds and
their patch counts at the top left. The counts per solid, sheet and element are ``iat info``'s.
"""

from __future__ import annotations

import numpy as np


def add_faults_flag(sp) -> None:
    """``--faults`` on ``iat render``."""
    sp.add_argument(
        "--faults",
        action="store_true",
        help="tint the patches that carry a fault the loader found (inside-out solids, open sheets, faces "
        "cut by a crossing element, coincident faces), with a legend",
    )


def render_view(args, renderer, scene, camera, size, mode: str) -> np.ndarray:
    """(h, w, 3) float32 the image ``iat render`` saves: the renderer's linear radiance, or with
    ``--faults`` the exposed, tinted view (save it with exposure 1), a legend on it for a PNG."""
    if not getattr(args, "faults", False):
        return renderer.render(camera, size=size, mode=mode)
    from iat.render.fault_tint import draw_legend, legend_rows, render_faults

    img, bits = render_faults(renderer, scene, camera, size, mode, exposure=args.exposure or None)
    if str(args.output).lower().endswith(".png"):
        img = draw_legend(img, legend_rows(bits))
    return img
