"""Bake a scene's lighting into a lightmap atlas with Blender Cycles (bpy): python cycles_bake.py JOB.json

JOB.json: {"vertices": [[x, y, z], ...], "triangles": [[i, j, k], ...] (counter-clockwise seen from
the front), "triangle_material": [m, ...], "materials": [{"albedo": [r, g, b], "emission": [r, g, b]}],
"settings": [[N, [S, ...]], ...] (atlas resolutions, each with its sample counts), "out": DIR,
optional "margin_texels" (3), "bake_margin" (8 px), "seed" (0), "max_bounces" (128)}.

One mesh object (flat faces, exactly the given triangles), one material per scene material:
a Lambertian ``Diffuse BSDF`` of the albedo plus an ``Emission`` of the emitted radiance (strength 1:
radiance = colour), black (an absorber, emitting nothing) from behind -- single-sided surfaces as
the Mitsuba reference and the solver have them; no world light. For each resolution N a Smart UV
Project lightmap UV (islands scaled by area, ``margin_texels / N`` apart) and an N x N float atlas;
for each sample count S a Cycles CPU bake of type COMBINED with direct + indirect diffuse and
emission (the texel is the outgoing diffuse radiance, what a lightmapper stores), no clamping, no
denoising, ``max_bounces`` diffuse bounces. Writes ``uv_N.npy`` ((T, 3, 2) float32 UV of each
triangle's corners) and ``bake_N_S.npy`` ((N, N, 4) float32 scene-linear RGBA, row 0 at v = 0) in
``out``, and prints one JSON line per bake {"resolution", "samples", "bake_s"} and a last one
{"import_bpy_s", "setup_s", "threads", "blender"}. Run in its own process: bpy keeps global state.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path


def _material(bpy, name: str, albedo, emission):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    diff = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diff.inputs["Color"].default_value = (*[float(x) for x in albedo], 1.0)
    diff.inputs["Roughness"].default_value = 0.0
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (*[float(x) for x in emission], 1.0)
    emit.inputs["Strength"].default_value = 1.0 if max(emission) > 0 else 0.0
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(diff.outputs["BSDF"], add.inputs[0])
    nt.links.new(emit.outputs["Emission"], add.inputs[1])
    black = nt.nodes.new("ShaderNodeBsdfDiffuse")
    black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
    nt.links.new(add.outputs["Shader"], mix.inputs[1])
    nt.links.new(black.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexImage")  # the bake target (connected to nothing)
    tex.name = "bake_target"
    return mat


def main() -> int:
    t0 = time.perf_counter()
    import bpy
    import numpy as np

    t_import = time.perf_counter() - t0
    job = json.loads(Path(sys.argv[1]).read_text())
    out = Path(job["out"])
    out.mkdir(parents=True, exist_ok=True)
    t1 = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.world = None
    mesh = bpy.data.meshes.new("scene")
    tris = [tuple(int(i) for i in t) for t in job["triangles"]]
    mesh.from_pydata([tuple(v) for v in job["vertices"]], [], tris)
    mesh.update()
    mats = [_material(bpy, f"m{k}", m["albedo"], m["emission"]) for k, m in enumerate(job["materials"])]
    for m in mats:
        mesh.materials.append(m)
    mesh.polygons.foreach_set("material_index", [int(m) for m in job["triangle_material"]])
    for p in mesh.polygons:
        p.use_smooth = False
    obj = bpy.data.objects.new("scene", mesh)
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)

    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.use_denoising = False
    cy.use_adaptive_sampling = False
    cy.seed = int(job.get("seed", 0))
    nb = int(job.get("max_bounces", 128))
    cy.max_bounces = nb
    cy.diffuse_bounces = nb
    cy.glossy_bounces = 0
    cy.transmission_bounces = 0
    cy.volume_bounces = 0
    cy.transparent_max_bounces = 0
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.caustics_reflective = False
    cy.caustics_refractive = False
    cy.blur_glossy = 0.0
    bake = scene.render.bake
    bake.use_pass_direct = True
    bake.use_pass_indirect = True
    bake.use_pass_diffuse = True
    bake.use_pass_emit = True
    bake.use_pass_glossy = False
    bake.use_pass_transmission = False
    bake.margin = int(job.get("bake_margin", 8))
    bake.margin_type = "EXTEND"
    bake.target = "IMAGE_TEXTURES"
    bake.use_clear = True
    t_setup = time.perf_counter() - t1

    margin_texels = float(job.get("margin_texels", 3.0))
    for n, sample_counts in job["settings"]:
        n = int(n)
        while mesh.uv_layers:
            mesh.uv_layers.remove(mesh.uv_layers[0])
        mesh.uv_layers.new(name="lightmap")
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.uv.smart_project(
            angle_limit=math.radians(66.0),
            margin_method="FRACTION",
            island_margin=margin_texels / n,
            area_weight=0.0,
            correct_aspect=True,
            scale_to_bounds=False,
        )
        bpy.ops.object.mode_set(mode="OBJECT")
        uv = np.zeros(len(mesh.loops) * 2, dtype=np.float32)
        mesh.uv_layers["lightmap"].data.foreach_get("uv", uv)
        loop_start = np.zeros(len(mesh.polygons), dtype=np.int64)
        mesh.polygons.foreach_get("loop_start", loop_start)
        uv = uv.reshape(-1, 2)[loop_start[:, None] + np.arange(3)[None, :]]
        np.save(out / f"uv_{n}.npy", uv)
        img = bpy.data.images.new(f"lightmap_{n}", n, n, alpha=True, float_buffer=True)
        img.colorspace_settings.name = "Linear Rec.709"
        for m in mats:
            node = m.node_tree.nodes["bake_target"]
            node.image = img
            m.node_tree.nodes.active = node
        for s in sample_counts:
            cy.samples = int(s)
            tb = time.perf_counter()
            bpy.ops.object.bake(type="COMBINED")
            dt = time.perf_counter() - tb
            px = np.zeros(n * n * 4, dtype=np.float32)
            img.pixels.foreach_get(px)
            np.save(out / f"bake_{n}_{int(s)}.npy", px.reshape(n, n, 4))
            print(json.dumps({"resolution": n, "samples": int(s), "bake_s": dt}), flush=True)
    print(
        json.dumps(
            {
                "import_bpy_s": t_import,
                "setup_s": t_setup,
                "threads": scene.render.threads,
                "blender": bpy.app.version_string,
            }
        ),
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
