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
import itertools
import json
import logging
import os
import sys
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from iat.errors import IATError, OptionError
from iat.tools.batch_work import load_model, run_task
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
            if batch.daylight is not None:  # (absent otherwise: the keys of earlier runs stay)
                spec["daylight"] = batch.daylight.to_dict()
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
    log = _Log(folder / LOG_NAME, on_result)
    for name, err in job_errors.items():
        log.report(_failed(name, err))
    todo = []
    for t in tasks:
        if _is_done(folder, t):
            log.report(TaskResult(t.name, "skipped", outputs=[str(o) for o in t.outputs(folder)]))
        else:
            todo.append(t)
    order = [t.name for t in tasks] + list(job_errors)
    n_workers = 0
    if todo:
        with _client(client, workers, scheduler) as c:
            n_workers = len(c.nthreads())
            counter = _Progress(progress, _Eta(todo, n_workers), len(log.results), len(order))
            _Scheduler.start(c, folder, tasks, todo, log.report, counter, batch.daylight).run()
    return BatchReport([log.results[n] for n in order], time.perf_counter() - t_start, n_workers, str(folder))


@contextlib.contextmanager
def _client(client, workers: int | None, scheduler: str | None):
    """``client`` if given (left open), else one of :func:`start_client`, closed with its cluster."""
    if client is not None:
        yield client
        return
    client, cluster = start_client(workers, scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass
class _Log:
    """The tasks' results as they come: kept by name, one line each in the batch's log (and one per
    warning), handed to ``on_result``."""

    path: Path
    on_result: Callable[[TaskResult], None] | None = None
    results: dict[str, TaskResult] = field(default_factory=dict)

    def report(self, r: TaskResult) -> None:
        self.results[r.name] = r
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
        line = f"{stamp}\t{r.name}\t{r.status}\t{r.seconds:.2f}\t{r.error}\n"
        line += "".join(f"{stamp}\t{r.name}\twarning\t\t{w}\n" for w in r.warnings)
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
        if self.on_result is not None:
            self.on_result(r)


@dataclass
class _Progress:
    """``callback(fraction of tasks finished, "done/total eta M:SS name")`` as each task run finishes."""

    callback: Callable[[float, str], object] | None
    eta: _Eta
    done: int  # tasks finished, those that failed in the plan or were done before included
    total: int

    def step(self, r: TaskResult) -> None:
        self.eta.done(r.name, r.seconds if r.status == "ok" else None)
        self.done += 1
        if self.callback is not None:
            eta = _fmt_s(self.eta.remaining_s())
            self.callback(self.done / self.total, f"{self.done}/{self.total} eta {eta} {r.name}")


@dataclass
class _Scenes:
    """The Scenes of a run's tasks: each loaded once, by a task on a worker (:func:`load_model`), and
    let go here once the last task that needs it is submitted (its tasks hold it then: the cluster
    frees it after the last)."""

    client: object
    run_id: str  # the run's suffix of every key
    need: Counter  # scene key (:func:`_scene_key`) -> tasks not submitted yet that need it
    loading: dict[tuple, object] = field(default_factory=dict)  # scene key -> its load's future
    loads: Iterator[int] = field(default_factory=itertools.count)
    daylight: object = None  # the batch's :class:`~iat.lighting.daylight_default.DaylightRequest`

    def take(self, t: Task):
        """The future of the Scene ``t`` needs (None for a merge), its load submitted if none is."""
        sk = _scene_key(t)
        if sk is None:
            return None
        if sk not in self.loading:
            key = f"load-{t.job.model.stem}-{next(self.loads)}-{self.run_id}"
            lk = t.job.options.load_kwargs()
            self.loading[sk] = self.client.submit(
                load_model, str(t.job.model), lk, self.daylight, key=key, pure=False
            )
        scene = self.loading[sk]
        self.need[sk] -= 1
        if not self.need[sk]:
            del self.loading[sk]
        return scene


@dataclass
class _Scheduler:
    """Runs a batch's tasks on ``client``'s workers; writes and reports each task as it finishes.

    The client places the tasks itself: a task is submitted once its inputs are done, to the least
    busy worker, never more at a time than the workers have threads, the longest expected first
    (:func:`expected_order`). Left to Dask, a task goes where its inputs are (the Scene on the worker
    that loaded it) and the other workers wait for work stealing: seconds idle per phase of the
    house's day cycle. A result no unfinished task needs is let go (and freed on the cluster) as the
    last task needing it finishes."""

    client: object
    folder: Path
    tasks: dict[str, Task]  # the plan's tasks by name
    report: Callable[[TaskResult], None]
    progress: _Progress
    scenes: _Scenes
    states_of: dict[str, dict]  # states job -> {state: state dict}
    run_id: str  # the run's suffix of every key
    waiting: list[Task]  # not submitted yet, in the plan's order
    users: dict[str, set[str]]  # task to run -> the unfinished tasks that need its result
    pending: object  # ``distributed.as_completed`` of the submitted tasks
    futures: dict[str, object] = field(default_factory=dict)  # running, or finished and still needed
    running: dict[str, tuple[str, str]] = field(default_factory=dict)  # future key -> (task, worker)
    computed: set[str] = field(default_factory=set)  # came back from the cluster (written or not)
    failures: dict[str, TaskResult] = field(default_factory=dict)
    took: dict[tuple, float] = field(default_factory=dict)  # (job, state) -> seconds of its task
    warned: set[str] = field(default_factory=set)  # reported once (a model's come with each task)

    @classmethod
    def start(
        cls, client, folder: Path, tasks: list[Task], todo: list[Task], report, progress, daylight=None
    ) -> _Scheduler:
        """The scheduler of ``todo`` (in dependency order; the other ``tasks`` are done); the models
        load with ``daylight`` (a :class:`~iat.lighting.daylight_default.DaylightRequest` or None)."""
        from distributed import as_completed

        run_id = uuid.uuid4().hex[:8]
        jobs = {t.job.name: t.job for t in todo}
        return cls(
            client,
            folder,
            {t.name: t for t in tasks},
            report,
            progress,
            _Scenes(client, run_id, Counter(_scene_key(t) for t in todo), daylight=daylight),
            {name: _job_states(job) for name, job in jobs.items() if job.states is not None},
            run_id,
            list(todo),
            {t.name: {u.name for u in todo if t.name in u.deps} for t in todo},
            as_completed(),
        )

    def run(self) -> None:
        self._dispatch()
        while self._collect_next():
            pass

    def _collect_next(self) -> bool:
        """Wait for the next task to finish, submit the tasks it makes ready, then write and report
        it (the workers need not wait for the writing). False when none is running."""
        fut = next(self.pending, None)
        if fut is None:
            return False
        name, _ = self.running.pop(fut.key)
        task = self.tasks[name]
        res, err = _outcome(fut)
        del fut  # held by self.futures alone: let go when no unfinished task needs it
        if res is None:
            self._finish(_failed(name, err), task)
            self._dispatch()
            return True
        self.computed.add(name)
        self.took[(task.job.name, task.state)] = res["seconds"]
        self._dispatch()
        r = self._written(task, res)
        del res
        self._finish(r, task)
        return True

    def _written(self, task: Task, res: dict) -> TaskResult:
        """Write a task's result; one that cannot be written is that task's failure."""
        try:
            r = TaskResult(task.name, "ok", res["seconds"], outputs=_write_outputs(self.folder, task, res))
        except Exception as e:
            return _failed(task.name, e)
        r.warnings = [w for w in res.get("warnings", []) if w not in self.warned]
        self.warned.update(r.warnings)
        return r

    def _finish(self, r: TaskResult, task: Task) -> None:
        """Report a finished task; let go of the results no unfinished task needs now."""
        if r.status == "failed":
            self.failures[r.name] = r
        for n in (r.name, *task.deps):
            self.users.get(n, set()).discard(r.name)
            if n in self.futures and not self.users.get(n):
                self.futures.pop(n)
        self.report(r)
        self.progress.step(r)

    def _dispatch(self) -> None:
        """Report the tasks whose inputs failed (not computed); submit the ready ones to free threads."""
        self._drop_blocked()
        # an input not in users was done in an earlier run
        ready = [t for t in self.waiting if all(d in self.computed or d not in self.users for d in t.deps)]
        if ready:
            self._place(ready)

    def _drop_blocked(self) -> None:
        for t in list(self.waiting):
            bad = next((d for d in t.deps if d in self.failures and d not in self.computed), None)
            if bad:
                self.waiting.remove(t)
                r = TaskResult(t.name, "failed", error=f"not run: {bad} failed")
                r.user_error = self.failures[bad].user_error
                self._finish(r, t)

    def _place(self, ready: list[Task]) -> None:
        """Submit the ready tasks, the longest expected first, each to the least busy worker with a
        free thread, until none has one."""
        threads = self._threads()
        busy = Counter(w for _, w in self.running.values())
        for t in sorted(ready, key=lambda t: expected_order(t, self.took, self.states_of)):
            free = [w for w in threads if busy[w] < threads[w]]
            if not free:
                break
            w = min(free, key=lambda w: busy[w] / threads[w])
            busy[w] += 1
            self.waiting.remove(t)
            self._submit(t, w)

    def _threads(self) -> dict[str, int]:
        """{worker: threads}, waiting for a worker when there is none and nothing runs."""
        threads = self.client.nthreads()
        if not threads and not self.running:
            self.client.wait_for_workers(1)
            threads = self.client.nthreads()
        return threads

    def _submit(self, t: Task, worker: str) -> None:
        job = t.job
        args = (
            t.kind,
            self.scenes.take(t),
            job.options,
            self.states_of.get(job.name),
            t.state,
            job.bake,
            job.render,
        )
        key = f"{t.name}-{t.key}-{self.run_id}"
        fut = self.client.submit(
            run_task, *args, *self._inputs(t), key=key, pure=False, workers=[worker], allow_other_workers=True
        )
        self.futures[t.name], self.running[fut.key] = fut, (t.name, worker)
        self.pending.add(fut)

    def _inputs(self, t: Task) -> list:
        """The results of ``t``'s inputs: their futures, or those done in an earlier run read here
        and sent once."""
        from iat.radiosity.solution import Solution

        return [
            self.futures[d]
            if d in self.futures
            else self.client.scatter(Solution.load(self.folder / f"{d}.npz"))
            for d in t.deps
        ]


def _outcome(fut) -> tuple[dict | None, BaseException | None]:
    """``(result, None)`` of a finished future, or ``(None, its error)``."""
    if fut.status == "error":
        return None, fut.exception()
    try:
        return fut.result(), None
    except Exception as e:
        return None, e


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
