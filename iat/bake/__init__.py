"""Solution -> textures: ``flatten`` (quad-tree -> tile), ``seams`` (harmonised shared edges), ``atlas``
(packing), ``policy``, ``formats`` (GPU pixel formats), ``memory`` (memory report, host memory),
``budget``, ``boxes`` (tile boxes, pages), ``polygons`` (vertex arrays), ``baked`` (Baked, BakedSet),
``baker`` (the cached Baker)."""
