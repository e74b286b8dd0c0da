"""Drawing with OpenGL (moderngl): ``renderer`` (preview / mesh / iat / split / diff), ``glb_view``
(an exported GLB drawn by our own code, to check the export)."""
