"""Geometry shared by the solver, the baker and the renderer: ``quadtree`` (the lattice and the per-patch
quad-trees as flat arrays)."""
