"""Mitsuba 3 path-traced references of a :class:`~iat.io.scene.Scene`.

The reference is what the radiosity solution should converge to: the same
patches, the same diffuse albedos, the same emitters, rendered by an unbiased
path tracer. It is compared with the renderer's float output (``mesh`` / ``iat``
modes) through :mod:`iat.measure.metrics`.

Conventions (checked by ``tests/test_reference.py``)
----------------------------------------------------
- Image: ``(h, w, 3) float32`` linear RGB radiance, row 0 is the **top** of the
  picture and column 0 its **left**, not mirrored: for a camera looking down -Z
  with +Y up, world +X is on the right (column ``w - 1``) and world +Y at the top
  (row 0) -- the same layout as the renderer's read-back after its vertical flip
  and as a PNG.
- Pixels are plain averages over their footprint (box reconstruction filter of
  radius half a pixel), like a rasteriser's supersampled pixel: compare them with
  :func:`box_filtered_render` (``SUPERSAMPLE`` x ``SUPERSAMPLE`` samples a pixel),
  not with a render sampled at pixel centres, whose edges and curved gradients differ
  from the reference's by more than the light does (the Cornell box at the solver's
  defaults: 3.25 % per pixel and 7.2 % on 8 x 8 blocks sampled at centres, 1.9 % and
  1.25 % box-filtered).
- Units: patch emission is radiance (W m^-2 sr^-1 per unit colour); a point or
  spot light's ``color * intensity`` is radiant intensity in W/sr (glTF candela
  read as radiometric), given to Mitsuba's ``intensity`` as is, so a white
  Lambertian floor of albedo rho at distance h straight below a point light of
  intensity I has radiance ``rho / pi * I / h**2``.
- Surfaces are single-sided, like the solver's patches: the front is the side
  of :attr:`Scene.patch_normal` (``cross(c1 - c0, c2 - c0)``); area emitters
  emit only on the front and the diffuse BSDF is black from behind (pass
  ``two_sided=True`` for a BSDF that reflects on both sides).
- ``max_depth`` follows Mitsuba: ``-1`` unlimited, ``1`` emitters seen directly
  only, ``2`` adds direct lighting, ``3`` one indirect bounce, ... Russian
  roulette starts at ``rr_depth`` bounces (unbiased, adds variance only).
- Spot lights: Mitsuba's ``spot`` has its full intensity inside ``beam_width``
  (the glTF inner cone) and falls off *linearly in angle* to zero at
  ``cutoff_angle`` (the outer cone); glTF's falloff is smooth in cos(angle), so
  spot references match the solver inside the inner cone and only roughly in the
  transition ring.
- Glass (``transmission > 0``) as the solver has it (:mod:`iat.radiosity.visibility`): it does not
  occlude, multiplies the light crossing it by its transmittance, keeps the rest and reflects
  nothing: a ``mask`` of black, rendered with ``volpath``, whose shadow rays pass a mask times its
  null transmission (``path``'s ``ray_test`` stops there: no sun or lamp behind a pane). The solver
  counts the first pane a ray crosses only, so the faces of one pane (a thin solid, double
  glazing: faces within :data:`PANE_DEPTH` along their normal, :func:`pane_layers`) pass the k-th
  root each; panes farther apart multiply (the solver: the first only). Scenes without glass keep
  ``path`` and their keys.

Variant: ``scalar_rgb`` (works everywhere). ``llvm_ad_rgb`` is used when the
environment variable ``IAT_MITSUBA_VARIANT`` names it, or when
``DRJIT_LIBLLVM_PATH`` is set and a small probe render in a subprocess succeeds
(with the system's LLVM 15 the LLVM backend aborts the process, so it is never
tried in-process without that check).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from iat.camera import Camera
from iat.io.scene import Scene
from iat.radiosity.sky import mitsuba_emitter, sky_equirect

__all__ = [
    "SUPERSAMPLE",
    "box_filtered_render",
    "mitsuba_variant",
    "build_mitsuba_scene",
    "render_reference",
    "render_reference_cached",
    "render_irradiance",
    "render_irradiance_cached",
    "reference_key",
    "pane_layers",
    "REFERENCE_VERSION",
]

#: samples per pixel side of :func:`box_filtered_render` (8: the Cornell box's per-pixel errors within 0.05
#: points of 16's, the 8 x 8 block errors within 0.15)
SUPERSAMPLE = 8


def box_filtered_render(
    renderer, camera: Camera, size: tuple[int, int], mode: str = "mesh", factor: int = SUPERSAMPLE
):
    """``(h, w, 3) float64`` linear radiance of ``renderer`` (a :class:`~iat.render.renderer.Renderer`
    holding a solution or bake) from ``camera``, each pixel the mean of ``factor`` x ``factor`` samples
    over its footprint: the reference's box filter. size : (w, h) pixels of the result."""
    w, h, k = int(size[0]), int(size[1]), int(factor)
    img = renderer.render(camera, (w * k, h * k), mode=mode).astype(np.float64)
    return img.reshape(h, k, w, k, 3).mean(axis=(1, 3))


#: bump when the way references are built changes, so cached ``.npy`` files are redone
REFERENCE_VERSION = 1
#: glass faces within this distance (m) along their normal are one pane (:func:`pane_layers`)
PANE_DEPTH = 0.1
#: how references pass light through glass: part of the key of a scene with glass only (the keys
#: of glass-free scenes are unchanged)
GLASS_MODEL = f"volpath, mask, first pane: faces within {PANE_DEPTH} m"

_VARIANT: str | None = None

_LLVM_PROBE = """
import mitsuba as mi
mi.set_variant('llvm_ad_rgb')
s = mi.load_dict(mi.cornell_box())
import numpy as np
img = np.array(mi.render(s, spp=2))
assert img.shape[-1] == 3 and np.isfinite(img).all()
"""


def _import_mitsuba():
    try:
        import mitsuba as mi  # noqa: F401
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "iat.measure.reference needs the 'mitsuba' package (Mitsuba 3) for path-traced references: "
            f"pip install mitsuba ({e})"
        ) from e
    return mi


def mitsuba_variant() -> str:
    """Pick (once per process) and set the Mitsuba variant; returns its name.

    ``IAT_MITSUBA_VARIANT`` forces one; otherwise ``llvm_ad_rgb`` when
    ``DRJIT_LIBLLVM_PATH`` is set and a probe render in a subprocess works, else
    ``scalar_rgb``. Raises ImportError when mitsuba is missing.
    """
    global _VARIANT
    mi = _import_mitsuba()
    if _VARIANT is None:
        forced = os.environ.get("IAT_MITSUBA_VARIANT", "").strip()
        if forced:
            if forced not in ("scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb"):
                raise ValueError(
                    f"IAT_MITSUBA_VARIANT={forced!r}: use scalar_rgb, llvm_ad_rgb or cuda_ad_rgb"
                )
            _VARIANT = forced
        else:
            _VARIANT = "scalar_rgb"
            if os.environ.get("DRJIT_LIBLLVM_PATH") and "llvm_ad_rgb" in mi.variants():
                try:
                    r = subprocess.run(
                        [sys.executable, "-c", _LLVM_PROBE], capture_output=True, timeout=120, check=False
                    )
                    if r.returncode == 0:
                        _VARIANT = "llvm_ad_rgb"
                except (OSError, subprocess.TimeoutExpired):
                    pass
    if mi.variant() != _VARIANT:
        mi.set_variant(_VARIANT)
    return _VARIANT


def _rgb(value) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.asarray(value, dtype=np.float64).reshape(3)]}


def _camera_frame(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eye, target and an orthonormal up taken from the camera's own view matrix
    (so degenerate up vectors are resolved exactly as the renderer does)."""
    v = camera.view_from_world()
    up = v[1, :3]
    return camera.eye, camera.eye + camera.forward, up


def _group_triangles(scene: Scene) -> dict[int, np.ndarray]:
    """World triangles per material, ``{material: (t, 3, 3) float64}``
    (:meth:`Scene.world_triangles`: the winding of their patch, so their face normal
    ``cross(v1 - v0, v2 - v0)`` is :attr:`Scene.patch_normal`)."""
    tris = scene.world_triangles()
    mat = scene.patch_material[scene.world_triangle_patch()]
    return {int(m): tris[mat == m] for m in np.unique(mat)}


def _make_mesh(mi, name: str, positions: np.ndarray, faces: np.ndarray, props):
    """An in-memory ``mi.Mesh`` (no vertex normals: flat face normals)."""
    mesh = mi.Mesh(name, len(positions), len(faces), props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    vp, fa = params["vertex_positions"], params["faces"]
    params["vertex_positions"] = type(vp)(np.ascontiguousarray(positions, dtype=np.float32).ravel())
    params["faces"] = type(fa)(np.ascontiguousarray(faces, dtype=np.uint32).ravel())
    params.update()
    return mesh


def pane_layers(tris: np.ndarray, depth: float | None = None) -> np.ndarray:
    """(t,) int64: of glass triangles ``tris`` (t, 3, 3), how many faces (distinct planes, itself
    included) the line along each one's normal through its centroid crosses within ``depth`` m
    (default :data:`PANE_DEPTH`) either side: 1 for a sheet, 2 for a pane modelled as a thin solid, 4
    for double glazing of two such panes."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    tris = np.asarray(tris, dtype=np.float64).reshape(-1, 3, 3)
    depth = PANE_DEPTH if depth is None else float(depth)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    sc = rtcs.EmbreeScene()
    v = np.ascontiguousarray(tris.reshape(-1, 3), dtype=np.float32)
    TriangleMesh(sc, v, np.arange(len(v), dtype=np.int32).reshape(-1, 3))
    origin = tris.mean(axis=1) - depth * n
    left = np.full(len(tris), 2 * depth)
    count = np.zeros(len(tris), dtype=np.int64)
    live = np.flatnonzero(left > 0)
    step = 1e-4 * max(depth, 1.0)  # past a hit (coplanar neighbours hit at one distance: one face)
    while len(live):
        res = sc.run(
            np.ascontiguousarray(origin[live], dtype=np.float32),
            np.ascontiguousarray(n[live], dtype=np.float32),
            dists=np.ascontiguousarray(left[live], dtype=np.float32),
            output=1,
        )
        hit = np.asarray(res["primID"]) >= 0
        live, t = live[hit], np.asarray(res["tfar"], dtype=np.float64)[hit] + step
        count[live] += 1
        origin[live] += t[:, None] * n[live]
        left[live] -= t
        live = live[left[live] > 0]
    return np.maximum(count, 1)


def _glass_parts(m: int, tris: np.ndarray, tau: float) -> dict:
    """``{name: (triangles, bsdf)}`` of glass material ``m``'s triangles as the solver has glass: a
    ``mask`` of black (it passes ``tau``, keeps the rest, reflects nothing). The solver counts the first
    glass a ray crosses only, so each of a pane's k faces (:func:`pane_layers`) passes ``tau ** (1 / k)``
    and a ray through the whole pane keeps ``tau``."""
    black = {"type": "diffuse", "reflectance": _rgb(np.zeros(3))}
    layers = pane_layers(tris)
    return {
        f"material_{m}" + (f"_faces_{k}" if k > 1 else ""): (
            tris[layers == k],
            {"type": "mask", "opacity": 1.0 - tau ** (1.0 / k), "material": black},
        )
        for k in np.unique(layers).tolist()
    }


def _content(mi, scene: Scene, max_depth: int, rr_depth: int, two_sided: bool) -> dict:
    """The ``mi.load_dict`` entries of a :class:`Scene` but its sensor: a ``path`` integrator, one
    ``mi.Mesh`` per material (diffuse BSDF of its albedo; an ``area`` emitter of its emission when that
    is non-zero), point, spot and directional emitters for the lights, and the sky."""
    # with glass: volpath, whose shadow rays pass a mask (path's stop there: no sun behind a pane)
    kind = "volpath" if any(m.transmission > 0 for m in scene.materials) else "path"
    d: dict = {"integrator": {"type": kind, "max_depth": int(max_depth), "rr_depth": int(rr_depth)}}
    for m, tris in _group_triangles(scene).items():
        mat = scene.materials[m]
        bsdf = {"type": "diffuse", "reflectance": _rgb(np.clip(mat.albedo, 0.0, 1.0))}
        if two_sided:
            bsdf = {"type": "twosided", "material": bsdf}
        parts = {f"material_{m}": (tris, bsdf)}
        if mat.transmission > 0:
            parts = _glass_parts(m, tris, float(mat.transmission))
        for name, (part, part_bsdf) in parts.items():
            positions = part.reshape(-1, 3)
            props = mi.Properties()
            props["bsdf"] = mi.load_dict(part_bsdf)
            if np.any(mat.emission > 0):
                emission = _rgb(np.maximum(mat.emission, 0.0))
                props["emitter"] = mi.load_dict({"type": "area", "radiance": emission})
            d[name] = _make_mesh(mi, name, positions, np.arange(len(positions)).reshape(-1, 3), props)

    for k, light in enumerate(scene.lights):
        inten = _rgb(light.radiant_intensity)
        if getattr(light, "ies", None) is not None:
            raise ValueError(f"light {k} ({light.name!r}): Mitsuba has no IES distribution")
        if light.kind == "point":
            d[f"light_{k}"] = {"type": "point", "position": light.position.tolist(), "intensity": inten}
        elif light.kind == "spot":
            dirn = light.direction / max(np.linalg.norm(light.direction), 1e-300)
            lup = np.array([0.0, 1.0, 0.0]) if abs(dirn[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
            outer = float(np.degrees(light.outer_cone))
            inner = float(np.degrees(min(light.inner_cone, light.outer_cone)))
            d[f"light_{k}"] = {
                "type": "spot",
                "to_world": mi.ScalarTransform4f().look_at(
                    origin=light.position.tolist(), target=(light.position + dirn).tolist(), up=lup.tolist()
                ),
                "intensity": inten,
                "cutoff_angle": outer,
                "beam_width": min(inner, outer * 0.9999),
            }
        elif light.kind == "directional":  # (a delta light: Mitsuba's sun has no disc)
            dirn = light.direction / max(np.linalg.norm(light.direction), 1e-300)
            d[f"light_{k}"] = {"type": "directional", "direction": dirn.tolist(), "irradiance": inten}
        else:
            raise ValueError(f"light {k} ({light.name!r}): unsupported kind {light.kind!r}")
    if getattr(scene, "sky", None) is not None:
        d["sky"] = mitsuba_emitter(scene.sky)
    return d


def build_mitsuba_scene(
    scene: Scene,
    camera: Camera,
    size: tuple[int, int] = (256, 256),
    seed: int = 0,
    max_depth: int = -1,
    rr_depth: int = 16,
    two_sided: bool = False,
):
    """Build the ``mi.Scene`` for a :class:`Scene` seen from ``camera``.

    size : (w, h) pixels. The scene's content (:func:`_content`) and a perspective sensor (vertical
    ``yfov``, box filter, independent sampler seeded by ``seed``).
    """
    mi = _import_mitsuba()
    mitsuba_variant()
    w, h = (int(size[0]), int(size[1]))
    if w <= 0 or h <= 0:
        raise ValueError(f"image size must be positive, got {size}")

    eye, target, up = _camera_frame(camera)
    content = _content(mi, scene, max_depth, rr_depth, two_sided)
    d: dict = {
        "type": "scene",
        "integrator": content.pop("integrator"),
        "sensor": {
            "type": "perspective",
            "fov": float(camera.yfov),
            "fov_axis": "y",
            "near_clip": float(camera.znear),
            "far_clip": float(camera.zfar),
            "to_world": mi.ScalarTransform4f().look_at(
                origin=eye.tolist(), target=target.tolist(), up=up.tolist()
            ),
            "film": {
                "type": "hdrfilm",
                "width": w,
                "height": h,
                "pixel_format": "rgb",
                "component_format": "float32",
                "rfilter": {"type": "box"},
            },
            "sampler": {"type": "independent", "seed": int(seed)},
        },
        **content,
    }
    return mi.load_dict(d)


def render_reference(
    scene: Scene,
    camera: Camera,
    size: tuple[int, int] = (256, 256),
    spp: int = 64,
    seed: int = 0,
    max_depth: int = -1,
    *,
    rr_depth: int = 16,
    two_sided: bool = False,
) -> np.ndarray:
    """Path-trace ``scene`` from ``camera`` with Mitsuba 3.

    size : (w, h) pixels; spp : samples per pixel; seed : sampler seed;
    max_depth : Mitsuba path depth (-1 unlimited, 2 = direct light only).
    Returns ``(h, w, 3) float32`` linear RGB radiance, row 0 at the top, column 0
    at the left (not mirrored; see the module docstring).
    Raises ImportError when mitsuba is not installed.
    """
    mi = _import_mitsuba()
    msc = build_mitsuba_scene(scene, camera, size, seed, max_depth, rr_depth, two_sided)
    img = mi.render(msc, spp=int(spp), seed=int(seed))
    out = np.array(img, dtype=np.float32)
    w, h = int(size[0]), int(size[1])
    return np.ascontiguousarray(out.reshape(h, w, -1)[..., :3])


def _scene_digest(scene: Scene):
    """``(hash, meta)``: a SHA-256 fed with the scene's arrays (geometry, materials, sky) and the
    JSON-able description of its lights and the reference version."""
    hsh = hashlib.sha256()
    for a in _scene_arrays(scene):
        hsh.update(str(a.shape).encode())
        hsh.update(a.tobytes())
    meta = {
        "version": REFERENCE_VERSION,
        "lights": [
            [
                l.kind,
                l.position.tolist(),
                l.direction.tolist(),
                l.color.tolist(),
                float(l.intensity),
                float(l.inner_cone),
                float(l.outer_cone),
            ]
            for l in scene.lights
        ],
    }
    if any(m.transmission > 0 for m in scene.materials):
        meta["glass"] = GLASS_MODEL
    return hsh, meta


def _scene_arrays(scene: Scene) -> list[np.ndarray]:
    def arr(a, dtype):
        return np.ascontiguousarray(np.asarray(a, dtype=dtype))

    out = [
        arr(scene.vertices, np.float64),
        arr(scene.patch_corners, np.int64),
        arr(scene.patch_material, np.int64),
    ]
    if len(scene.clip_patch):
        out += [arr(scene.clip_uv, np.float64), arr(scene.clip_patch, np.int64)]
    out.append(arr([m.albedo for m in scene.materials] or np.zeros((0, 3)), np.float64))
    out.append(arr([m.emission for m in scene.materials] or np.zeros((0, 3)), np.float64))
    if any(m.transmission > 0 for m in scene.materials):
        out.append(arr([m.transmission for m in scene.materials], np.float64))
    sky = getattr(scene, "sky", None)
    if sky is not None:
        out.append(arr(sky_equirect(sky, 64), np.float32))
    return out


def reference_key(
    scene: Scene,
    camera: Camera,
    size: tuple[int, int],
    spp: int,
    seed: int = 0,
    max_depth: int = -1,
    rr_depth: int = 16,
    two_sided: bool = False,
) -> str:
    """Hex SHA-256 (first 24 digits) of everything a reference depends on."""
    cam = [camera.eye.tolist(), camera.target.tolist(), camera.up.tolist()]
    cam += [float(camera.yfov), float(camera.znear), float(camera.zfar)]
    view = {"camera": cam, "size": [int(size[0]), int(size[1])]}
    return _render_key(scene, spp, seed, max_depth, rr_depth, two_sided, view)


def _render_key(
    scene: Scene, spp, seed, max_depth, rr_depth, two_sided, extra: dict, data: bytes = b""
) -> str:
    """Hex SHA-256 (first 24 digits) of a render's inputs: the scene (:func:`_scene_digest`), then
    ``data`` (raw bytes, e.g. sensor points), then the JSON (sorted keys) of the scene's description,
    the render settings and the ``extra`` fields."""
    hsh, meta = _scene_digest(scene)
    hsh.update(data)
    meta.update(extra)
    meta.update(
        spp=int(spp),
        seed=int(seed),
        max_depth=int(max_depth),
        rr_depth=int(rr_depth),
        two_sided=bool(two_sided),
    )
    hsh.update(json.dumps(meta, sort_keys=True).encode())
    return hsh.hexdigest()[:24]


def _cached(path: Path, shape: tuple, dtype, make, regen: bool | None) -> np.ndarray:
    """The array in ``path`` when it has ``shape`` and ``dtype`` (and ``regen`` is not true), else
    ``make()`` written there atomically. regen None: the environment variable ``IAT_REGEN_REFS``."""
    if regen is None:
        regen = os.environ.get("IAT_REGEN_REFS", "").strip().lower() in ("1", "true", "yes")
    if not regen and path.is_file():
        try:
            out = np.load(path, allow_pickle=False)
            if out.shape == shape and out.dtype == dtype:
                return out
        except (OSError, ValueError):
            pass  # damaged cache file: render again
    out = make()
    from iat.fsutil import atomic_write

    atomic_write(path, lambda f: np.save(f, out, allow_pickle=False))
    return out


def render_reference_cached(
    scene: Scene,
    camera: Camera,
    size: tuple[int, int],
    spp: int,
    cache_dir: str | Path,
    *,
    seed: int = 0,
    max_depth: int = -1,
    rr_depth: int = 16,
    two_sided: bool = False,
    regen: bool | None = None,
) -> np.ndarray:
    """:func:`render_reference`, stored in ``cache_dir/ref-<key>.npy``.

    The key (:func:`reference_key`) hashes the scene arrays, materials, lights,
    camera, size, spp, seed and depth settings, so any change renders anew.
    regen : True re-renders and overwrites; None reads the environment variable
    ``IAT_REGEN_REFS`` ("1"/"true"/"yes" mean regenerate; a pytest
    ``--regen-refs`` option can set it). The file is written atomically
    (temporary file + ``os.replace``). Returns ``(h, w, 3) float32``.
    """
    key = reference_key(scene, camera, size, spp, seed, max_depth, rr_depth, two_sided)
    return _cached(
        Path(cache_dir) / f"ref-{key}.npy",
        (int(size[1]), int(size[0]), 3),
        np.float32,
        lambda: render_reference(
            scene, camera, size, spp, seed, max_depth, rr_depth=rr_depth, two_sided=two_sided
        ),
        regen,
    )


# -- irradiance at points (work-plane sensors) ---------------------------------------------------
#: radius (m) of the disc each irradiance meter samples its rays from (it is in the scene: it shadows
#: that little)
METER_RADIUS = 1e-3


def _meter(mi, point: np.ndarray, normal: np.ndarray, index: int) -> dict:
    """A disc of :data:`METER_RADIUS` at ``point`` facing ``normal`` carrying an ``irradiancemeter``
    (its sampler's seed is its index: equal dicts would be loaded as one sensor)."""
    up = [0.0, 0.0, 1.0] if abs(normal[1]) > 0.9 else [0.0, 1.0, 0.0]
    to_world = mi.ScalarTransform4f().look_at(
        origin=point.tolist(), target=(point + normal).tolist(), up=up
    ) @ mi.ScalarTransform4f().scale(METER_RADIUS)
    film = {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "rgb", "rfilter": {"type": "box"}}
    sensor = {"type": "irradiancemeter", "film": film, "sampler": {"type": "independent", "seed": index}}
    return {"type": "disk", "to_world": to_world, "sensor": sensor}


def _delta_irradiance(mi, msc, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(3,) irradiance at ``point`` facing ``normal`` from the scene's delta emitters (point, spot and
    directional lights, which an irradiance meter's rays never meet), each as Mitsuba gives it and
    tested for shadow by Mitsuba's own rays."""
    it = mi.Interaction3f()
    it.p = mi.ScalarPoint3f(point.tolist())
    it.n = mi.ScalarNormal3f(normal.tolist())
    out = np.zeros(3)
    for em in msc.emitters():
        if not mi.has_flag(em.flags(), mi.EmitterFlags.Delta):
            continue
        ds, weight = em.sample_direction(it, mi.ScalarPoint2f(0.5, 0.5))
        cos = float(np.dot(np.array(ds.d), normal))
        if cos <= 0:
            continue
        ray = it.spawn_ray_to(ds.p) if np.isfinite(ds.dist) else it.spawn_ray(ds.d)
        if not msc.ray_test(ray):
            out += cos * np.array(weight, dtype=np.float64)[:3]
    return out


def render_irradiance(
    scene: Scene,
    points,
    normals=(0.0, 1.0, 0.0),
    spp: int = 4096,
    seed: int = 0,
    max_depth: int = -1,
    *,
    rr_depth: int = 16,
    two_sided: bool = False,
) -> np.ndarray:
    """(n, 3) float64 irradiance, W/m² per unit colour, on small planes at ``points`` (n, 3) facing
    ``normals`` ((n, 3) or one (3,); default up) by Mitsuba 3: an ``irradiancemeter`` per point
    (``spp`` cosine-distributed paths: light from surfaces, area emitters and the sky) plus the
    delta lights' direct light with Mitsuba's shadow rays. The independent counterpart of
    :func:`iat.measure.sensors.irradiance_at`. Keep points off the surfaces (a few mm): a meter on a
    surface sees it from behind half the time."""
    mi = _import_mitsuba()
    mitsuba_variant()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.broadcast_to(np.asarray(normals, dtype=np.float64), pts.shape).copy()
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    d = {"type": "scene", **_content(mi, scene, max_depth, rr_depth, two_sided)}
    for k, (p, n) in enumerate(zip(pts, nrm, strict=True)):
        d[f"meter_{k}"] = _meter(mi, p, n, k)
    msc = mi.load_dict(d)
    sensors = msc.sensors()
    out = np.zeros((len(pts), 3))
    for k in range(len(pts)):
        img = np.array(mi.render(msc, sensor=sensors[k], spp=int(spp), seed=int(seed) * len(pts) + k))
        out[k] = img.reshape(-1)[:3] + _delta_irradiance(mi, msc, pts[k], nrm[k])
    return out


def render_irradiance_cached(
    scene: Scene,
    points,
    normals=(0.0, 1.0, 0.0),
    spp: int = 4096,
    cache_dir: str | Path = ".",
    *,
    seed: int = 0,
    max_depth: int = -1,
    rr_depth: int = 16,
    two_sided: bool = False,
    regen: bool | None = None,
) -> np.ndarray:
    """:func:`render_irradiance`, stored in ``cache_dir/irr-<key>.npy`` (the key hashes the scene as
    :func:`reference_key` does, the points, normals, spp, seed and depth settings)."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    nrm = np.ascontiguousarray(np.broadcast_to(np.asarray(normals, dtype=np.float64), pts.shape))
    meters = {"irradiance": len(pts), "meter_radius": METER_RADIUS}
    key = _render_key(scene, spp, seed, max_depth, rr_depth, two_sided, meters, pts.tobytes() + nrm.tobytes())
    return _cached(
        Path(cache_dir) / f"irr-{key}.npy",
        pts.shape,
        np.float64,
        lambda: render_irradiance(
            scene, pts, nrm, spp, seed, max_depth, rr_depth=rr_depth, two_sided=two_sided
        ),
        regen,
    )
