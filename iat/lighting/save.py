"""Saving edited lights and emission back into a copy of the model's glTF (:func:`save_gltf`).

The source glTF's JSON is patched with pygltflib (``KHR_lights_punctual`` light
definitions and their nodes, emissive factors and ``KHR_materials_emissive_strength``,
the lighting states) and written atomically (temporary file, fsync, rename): a .gltf
keeps its buffer URIs, a GLB is framed by pygltflib (:meth:`pygltflib.GLTF2.save_to_bytes`),
whose binary chunk holds the source's buffer views in order, each 4-byte aligned (the
geometry bytes of a GLB IAT wrote come back unchanged).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from iat.errors import LoadError, OptionError
from iat.fsutil import atomic_write
from iat.io.glb import EXT_EMISSIVE_STRENGTH, EXT_LIGHTS, look_rotation, quat_from_matrix, quat_to_matrix
from iat.io.gltf import GltfDocument, local_matrix
from iat.io.scene import Scene
from iat.lighting.edits import LIGHT_KINDS, checked_light, copy_light
from iat.lighting.states import LIGHTING_STATES_KEY, check_states

log = logging.getLogger(__name__)


def _quat_from_direction(direction) -> list[float]:
    """Rotation quaternion (x, y, z, w) taking the node's -Z to ``direction``."""
    return [float(x) for x in quat_from_matrix(look_rotation(np.asarray(direction, dtype=np.float64)))]


def _emissive_write(mat, emission: np.ndarray, old: np.ndarray) -> bool:
    """Set a pygltflib material's emissiveFactor / strength so that it emits ``emission``
    (the file's own emission is ``old``); returns whether the strength extension is used."""
    emission = np.asarray(emission, dtype=np.float64)
    factor0 = np.asarray(mat.emissiveFactor or [0.0, 0.0, 0.0], dtype=np.float64)[:3]
    ext = dict(mat.extensions or {})
    s0 = float((ext.get(EXT_EMISSIVE_STRENGTH) or {}).get("emissiveStrength", 1.0))
    eff0 = factor0 * s0
    # keep an emissive texture's modulation: scale per channel where the file emitted
    ratio_ok = (old > 0) & (eff0 > 0)
    eff = np.where(ratio_ok, eff0 * np.divide(emission, old, out=np.zeros(3), where=old > 0), emission)
    strength = max(1.0, float(eff.max()))
    mat.emissiveFactor = [float(x) for x in eff / strength]
    if strength > 1.0:
        ext[EXT_EMISSIVE_STRENGTH] = {"emissiveStrength": strength}
    else:
        ext.pop(EXT_EMISSIVE_STRENGTH, None)
    mat.extensions = ext
    return strength > 1.0


def save_gltf(
    scene: Scene,
    src,
    dst,
    *,
    sources: list[int | None] | None = None,
    lighting_states: dict | None = None,
) -> Path:
    """Write ``dst``: the glTF ``src`` with ``scene``'s lights and emission (and lighting states).

    Patches the JSON with pygltflib and keeps the geometry bytes (a GLB's binary chunk is
    copied unchanged; a .gltf keeps its buffer URIs). Written atomically.

    - Lights: every point / spot light of ``src`` is replaced by ``scene.lights``: light k
      takes over the file's light ``sources[k]`` (its node is moved, or, when that node also
      holds a mesh, a camera or children, the light moves to a new node of its own), new
      lights (``None``) get new root nodes, file lights not taken over are removed from their
      nodes. ``sources`` None: by order when the counts match, else by name.
      Directional lights of the file stay.
    - Emission: materials are matched by name; where the emission differs from the file's,
      ``emissiveFactor`` and ``KHR_materials_emissive_strength`` are rewritten.
    - ``lighting_states``: written as the root ``extras["iat_lighting_states"]`` (checked).
    Returns ``dst``. Raises LoadError for an unreadable ``src``, OptionError for bad input.
    """
    from pygltflib import Node

    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise LoadError("no such file", src)
    gl = GltfDocument(src)
    doc = gl.doc
    world = gl.node_world()
    ext = dict(doc.extensions or {})
    defs = list((ext.get(EXT_LIGHTS) or {}).get("lights", []))

    # the file's point / spot lights in load order: (node, definition)
    file_lights = []
    for i in sorted(world):
        node = doc.nodes[i]
        li = ((node.extensions or {}).get(EXT_LIGHTS) or {}).get("light")
        if li is None or not 0 <= li < len(defs):
            continue
        if defs[li].get("type", "point") in LIGHT_KINDS:
            file_lights.append((i, li))
    if sources is None:
        if len(file_lights) == len(scene.lights):
            sources = list(range(len(scene.lights)))
        else:
            names = [defs[li].get("name") or doc.nodes[i].name for i, li in file_lights]
            sources = [names.index(lt.name) if lt.name in names else None for lt in scene.lights]
    if len(sources) != len(scene.lights):
        raise OptionError(f"{len(sources)} light sources given for {len(scene.lights)} lights")

    # the definitions kept: those of nodes that are not point / spot lights (directional)
    kept_defs: list[dict] = []
    remap: dict[int, int] = {}
    for i, node in enumerate(doc.nodes):
        li = ((node.extensions or {}).get(EXT_LIGHTS) or {}).get("light")
        if li is None:
            continue
        if any(i == fi for fi, _ in file_lights) or not 0 <= li < len(defs):
            e = dict(node.extensions)
            e.pop(EXT_LIGHTS, None)
            node.extensions = e
            continue
        if li not in remap:
            remap[li] = len(kept_defs)
            kept_defs.append(defs[li])
        node.extensions = {**node.extensions, EXT_LIGHTS: {"light": remap[li]}}

    scene_index = (
        doc.scene if doc.scene is not None and doc.scenes and 0 <= doc.scene < len(doc.scenes) else 0
    )
    used_nodes: set[int] = set()
    for k, lt in enumerate(scene.lights):
        lt = checked_light(copy_light(lt))
        d: dict = {"name": lt.name or f"light_{k}", "type": lt.kind}
        d["color"] = [float(x) for x in lt.color]
        d["intensity"] = float(lt.intensity)
        if lt.kind == "spot":
            d["spot"] = {"innerConeAngle": float(lt.inner_cone), "outerConeAngle": float(lt.outer_cone)}
        src_k = sources[k]
        node_i = None
        if src_k is not None:
            if not 0 <= int(src_k) < len(file_lights):
                raise OptionError(
                    f"light {k}: source {src_k} is not one of the file's {len(file_lights)} lights"
                )
            node_i = file_lights[int(src_k)][0]
            node = doc.nodes[node_i]
            old = defs[file_lights[int(src_k)][1]]
            for key in ("range", "extras", "extensions"):
                if key in old:
                    d[key] = old[key]
            if (
                node_i in used_nodes
                or node.mesh is not None
                or node.camera is not None
                or node.children
                or node.skin is not None
            ):
                node_i = None  # the node carries more than the light: give the light a node of its own
        li = len(kept_defs)
        kept_defs.append(d)
        rot = _quat_from_direction(lt.direction) if lt.kind == "spot" else None
        if node_i is None:
            node = Node(
                name=d["name"],
                translation=[float(x) for x in lt.position],
                rotation=_quat_from_direction(lt.direction),
                extensions={EXT_LIGHTS: {"light": li}},
            )
            doc.nodes.append(node)
            node_i = len(doc.nodes) - 1
            if doc.scenes:
                doc.scenes[scene_index].nodes = list(doc.scenes[scene_index].nodes or []) + [node_i]
        else:
            node = doc.nodes[node_i]
            parent = world[node_i] @ np.linalg.inv(local_matrix(node))
            target = np.eye(4)
            if rot is not None:
                target[:3, :3] = quat_to_matrix(rot)
            else:  # a point light keeps its orientation
                r = world[node_i][:3, :3]
                u, _, vt = np.linalg.svd(r)
                target[:3, :3] = u @ vt
            target[:3, 3] = lt.position
            if np.allclose(parent, np.eye(4), atol=1e-12):
                node.matrix = None
                node.scale = None
                node.translation = [float(x) for x in lt.position]
                node.rotation = [float(x) for x in quat_from_matrix(target[:3, :3])]
            else:
                local = np.linalg.inv(parent) @ target
                node.matrix = [float(x) for x in local.T.reshape(-1)]
                node.translation = node.rotation = node.scale = None
            node.extensions = {**(node.extensions or {}), EXT_LIGHTS: {"light": li}}
        used_nodes.add(node_i)

    used = set(doc.extensionsUsed or [])
    if kept_defs:
        ext[EXT_LIGHTS] = {**(ext.get(EXT_LIGHTS) or {}), "lights": kept_defs}
        used.add(EXT_LIGHTS)
    else:
        ext.pop(EXT_LIGHTS, None)
        used.discard(EXT_LIGHTS)
    doc.extensions = ext

    # emission, by material name
    by_name = {m.name: m for m in scene.materials}
    strength_used = False
    for gi, gm in enumerate(doc.materials or []):
        name = gm.name or f"material_{gi}"
        m = by_name.get(name)
        old = np.asarray(gl.material(gi).emission, dtype=np.float64)
        if m is not None and not np.allclose(m.emission, old, rtol=1e-9, atol=0.0):
            strength_used |= _emissive_write(gm, m.emission, old)
        else:
            strength_used |= EXT_EMISSIVE_STRENGTH in (gm.extensions or {})
    if strength_used:
        used.add(EXT_EMISSIVE_STRENGTH)
    else:
        used.discard(EXT_EMISSIVE_STRENGTH)
    doc.extensionsUsed = sorted(used) if used else []

    if lighting_states is not None:
        extras = dict(doc.extras or {})
        extras[LIGHTING_STATES_KEY] = check_states(lighting_states, "lighting_states")
        doc.extras = extras

    if src.suffix.lower() == ".glb":
        data = b"".join(doc.save_to_bytes())
    else:
        data = doc.gltf_to_json(separators=(",", ":"), indent=None).encode("utf-8")
    atomic_write(dst, lambda f: f.write(data))
    log.info("wrote %s (%d lights) from %s", dst, len(scene.lights), src)
    return dst
