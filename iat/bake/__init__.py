"""Solution -> textures: ``flatten`` (quad-tree -> tile), ``seams`` (harmonised shared edges), ``atlas``
(packing), ``baker`` (policy, formats, memory report, budget, the cached Baker, Baked)."""
