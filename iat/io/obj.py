"""OBJ text before trimesh reads it: decoding, n-gons re-triangulated, checks that name a fault.

- :func:`decode_text` reads UTF-8 (with or without BOM), UTF-16 and UTF-32 with a BOM,
  and anything else as Latin-1; bytes with NUL and no BOM are not a text file.
- :func:`triangulate_ngons` rewrites every face of more than 4 corners, and every
  non-convex quad, as triangles cut by earcut in the face's own plane
  (:func:`iat.io.triangulate.polygon_triangles`): trimesh fans them, which fills a
  concave or keyhole ("holed") face. The corner tokens (``v/vt/vn``, negative
  indices) are kept, so texture coordinates, ``usemtl`` and groups are unchanged.
- :func:`check_obj_textures` and :func:`obj_index_out_of_range` name a missing texture
  file and a face index out of range.
"""

from __future__ import annotations

import codecs
import logging
import re
from pathlib import Path

import numpy as np

from iat.errors import LoadError
from iat.io.messages import one_line
from iat.io.triangulate import newell_normal, polygon_triangles

log = logging.getLogger(__name__)

# longest first: the UTF-32 LE BOM starts with the UTF-16 LE one
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32-le"),
    (codecs.BOM_UTF32_BE, "utf-32-be"),
    (codecs.BOM_UTF8, "utf-8"),
    (codecs.BOM_UTF16_LE, "utf-16-le"),
    (codecs.BOM_UTF16_BE, "utf-16-be"),
)

_VERTEX = re.compile(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.M)
_NGON = re.compile(r"^[ \t]*f[ \t]+\S+(?:[ \t]+\S+){4}", re.M)  # 5 or more corner tokens
_QUAD = re.compile(r"^[ \t]*f[ \t]+(\d+)\S*[ \t]+(\d+)\S*[ \t]+(\d+)\S*[ \t]+(\d+)\S*[ \t\r]*$", re.M)
_POLYGON = re.compile(r"^[ \t]*f[ \t]+(\S+(?:[ \t]+\S+){3,})[ \t\r]*$", re.M)  # 4 or more corner tokens


def decode_text(data: bytes, path: Path, kind: str = "OBJ") -> str:
    """The text of an OBJ (or other ``kind`` of text) file from its bytes (encodings: see the module)."""
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            try:
                return data[len(bom) :].decode(encoding)
            except UnicodeDecodeError as e:
                raise LoadError(
                    f"cannot read {kind} file ({encoding} with a BOM): {one_line(e)}", path
                ) from e
    if b"\0" in data:
        raise LoadError(f"cannot read {kind} file (truncated or corrupt file): not valid data", path)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _convex_quads(P: np.ndarray) -> np.ndarray:
    """(q,) bool: the quads ``P`` (q, 4, 3) that are strictly convex (every turn along the normal)."""
    q = np.roll(P, -1, axis=1)
    n = newell_normal(P)
    turns = np.cross(q - P, np.roll(P, -2, axis=1) - q)  # (q, 4, 3) at corners 1, 2, 3, 0
    return (np.einsum("qcd,qd->qc", turns, n) > 0).all(axis=1)


def _all_quads_convex(text: str) -> bool:
    """True when every quad ``f`` line has positive indices in range and is convex (no n-gons checked)."""
    quads = _QUAD.findall(text)
    n_faces = len(_POLYGON.findall(text))
    if not quads:
        return n_faces == 0
    try:
        V = np.array(_VERTEX.findall(text), dtype=np.float64).reshape(-1, 3)
    except ValueError:
        return True  # unparsable coordinates: trimesh's error
    idx = np.array(quads, dtype=np.int64) - 1
    if n_faces != len(quads) or idx.min() < 0 or idx.max() >= len(V):
        return False  # negative indices or other forms: the full pass
    return bool(_convex_quads(V[idx]).all())


def triangulate_ngons(text: str, path: Path) -> str:
    """``text`` with its n-gons (n > 4) and non-convex quads rewritten as triangle ``f`` lines.

    Faces whose indices cannot be resolved are left for trimesh (and
    :func:`obj_index_out_of_range`) to report.
    """
    if _NGON.search(text) is None and _all_quads_convex(text):
        return text  # the common case, found without a Python loop over the faces
    faces = list(_POLYGON.finditer(text))
    if not faces:
        return text
    vmatch = list(_VERTEX.finditer(text))
    try:
        V = np.array([m.groups() for m in vmatch], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        return text  # unparsable coordinates: trimesh's error
    vstart = np.array([m.start() for m in vmatch], dtype=np.int64)
    before = np.searchsorted(vstart, [m.start() for m in faces])  # vertices defined before each face
    tokens, corners = [], []
    for m, nv in zip(faces, before, strict=True):
        toks = m.group(1).split("#", 1)[0].split()
        try:
            idx = [int(t.split("/", 1)[0]) for t in toks]
        except ValueError:
            idx = [0]
        idx = [i - 1 if i > 0 else nv + i for i in idx]
        if len(toks) < 4 or min(idx) < 0 or max(idx) >= nv:
            idx = None
        tokens.append(toks)
        corners.append(idx)
    quads = [k for k, c in enumerate(corners) if c is not None and len(c) == 4]
    redo = {k for k, c in enumerate(corners) if c is not None and len(c) > 4}
    if quads:
        convex = _convex_quads(V[np.array([corners[k] for k in quads])])
        redo.update(k for k, ok in zip(quads, convex, strict=True) if not ok)
    if not redo:
        return text
    out, last, line = [], 0, 1
    for k in sorted(redo):
        m, toks = faces[k], tokens[k]
        line += text.count("\n", last, m.start())
        tris = polygon_triangles(V[corners[k]], f"{path}: face at line {line}")
        out.append(text[last : m.start()])
        out.append("\n".join("f " + " ".join(toks[i] for i in t) for t in tris))
        last = m.end()
    out.append(text[last:])
    log.debug("%s: %d polygons re-triangulated with earcut", path, len(redo))
    return "".join(out)


def check_obj_textures(path: Path) -> None:
    """Raise LoadError when an OBJ's material library names a texture file that is missing."""
    try:
        data = path.read_bytes()
    except OSError as e:
        raise LoadError(f"cannot read file: {one_line(e)}", path) from e
    libs = [
        m.decode("utf-8", "replace").strip()
        for m in re.findall(rb"^[ \t]*mtllib[ \t]+([^\r\n]+)", data, re.M)
    ]
    for lib in libs:
        mtl = path.parent / lib
        if mtl.is_file():
            mtls = [mtl]
        else:
            mtls = [path.parent / t for t in lib.split() if (path.parent / t).is_file()]
            if not mtls:
                log.warning("%s: material library %s not found; default materials used", path, lib)
                continue
        for m in mtls:
            for line in m.read_text(errors="replace").splitlines():
                toks = line.strip().split()
                if len(toks) < 2:
                    continue
                key = toks[0].lower()
                if not (key.startswith("map_") or key in ("bump", "disp", "decal", "norm", "refl")):
                    continue
                rest = line.strip()[len(toks[0]) :].strip()
                last = toks[-1].replace("\\", "/")
                cands = {rest, toks[-1], last, last.rsplit("/", 1)[-1]}
                if any((m.parent / c).is_file() for c in cands):
                    continue
                raise LoadError(f"missing texture file {toks[-1]}", path)


def obj_index_out_of_range(text: str) -> bool:
    """True when an OBJ face refers to a vertex that does not exist (only run after a failed load)."""
    lines = text.splitlines()
    nv = sum(1 for ln in lines if ln.startswith("v ") or ln.startswith("v\t"))
    for ln in lines:
        if not (ln.startswith("f ") or ln.startswith("f\t")):
            continue
        for tok in ln.split()[1:]:
            try:
                i = int(tok.split("/")[0])
            except ValueError:
                continue
            if i == 0 or i > nv or -i > nv:
                return True
    return False
