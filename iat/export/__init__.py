"""Baked -> files other tools open: ``gltf`` (GLB, unlit with vertex colours or layered)."""
