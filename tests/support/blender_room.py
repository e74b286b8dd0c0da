"""The script Blender (``bpy`` as a module) runs to build and export the room with openings.

Run as ``python tests/support/blender_room.py OUT_DIR`` in its own process (bpy is heavy and
process-global); :func:`tests.support.real_models.blender_room` does that with a timeout.

The room (Blender units = metres, Z up): a 4 x 3 x 2.5 m shell, 0.2 m thick, made as an outer
box minus an inner box, with a window (1.2 x 1.0 m, sill at 0.9 m) in the +Y wall and a door
(0.9 x 2.0 m) in the -X wall cut by EXACT boolean modifiers (so the walls carry the n-gons and
long thin faces CAD booleans make), a table (top and four legs), and a ceiling lamp: an emissive
0.6 x 0.6 m panel facing down 5 cm under the ceiling. The GLB also holds a point light (5 W)
30 cm under the panel (the exporter converts watts to candela). Written:

- ``room.glb``: ``export_scene.gltf`` (GLB, Y up, modifiers applied, lights exported)
- ``room.obj`` + ``room.mtl``: ``wm.obj_export`` with triangulation off (n-gons as Blender has them)
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import bpy

POINT_WATTS = 5.0
PANEL_STRENGTH = 8.0


def material(name: str, rgb, emission=None):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = PANEL_STRENGTH
    return m


def box(name: str, size, centre):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=centre)
    ob = bpy.context.active_object
    ob.name = name
    ob.scale = size
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    return ob


def cut(target, cutter) -> None:
    mod = target.modifiers.new(name=f"cut_{cutter.name}", type="BOOLEAN")
    mod.operation = "DIFFERENCE"
    mod.solver = "EXACT"
    mod.object = cutter
    bpy.context.view_layer.objects.active = target
    bpy.ops.object.modifier_apply(modifier=mod.name)
    bpy.data.objects.remove(cutter, do_unlink=True)


def build() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    wall_m = material("wall", (0.75, 0.72, 0.68))
    floor_m = material("floor", (0.45, 0.35, 0.25))
    table_m = material("table", (0.6, 0.25, 0.15))
    lamp_m = material("lamp", (0.9, 0.9, 0.9), emission=(1.0, 0.95, 0.85))

    shell = box("room", (4.4, 3.4, 2.9), (0.0, 0.0, 1.25))
    cut(shell, box("inside", (4.0, 3.0, 2.5), (0.0, 0.0, 1.25)))
    cut(shell, box("window", (1.2, 1.0, 1.0), (0.4, 1.6, 1.4)))
    cut(shell, box("door", (1.0, 0.9, 2.0), (-2.1, -0.6, 1.0)))
    shell.data.materials.append(wall_m)
    shell.data.materials.append(floor_m)
    for poly in shell.data.polygons:  # the floor's inner face (normal up at z = 0) gets the floor colour
        if poly.normal.z > 0.99 and abs(poly.center.z + shell.location.z) < 1e-4:
            poly.material_index = 1

    parts = [box("top", (1.2, 0.8, 0.05), (0.5, -0.4, 0.75))]
    for sx in (-1, 1):
        for sy in (-1, 1):
            at = (0.5 + sx * 0.55, -0.4 + sy * 0.35, 0.3625)
            parts.append(box(f"leg{sx}{sy}", (0.05, 0.05, 0.725), at))
    bpy.ops.object.select_all(action="DESELECT")
    for p in parts:
        p.select_set(True)
    bpy.context.view_layer.objects.active = parts[0]
    bpy.ops.object.join()
    table = bpy.context.active_object
    table.name = "table"
    table.data.materials.append(table_m)

    bpy.ops.mesh.primitive_plane_add(size=0.6, location=(0.0, 0.0, 2.45), rotation=(math.pi, 0.0, 0.0))
    lamp = bpy.context.active_object
    lamp.name = "lamp"
    lamp.data.materials.append(lamp_m)
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=True)


def add_point_light() -> None:
    data = bpy.data.lights.new("bulb", type="POINT")
    data.energy = POINT_WATTS
    data.shadow_soft_size = 0.0
    ob = bpy.data.objects.new("bulb", data)
    ob.location = (0.0, 0.0, 2.15)
    bpy.context.scene.collection.objects.link(ob)


def export(out: Path) -> None:
    bpy.ops.wm.obj_export(
        filepath=str(out / "room.obj"),
        export_triangulated_mesh=False,
        export_materials=True,
        export_selected_objects=False,
        export_uv=False,
        export_normals=False,
        forward_axis="NEGATIVE_Z",
        up_axis="Y",
    )
    add_point_light()
    bpy.ops.export_scene.gltf(
        filepath=str(out / "room.glb"),
        export_format="GLB",
        export_lights=True,
        export_apply=True,
        export_yup=True,
        export_texcoords=False,
        export_normals=False,
    )


if __name__ == "__main__":
    target = Path(sys.argv[1])
    target.mkdir(parents=True, exist_ok=True)
    build()
    export(target)
    print("wrote", sorted(p.name for p in target.iterdir()), flush=True)
    os._exit(0)  # bpy's own teardown at interpreter exit can crash (segfault) after the files are written
