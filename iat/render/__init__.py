"""Drawing with OpenGL (moderngl): ``renderer`` (preview / mesh / iat / split / diff) on ``gl``
(shaders, programs, the GL object registry), ``buffers`` (geometry written in place) and ``pages``
(the page texture array); ``glb_view`` (an exported GLB drawn by our own code, to check the export).
Shaders in ``shaders/*.glsl``, the shared colour code in ``shaders/color.glsl``."""
