"""Solution sets: several solutions of one model with different lighting, and blending between them.

A :class:`SolutionSet` holds solutions of the same patches solved on one settled
mesh (``solve(scene, mesh=first)`` or :func:`iat.radiosity.resolve`), so their
quad-trees, vertex keys and triangles are identical and every vertex (and, once
baked with :meth:`iat.bake.baker.Baker.bake_set`, every texel) of one has its partner
in the others. Each solution has a key time in [0, 1] (a time of day, or any
other parameter); the light at time ``t`` is the linear blend of the two
neighbouring key solutions (report §6.2.1: radiosity is linear in the sources,
so blending two solutions is the solution of the blended sources),
:func:`blend_weights`: exact at the key times, clamped outside them.

:func:`solve_set` solves a model's lighting states (``extras["iat_lighting_states"]``,
see :mod:`iat.lighting.states`) on one mesh: by default the *merged* mesh (every state
solved adaptively, then the union of their quad-trees, :func:`merge_meshes`: each
state's shadows resolved as finely as its own solve would), then every state on it.
Cheaper choices: the mesh of all sources at once (``"union"``), or the first state's.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from iat.errors import OptionError, SolutionFileError

log = logging.getLogger(__name__)

__all__ = [
    "SolutionSet",
    "blend_radiance",
    "blend_weights",
    "even_times",
    "load_set",
    "merge_meshes",
    "same_mesh",
    "solve_set",
]


def even_times(n: int) -> np.ndarray:
    """(n,) float64 key times evenly spaced in [0, 1] (``[0.0]`` for one)."""
    n = int(n)
    if n < 1:
        raise OptionError("a set needs at least one solution")
    return np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)


def _check_times(times, n: int | None = None) -> np.ndarray:
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if n is not None and len(t) != n:
        raise OptionError(f"{len(t)} key times for {n} solutions")
    if not len(t) or not np.isfinite(t).all():
        raise OptionError(f"key times must be finite numbers, got {t.tolist()}")
    if len(t) > 1 and not (np.diff(t) > 0).all():
        raise OptionError(f"key times must increase strictly, got {t.tolist()}")
    return t


def blend_weights(times, t: float) -> tuple[int, int, float]:
    """The neighbouring key states of time ``t`` and the mix: ``(a, b, w)`` with
    ``radiance(t) = (1 - w) radiance[a] + w radiance[b]``.

    times : (n,) strictly increasing key times. At a key time ``times[k]`` the result is
    ``(k, k + 1, 0.0)`` (``(n-1, n-1, 0.0)`` at the last): exactly state k. Before the first
    key time it is the first state, after the last the last (clamped).
    """
    times = _check_times(times)
    n = len(times)
    t = float(t)
    if not np.isfinite(t):
        raise OptionError(f"time must be a finite number, got {t}")
    if n == 1 or t <= times[0]:
        return 0, min(1, n - 1), 0.0
    if t >= times[-1]:
        return n - 1, n - 1, 0.0
    a = int(np.searchsorted(times, t, side="right") - 1)
    w = (t - times[a]) / (times[a + 1] - times[a])
    return a, a + 1, float(min(max(w, 0.0), 1.0))


def same_mesh(a, b) -> bool:
    """True when solutions ``a`` and ``b`` share patches, leaves, vertex keys and triangles."""
    if a is b:
        return True
    if int(a.max_depth) != int(b.max_depth):
        return False
    for name in (
        "vert_key",
        "leaf_patch",
        "leaf_level",
        "leaf_i",
        "leaf_j",
        "leaf_flip",
        "tri_vertices",
        "patch_is_quad",
    ):
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if x.shape != y.shape or not np.array_equal(x, y):
            return False
    pa, pb = np.asarray(a.patch_corners), np.asarray(b.patch_corners)
    return pa.shape == pb.shape and np.allclose(
        pa, pb, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(pa).max(initial=0)))
    )


def _leaf_codes(forest) -> np.ndarray:
    """(L,) int64 identity of each leaf: (patch, level, i, j, flip)."""
    n1 = np.int64(forest.n + 1)
    code = np.asarray(forest.leaf_patch, np.int64) * np.int64(forest.max_depth + 1) + forest.leaf_level
    code = (code * n1 + forest.leaf_i) * n1 + forest.leaf_j
    return code * 2 + np.asarray(forest.leaf_flip, np.int64)


def merge_meshes(solutions):
    """A Solution (radiance zero) whose quad-trees are the union of ``solutions``' trees: every
    element split in any of them is split (then 2:1 balanced). Every vertex of every input is a
    vertex of the result, so a solve on it (``solve(scene, mesh=merged)``) resolves each input's
    features as finely as that input did."""
    from iat.geometry import quadtree as qt
    from iat.radiosity.solution import Solution

    sols = list(solutions)
    first = sols[0]
    D = int(first.max_depth)
    for s in sols[1:]:
        if (
            int(s.max_depth) != D
            or np.asarray(s.patch_corners).shape != np.asarray(first.patch_corners).shape
        ):
            raise OptionError("merge_meshes: the solutions have different patches or max_depth")
    leaves = [np.sort(_leaf_codes(s.forest)) for s in sols]
    forest = qt.roots(np.asarray(first.patch_is_quad, dtype=bool), D)
    node_of = np.ones((forest.n_leaves, len(sols)), dtype=bool)  # this leaf is a node of tree k
    for _ in range(D + 1):
        code = _leaf_codes(forest)
        internal = node_of & ~np.stack([np.isin(code, lv) for lv in leaves], axis=1)
        mask = internal.any(axis=1) & (forest.leaf_level < D)
        if not mask.any():
            break
        node_of = np.concatenate([node_of[~mask], np.tile(internal[mask], (4, 1))])
        forest = qt.split(forest, mask)  # keeps the unsplit leaves first, then the 4 children blocks
    forest = qt.balance(forest)
    keys = qt.vertex_keys(forest)
    return Solution.from_forest(
        forest,
        first.patch_corners,
        first.patch_material,
        first.patch_albedo,
        keys,
        np.zeros((len(keys), 3), np.float32),
        options=dict(first.options),
        model_path=first.model_path,
        clip_uv=first.clip_uv,
        clip_patch=first.clip_patch,
        patch_transmission=first.patch_transmission,
    )


def blend_radiance(solutions, times, t: float) -> np.ndarray:
    """(V, 3) float32 vertex radiance of the blend at time ``t`` (exact at the key times)."""
    a, b, w = blend_weights(times, t)
    ra = np.asarray(solutions[a].vert_radiance, dtype=np.float32)
    if w == 0.0:
        return ra.copy()
    rb = np.asarray(solutions[b].vert_radiance, dtype=np.float32)
    return ((1.0 - w) * ra.astype(np.float64) + w * rb.astype(np.float64)).astype(np.float32)


@dataclass
class SolutionSet:
    """Solutions of one model under different lighting, on one mesh, with key times.

    solutions : list of :class:`~iat.radiosity.solution.Solution` (checked: same mesh)
    times : (n,) strictly increasing key times (default: evenly spaced in [0, 1])
    names : a name per state (default ``state0`` ...)
    """

    solutions: list
    times: np.ndarray | None = None
    names: list[str] = field(default_factory=list)

    def __post_init__(self):
        self.solutions = list(self.solutions)
        n = len(self.solutions)
        if n == 0:
            raise OptionError("a solution set needs at least one solution")
        for k, s in enumerate(self.solutions[1:], 1):
            if not same_mesh(self.solutions[0], s):
                raise OptionError(
                    f"solution {k} ({self._name(k)}) is not on the mesh of solution 0: solve the states "
                    "with solve(scene, mesh=first) or resolve(first, scene)"
                )
        self.times = even_times(n) if self.times is None else _check_times(self.times, n)
        if not self.names:
            self.names = [f"state{k}" for k in range(n)]
        if len(self.names) != n:
            raise OptionError(f"{len(self.names)} names for {n} solutions")
        self.names = [str(x) for x in self.names]

    def _name(self, k):
        return self.names[k] if self.names and k < len(self.names) else f"#{k}"

    def __len__(self) -> int:
        return len(self.solutions)

    def __iter__(self):
        return iter(self.solutions)

    def __getitem__(self, k):
        return self.solutions[k]

    @property
    def first(self):
        return self.solutions[0]

    def weights(self, t: float) -> tuple[int, int, float]:
        """``(a, b, w)`` of time ``t`` (:func:`blend_weights`)."""
        return blend_weights(self.times, t)

    def radiance_at(self, t: float) -> np.ndarray:
        """(V, 3) float32 blended vertex radiance at ``t``."""
        return blend_radiance(self.solutions, self.times, t)

    def at(self, t: float):
        """A :class:`~iat.radiosity.solution.Solution` of the blend at time ``t`` (shares the mesh
        arrays; its radiance is the blend). At a key time it is that solution itself."""
        a, b, w = self.weights(t)
        if w == 0.0:
            return self.solutions[a]
        s = dataclasses.replace(self.solutions[a], vert_radiance=self.radiance_at(t))
        s.stats = {**s.stats, "blend": {"time": float(t), "a": self.names[a], "b": self.names[b], "w": w}}
        return s

    def save(self, directory, stem: str = "state") -> list[Path]:
        """Write every solution as ``<directory>/<stem>-<name>.npz`` (key time and name in its stats)."""
        directory = Path(directory)
        out = []
        for name, t, sol in zip(self.names, self.times, self.solutions, strict=True):
            sol.stats = {**sol.stats, "lighting_state": name, "lighting_time": float(t)}
            p = directory / f"{stem}-{name}.npz"
            sol.save(p)
            out.append(p)
        return out


def load_set(paths, times=None, names=None) -> SolutionSet:
    """A :class:`SolutionSet` from solution files (in the order given, or by their recorded key
    times when every file has one and no times or names are given).

    times : None takes each file's ``stats['lighting_time']`` when all have one, else the
      key times of the model's lighting states named in ``stats['lighting_state']``, else
      evenly spaced in [0, 1]
    """
    from iat.radiosity.solution import Solution

    paths = [Path(p) for p in paths]
    if not paths:
        raise OptionError("--set needs at least one solution file")
    sols = [Solution.load(p) for p in paths]
    stamped = [s.stats.get("lighting_time") for s in sols]
    if times is None and names is None and all(isinstance(x, int | float) for x in stamped):
        order = np.argsort(stamped, kind="stable")  # files given in any order (a shell glob)
        sols, paths = [sols[k] for k in order], [paths[k] for k in order]
    if names is None:
        names = [str(s.stats.get("lighting_state") or p.stem) for s, p in zip(sols, paths, strict=True)]
    if times is None:
        stamped = [s.stats.get("lighting_time") for s in sols]
        if all(isinstance(x, int | float) for x in stamped):
            times = [float(x) for x in stamped]
        else:
            times = _times_from_model(sols)
    try:
        return SolutionSet(sols, times, list(names))
    except OptionError as e:
        raise SolutionFileError(str(e), paths[0]) from e


def _times_from_model(sols) -> np.ndarray | None:
    from iat.lighting.states import lighting_states, state_times

    model = sols[0].model_path
    wanted = [s.stats.get("lighting_state") for s in sols]
    if not model or not all(wanted):
        return None
    try:
        states = lighting_states(model)
    except Exception:  # a moved or unreadable model: fall back to even spacing
        return None
    if not states or not all(w in states for w in wanted):
        return None
    t = dict(zip(states, state_times(states), strict=True))
    out = np.array([t[w] for w in wanted])
    return out if len(out) < 2 or (np.diff(out) > 0).all() else None


def solve_set(
    scene,
    states: Mapping | None = None,
    options=None,
    progress: Callable[[float, str], bool | None] | None = None,
    *,
    mesh: str = "merge",
    method: str = "mesh",
) -> SolutionSet:
    """Solve lighting states of ``scene`` on one mesh.

    states : {name: state dict (see :mod:`iat.lighting.states`) or Scene}; None: the model's own
      ``extras["iat_lighting_states"]``. Key times from the states (``time``) or even.
    mesh : "merge" (default) solves every state adaptively and merges their trees
      (:func:`merge_meshes`: each state's features as fine as its own solve; 2 N solves),
      "union" settles the mesh on every source at once (N + 1 solves; the brightest sources
      decide where it refines), "first" on the first state (N solves; later states' shadows only
      as fine as the first state's mesh happens to be there), or a Solution to reuse.
    method : "mesh" solves each state afresh on that mesh (``solve(..., mesh=)``), "resolve"
      continues from the mesh solution (shoots only the difference: faster when the states share
      most sources).
    progress : ``progress(fraction, message) -> bool``; False cancels (raises Cancelled).
    """
    from iat.errors import Cancelled
    from iat.io.scene import Scene
    from iat.lighting.states import apply_lighting_state, lighting_states, state_times, union_lighting
    from iat.radiosity import SolveOptions, resolve, solve

    states = lighting_states(scene) if states is None else dict(states)
    if not states:
        raise OptionError(f"{getattr(scene, 'path', '') or 'the scene'} has no lighting states")
    if method not in ("mesh", "resolve"):
        raise OptionError(f'method must be "mesh" or "resolve", got {method!r}')
    opts = options or SolveOptions()
    names = list(states)
    spec = {k: v for k, v in states.items() if not isinstance(v, Scene)}
    times = state_times(spec) if len(spec) == len(states) else even_times(len(states))
    scenes = [v if isinstance(v, Scene) else apply_lighting_state(scene, v) for v in states.values()]
    n = len(scenes)
    t_start = time.perf_counter()
    steps = n + {"union": 1, "merge": n}.get(mesh, 0) if isinstance(mesh, str) else n
    done = [0]

    def sub(label):
        def cb(fraction, message):
            ok = True if progress is None else progress((done[0] + fraction) / steps, f"{label}: {message}")
            return ok is not False

        return cb

    def check(sol, label):
        if sol.stats.get("cancelled"):
            raise Cancelled(f"solve of {label} cancelled")
        done[0] += 1
        return sol

    if isinstance(mesh, str):
        if mesh == "union":
            base = check(solve(union_lighting(scenes), opts, sub("mesh (all sources)")), "the union")
        elif mesh == "merge":
            own = [
                check(solve(sc, opts, sub(f"mesh of {name}")), name)
                for name, sc in zip(names, scenes, strict=True)
            ]
            base = merge_meshes(own)
        elif mesh == "first":
            base = None
        else:
            raise OptionError(f'mesh must be "merge", "union", "first" or a Solution, got {mesh!r}')
    else:
        base = mesh
    sols = []
    for k, (name, sc) in enumerate(zip(names, scenes, strict=True)):
        if base is None and k == 0:
            sol = check(solve(sc, opts, sub(name)), name)
            base = sol
        elif method == "resolve" and "sources" in (base.stats or {}):
            sol = check(resolve(base, sc, opts, sub(name)), name)
        else:
            sol = check(solve(sc, opts, sub(name), mesh=base), name)
        sol.stats = {**sol.stats, "lighting_state": name, "lighting_time": float(times[k])}
        sol.model_path = sol.model_path or str(getattr(scene, "path", "") or "")
        sols.append(sol)
    log.info("solved %d lighting states in %.1f s", n, time.perf_counter() - t_start)
    return SolutionSet(sols, times, names)
