"""Batch solves, bakes and renders as Dask tasks (``iat batch JOBS.toml``).

Independent solves run as tasks on a :class:`distributed.LocalCluster` (processes, one thread each,
their kernels and rays too: :data:`WORKER_ENV`; glibc's malloc as in a plain process and no
profiler: :data:`WORKER_MALLOC_ENV`, :data:`WORKER_CONFIG`; as many workers as cores) or on an
existing cluster (``scheduler="tcp://host:8786"``). The client hands each worker its next task as it
frees up, the longest expected first. Results come back to the client, which writes them atomically
(:func:`iat.fsutil.atomic_write`, :meth:`Solution.save`) into one output folder: the workers need
the model files (they load them), never the output folder.

The job file's format is :mod:`iat.tools.jobfile`'s. A plain job is one task writing ``<name>.npz``
(and ``.glb``, ``.png``). A ``states`` job is the task graph of
:func:`iat.lighting.solution_set.solve_set`: for ``merge`` each state's own adaptive solve
(``<name>.own-<state>.npz``, in parallel), then their merged mesh (``<name>.mesh.npz``), then every
state on that mesh (``<name>-<state>.npz``, in parallel, each with its bake and render); for
``union`` one solve of all the sources at once is the mesh; for ``first`` the first state's solve
is.

Every task records its inputs in ``<output>/.batch/<task>.json`` once its outputs are written: the
key hashes the model's bytes and the solve options (:func:`iat.radiosity.cache.solution_key`, with
the solver's source), the task's own settings (state, bake, render) and its inputs' keys; a rerun
skips a task whose record matches and whose outputs exist. ``<output>/batch.log`` gets one line per
task (name, status, seconds, error). A failing task is reported with its one-line error; the others
go on (tasks that depend on it report that it failed).

Each model is loaded once, by a task on a worker; the Scene stays in the cluster's memory and Dask
sends it to every other worker that needs it, once (a pickled house Scene is 0.15 MB and 2 ms
against 0.85 s to load it again: ``benchmarks/batch_bench.py``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from iat.errors import IATError, OptionError
from iat.tools.jobfile import NAME, Batch, Job, parse_jobs

#: per-task records of a batch's output folder
RECORD_DIR = ".batch"
#: the batch's log, one line per task, in the output folder
LOG_NAME = "batch.log"
#: the environment of a LocalCluster's workers: one thread each (the cluster's threads_per_worker) for
#: the numba kernels and the ray queries too, so two workers do not fight over two cores with four
#: threads (the house's day cycle on 2 workers: batch 68-73 s -> 58.5-58.9 s)
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "IAT_RAY_THREADS": "1"}
#: glibc's malloc settings for a LocalCluster's worker processes: those of a plain process. Dask's
#: ``MALLOC_TRIM_THRESHOLD_=65536`` turns off glibc's growing mmap threshold, so every array over
#: 128 KiB is mapped and faulted in afresh (a house solve: 1.0 M page faults, 6.2 s of CPU against 4.4 s)
WORKER_MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(32 << 20), "MALLOC_TRIM_THRESHOLD_": str(64 << 20)}
#: Dask settings of a LocalCluster's workers: no sampling profiler (it takes the GIL 100 times a
#: second: 4 % of a solve's CPU)
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}

__all__ = [
    "Batch",
    "BatchReport",
    "Job",
    "Task",
    "TaskResult",
    "one_line",
    "parse_jobs",
    "plan",
    "presolve",
    "run_batch",
    "start_client",
]


# -- the task graph --------------------------------------------------------------
@dataclass
class Task:
    """One reported unit of work: its outputs, its inputs' tasks and the key of its inputs.

    kind : "solve" (a plain job), "own" (a state's own adaptive solve), "mesh" (the shared mesh of
      a states job), "state" (a state on that mesh, or the first state for ``first``)
    """

    name: str
    kind: str
    job: Job
    state: str | None = None
    deps: list[str] = field(default_factory=list)
    key: str = ""

    def outputs(self, folder: Path) -> list[Path]:
        out = [folder / f"{self.name}.npz"]
        if self.kind in ("solve", "state"):
            if self.job.bake is not None:
                out.append(folder / f"{self.name}.glb")
            if self.job.render is not None:
                out.append(folder / f"{self.name}.png")
        return out


def _job_states(job: Job) -> dict[str, dict]:
    """{name: state dict} of a states job (read from the model for ``true`` or a list)."""
    from iat.lighting.states import check_states, lighting_states

    if isinstance(job.states, dict):
        return _named(check_states(job.states, job.model), job)
    have = lighting_states(job.model)
    if not have:
        raise OptionError("has no lighting states (extras iat_lighting_states)", job.model)
    if job.states is True:
        return _named(have, job)
    missing = [s for s in job.states if s not in have]
    if missing:
        raise OptionError(f"no lighting state(s) {', '.join(map(str, missing))} (has {', '.join(have)})")
    return _named({s: have[s] for s in job.states}, job)


def _named(states: dict[str, dict], job: Job) -> dict[str, dict]:
    bad = [s for s in states if not NAME.fullmatch(s)]
    if bad:
        raise OptionError(f"job {job.name!r}: state name(s) {bad} cannot name files")
    return states


def plan(batch: Batch) -> tuple[list[Task], dict[str, BaseException]]:
    """``(tasks in dependency order, {job name: error})``: the tasks of every job, each with the key
    of its inputs; a job whose model cannot be read or whose states are wrong gets no tasks and its
    error instead."""
    from iat.radiosity.cache import solution_key

    tasks: list[Task] = []
    errors: dict[str, BaseException] = {}
    model_keys: dict[tuple, str] = {}
    for job in batch.jobs:
        try:
            mk = (str(job.model), json.dumps(dataclasses.asdict(job.options), sort_keys=True, default=str))
            if mk not in model_keys:
                if not job.model.is_file():
                    from iat.errors import LoadError

                    raise LoadError("file not found" if not job.model.exists() else "not a file", job.model)
                model_keys[mk] = solution_key(job.model, job.options)
            base = model_keys[mk]
            states = None if job.states is None else _job_states(job)
            new = [Task(job.name, "solve", job)] if states is None else _state_tasks(job, states)
        except (IATError, OSError) as e:
            errors[job.name] = e
            continue
        keys = {t.name: t.key for t in tasks}
        for t in new:
            spec = {
                "kind": t.kind,
                "model": base,
                "state": states[t.state] if t.state else None,
                "states_mesh": job.states_mesh if job.states is not None else None,
                "bake": job.bake if t.kind in ("solve", "state") else None,
                "render": job.render if t.kind in ("solve", "state") else None,
                "deps": [keys[d] for d in t.deps],
            }
            t.key = hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:16]
            keys[t.name] = t.key
        tasks.extend(new)
    return tasks, errors


def _state_tasks(job: Job, states: dict[str, dict]) -> list[Task]:
    n = job.name
    names = list(states)
    if job.states_mesh == "first":
        first = Task(f"{n}-{names[0]}", "state", job, names[0])
        return [first] + [Task(f"{n}-{s}", "state", job, s, [first.name]) for s in names[1:]]
    if job.states_mesh == "merge":
        own = [Task(f"{n}.own-{s}", "own", job, s) for s in names]
        mesh = Task(f"{n}.mesh", "mesh", job, None, [t.name for t in own])
    else:
        own, mesh = [], Task(f"{n}.mesh", "mesh", job)
    return [*own, mesh] + [Task(f"{n}-{s}", "state", job, s, [mesh.name]) for s in names]


# -- work done on the workers ----------------------------------------------------
def load_model(model: str, load_kwargs: dict):
    """``(Scene of model, [one-line warnings])`` (a task: its result stays on the cluster for the
    tasks that need it; the warnings reach the client through the first of them)."""
    from iat.io.load import load_scene

    with _warnings_caught() as caught:
        scene = load_scene(model, **load_kwargs)
    return scene, caught


@contextlib.contextmanager
def _warnings_caught():
    """Collect the warnings raised inside as one-line strings (a worker's warnings are not seen by
    the client otherwise); a repeated message is kept once."""
    out: list[str] = []
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        yield out
    for w in rec:
        text = " ".join(str(w.message).split())
        if text not in out:
            out.append(text)


def _solution(x):
    return x["solution"] if isinstance(x, dict) else x


def _state_scene(scene, states: dict, state: str | None):
    from iat.lighting.states import apply_lighting_state, union_lighting

    if state is not None:
        return apply_lighting_state(scene, states[state])
    return union_lighting([apply_lighting_state(scene, st) for st in states.values()])


def run_task(kind: str, loaded, options, states, state, bake, render, *deps) -> dict:
    """One task's work (on a worker): ``{"solution", "glb" (bytes or None), "image" (linear (h, w, 3)
    or None), "seconds", "warnings"}``. ``loaded`` is :func:`load_model`'s result (None for a merge);
    ``deps`` are the results (or Solutions) of its inputs' tasks. ``warnings``: the one-line warnings
    of its model's loading and of its own work."""
    scene, load_warnings = loaded if loaded is not None else (None, [])
    with _warnings_caught() as caught:
        out = _run_task(kind, scene, options, states, state, bake, render, *deps)
    out["warnings"] = [*load_warnings, *(w for w in caught if w not in load_warnings)]
    return out


def _run_task(kind: str, scene, options, states, state, bake, render, *deps) -> dict:
    from iat.radiosity import solve

    t0 = time.perf_counter()
    if kind == "mesh" and deps:  # merge: the union of the states' own trees
        from iat.lighting.solution_set import merge_meshes

        sol = merge_meshes([_solution(d) for d in deps])
    elif kind == "solve":
        sol = solve(scene, options)
    else:
        sc = _state_scene(scene, states, state)
        mesh = _solution(deps[0]) if (kind == "state" and deps) else None
        sol = solve(sc, options, mesh=mesh)
        if kind == "state":
            from iat.lighting.states import state_times

            t = dict(zip(states, state_times(states), strict=True))[state]
            sol.stats = {**sol.stats, "lighting_state": state, "lighting_time": float(t)}
            scene = sc
    sol.model_path = str(scene.path) if getattr(scene, "path", None) else sol.model_path
    out = {"solution": sol, "glb": None, "image": None}
    if kind in ("solve", "state") and (bake is not None or render is not None):
        out.update(_bake_and_render(sol, scene, bake, render))
    out["seconds"] = time.perf_counter() - t0
    return out


def _bake_and_render(sol, scene, bake, render) -> dict:
    from iat.bake.baker import Baker
    from iat.bake.policy import BakePolicy

    out = {}
    policy = BakePolicy(**bake) if bake is not None else BakePolicy()
    baked = None
    if bake is not None:
        from iat.export.gltf import export_glb

        baked = Baker(sol, scene).bake(policy)
        with tempfile.TemporaryDirectory() as d:
            glb = export_glb(baked, Path(d) / "out.glb", scene=scene)
            out["glb"] = glb.read_bytes()
    if render is not None:
        from iat.render.renderer import Renderer

        cams = scene.cameras
        k = render.get("camera")
        if k is not None and not (0 <= k < len(cams)):
            raise OptionError(f"render camera {k}: the file has {len(cams)} camera(s)")
        cam = cams[k if k is not None else 0] if cams else scene.default_camera()
        r = Renderer()
        try:
            r.set_scene(scene)
            r.set_sky(scene.sky)
            if render["mode"] != "preview":
                r.set_solution(sol)
            if render["mode"] == "iat":
                r.set_baked(baked if baked is not None else Baker(sol, scene).bake(policy))
            out["image"] = r.render(cam, size=tuple(render["size"]), mode=render["mode"])
        finally:
            r.release()
    return out


# -- running ---------------------------------------------------------------------
@dataclass
class TaskResult:
    """What became of one task: status "ok", "skipped" (done before) or "failed" (``error``)."""

    name: str
    status: str
    seconds: float = 0.0
    error: str = ""
    outputs: list[str] = field(default_factory=list)
    user_error: bool = False  # the failure is an IATError (a bad file or option), not a bug
    warnings: list[str] = field(default_factory=list)  # raised on the worker, one line each


def _failed(name: str, e: BaseException) -> TaskResult:
    return TaskResult(name, "failed", error=one_line(e), user_error=isinstance(e, IATError))


@dataclass
class BatchReport:
    """The tasks' results in the order of the plan, the wall time and the workers used."""

    results: list[TaskResult]
    wall_s: float
    workers: int
    output: str

    @property
    def failed(self) -> list[TaskResult]:
        return [r for r in self.results if r.status == "failed"]

    def to_dict(self) -> dict:
        return {
            "output": self.output,
            "workers": self.workers,
            "wall_s": self.wall_s,
            "ok": sum(r.status == "ok" for r in self.results),
            "skipped": sum(r.status == "skipped" for r in self.results),
            "failed": len(self.failed),
            "tasks": [dataclasses.asdict(r) for r in self.results],
        }


def one_line(e: BaseException) -> str:
    """An exception as one line: an IATError's own message, anything else with its type."""
    text = " ".join(str(e).split())
    return text if isinstance(e, IATError) else f"{type(e).__name__}: {text}"


def start_client(workers: int | None = None, scheduler: str | None = None):
    """``(client, cluster)``: a Client of the cluster at ``scheduler``, or of a new LocalCluster of
    ``workers`` processes with one thread each (default: as many as cores; ``cluster`` None when
    connecting to an existing one). Raises OptionError when the cluster cannot be reached."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as e:
            raise OptionError(f"cannot reach the Dask scheduler at {scheduler}: {one_line(e)}") from None
    if workers is not None and int(workers) < 1:
        raise OptionError(f"--workers must be >= 1, got {workers}")
    n = int(workers or os.cpu_count() or 1)
    # inherited by the worker processes; set here as Dask sets its own (which a cluster started before
    # in this process left in its environment, and which would win over its configuration)
    os.environ.update(WORKER_MALLOC_ENV)
    try:
        with dask.config.set(WORKER_CONFIG):
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
                env=WORKER_ENV,
            )
    except (OSError, RuntimeError) as e:
        raise OptionError(f"cannot start a local Dask cluster of {n} workers: {one_line(e)}") from None
    return Client(cluster), cluster


def _record_path(folder: Path, name: str) -> Path:
    return folder / RECORD_DIR / f"{name}.json"


def _is_done(folder: Path, task: Task) -> bool:
    p = _record_path(folder, task.name)
    try:
        rec = json.loads(p.read_text())
    except (OSError, ValueError):
        return False
    return rec.get("key") == task.key and all(o.is_file() for o in task.outputs(folder))


def _write_outputs(folder: Path, task: Task, res: dict) -> list[str]:
    """Write a task's result atomically, then its record (so a killed write is redone)."""
    from iat.fsutil import atomic_write

    outs = task.outputs(folder)
    res["solution"].save(outs[0])
    for p in outs[1:]:
        if p.suffix == ".glb":
            atomic_write(p, lambda f, b=res["glb"]: f.write(b))
        else:
            from iat.color import auto_exposure
            from iat.io.images import save_png

            img, e = res["image"], task.job.render.get("exposure")
            save_png(p, img, exposure=e if e else auto_exposure(img))
    rec = {"key": task.key, "task": task.name, "seconds": res["seconds"], "outputs": [o.name for o in outs]}
    atomic_write(_record_path(folder, task.name), lambda f: f.write(json.dumps(rec, indent=1).encode()))
    return [str(o) for o in outs]


class _Eta:
    """Remaining time from completed tasks' durations (per kind, else all), over the workers."""

    def __init__(self, tasks: list[Task], workers: int):
        self.kind = {t.name: t.kind for t in tasks}
        self.pending = set(self.kind)
        self.seconds: dict[str, list[float]] = {}
        self.workers = max(1, workers)

    def done(self, name: str, seconds: float | None) -> None:
        self.pending.discard(name)
        if seconds is not None:
            self.seconds.setdefault(self.kind[name], []).append(seconds)

    def remaining_s(self) -> float | None:
        every = [s for v in self.seconds.values() for s in v]
        if not every:
            return None
        mean = sum(every) / len(every)
        total = 0.0
        for name in self.pending:
            got = self.seconds.get(self.kind[name])
            total += sum(got) / len(got) if got else mean
        return total / min(self.workers, max(1, len(self.pending)))


def _fmt_s(s: float | None) -> str:
    if s is None:
        return "?"
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def run_batch(
    batch: Batch,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    progress: Callable[[float, str], object] | None = None,
    on_result: Callable[[TaskResult], None] | None = None,
) -> BatchReport:
    """Run every task of ``batch`` (see the module docstring) and return what became of each.

    client : a ``distributed.Client`` to use (then ``workers`` and ``scheduler`` are not used and it
      is left open); else one of :func:`start_client`, closed at the end.
    progress : ``progress(fraction of tasks finished, "done/total eta M:SS name")``.
    on_result : called with each task's :class:`TaskResult` as it finishes (in completion order).
    A failing task never raises: its result has status "failed" and a one-line ``error``.
    """
    t_start = time.perf_counter()
    folder = Path(batch.output)
    folder.mkdir(parents=True, exist_ok=True)
    tasks, job_errors = plan(batch)
    results: dict[str, TaskResult] = {}
    order = [t.name for t in tasks]
    for name, err in job_errors.items():
        results[name] = _failed(name, err)
        order.append(name)
    log_file = folder / LOG_NAME
    n_total = len(order)

    def report(r: TaskResult) -> None:
        results[r.name] = r
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
        line = f"{stamp}\t{r.name}\t{r.status}\t{r.seconds:.2f}\t{r.error}\n"
        line += "".join(f"{stamp}\t{r.name}\twarning\t\t{w}\n" for w in r.warnings)
        with open(log_file, "a", encoding="utf-8") as f:
            f.write(line)
        if on_result is not None:
            on_result(r)

    for name in job_errors:
        report(results[name])
    todo = []
    for t in tasks:
        if _is_done(folder, t):
            report(TaskResult(t.name, "skipped", outputs=[str(o) for o in t.outputs(folder)]))
        else:
            todo.append(t)
    own_client = client is None
    cluster = None
    if todo and own_client:
        client, cluster = start_client(workers, scheduler)
    try:
        n_workers = len(client.nthreads()) if todo else 0
        if todo:
            _run_on(client, folder, tasks, todo, report, progress, n_workers, n_total, len(results))
    finally:
        if own_client and client is not None:
            client.close()
            if cluster is not None:
                cluster.close()
    return BatchReport([results[n] for n in order], time.perf_counter() - t_start, n_workers, str(folder))


def _run_on(client, folder, tasks, todo, report, progress, n_workers, n_total, n_done) -> None:
    """Run ``todo`` (in dependency order) on ``client``'s workers; write and report each task as it
    finishes.

    The client places the tasks itself: a task is submitted once its inputs are done, to the least
    busy worker, never more at a time than the workers have threads, the longest expected first
    (:func:`expected_order`). Left to Dask, a task goes where its inputs are (the Scene on the worker that
    loaded it) and the other workers wait for work stealing: seconds idle per phase of the house's
    day cycle."""
    import itertools
    import uuid
    from collections import Counter

    from distributed import as_completed

    by_name = {t.name: t for t in tasks}
    run = uuid.uuid4().hex[:8]
    waiting = list(todo)
    users = {t.name: {u.name for u in todo if t.name in u.deps} for t in todo}  # who needs a result
    futures: dict[str, object] = {}  # running, or finished and still needed
    where: dict[str, str] = {}  # running task -> its worker
    computed: set[str] = set()
    failures: dict[str, TaskResult] = {}
    took: dict[tuple, float] = {}  # (job, state) -> seconds of its finished task
    scenes: dict[tuple, object] = {}
    loads = itertools.count()
    scene_need = Counter(_scene_key(t) for t in todo)
    jobs = {t.job.name: t.job for t in todo}
    states_of = {name: _job_states(job) for name, job in jobs.items() if job.states is not None}
    warned: set[str] = set()  # each warning reported once (a model's load warnings come with each task)
    pending = as_completed()
    names: dict[str, str] = {}
    eta = _Eta(todo, n_workers)
    done = n_done

    def finish(r: TaskResult, task: Task) -> None:
        nonlocal done
        if r.status == "failed":
            failures[r.name] = r
        eta.done(r.name, r.seconds if r.status == "ok" else None)
        for n in (r.name, *task.deps):  # results no unfinished task needs are freed on the cluster
            users.get(n, set()).discard(r.name)
            if n in futures and not users.get(n):
                futures.pop(n)
        done += 1
        report(r)
        if progress is not None:
            progress(done / n_total, f"{done}/{n_total} eta {_fmt_s(eta.remaining_s())} {r.name}")

    def submit(t: Task, worker: str) -> None:
        job, sk = t.job, _scene_key(t)
        scene = None
        if sk is not None:
            if sk not in scenes:
                key = f"load-{job.model.stem}-{next(loads)}-{run}"
                lk = job.options.load_kwargs()
                scenes[sk] = client.submit(load_model, str(job.model), lk, key=key, pure=False)
            scene = scenes[sk]
            scene_need[sk] -= 1
            if not scene_need[sk]:  # its tasks hold it now: the Scene is freed after the last
                del scenes[sk]
        deps = []
        for d in t.deps:
            if d in futures:
                deps.append(futures[d])
            else:  # done in an earlier run: read here, sent once
                from iat.radiosity.solution import Solution

                deps.append(client.scatter(Solution.load(folder / f"{d}.npz")))
        args = (t.kind, scene, job.options, states_of.get(job.name), t.state, job.bake, job.render)
        key = f"{t.name}-{t.key}-{run}"
        fut = client.submit(
            run_task, *args, *deps, key=key, pure=False, workers=[worker], allow_other_workers=True
        )
        futures[t.name], where[t.name], names[fut.key] = fut, worker, t.name
        pending.add(fut)

    def dispatch() -> None:
        """Report the tasks whose inputs failed (not computed); submit the ready ones to free threads."""
        for t in list(waiting):
            bad = next((d for d in t.deps if d in failures and d not in computed), None)
            if bad:
                waiting.remove(t)
                r = TaskResult(t.name, "failed", error=f"not run: {bad} failed")
                r.user_error = failures[bad].user_error
                finish(r, t)
        ready = [t for t in waiting if all(d in computed or d not in users for d in t.deps)]
        if not ready:
            return
        threads = client.nthreads()
        if not threads and not where:
            client.wait_for_workers(1)
            threads = client.nthreads()
        busy = Counter(where.values())
        for t in sorted(ready, key=lambda t: expected_order(t, took, states_of)):
            free = [w for w in threads if busy[w] < threads[w]]
            if not free:
                break
            w = min(free, key=lambda w: busy[w] / threads[w])
            busy[w] += 1
            waiting.remove(t)
            submit(t, w)

    dispatch()
    for fut in pending:
        name = names.pop(fut.key)
        task = by_name[name]
        del where[name]
        res, err = None, None
        if fut.status == "error":
            err = fut.exception()
        else:
            try:
                res = fut.result()
            except Exception as e:
                err = e
        del fut
        if res is None:
            finish(_failed(name, err), task)
            dispatch()
            continue
        computed.add(name)
        took[(task.job.name, task.state)] = res["seconds"]
        dispatch()  # before writing: the workers need not wait for it
        try:
            r = TaskResult(name, "ok", res["seconds"], outputs=_write_outputs(folder, task, res))
            r.warnings = [w for w in res.get("warnings", []) if w not in warned]
            warned.update(r.warnings)
        except Exception as e:  # a result that cannot be written is that task's failure
            r = _failed(name, e)
        del res
        finish(r, task)


def expected_order(t: Task, took: dict, states_of: dict) -> tuple:
    """Sort key of a ready task, the longest expected first: the time its state's task took already
    (its own solve, for a state on the shared mesh), else how many lights and emitters its state
    sets on (each is shot: on the house's day cycle the two noon states, two windows, are the
    shortest own solves). Equal keys keep the plan's order."""
    state = states_of[t.job.name][t.state] if t.state is not None else {}
    on = 0
    for part in ("lights", "emission"):
        for v in state.get(part, {}).values():
            v = v.get("intensity", 1.0) if isinstance(v, dict) else v
            on += any(float(x) != 0.0 for x in (v if isinstance(v, list) else [v]))
    return -took.get((t.job.name, t.state), 0.0), -on


def _scene_key(t: Task) -> tuple | None:
    """``(model, load options as JSON)`` of the Scene a task needs (None for a merge of its inputs)."""
    if t.kind == "mesh" and t.deps:
        return None
    return str(t.job.model), json.dumps(t.job.options.load_kwargs(), sort_keys=True)


def presolve(pairs, directory, *, workers=None, scheduler=None, client=None, progress=None):
    """Solve the ``(model path, SolveOptions)`` pairs that the solution cache ``directory`` lacks, as
    parallel tasks, each written where :func:`iat.radiosity.cache.cached_solve` then finds it
    (``<model stem>-<key>.npz``; the batch's records and log go into that folder too). Used by
    ``iat chart --workers``. Returns the :class:`BatchReport`, or None when every pair is cached;
    OptionError for a model whose file name cannot name a task."""
    from iat.radiosity.cache import solution_cache_path

    jobs, seen = [], set()
    for model, options in pairs:
        path = solution_cache_path(model, options, directory)
        if path.is_file() or path.stem in seen:
            continue
        if not NAME.fullmatch(path.stem):
            raise OptionError(
                f"{model}: this file name cannot name a batch task (letters, digits, '-', '_', '.')"
            )
        seen.add(path.stem)
        jobs.append(Job(path.stem, Path(model).resolve(), options))
    if not jobs:
        return None
    batch = Batch(Path(directory), jobs)
    return run_batch(batch, workers=workers, scheduler=scheduler, client=client, progress=progress)


def print_errors(report: BatchReport, prog: str = "iat batch", file=None) -> None:
    """``iat batch: warning: <task>: <message>`` for every worker warning, then ``iat batch: error:
    <task>: <cause>`` for every failed task, on stderr."""
    for r in report.results:
        for w in r.warnings:
            print(f"{prog}: warning: {r.name}: {w}", file=file or sys.stderr)
    for r in report.failed:
        print(f"{prog}: error: {r.name}: {r.error}", file=file or sys.stderr)
