"""Import an IAT export into Blender with its lightmaps wired (Blender 4.2, bpy).

Blender's glTF importer reads the default export as it is (unlit: Emission through a Light Path
node). The layered export (``iat bake --layered``) puts the illumination on a second UV map through
``MOZ_lightmap``, which the importer does not know: it imports the albedo on a Principled BSDF and
leaves ``UVMap.001`` unused. This script imports the file and rebuilds each such material as

    UV Map(TEXCOORD_0) -> Image(albedo) --\\
                                           Multiply -> x intensity / pi -> Emission -> Output
    UV Map(TEXCOORD_1) -> Image(lightmap) -/

so that Cycles and EEVEE show albedo x illumination at the file's exposure (use the Standard view
transform). It needs nothing but Blender: run it as

    blender --background --python iat_import.py -- FILE.glb [OUT.blend]

or, inside Blender's Python, ``import_iat("FILE.glb")``. Shipped with the ``iat`` package
(``iat/export/clients/blender/iat_import.py``); see docs/export.md.
"""

from __future__ import annotations

import json
import math
import os
import struct
import sys
import tempfile

EXTENSION = "MOZ_lightmap"


def read_glb(path: str) -> tuple[dict, bytes]:
    """(JSON, BIN chunk) of a GLB file."""
    with open(path, "rb") as f:
        data = f.read()
    magic, _, _ = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF":
        raise ValueError(f"{path}: not a GLB file")
    doc, binary, off = None, b"", 12
    while off + 8 <= len(data):
        n, kind = struct.unpack_from("<II", data, off)
        chunk = data[off + 8 : off + 8 + n]
        if kind == 0x4E4F534A:
            doc = json.loads(chunk.decode("utf-8"))
        elif kind == 0x004E4942:
            binary = chunk
        off += 8 + n
    if doc is None:
        raise ValueError(f"{path}: no JSON chunk")
    return doc, binary


def lightmaps(doc: dict, binary: bytes) -> dict[int, dict]:
    """{material index: {"name", "png" (bytes), "texCoord", "intensity", "rgbm" (range or None)}}
    of the materials with ``MOZ_lightmap``."""
    out = {}
    for i, mat in enumerate(doc.get("materials", [])):
        ext = (mat.get("extensions") or {}).get(EXTENSION)
        if not ext:
            continue
        image = doc["images"][doc["textures"][ext["index"]]["source"]]
        view = doc["bufferViews"][image["bufferView"]]
        start = view.get("byteOffset", 0)
        out[i] = {
            "name": mat.get("name", f"material_{i}"),
            "png": binary[start : start + view["byteLength"]],
            "texCoord": int(ext.get("texCoord", 1)),
            "intensity": float(ext.get("intensity", 1.0)),
            "rgbm": _rgbm_range(mat),
        }
    return out


def _rgbm_range(mat: dict) -> float | None:
    """The RGBM range of an ``iat bake --hdr`` lightmap (``extras.iat_illumination``), else None."""
    ill = (mat.get("extras") or {}).get("iat_illumination") or {}
    return float(ill.get("rgbm_range", 16.0)) if ill.get("encoding") == "rgbm" else None


def _uv_name(material, index: int, default: str) -> str:
    import bpy

    for obj in bpy.data.objects:
        if obj.type != "MESH" or material.name not in [m.name for m in obj.data.materials if m]:
            continue
        layers = obj.data.uv_layers
        if index < len(layers):
            return layers[index].name
    return default


def _base_image(material):
    """The image the importer linked to the Principled BSDF's Base Color (None without one)."""
    for node in material.node_tree.nodes:
        if node.type == "BSDF_PRINCIPLED":
            links = node.inputs["Base Color"].links
            if links and links[0].from_node.type == "TEX_IMAGE":
                return links[0].from_node.image
    return None


def wire(material, lightmap_image, texcoord: int, intensity: float, rgbm: float | None = None) -> None:
    """Rebuild ``material``'s nodes: albedo (its base colour image, UV map 0) x lightmap (UV map
    ``texcoord``; RGBM: colour x alpha x ``rgbm``) x intensity / pi -> Emission -> Material Output."""
    albedo = _base_image(material)
    nt = material.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    uv1 = nt.nodes.new("ShaderNodeUVMap")
    uv1.uv_map = _uv_name(material, texcoord, "UVMap.001")
    lm = nt.nodes.new("ShaderNodeTexImage")
    lm.image = lightmap_image
    lm.interpolation = "Linear"
    lm.extension = "EXTEND"  # the export's CLAMP_TO_EDGE
    nt.links.new(uv1.outputs["UV"], lm.inputs["Vector"])
    light = lm.outputs["Color"]
    if rgbm is not None:  # colour x alpha x range
        mult = nt.nodes.new("ShaderNodeMath")
        mult.operation = "MULTIPLY"
        mult.inputs[1].default_value = rgbm
        nt.links.new(lm.outputs["Alpha"], mult.inputs[0])
        dec = nt.nodes.new("ShaderNodeVectorMath")
        dec.operation = "SCALE"
        nt.links.new(lm.outputs["Color"], dec.inputs[0])
        nt.links.new(mult.outputs["Value"], dec.inputs["Scale"])
        light = dec.outputs["Vector"]
    scale = nt.nodes.new("ShaderNodeMix")
    scale.data_type = "RGBA"
    scale.blend_type = "MULTIPLY"
    scale.inputs["Factor"].default_value = 1.0
    scale.inputs["B"].default_value = (intensity / math.pi,) * 3 + (1.0,)
    if albedo is not None:
        uv0 = nt.nodes.new("ShaderNodeUVMap")
        uv0.uv_map = _uv_name(material, 0, "UVMap")
        base = nt.nodes.new("ShaderNodeTexImage")
        base.image = albedo
        base.interpolation = "Linear"
        nt.links.new(uv0.outputs["UV"], base.inputs["Vector"])
        mul = nt.nodes.new("ShaderNodeMix")
        mul.data_type = "RGBA"
        mul.blend_type = "MULTIPLY"
        mul.inputs["Factor"].default_value = 1.0
        nt.links.new(base.outputs["Color"], mul.inputs["A"])
        nt.links.new(light, mul.inputs["B"])
        nt.links.new(mul.outputs["Result"], scale.inputs["A"])
    else:
        nt.links.new(light, scale.inputs["A"])
    nt.links.new(scale.outputs["Result"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])


def import_iat(path: str) -> list[str]:
    """Import the GLB at ``path`` into the current scene and wire its lightmaps; returns the names
    of the materials wired."""
    import bpy

    doc, binary = read_glb(path)
    before = {m.name for m in bpy.data.materials}
    bpy.ops.import_scene.gltf(filepath=os.path.abspath(path))
    new = [m for m in bpy.data.materials if m.name not in before]
    images: dict[bytes, object] = {}
    wired = []
    for info in lightmaps(doc, binary).values():
        hits = [m for m in new if m.name == info["name"] or m.name.startswith(info["name"] + ".")]
        if not hits or not hits[0].use_nodes:
            continue
        key = info["png"]
        if key not in images:
            with tempfile.NamedTemporaryFile(suffix=".png", delete=False) as f:
                f.write(key)
            try:
                img = bpy.data.images.load(f.name)
                img.pack()
            finally:
                os.unlink(f.name)
            img.name = f"{info['name']}_lightmap"
            img.colorspace_settings.name = "sRGB"
            if info["rgbm"] is not None:
                img.alpha_mode = "CHANNEL_PACKED"  # alpha is the RGBM multiplier, not coverage
            images[key] = img
        wire(hits[0], images[key], info["texCoord"], info["intensity"], info["rgbm"])
        wired.append(hits[0].name)
    return wired


def main(argv: list[str]) -> int:
    args = argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]
    if not args:
        print("usage: blender --background --python iat_import.py -- FILE.glb [OUT.blend]")
        return 2
    wired = import_iat(args[0])
    print(f"iat_import: {args[0]}: {len(wired)} lightmapped material(s) wired")
    if len(args) > 1:
        import bpy

        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
