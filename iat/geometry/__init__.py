"""Geometry shared by the loader, the solver, the baker and the renderer: ``mesh`` (welding, quad
merging and pre-splitting on arrays) and ``quadtree`` (the lattice and the per-patch quad-trees as flat
arrays)."""
