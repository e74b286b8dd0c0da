"""glTF checked and converted before trimesh reads it.

- :func:`check_version`: glTF 1.0 (``asset.version`` "1.x", a GLB container of
  version 1, or no ``asset`` with glTF 1's dict-valued ``meshes``) and other
  versions than 2 are refused in one line, before pygltflib misreads them.
- :func:`check_primitives`: every accessor a primitive uses exists, lies inside its
  buffer view, the view inside its buffer; the vertex attributes have as many
  elements as POSITION; indices are below POSITION's count.
- :func:`convert_primitives`: TRIANGLE_FAN primitives (mode 6, which trimesh skips)
  become indexed triangle lists, ``(0, i, i + 1)``; ``KHR_draco_mesh_compression``
  primitives are decoded with DracoPy into plain accessors. All buffers are then
  merged into one binary chunk: the result is a GLB for trimesh, and the document
  is changed in place to match it (same meshes, materials and images).

``gl`` is a :class:`iat.io.gltf.GltfDocument` (``doc``, ``path``, ``buffer(i)``).
"""

from __future__ import annotations

import json
import struct

import numpy as np

from iat.errors import LoadError
from iat.io.messages import one_line

DRACO = "KHR_draco_mesh_compression"
FAN = 6
TRIANGLES = 4

_DTYPE = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_INDEX_TYPES = (5121, 5123, 5125)

_CONVERT = "convert it to glTF 2.0, e.g. with 'npx gltf-pipeline -i <file> -o out.glb'"


def _json_of(path) -> dict | None:
    """The JSON object of a .gltf or .glb, or None when it cannot be read (pygltflib reports that)."""
    try:
        with open(path, "rb") as f:
            head = f.read(20)
            if head[:4] == b"glTF":
                version, _, length, kind = struct.unpack("<III4s", head[4:20])
                if version == 1:
                    raise LoadError(
                        f"glTF 1.0 (binary) is not supported (this IAT reads glTF 2.0); {_CONVERT}", path
                    )
                if version != 2:
                    raise LoadError(
                        f"GLB container version {version} is not supported (this IAT reads 2)", path
                    )
                if kind != b"JSON":
                    return None
                data = f.read(length)
            else:
                data = head + f.read()
        js = json.loads(data)
    except (OSError, ValueError, struct.error):
        return None
    return js if isinstance(js, dict) else None


def check_version(path) -> None:
    """Raise LoadError for a glTF that is not version 2 (see the module docstring)."""
    js = _json_of(path)
    if js is None:
        return
    asset = js.get("asset")
    version = asset.get("version") if isinstance(asset, dict) else None
    if version is None:
        if any(isinstance(js.get(k), dict) for k in ("meshes", "accessors", "nodes", "buffers")):
            raise LoadError(f"glTF 1.0 is not supported (this IAT reads glTF 2.0); {_CONVERT}", path)
        return
    major = str(version).split(".", 1)[0]
    if major == "1":
        raise LoadError(f"glTF 1.0 is not supported (this IAT reads glTF 2.0); {_CONVERT}", path)
    if major != "2":
        raise LoadError(f"glTF version {version} is not supported (this IAT reads glTF 2.0)", path)


def _malformed(gl, what: str) -> LoadError:
    return LoadError(f"malformed glTF: {what}", gl.path)


def _attributes(prim) -> dict[str, int]:
    """Vertex attribute name -> accessor index of a pygltflib primitive."""
    return {k: v for k, v in vars(prim.attributes).items() if v is not None and not k.startswith("_")}


def _accessor(gl, index, role: str):
    """The pygltflib accessor ``index`` (``role`` names its use in messages)."""
    acc = gl.doc.accessors
    if not isinstance(index, int) or not 0 <= index < len(acc):
        raise _malformed(gl, f"{role} refers to accessor {index}, the file has {len(acc)}")
    a = acc[index]
    if a.componentType not in _DTYPE or a.type not in _WIDTH:
        raise _malformed(gl, f"accessor {index} ({role}) has component type {a.componentType}, type {a.type}")
    if not isinstance(a.count, int) or a.count < 0:
        raise _malformed(gl, f"accessor {index} ({role}) has count {a.count}")
    return a


def _view_bytes(gl, view_index, role: str) -> bytes:
    """The bytes of buffer view ``view_index``, checked against its buffer."""
    views = gl.doc.bufferViews
    if not isinstance(view_index, int) or not 0 <= view_index < len(views):
        raise _malformed(gl, f"{role} refers to buffer view {view_index}, the file has {len(views)}")
    v = views[view_index]
    if not isinstance(v.buffer, int) or not 0 <= v.buffer < len(gl.doc.buffers):
        raise _malformed(
            gl, f"buffer view {view_index} refers to buffer {v.buffer}, the file has {len(gl.doc.buffers)}"
        )
    data = gl.buffer(v.buffer)
    start = v.byteOffset or 0
    end = start + (v.byteLength or 0)
    if end > len(data):
        raise _malformed(
            gl,
            f"buffer view {view_index} ends at byte {end} of buffer {v.buffer}, "
            f"which has {len(data)} (truncated?)",
        )
    return data[start:end]


def read_accessor(gl, index, role: str) -> np.ndarray | None:
    """(count, width) array of accessor ``index``, checked to lie inside its buffer view;
    None for an accessor without a buffer view (zeros, sparse or Draco)."""
    a = _accessor(gl, index, role)
    if a.bufferView is None:
        return None
    data = _view_bytes(gl, a.bufferView, f"accessor {index} ({role})")
    dtype = np.dtype(_DTYPE[a.componentType]).newbyteorder("<")
    width = _WIDTH[a.type]
    stride = gl.doc.bufferViews[a.bufferView].byteStride or dtype.itemsize * width
    offset = a.byteOffset or 0
    need = offset + (stride * (a.count - 1) + dtype.itemsize * width if a.count else 0)
    if need > len(data):
        raise _malformed(
            gl,
            f"accessor {index} ({role}) needs {need} bytes of buffer view {a.bufferView}, "
            f"which has {len(data)}",
        )
    if a.count == 0:
        return np.zeros((0, width), dtype=dtype)
    return np.lib.stride_tricks.as_strided(
        np.frombuffer(data, dtype=dtype, count=(need - offset) // dtype.itemsize, offset=offset),
        shape=(a.count, width),
        strides=(stride, dtype.itemsize),
    )


def check_primitives(gl) -> None:
    """Raise LoadError naming the first inconsistent accessor of any mesh primitive."""
    for mi, mesh in enumerate(gl.doc.meshes):
        for pi, prim in enumerate(mesh.primitives):
            where = f"mesh {mi} primitive {pi}"
            draco = (prim.extensions or {}).get(DRACO)
            if draco is not None:
                if not isinstance(draco, dict):
                    raise _malformed(gl, f"{where}: {DRACO} is not an object")
                _view_bytes(gl, draco.get("bufferView"), f"{where} ({DRACO})")
                continue  # its accessors are decoded from the Draco bytes
            attrs = _attributes(prim)
            if "POSITION" not in attrs:
                raise _malformed(gl, f"{where} has no POSITION")
            counts = {}
            for name, index in attrs.items():
                read_accessor(gl, index, f"{name} of {where}")
                counts[name] = gl.doc.accessors[index].count
            n = counts["POSITION"]
            for name, count in counts.items():
                if count != n:
                    raise _malformed(gl, f"{where}: {name} has {count} elements, POSITION has {n}")
            if prim.indices is not None:
                idx = read_accessor(gl, prim.indices, f"indices of {where}")
                if gl.doc.accessors[prim.indices].componentType not in _INDEX_TYPES:
                    raise _malformed(gl, f"{where}: indices are not unsigned integers")
                top = int(idx.max()) if idx is not None and idx.size else -1
                if top >= n:
                    raise _malformed(
                        gl, f"{where}: face index out of range ({top}, POSITION has {n} elements)"
                    )


def _decode_draco(gl, prim, where: str) -> dict[str, np.ndarray]:
    """Attribute name -> array (float32 attributes, ``"indices"`` (f, 3) uint32) of a Draco primitive."""
    try:
        import DracoPy
    except ImportError as e:
        raise LoadError(f"glTF is Draco-compressed ({DRACO}): pip install DracoPy", gl.path) from e
    ext = prim.extensions[DRACO]
    try:
        mesh = DracoPy.decode(_view_bytes(gl, ext["bufferView"], where))
        out = {"indices": np.asarray(mesh.faces, dtype=np.uint32).reshape(-1, 3)}
        for name, uid in (ext.get("attributes") or {}).items():
            att = mesh.get_attribute_by_unique_id(uid)
            if att is None:
                raise ValueError(f"no attribute of id {uid} for {name}")
            out[name] = np.asarray(att["data"], dtype=np.float32).reshape(len(att["data"]), -1)
    except LoadError:
        raise
    except Exception as e:  # noqa: BLE001 - DracoPy raises its own types and ValueError
        raise LoadError(f"cannot decode Draco mesh ({where}): {one_line(e)}", gl.path) from e
    if "POSITION" not in out:
        raise _malformed(gl, f"{where}: {DRACO} has no POSITION")
    n = len(out["POSITION"])
    if out["indices"].size and int(out["indices"].max()) >= n:
        raise _malformed(gl, f"{where}: face index out of range (Draco data)")
    return out


def convert_primitives(gl) -> bytes | None:
    """A GLB of ``gl.doc`` with fans and Draco primitives as triangle lists, or None when it has none.

    ``gl.doc`` is changed to the converted document (one buffer, the GLB's binary chunk).
    """
    import pygltflib

    doc = gl.doc
    todo = [
        (mi, pi, prim)
        for mi, mesh in enumerate(doc.meshes)
        for pi, prim in enumerate(mesh.primitives)
        if prim.mode == FAN or DRACO in (prim.extensions or {})
    ]
    if not todo:
        return None
    decoded = {}
    for mi, pi, prim in todo:  # read everything before the buffers are merged
        where = f"mesh {mi} primitive {pi}"
        if DRACO in (prim.extensions or {}):
            decoded[mi, pi] = _decode_draco(gl, prim, where)
        elif prim.indices is not None:
            decoded[mi, pi] = {"fan": read_accessor(gl, prim.indices, f"indices of {where}").ravel()}
        else:
            decoded[mi, pi] = {"fan": np.arange(doc.accessors[prim.attributes.POSITION].count)}
    blob = bytearray()
    base = []
    for b in range(len(doc.buffers)):
        blob += b"\0" * (-len(blob) % 4)
        base.append(len(blob))
        blob += gl.buffer(b)
    for v in doc.bufferViews:
        v.byteOffset, v.buffer = (v.byteOffset or 0) + base[v.buffer], 0

    def add(arr: np.ndarray, kind: str) -> int:
        nonlocal blob
        arr = np.ascontiguousarray(arr)
        blob += b"\0" * (-len(blob) % 4)
        doc.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob += arr.astype(arr.dtype.newbyteorder("<")).tobytes()
        ctype = pygltflib.FLOAT if arr.dtype == np.float32 else pygltflib.UNSIGNED_INT
        acc = pygltflib.Accessor(
            bufferView=len(doc.bufferViews) - 1, componentType=ctype, count=len(arr), type=kind
        )
        if kind == "VEC3" and ctype == pygltflib.FLOAT and len(arr):
            acc.min, acc.max = arr.min(axis=0).tolist(), arr.max(axis=0).tolist()
        doc.accessors.append(acc)
        return len(doc.accessors) - 1

    for mi, pi, prim in todo:
        data = decoded[mi, pi]
        if "fan" in data:
            f = np.asarray(data["fan"], dtype=np.uint32)
            tris = np.stack([np.repeat(f[:1], max(len(f) - 2, 0)), f[1:-1], f[2:]], axis=1)
        else:
            tris = data.pop("indices")
            prim.extensions = {k: v for k, v in prim.extensions.items() if k != DRACO}
            for name, arr in data.items():
                setattr(
                    prim.attributes,
                    name,
                    add(arr, {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}[arr.shape[1]]),
                )
        prim.indices = add(tris.reshape(-1), "SCALAR")
        prim.mode = TRIANGLES
    doc.extensionsUsed = [e for e in doc.extensionsUsed or [] if e != DRACO]
    doc.extensionsRequired = [e for e in doc.extensionsRequired or [] if e != DRACO]
    blob += b"\0" * (-len(blob) % 4)
    doc.buffers = [pygltflib.Buffer(byteLength=len(blob))]
    doc.set_binary_blob(bytes(blob))
    js = doc.gltf_to_json(separators=(",", ":"), indent=None).encode("utf-8")
    js += b" " * (-len(js) % 4)
    size = 12 + 8 + len(js) + 8 + len(blob)
    return b"".join(
        [
            b"glTF",
            struct.pack("<III", 2, size, len(js)),
            b"JSON",
            js,
            struct.pack("<I", len(blob)),
            b"BIN\0",
            blob,
        ]
    )
