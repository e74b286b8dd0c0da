"""What one solve reads as it runs (:class:`Context`), by topic: the scene's patches, the gather
threads, the gathers from a shooting patch and the direct light of the sources."""

from __future__ import annotations

from iat.radiosity.direct import DirectLight
from iat.radiosity.gathers import Gathers
from iat.radiosity.heap import fix_mmap_threshold
from iat.radiosity.options import SolveOptions
from iat.radiosity.patches import Patches
from iat.radiosity.tasks import TaskPool
from iat.radiosity.visibility import Visibility


class Context:
    """The parts of a solve that its stages share, one owner each: ``patches``
    (:class:`~iat.radiosity.patches.Patches`, frozen), ``pool`` (the gather threads), ``gathers``
    (:class:`~iat.radiosity.gathers.Gathers`: patterns, form factors, culling counts) and
    ``light`` (:class:`~iat.radiosity.direct.DirectLight`: the sources and their direct light)."""

    def __init__(self, scene, opts: SolveOptions, vis: Visibility):
        fix_mmap_threshold()
        self.opts, self.vis = opts, vis
        self.patches = Patches.of_scene(scene, opts)
        self.pool = TaskPool(vis)
        self.gathers = Gathers(self.patches, opts, vis, self.pool)
        self.light = DirectLight(scene, self.patches, opts, vis, self.pool, self.gathers)
