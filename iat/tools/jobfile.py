"""The job file of ``iat batch`` (:mod:`iat.tools.batch`): parsed and checked into a :class:`Batch`.

Job file (TOML; relative paths are relative to the job file)::

    output = "out/batch"          # folder for the results (required)
    [defaults]                    # SolveOptions fields for every job (optional)
    max_depth = 5
    [[job]]
    name = "cornell"              # unique; letters, digits, "-", "_", "."; names the outputs
    model = "sample_models/cornell_box.glb"
    options = { seed = 1 }        # optional: SolveOptions fields over [defaults]
    bake = { threshold = 2 }      # optional: also bake (BakePolicy fields), written as <name>.glb
    render = { size = "320x240", mode = "iat", camera = 0, exposure = 1.0 }
                                  # optional: a PNG <name>.png (mode mesh | iat | preview; camera: the
                                  # file's K-th camera, default its first or the default camera)
    [[job]]
    name = "house-day"
    model = "sample_models/house.glb"
    states = true                 # the model's lighting states (or a list of their names, or a table
                                  # {name = {state...}} of states of its own, iat.lighting.states)
    states_mesh = "merge"         # "merge" (default, as solve_set), "union" or "first"
"""

from __future__ import annotations

import dataclasses
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from iat.errors import OptionError

#: what may name a job, a state or a task (it names their files)
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_JOB_KEYS = {"name", "model", "options", "bake", "render", "states", "states_mesh"}
_RENDER_KEYS = {"size", "mode", "camera", "exposure"}

__all__ = ["NAME", "Batch", "Job", "parse_jobs"]


@dataclass
class Job:
    """One ``[[job]]`` of a job file, checked."""

    name: str
    model: Path
    options: object  # SolveOptions
    bake: dict | None = None
    render: dict | None = None
    states: object = None  # None, True, [names] or {name: state}
    states_mesh: str = "merge"


@dataclass
class Batch:
    """A parsed job file: the output folder and its jobs."""

    output: Path
    jobs: list[Job]
    source: Path | None = None
    #: a :class:`iat.lighting.daylight_default.DaylightRequest` for every model (``iat batch``'s
    #: ``--sun``, ``--sky``, ``--no-daylight``); None: none (the models' own light only)
    daylight: object = None


def _bad(where, why):
    from iat.errors import LoadError

    raise LoadError(why, where)


def _checked(cls, table: dict, where, what: str):
    """``cls(**table).validate()`` after naming any key that is not one of its fields."""
    unknown = set(table) - {f.name for f in dataclasses.fields(cls)}
    if unknown:
        _bad(where, f"unknown {what} option(s) {', '.join(sorted(unknown))}")
    return cls(**table).validate()


def _solve_options(table: dict, where):
    from iat.radiosity import SolveOptions

    return _checked(SolveOptions, table, where, "solve")


def _bake_policy(table: dict, where):
    from iat.bake.policy import BakePolicy

    return _checked(BakePolicy, table, where, "bake")


def parse_jobs(path, data: dict | None = None) -> Batch:
    """The :class:`Batch` of a job file (see the module docstring), every field checked.

    data : the parsed TOML itself (then ``path`` only names it and anchors relative paths).
    Raises :class:`~iat.errors.LoadError` naming the file and the cause.
    """
    path = Path(path)
    if data is None:
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            _bad(path, "file not found")
        except (OSError, UnicodeDecodeError) as e:
            _bad(path, f"cannot read: {e}")
        except tomllib.TOMLDecodeError as e:
            _bad(path, f"not a valid TOML job file: {e}")
    base = Path(os.path.abspath(path)).parent  # absolute: the workers may run elsewhere
    unknown = set(data) - {"output", "defaults", "job"}
    if unknown:
        _bad(path, f"unknown key(s) {', '.join(sorted(unknown))} (output, defaults, [[job]])")
    if not isinstance(data.get("output"), str) or not data["output"]:
        _bad(path, 'needs output = "FOLDER"')
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        _bad(path, "[defaults] must be a table of solve options")
    jobs_in = data.get("job", [])
    if not isinstance(jobs_in, list) or not jobs_in:
        _bad(path, "needs at least one [[job]]")
    jobs, seen = [], set()
    for k, j in enumerate(jobs_in):
        where = f"{path} job {k + 1}"
        if not isinstance(j, dict):
            _bad(where, "must be a table")
        name = j.get("name")
        where = f"{path} job {name!r}" if isinstance(name, str) else where
        if set(j) - _JOB_KEYS:
            _bad(where, f"unknown key(s) {', '.join(sorted(set(j) - _JOB_KEYS))}")
        if not isinstance(name, str) or not NAME.fullmatch(name):
            _bad(where, "needs a name of letters, digits, '-', '_' and '.'")
        if name in seen:
            _bad(where, "the name is used twice")
        seen.add(name)
        if not isinstance(j.get("model"), str):
            _bad(where, 'needs model = "PATH"')
        try:
            options = _solve_options({**defaults, **j.get("options", {})}, where)
            bake = j.get("bake")
            if bake is not None:
                bake = dataclasses.asdict(_bake_policy(bake, where))
            render = j.get("render")
            if render is not None:
                render = _render_spec(render, where)
        except (TypeError, ValueError) as e:
            _bad(where, str(e))
        except OptionError as e:
            _bad(where, str(e))
        states = j.get("states")
        if states is False:
            states = None
        if not (states is None or states is True or isinstance(states, list | dict)):
            _bad(where, "states must be true, a list of state names or a table of states")
        mesh = j.get("states_mesh", "merge")
        if mesh not in ("merge", "union", "first"):
            _bad(where, f'states_mesh must be "merge", "union" or "first", got {mesh!r}')
        jobs.append(Job(name, base / j["model"], options, bake, render, states, mesh))
    return Batch(base / data["output"], jobs, path)


def _render_spec(r: dict, where) -> dict:
    if not isinstance(r, dict) or set(r) - _RENDER_KEYS:
        _bad(where, f"render takes {', '.join(sorted(_RENDER_KEYS))}")
    size = re.fullmatch(r"(\d+)x(\d+)", str(r.get("size", "320x240")).lower())
    if not size or not all(1 <= int(x) <= 16384 for x in size.groups()):
        _bad(where, f"render size must be WxH, got {r.get('size')!r}")
    out = {"size": [int(x) for x in size.groups()], "mode": r.get("mode", "iat")}
    if out["mode"] not in ("mesh", "iat", "preview"):
        _bad(where, f'render mode must be "mesh", "iat" or "preview", got {out["mode"]!r}')
    out["camera"] = None if r.get("camera") is None else int(r["camera"])
    out["exposure"] = None if r.get("exposure") is None else float(r["exposure"])
    return out
