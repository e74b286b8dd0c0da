"""Import a GLB with Blender (bpy) and render it with Cycles: python blender_render.py JOB.json

JOB.json: {"glb": PATH, "out": PATH.png, "width": W, "height": H, "camera": K,
"script": PATH of iat/export/clients/blender/iat_import.py or null (Blender's importer alone),
"reader": that script (its GLB reader finds the cameras), optional "samples", "filter"}.
The file's K-th glTF camera draws it (vertical field of view and clip range as in the file) with
the Standard view transform (no tone curve), a magenta world, ``samples`` (16) per pixel over a
``filter``-pixel (0.01) filter: point sampling at the pixel centre, as a rasteriser without
antialiasing (a 1-pixel filter averages the pool's detail textures as mipmaps would, 38.7 dB
against 36.7 dB layered, but antialiases every edge: Cornell box 30 dB against 48.6 dB).
Prints one JSON line {"wired": [...]}.
Run in its own process: bpy keeps global state.
"""

from __future__ import annotations

import importlib.util
import json
import sys


def main() -> int:
    import bpy

    job = json.loads(open(sys.argv[1]).read())
    bpy.ops.wm.read_factory_settings(use_empty=True)
    wired = []
    if job.get("script"):
        spec = importlib.util.spec_from_file_location("iat_import", job["script"])
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        wired = mod.import_iat(job["glb"])
        doc, _ = mod.read_glb(job["glb"])
    else:
        bpy.ops.import_scene.gltf(filepath=job["glb"])
        spec = importlib.util.spec_from_file_location("iat_import", job["reader"])
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        doc, _ = mod.read_glb(job["glb"])
    scene = bpy.context.scene
    k = int(job.get("camera", 0))
    cams = [o for o in bpy.data.objects if o.type == "CAMERA"]
    node_names = [n.get("name") for n in doc["nodes"] if n.get("camera") == k]
    cam = next((o for o in cams if o.name in node_names), cams[0] if cams else None)
    if cam is None:
        raise SystemExit("no camera in the file")
    gl = doc["cameras"][k]["perspective"]
    cam.data.sensor_fit = "VERTICAL"
    cam.data.angle_y = gl["yfov"]
    cam.data.clip_start = gl.get("znear", 0.01)
    cam.data.clip_end = gl.get("zfar", 1000.0)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = int(job.get("samples", 16))
    scene.cycles.use_denoising = False
    scene.cycles.filter_width = float(job.get("filter", 0.01))
    scene.cycles.max_bounces = 0
    scene.render.resolution_x = int(job["width"])
    scene.render.resolution_y = int(job["height"])
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    world = bpy.data.worlds.new("magenta")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 0.0, 1.0, 1.0)
    scene.world = world
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.filepath = job["out"]
    bpy.ops.render.render(write_still=True)
    print(json.dumps({"wired": wired}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
