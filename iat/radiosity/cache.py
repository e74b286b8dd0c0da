"""One content-keyed cache of solutions, shared by the viewer, the benchmarks and the tests.

A solution is stored as ``<directory>/<model stem>-<key>.npz``. The key hashes the model file's
bytes, the solve options and the solver's source (:func:`iat.radiosity.solver_fingerprint`), so an
edited model, other options or a changed solver never reuse an old solution, and a copied or
touched model still finds its own.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from dataclasses import asdict
from pathlib import Path

from iat.errors import IATError
from iat.progress import Progress

log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The default directory: ``$IAT_CACHE_DIR``, else ``$XDG_CACHE_HOME/iat/solutions`` (``~/.cache``)."""
    env = os.environ.get("IAT_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "iat" / "solutions"


def solution_key(model: str | os.PathLike, options) -> str:
    """16 hex digits of a hash of the model file's bytes, ``options`` (SolveOptions) and the solver's
    source."""
    from iat.radiosity import solver_fingerprint

    h = hashlib.sha256()
    h.update(Path(model).read_bytes())
    h.update(json.dumps(asdict(options), sort_keys=True, default=str).encode())
    h.update(solver_fingerprint().encode())
    return h.hexdigest()[:16]


def solution_cache_path(
    model: str | os.PathLike, options, directory: str | os.PathLike | None = None
) -> Path:
    """The cache file of ``model`` solved with ``options``, in ``directory`` (default :func:`cache_dir`)."""
    directory = cache_dir() if directory is None else Path(directory)
    return directory / f"{Path(model).stem}-{solution_key(model, options)}.npz"


def load_cached(path: Path, n_patches: int):
    """The Solution cached at ``path``, or None when there is none or it is unreadable or of another
    model (its patch count differs from ``n_patches``)."""
    from iat.radiosity.solution import Solution

    if not path.is_file():
        return None
    try:
        sol = Solution.load(path)
    except (IATError, OSError) as e:  # damaged, of an older format or unreadable: solve again
        log.info("cache %s not used: %s", path, e)
        return None
    return sol if len(sol.patch_is_quad) == n_patches else None


def cached_solve(model, options=None, directory=None, progress: Progress | None = None):
    """``(scene, solution, info)`` for a model file, the solution read from or written to the cache.

    options : SolveOptions (None: defaults); directory : default :func:`cache_dir`.
    info : ``{"load_s", "solve_s", "cached", "cache_file"}``; ``solve_s`` is the time the solve took
    when it ran (read from the solution's stats when cached). A cache that cannot be written is
    no error (logged).
    """
    from iat.io.load import load_scene
    from iat.radiosity import SolveOptions, solve

    options = SolveOptions() if options is None else options
    model = Path(model)
    t0 = time.perf_counter()
    scene = load_scene(model, **options.load_kwargs())
    load_s = time.perf_counter() - t0
    path = solution_cache_path(model, options, directory)
    sol = load_cached(path, scene.n_patches)
    cached = sol is not None
    if sol is None:
        t0 = time.perf_counter()
        sol = solve(scene, options, progress=progress)
        solve_s = time.perf_counter() - t0
        sol.model_path = str(model.resolve())
        sol.stats = {**sol.stats, "wall_s": solve_s}
        try:
            sol.save(path)
        except OSError as e:
            log.info("cannot cache the solution at %s: %s", path, e)
    solve_s = float(sol.stats.get("wall_s", sol.stats.get("time_s", float("nan"))))
    return scene, sol, {"load_s": load_s, "solve_s": solve_s, "cached": cached, "cache_file": str(path)}
