"""Shared helpers of the stability catalogue (docs/stability.md; tests/test_stability_*.py, one file
per section of the doc): one test per failure mode.

Each test builds the input that provokes the failure mode (tests/stability_scenes.py),
runs what IAT does with it, measures a figure and holds the guarantee the catalogue
states. Figures are recorded with :func:`record` and written to a JSON file
(``$IAT_STABILITY_JSON``, default ``<pytest basetemp>/stability.json``) by the
``stability_figures`` fixture (tests/conftest.py) after each module, and printed,
so the table in docs/stability.md can be refreshed from a run:

    xvfb-run -a -s "-screen 0 1280x800x24" .venv/bin/python -m pytest -q tests/test_stability_*.py
    IAT_STABILITY_JSON=out/stability.json ...   # to keep the figures

Tests marked ``xfail(strict=True)`` show a defect found while writing the catalogue: they
run (nothing is skipped) and fail as expected today; when the defect is fixed they pass,
strict mode turns that into a failure, and the marker (and the doc's row) must be updated.
None is marked today: the defects found (D1-D10) are fixed and their tests hold the fixes.
Timings are bounds with a wide margin, never comparisons between runs.

Also here: :func:`atomic_writers` and :class:`DiskFull`, which the interrupted-write tests
use in the test process and in the child process they kill.
"""

from __future__ import annotations

import dataclasses
import errno
import json
from pathlib import Path

import numpy as np

from iat.bake.baker import Baker
from iat.bake.policy import BakePolicy
from iat.geometry import quadtree as qt
from iat.radiosity import Solution, SolveOptions

ROOT = Path(__file__).resolve().parents[2]

_SOLVE_FIELDS = {f.name for f in dataclasses.fields(SolveOptions)}


def opts(**kw) -> SolveOptions:
    """SolveOptions pinned for the catalogue, so that its figures measure the geometry, not a default:
    no minimum element size (max_depth is the only limit on refinement) and no ambient term (a
    uniform estimate of the light left unshot, which would light the far side of every wall).
    Fields the solver does not have are left out, so the catalogue follows the solver's API."""
    base = {"min_element_size": 0.0, "ambient": False}
    base.update(kw)
    return SolveOptions(**{k: v for k, v in base.items() if k in _SOLVE_FIELDS})


# -- recording the figures -------------------------------------------------------------------------
_FIGURES: dict[str, dict] = {}


def record(name: str, **values) -> None:
    """Keep the measured figures of one catalogue row (written to JSON by :func:`write_figures`)."""
    clean = {}
    for k, v in values.items():
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            v = str(v)
        clean[k] = v
    _FIGURES.setdefault(name, {}).update(clean)
    print(f"[stability] {name}: " + ", ".join(f"{k}={v}" for k, v in clean.items()))


def write_figures(out: Path) -> None:
    """Write every figure recorded so far in this session to ``out`` (JSON)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(_FIGURES, indent=1, sort_keys=True))
    print(f"\n[stability] figures written to {out}")


def vertex_patch(sol: Solution) -> np.ndarray:
    """(n_vertices,) patch index of each vertex of ``sol``."""
    return qt.decode_key(sol.vert_key, sol.n)[0]


# -- interrupted writes ----------------------------------------------------------------------------
class DiskFull:
    """A file object that takes ``limit`` bytes, then fails like a full disk."""

    def __init__(self, f, limit):
        self._f, self._left = f, limit

    def write(self, data):
        data = memoryview(data).cast("B") if not isinstance(data, bytes | bytearray) else data
        if len(data) > self._left:
            self._f.write(bytes(data[: self._left]))
            self._left = 0
            raise OSError(errno.ENOSPC, "No space left on device (simulated)")
        self._left -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


def atomic_writers(tmp_path, small_solution_file):
    """name -> (target path, write function) for the three files IAT writes."""
    from iat.export.gltf import export_glb
    from iat.io.images import save_png

    sol = Solution.load(small_solution_file)
    baked = Baker(sol).bake(BakePolicy(threshold=0))
    img = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)
    return {
        "solution": (tmp_path / "out.npz", lambda p: sol.save(p)),
        "glb": (tmp_path / "out.glb", lambda p: export_glb(baked, p)),
        "png": (tmp_path / "out.png", lambda p: save_png(p, img)),
    }
