"""GL plumbing shared by the drawers: shader lookup and programs, the one libGL call moderngl
lacks, and the registry of GL objects a drawer owns.

Shaders live in the top-level ``shaders/<name>.glsl`` (a wheel installs them as ``iat/shaders``, see
:func:`shader_dir`), both stages in one file (``#if defined VERTEX_SHADER`` / ``#elif defined
FRAGMENT_SHADER``). A line ``#include "other.glsl"`` is replaced
by that file's text (one level: included files include nothing); GLSL 330 has no ``#include``.
(moderngl also resolves ``#include "..."`` on any line, comments too, from ``ctx.includes``: so no
shader text may contain one that this loader does not replace.)
"""

from __future__ import annotations

import importlib.resources
import re
from pathlib import Path
from typing import Any

from iat.errors import RenderError

_GL_TEXTURE_2D_ARRAY = 0x8C1A
#: moderngl dtype -> (GL format, GL type) of the data: GL_RGBA + UNSIGNED_BYTE / HALF_FLOAT
_GL_FORMAT_TYPE = {"f1": (0x1908, 0x1401), "f2": (0x1908, 0x140B)}
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')


# -- shaders ------------------------------------------------------------------------------------
def shader_dir() -> Any:
    """The ``.glsl`` files, as an ``importlib.resources`` Traversable (a :class:`pathlib.Path` on a
    file system): ``iat/shaders`` inside an installed wheel (``pyproject.toml`` force-includes the
    top-level ``shaders/`` there), else ``shaders/`` beside the ``iat`` package (a source tree, an
    editable install)."""
    tried = []
    for d in (importlib.resources.files("iat") / "shaders", Path(__file__).resolve().parents[2] / "shaders"):
        if (d / "mesh.glsl").is_file():
            return d
        tried.append(str(d))
    raise RenderError(f"shader directory not found (looked in {' and '.join(tried)})")


def _read_shader(filename: str) -> str:
    path = shader_dir() / filename
    try:
        return path.read_text(encoding="utf-8")
    except OSError as e:
        raise RenderError(f"cannot read shader: {e}", path) from e


def shader_source(name: str, stage: str) -> str:
    """Source of program ``name`` (``shaders/<name>.glsl``) for ``stage`` "VERTEX_SHADER" / "FRAGMENT_SHADER".

    Prepends ``#version 330 core`` and the stage's define, and splices in every ``#include``d
    file (``#line`` directives keep compiler messages on the right file and line: source string
    1 is the included file, 0 the program's own).
    """
    lines = []
    for k, line in enumerate(_read_shader(f"{name}.glsl").splitlines(), 1):
        m = _INCLUDE.match(line)
        if m is None:
            lines.append(line)
        else:
            lines += ["#line 1 1", _read_shader(m.group(1)).rstrip("\n"), f"#line {k + 1} 0"]
    body = "\n".join(lines)
    return f"#version 330 core\n#define {stage}\n#line 1\n{body}\n"


def program(ctx, name: str):
    """The compiled and linked program ``shaders/<name>.glsl`` on moderngl context ``ctx``."""
    try:
        return ctx.program(
            vertex_shader=shader_source(name, "VERTEX_SHADER"),
            fragment_shader=shader_source(name, "FRAGMENT_SHADER"),
        )
    except RenderError:
        raise
    except Exception as e:  # moderngl raises plain Exception subclasses
        raise RenderError(f"shader {name}.glsl does not compile: {e}") from e


# -- the GL call moderngl lacks -------------------------------------------------------------------
_LIBGL = None


def libgl():
    """The process's GL entry points (glvnd's libOpenGL, else libGL), a ``ctypes.CDLL`` with
    ``glTexImage3D`` typed, for the one call moderngl lacks: glTexImage3D with an internal format
    (sRGB8 and RGB9_E5 texture arrays)."""
    global _LIBGL
    if _LIBGL is None:
        import ctypes

        for name in ("libOpenGL.so.0", "libGL.so.1", "libGL.so", "opengl32"):
            try:
                lib = ctypes.CDLL(name)
                f = lib.glTexImage3D
            except (OSError, AttributeError):
                continue
            f.argtypes = (
                [ctypes.c_uint] + [ctypes.c_int] * 6 + [ctypes.c_uint, ctypes.c_uint, ctypes.c_void_p]
            )
            f.restype = None
            _LIBGL = lib
            break
        else:
            raise RenderError("cannot load libOpenGL/libGL to create an sRGB8 or RGB9_E5 texture array")
    return _LIBGL


def respecify_texture_array(tex, internal_format: int, dtype: str) -> None:
    """Re-allocate level 0 of moderngl texture array ``tex`` with GL internal format
    ``internal_format`` (e.g. GL_SRGB8_ALPHA8, GL_RGB9_E5), which moderngl cannot ask for.

    dtype : the moderngl dtype the texture was created with and will be written in ("f1" / "f2").
    Binds ``tex`` to texture unit 0.
    """
    fmt, typ = _GL_FORMAT_TYPE[dtype]
    w, h, n = tex.width, tex.height, tex.layers
    tex.use(0)
    libgl().glTexImage3D(_GL_TEXTURE_2D_ARRAY, 0, internal_format, w, h, n, 0, fmt, typ, None)


# -- GL object bookkeeping ------------------------------------------------------------------------
class Registry:
    """Every GL object a drawer owns, so that ``release_all()`` frees them all and tests can count them."""

    def __init__(self):
        self._objects: dict[int, Any] = {}

    def add(self, obj):
        self._objects[id(obj)] = obj
        return obj

    def release(self, obj) -> None:
        if obj is not None and self._objects.pop(id(obj), None) is not None:
            obj.release()

    def release_all(self) -> None:
        # vertex arrays first, then programs, framebuffers, attachments, buffers
        objs = list(self._objects.values())
        order = {"VertexArray": 0, "Framebuffer": 1, "Program": 2}
        objs.sort(key=lambda o: order.get(type(o).__name__, 3))
        for o in objs:
            o.release()
        self._objects.clear()

    def __len__(self) -> int:
        return len(self._objects)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for o in self._objects.values():
            out[type(o).__name__] = out.get(type(o).__name__, 0) + 1
        return out
