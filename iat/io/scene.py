"""Scenes: world-space arrays of root patches, materials, lights and cameras.

A *patch* is a root polygon of the report: a planar convex quad (coplanar
triangle pairs merged back, near-parallelograms only), a triangle, or a cell of a
*panel* (:mod:`iat.geometry.panels`): a rectangle root of which only the part covered by
its *clip triangles* is surface (``clip_uv`` in the patch's lattice coordinates; holes
stay holes). Quads keep their corners in order around the polygon; triangles store
``-1`` as their fourth corner.

Lattice parametrisation (shared by the solver, the baker and the renderer):
for a quad with corners c0..c3 the point at ``(u, v)`` in ``[0, 1]^2`` is
``(1-u)(1-v) c0 + u(1-v) c1 + u v c2 + (1-u) v c3``; for a triangle
``c0 + u (c1 - c0) + v (c2 - c0)`` with ``u + v <= 1``.

Files are read into a :class:`Scene` by :func:`iat.io.load.load_scene`;
:func:`scene_digest` keys the geometry and materials a solution depends on.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from iat.camera import Camera
from iat.errors import OptionError
from iat.geometry.faults import FaultFaces
from iat.geometry.mesh import corner_positions, patch_areas, patch_normals
from iat.geometry.pierce import PierceReport
from iat.geometry.quadtree import bilinear
from iat.geometry.sides import SideReport
from iat.io.ies import Photometry


@dataclass
class Material:
    """A diffuse material.

    albedo : (3,) float64 linear RGB in [0, 1] (baseColorFactor x mean of its texture)
    emission : (3,) float64 emitted radiance, linear RGB (emissiveFactor x strength)
    detail : (h, w, 3) float32 linear RGB albedo texture repeated on the surface, or None
    transmission : float in [0, 1], the transmittance of a thin glass (0: opaque); light
      crossing it is multiplied by it, and it reflects and stores nothing
    double_sided : the file says both faces are surface (glTF ``doubleSided``): its open sheets
      get a back face (:mod:`iat.geometry.sides`)
    """

    name: str = ""
    albedo: np.ndarray = field(default_factory=lambda: np.full(3, 0.5))
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    detail: np.ndarray | None = None
    transmission: float = 0.0
    double_sided: bool = False

    def __post_init__(self):
        self.albedo = np.asarray(self.albedo, dtype=np.float64).reshape(3)
        self.emission = np.asarray(self.emission, dtype=np.float64).reshape(3)


@dataclass
class Light:
    """A KHR_lights_punctual point, spot or directional light.

    kind : "point", "spot" or "directional" (the sun: a disc of ``angular_diameter``)
    position : (3,) float64 world (unused by a directional light)
    direction : (3,) float64 unit vector the light points along (world): a spot's axis, and for a
      directional light the direction its light travels (from the sun towards the scene)
    color : (3,) float64 linear RGB
    intensity : float, W/sr per unit colour for point and spot lights (glTF candela read as
      radiometric); W/m² per unit colour on a surface facing a directional light (glTF lux)
    inner_cone, outer_cone : spot cone half-angles in radians
    angular_diameter : a directional light's disc, radians (the sun: 0.53 degrees)
    ies : a point or spot light's IES distribution (:class:`iat.io.ies.Photometry`) about its nadir
      ``direction``, or None; with one, ``intensity`` is its peak
    """

    kind: str = "point"
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    direction: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0, 0.0]))
    color: np.ndarray = field(default_factory=lambda: np.ones(3))
    intensity: float = 1.0
    inner_cone: float = 0.0
    outer_cone: float = np.pi / 4
    name: str = ""
    angular_diameter: float = float(np.radians(0.53))
    ies: Photometry | None = None

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.direction = np.asarray(self.direction, dtype=np.float64).reshape(3)
        self.color = np.asarray(self.color, dtype=np.float64).reshape(3)

    @property
    def radiant_intensity(self) -> np.ndarray:
        """(3,) float64 intensity x colour."""
        return self.color * float(self.intensity)


@dataclass
class Sky:
    """An environment that emits from every direction the geometry does not block.

    kind : "uniform" (``radiance`` everywhere above the horizon), "cie_overcast" (CIE overcast,
      ``radiance`` at the zenith), "preetham" (clear sky of ``turbidity`` for ``sun_direction``,
      scaled by ``radiance``), "hdr" (the equirectangular ``image``, times ``radiance``)
    radiance : (3,) float64 linear RGB radiance scale, W/(m² sr) per unit colour
    sun_direction : (3,) float64 unit vector from the scene towards the sun (preetham)
    turbidity : float, the atmosphere's turbidity (preetham; 2 clear ... 10 hazy)
    image : (h, w, 3) float32 linear radiance, equirectangular (hdr), or None
    rotation : float, radians about +Y applied to the image
    ground : (3,) float64 radiance below the horizon (0: the model brings its ground)
    """

    kind: str = "uniform"
    radiance: np.ndarray = field(default_factory=lambda: np.ones(3))
    sun_direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    turbidity: float = 3.0
    image: np.ndarray | None = None
    rotation: float = 0.0
    ground: np.ndarray = field(default_factory=lambda: np.zeros(3))
    name: str = "sky"

    def __post_init__(self):
        self.radiance = np.asarray(self.radiance, dtype=np.float64).reshape(3)
        self.sun_direction = np.asarray(self.sun_direction, dtype=np.float64).reshape(3)
        self.ground = np.asarray(self.ground, dtype=np.float64).reshape(3)

    @classmethod
    def from_spec(cls, spec) -> Sky | None:
        """The sky of a JSON spec ``{"kind", "radiance", "sun_direction", "turbidity", "ground"}``
        (a lighting state's ``sky``, a file's root ``extras["iat_sky"]``); ``radiance`` may be one
        number; None gives None (no sky). OptionError (one line) for a malformed spec."""
        if spec is None:
            return None
        if not isinstance(spec, dict):
            raise OptionError("sky must be an object or null")
        if set(spec) - set(SKY_SPEC_KEYS):
            raise OptionError(f"unknown sky key(s) {', '.join(sorted(set(spec) - set(SKY_SPEC_KEYS)))}")
        kw = {k: spec[k] for k in SKY_SPEC_KEYS if k in spec}
        if isinstance(kw.get("radiance"), int | float):
            kw["radiance"] = [float(kw["radiance"])] * 3
        try:
            sky = cls(**kw)
        except (TypeError, ValueError) as e:
            raise OptionError(f"sky: {e}") from None
        if not (np.isfinite(sky.radiance).all() and (sky.radiance >= 0).all()):
            raise OptionError(f"sky radiance must be finite and >= 0, got {sky.radiance.tolist()}")
        return sky

    def spec(self) -> dict | None:
        """The JSON spec :meth:`from_spec` reads back; None for an "hdr" sky (its image is no spec)."""
        if self.kind == "hdr":
            return None
        return {
            "kind": self.kind,
            "radiance": [float(x) for x in self.radiance],
            "sun_direction": [float(x) for x in self.sun_direction],
            "turbidity": float(self.turbidity),
            "ground": [float(x) for x in self.ground],
        }


#: albedo at or below which a patch takes no detail texture (:meth:`Scene.detail_patches`)
DETAIL_ALBEDO_FLOOR = 1e-4

#: the keys of a sky's JSON spec (:meth:`Sky.from_spec`)
SKY_SPEC_KEYS = ("kind", "radiance", "sun_direction", "turbidity", "ground")


@dataclass
class Scene:
    """World-space arrays of a model.

    vertices : (n, 3) float64 world positions
    patch_corners : (p, 4) int64 indices into ``vertices``; -1 in column 3 for triangles
    patch_material : (p,) int64 index into ``materials``
    patch_uv : (p, 4, 2) float64 detail-texture UVs at the corners (0 where none)
    materials, lights, cameras : lists
    camera_paths : named lists of Camera poses (walkthrough paths), may be empty
    path : the file it came from ("" when built in memory)
    clip_uv : (C, 3, 2) float64 clip triangles in their patch's lattice (u, v), sorted by patch
    clip_patch : (C,) int64 the (quad) patch each clip triangle belongs to; a patch with none is whole
    sky : a :class:`Sky` around the model, or None
    sides : the loader's :class:`~iat.geometry.sides.SideReport` (inside-out solids turned, open
      sheets given a back face), or None for a scene built in memory
    pierce : the loader's :class:`~iat.geometry.pierce.PierceReport` (faces other objects pierce,
      cut along the crossings), or None for a scene built in memory
    faults : the faces the loader found faulty (:class:`~iat.geometry.faults.FaultFaces`: inside-out
      solids turned, open sheets given a back, faces cut by a crossing, repeats dropped; which patches
      carry them: :func:`iat.geometry.faults.patch_faults`), or None for a scene built in memory
    patch_family : (p,) int64 a label shared by the roots one root was cut into along shadows
      (:mod:`iat.geometry.discontinuity`: its pieces shoot together, as the root would), or None
      when no root was cut
    shadow_cuts : the lights whose hard shadows the roots were cut along, one list of
      :func:`iat.geometry.discontinuity.shadow_key` per cut, in order (a solution records them, so
      that its model reloaded is cut the same: :func:`iat.geometry.discontinuity.replay_cuts`)
    """

    vertices: np.ndarray
    patch_corners: np.ndarray
    patch_material: np.ndarray
    materials: list[Material]
    patch_uv: np.ndarray | None = None
    lights: list[Light] = field(default_factory=list)
    cameras: list[Camera] = field(default_factory=list)
    camera_paths: dict[str, list[Camera]] = field(default_factory=dict)
    path: str = ""
    clip_uv: np.ndarray | None = None
    clip_patch: np.ndarray | None = None
    sky: Sky | None = None
    sides: SideReport | None = None
    pierce: PierceReport | None = None
    faults: FaultFaces | None = None
    patch_family: np.ndarray | None = None
    shadow_cuts: list[list[tuple]] = field(default_factory=list)

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.patch_corners = np.asarray(self.patch_corners, dtype=np.int64).reshape(-1, 4)
        self.patch_material = np.asarray(self.patch_material, dtype=np.int64).reshape(-1)
        if self.patch_uv is None:
            self.patch_uv = np.zeros((len(self.patch_corners), 4, 2))
        self.patch_uv = np.asarray(self.patch_uv, dtype=np.float64).reshape(-1, 4, 2)
        self.clip_uv = np.zeros((0, 3, 2)) if self.clip_uv is None else np.asarray(self.clip_uv, np.float64)
        self.clip_uv = self.clip_uv.reshape(-1, 3, 2)
        self.clip_patch = np.zeros(0, np.int64) if self.clip_patch is None else np.asarray(self.clip_patch)
        self.clip_patch = self.clip_patch.astype(np.int64).reshape(-1)

    # -- derived per-patch data -------------------------------------------------
    @property
    def n_patches(self) -> int:
        return len(self.patch_corners)

    @property
    def patch_is_quad(self) -> np.ndarray:
        """(p,) bool: True for quads, False for triangles."""
        return self.patch_corners[:, 3] >= 0

    @property
    def corner_positions(self) -> np.ndarray:
        """(p, 4, 3) float64 corner positions; a triangle's 4th corner repeats its 3rd."""
        return corner_positions(self.vertices, self.patch_corners)

    @property
    def patch_normal(self) -> np.ndarray:
        """(p, 3) float64 unit normals (right-handed winding of the corners)."""
        return patch_normals(self.corner_positions, self.patch_is_quad)

    @property
    def clip_start(self) -> np.ndarray:
        """(p + 1,) int64: patch p's clip triangles are ``clip_uv[clip_start[p]:clip_start[p + 1]]``."""
        return np.searchsorted(self.clip_patch, np.arange(self.n_patches + 1)).astype(np.int64)

    @property
    def patch_clipped(self) -> np.ndarray:
        """(p,) bool: panel cells covered only in part (drawn and solved through their clip triangles)."""
        return np.diff(self.clip_start) > 0

    @property
    def lattice_area(self) -> np.ndarray:
        """(p,) float64 area of each root's whole lattice (its rectangle for a clipped cell)."""
        return patch_areas(self.corner_positions, self.patch_is_quad)

    @property
    def patch_area(self) -> np.ndarray:
        """(p,) float64 surface areas in square scene units (a clipped cell: its clip triangles')."""
        a = self.lattice_area
        if len(self.clip_patch):
            t = self.clip_uv
            uv_area = 0.5 * np.abs(
                (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
                - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0])
            )
            cov = np.bincount(self.clip_patch, weights=uv_area, minlength=self.n_patches)
            a = np.where(self.patch_clipped, a * cov, a)
        return a

    def world_triangles(self) -> np.ndarray:
        """(T, 3, 3) float64 the surface as triangles: whole patches' (one, or two for a quad) and
        clipped cells' clip triangles, in patch order (what rays hit and references render)."""
        c = self.corner_positions
        whole = ~self.patch_clipped
        q = self.patch_is_quad
        parts = [c[whole][:, [0, 1, 2]], c[whole & q][:, [0, 2, 3]]]
        if len(self.clip_patch):  # cells are rectangles: the bilinear map is affine over a triangle
            uv = self.clip_uv.reshape(-1, 2)
            w = bilinear(c[np.repeat(self.clip_patch, 3)], uv[:, 0], uv[:, 1]).reshape(-1, 3, 3)
            parts.append(w)
        return np.concatenate(parts)

    def world_triangle_uv(self) -> np.ndarray:
        """(T, 3, 2) float64 the lattice parameters (u, v) of :meth:`world_triangles`' corners in
        their patch (a quad's corners are (0, 0), (1, 0), (1, 1), (0, 1), a triangle's (0, 0),
        (1, 0), (0, 1)); linear over each triangle (exact but on a skewed quad's bilinear map)."""
        whole = ~self.patch_clipped
        q = self.patch_is_quad
        first = np.where(
            q[whole][:, None, None], np.array([[0, 0], [1, 0], [1, 1]]), np.array([[0, 0], [1, 0], [0, 1]])
        )
        second = np.broadcast_to(np.array([[0, 0], [1, 1], [0, 1]]), (int((whole & q).sum()), 3, 2))
        return np.concatenate([first, second, self.clip_uv.reshape(-1, 3, 2)]).astype(np.float64)

    def world_triangle_patch(self) -> np.ndarray:
        """(T,) int64 the patch of each of :meth:`world_triangles`."""
        whole = ~self.patch_clipped
        idx = np.arange(self.n_patches)
        return np.concatenate([idx[whole], idx[whole & self.patch_is_quad], self.clip_patch])

    @property
    def patch_albedo(self) -> np.ndarray:
        """(p, 3) float64 albedo per patch."""
        return np.array([m.albedo for m in self.materials])[self.patch_material]

    @property
    def patch_transmission(self) -> np.ndarray:
        """(p,) float64 transmittance per patch (0 opaque; glass passes that much light)."""
        return np.array([float(m.transmission) for m in self.materials] or [0.0])[self.patch_material]

    @property
    def patch_emission(self) -> np.ndarray:
        """(p, 3) float64 emitted radiance per patch."""
        return np.array([m.emission for m in self.materials])[self.patch_material]

    def detail_patches(self, albedo) -> np.ndarray:
        """(p,) bool the patches drawn as incoming light x their material's detail texture: the
        material has one and emits nothing, and the patch's ``albedo`` ((p, 3), the solver's) is
        above ``DETAIL_ALBEDO_FLOOR`` in every channel (the light is divided by it)."""
        mats = self.materials
        has = np.array([m.detail is not None and not np.any(m.emission > 0) for m in mats] or [False])
        mat = np.asarray(self.patch_material, dtype=np.int64).reshape(-1)
        ok = (mat >= 0) & (mat < len(mats))
        out = np.zeros(len(mat), dtype=bool)
        out[ok] = has[mat[ok]]
        return out & (np.asarray(albedo, dtype=np.float64).reshape(-1, 3) > DETAIL_ALBEDO_FLOOR).all(axis=1)

    @property
    def has_light_sources(self) -> bool:
        """True when a light, the sky or a used material emits (a scene without is black whatever
        the solve)."""
        if any(float(np.max(lt.radiant_intensity)) > 0 for lt in self.lights):
            return True
        sky = self.sky
        if sky is not None and float(np.max(sky.radiance)) > 0:
            return sky.kind != "hdr" or sky.image is not None
        used = np.unique(self.patch_material)
        return any(float(self.materials[k].emission.max()) > 0 for k in used if 0 <= k < len(self.materials))

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 min and max corner of the used vertices."""
        used = np.zeros(len(self.vertices), dtype=bool)
        used[self.patch_corners[self.patch_corners >= 0]] = True
        v = self.vertices[used]
        return np.array([v.min(axis=0), v.max(axis=0)])

    def default_camera(self) -> Camera:
        """The file's first camera, or one that frames the bounds from +Z."""
        if self.cameras:
            return self.cameras[0]
        lo, hi = self.bounds
        c = (lo + hi) / 2
        r = max(np.linalg.norm(hi - lo) / 2, 1e-6)
        return Camera(eye=c + np.array([0.0, 0.0, 2.2 * r]), target=c, yfov=50.0, znear=r * 0.01, zfar=r * 10)


def scene_digest(scene: Scene) -> str:
    """sha1 hex digest of the geometry and materials a solution depends on.

    Covers vertices, patch corners, patch materials, each material's albedo and
    emission, and the lights (kind, position, direction, radiant intensity,
    cones): not names, detail textures, UVs, cameras or the path.
    """
    h = hashlib.sha1()
    h.update(b"iat-scene-v1")
    h.update(np.ascontiguousarray(scene.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_corners, dtype="<i8").tobytes())
    h.update(np.ascontiguousarray(scene.patch_material, dtype="<i8").tobytes())
    if len(scene.clip_patch):
        h.update(np.ascontiguousarray(scene.clip_uv, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(scene.clip_patch, dtype="<i8").tobytes())
    for m in scene.materials:
        h.update(np.ascontiguousarray(m.albedo, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(m.emission, dtype="<f8").tobytes())
    for lt in scene.lights:
        h.update(lt.kind.encode())
        for a in (lt.position, lt.direction, lt.radiant_intensity, [lt.inner_cone, lt.outer_cone]):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
        if lt.ies is not None:
            h.update(lt.ies.digest())
    return h.hexdigest()
