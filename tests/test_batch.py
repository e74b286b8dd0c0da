"""``iat batch``: Dask tasks on a LocalCluster give the serial path's solutions bit for bit; a failing
task is reported on one line while the others finish; a rerun skips what is done."""

from __future__ import annotations

import asyncio
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from iat.cli.commands import main
from iat.errors import LoadError
from iat.io.load import load_scene
from iat.lighting.solution_set import solve_set
from iat.radiosity import Solution, SolveOptions, solve
from iat.tools.batch import LOG_NAME, WORKER_ENV, WORKER_MALLOC_ENV, parse_jobs, run_batch, start_client

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

CORNELL = Path(__file__).resolve().parent.parent / "sample_models" / "cornell_box.glb"
DEPTH = 3
STATES = {"full": {"emission": {"light": 1.0}}, "dim": {"emission": {"light": 0.4}}}


@pytest.fixture(scope="module")
def client():
    try:
        cluster = distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        )
    except Exception as e:  # no processes or sockets here
        pytest.skip(f"distributed cannot start a LocalCluster here: {e}")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _jobs(tmp_path: Path, jobs: str) -> Path:
    (tmp_path / "empty.obj").write_text("")
    p = tmp_path / "jobs.toml"
    p.write_text(f'output = "out"\n[defaults]\nmax_depth = {DEPTH}\n' + jobs)
    return p


def _seed_jobs(seeds) -> str:
    return "".join(
        f'[[job]]\nname = "seed{k}"\nmodel = "{CORNELL}"\noptions = {{ seed = {k} }}\n' for k in seeds
    )


BAD = '[[job]]\nname = "bad"\nmodel = "empty.obj"\n'


def _same(a, b) -> None:
    for name in ("vert_key", "vert_radiance", "tri_vertices", "leaf_patch", "leaf_level", "leaf_i", "leaf_j"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_four_variants_match_serial_and_a_bad_file_fails_alone(client, tmp_path):
    seeds = [0, 1, 2, 3]
    batch = parse_jobs(_jobs(tmp_path, _seed_jobs(seeds) + BAD))
    seen = []
    with distributed.get_task_stream(client) as stream:
        report = run_batch(batch, client=client, on_result=seen.append)
    solves = sorted(
        (s["start"], s["stop"], t["worker"])
        for t in stream.data
        if t["key"].startswith("seed")
        for s in t["startstops"]
        if s["action"] == "compute"
    )
    # the solves go to both workers (Dask alone would queue them all where the Scene is); which two
    # start first depends on what else a fresh worker is doing (the bad file's load, its imports)
    assert len({w for *_, w in solves}) == 2
    by = {r.name: r for r in report.results}
    assert [r.name for r in report.results] == [f"seed{k}" for k in seeds] + ["bad"]
    assert all(by[f"seed{k}"].status == "ok" for k in seeds)
    assert by["bad"].status == "failed" and by["bad"].user_error
    assert by["bad"].error.endswith("empty.obj: empty file") and "\n" not in by["bad"].error
    assert len(seen) == 5
    scene = load_scene(CORNELL)
    out = tmp_path / "out"
    for k in seeds:  # the serial path: the same options give the same solution, bit for bit
        serial = solve(scene, SolveOptions(max_depth=DEPTH, seed=k))
        _same(Solution.load(out / f"seed{k}.npz"), serial)
    assert not np.array_equal(
        Solution.load(out / "seed0.npz").vert_radiance, Solution.load(out / "seed1.npz").vert_radiance
    )
    log = (out / LOG_NAME).read_text().splitlines()
    assert len(log) == 5 and sum("\tok\t" in line for line in log) == 4
    assert any(line.split("\t")[1:3] == ["bad", "failed"] for line in log)
    # a rerun skips what is done (and runs the failed task again)
    again = run_batch(parse_jobs(tmp_path / "jobs.toml"), client=client)
    assert [r.status for r in again.results] == ["skipped"] * 4 + ["failed"]
    # an output gone: that task runs again
    (out / "seed0.npz").unlink()
    third = run_batch(parse_jobs(tmp_path / "jobs.toml"), client=client)
    assert [r.status for r in third.results][:4] == ["ok", "skipped", "skipped", "skipped"]


def test_states_job_matches_solve_set(client, tmp_path):
    states = "".join(
        f"{k} = {{ emission = {{ light = {v['emission']['light']} }} }}\n" for k, v in STATES.items()
    )
    jobs = f'[[job]]\nname = "box"\nmodel = "{CORNELL}"\nstates_mesh = "merge"\n[job.states]\n{states}'
    report = run_batch(parse_jobs(_jobs(tmp_path, jobs)), client=client)
    names = [r.name for r in report.results]
    assert names == ["box.own-full", "box.own-dim", "box.mesh", "box-full", "box-dim"]
    assert all(r.status == "ok" for r in report.results)
    sset = solve_set(load_scene(CORNELL), STATES, SolveOptions(max_depth=DEPTH))
    for name, serial in zip(sset.names, sset.solutions, strict=True):
        got = Solution.load(tmp_path / "out" / f"box-{name}.npz")
        _same(got, serial)
        assert got.stats["lighting_state"] == name


def test_tasks_after_a_failed_one_are_reported_not_run(client, tmp_path):
    """A states job on a bad file: its own solves fail with the file's error; the merge and the states
    on it are not run, each naming a failed task it waited for."""
    states = "".join(f"{k} = {{ emission = {{ light = 1.0 }} }}\n" for k in ("a", "b"))
    report = run_batch(parse_jobs(_jobs(tmp_path, BAD + f"[job.states]\n{states}")), client=client)
    got = {r.name: r.error for r in report.results}
    assert list(got) == ["bad.own-a", "bad.own-b", "bad.mesh", "bad-a", "bad-b"]
    assert all(got[f"bad.own-{k}"].endswith("empty.obj: empty file") for k in "ab")
    assert got["bad.mesh"] in ("not run: bad.own-a failed", "not run: bad.own-b failed")  # the first to fail
    assert got["bad-a"] == got["bad-b"] == "not run: bad.mesh failed"
    assert all(r.status == "failed" and r.user_error for r in report.results)


def test_ready_tasks_go_longest_expected_first():
    """Before any is timed, the state setting more lights and emitters on goes first; once its own
    solve is timed, a state's task goes by that time."""
    from iat.tools.batch import Job, Task, expected_order

    states = {
        "off": {"lights": {"x": 0.0}, "emission": {"w": [0, 0, 0]}},
        "one": {"emission": {"w": 1.0, "v": 0.0}},
        "three": {"lights": {"x": 2.0, "y": {"intensity": 1.0}}, "emission": {"w": [0, 0, 0.5]}},
    }
    job = Job("h", CORNELL, SolveOptions(), states=states)
    own = [Task(f"h.own-{s}", "own", job, s) for s in states]

    def order(took):
        return [t.state for t in sorted(own, key=lambda t: expected_order(t, took, {"h": states}))]

    assert order({}) == ["three", "one", "off"]
    assert order({("h", "one"): 5.0, ("h", "three"): 1.0}) == ["one", "three", "off"]


def test_start_client_sets_up_its_workers():
    """A LocalCluster of start_client: one thread for the kernels and rays, glibc's malloc as in a
    plain process (not Dask's trim threshold), no sampling profiler."""
    client, cluster = start_client(1)
    try:
        (env, profiling), *_ = client.run(
            lambda: (
                {k: os.environ.get(k) for k in [*WORKER_MALLOC_ENV, *WORKER_ENV]},
                dask.config.get("distributed.worker.profile.enabled"),
            )
        ).values()
    finally:
        client.close()
        cluster.close()
    assert env == {
        "MALLOC_MMAP_THRESHOLD_": str(32 << 20),
        "MALLOC_TRIM_THRESHOLD_": str(64 << 20),
        **WORKER_ENV,
    }
    assert profiling is False


def test_job_file_errors_name_the_file(tmp_path):
    p = tmp_path / "jobs.toml"
    p.write_text('output = "out"\n[[job]]\nname = "a"\nmodel = "x.obj"\nbogus = 1\n')
    with pytest.raises(LoadError, match=r"jobs.toml job 'a': unknown key\(s\) bogus"):
        parse_jobs(p)
    p.write_text('output = "out"\n[[job]]\nname = "a"\nmodel = "x.obj"\noptions = { max_depth = 99 }\n')
    with pytest.raises(LoadError, match="max_depth"):
        parse_jobs(p)
    p.write_text("output = [")
    with pytest.raises(LoadError, match="not a valid TOML job file"):
        parse_jobs(p)


def test_cli_reports_each_failed_task_on_one_line(client, tmp_path, capsys):
    """Done tasks are skipped and a missing model fails before any cluster starts: exit 2."""
    p = _jobs(tmp_path, _seed_jobs([5]) + '[[job]]\nname = "gone"\nmodel = "missing.glb"\n')
    run_batch(parse_jobs(p), client=client)  # seed5 done, gone failed
    capsys.readouterr()
    assert main(["batch", str(p), "--json", "--no-daylight"]) == 2  # (run_batch's default: no daylight)
    cap = capsys.readouterr()
    report = json.loads(cap.out)
    assert [t["status"] for t in report["tasks"]] == ["skipped", "failed"]
    assert cap.err.strip().splitlines() == [
        f"iat batch: error: gone: {tmp_path / 'missing.glb'}: file not found"
    ]


def test_worker_warnings_reach_the_report_log_and_cli(client, tmp_path, capsys):
    """A model's load warning (albedo clamped) and its solve warning (no light source) raised on a
    worker come back as one line each, once, in the report, the log and on stderr."""
    (tmp_path / "bright.mtl").write_text("newmtl bright\nKd 1.5 0.5 0.25\n")
    obj = tmp_path / "bright.obj"
    obj.write_text("mtllib bright.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nusemtl bright\nf 1 2 3 4\n")
    jobs = "".join(
        f'[[job]]\nname = "dark{k}"\nmodel = "bright.obj"\noptions = {{ seed = {k} }}\n' for k in (1, 2)
    )
    p = _jobs(tmp_path, jobs)
    report = run_batch(parse_jobs(p), client=client)
    assert [r.status for r in report.results] == ["ok", "ok"]
    clamp = f"{obj}: albedo outside [0, 1] clamped in 1 material: 'bright' (1.5, 0.5, 0.25)"
    dark = f"{obj}: no light sources (no lights, no sky, no emissive materials): the solution is black"
    said = [w for r in report.results for w in r.warnings]
    assert sorted(said) == sorted([clamp, dark])  # each once over the batch
    log = (tmp_path / "out" / LOG_NAME).read_text()
    assert log.count("\twarning\t") == 2 and clamp in log
    for f in (tmp_path / "out").glob("*.npz"):
        f.unlink()
    assert main(["batch", str(p), "--workers", "1", "--no-daylight"]) == 0  # (the model has no light)
    err = capsys.readouterr().err.strip().splitlines()
    assert [line.split(": ", 2)[1] for line in err] == ["warning", "warning"]
    assert {line.split(": ", 3)[3] for line in err} == {clamp, dark}


def test_solve_states_on_the_engine_matches_the_serial_cli(tmp_path, capsys):
    """``iat solve --states --workers 2`` writes the same OUT-<state>.npz as ``iat solve --states``."""
    from iat.lighting.save import save_gltf

    model = save_gltf(load_scene(CORNELL), CORNELL, tmp_path / "box.glb", lighting_states=STATES)
    flags = ["--max-depth", str(DEPTH), "--json"]
    assert main(["solve", str(model), "--states", "-o", str(tmp_path / "serial.npz"), *flags]) == 0
    capsys.readouterr()
    assert (
        main(["solve", str(model), "--states", "--workers", "2", "-o", str(tmp_path / "dask.npz"), *flags])
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert [s["state"] for s in out["states"]] == list(STATES) and out["workers"] == 2
    for name in STATES:
        _same(Solution.load(tmp_path / f"dask-{name}.npz"), Solution.load(tmp_path / f"serial-{name}.npz"))
    assert (tmp_path / ".dask.batch" / LOG_NAME).is_file()
    assert main(["solve", str(model), "--workers", "2", "-o", str(tmp_path / "x.npz")]) == 2
    assert capsys.readouterr().err.strip() == (
        "iat solve: error: --workers and --scheduler go with --states (one solve runs in this process)"
    )


def test_presolve_fills_the_solution_cache(client, tmp_path):
    """``iat chart --workers``'s first step: the sweep's solves as tasks, written where cached_solve
    finds them, equal to the serial solves; a second call has nothing to do."""
    from iat.radiosity.cache import cached_solve
    from iat.tools.batch import presolve

    cache = tmp_path / "cache"
    pairs = [(CORNELL, SolveOptions(max_depth=DEPTH, tolerance=t)) for t in (0.2, 0.4)]
    report = presolve(pairs + pairs[:1], cache, client=client)
    assert [r.status for r in report.results] == ["ok", "ok"]
    for model, opts in pairs:
        scene, sol, info = cached_solve(model, opts, cache)
        assert info["cached"]
        _same(sol, solve(scene, opts))
    assert presolve(pairs, cache, client=client) is None


def test_progress_counts_every_task_and_results_are_freed_once_no_task_needs_them(client, tmp_path):
    """A merge states job: progress says ``k/5 eta M:SS task`` once per task, in completion order; at
    each task's report the client holds only the results (and the Scene) an unfinished task still
    needs: the own solves until the merge is done, the merged mesh until both states are, nothing
    after the last. A rerun skips everything and reports no progress."""
    import shutil

    model = shutil.copy(CORNELL, tmp_path / "heldbox.glb")
    states = "".join(f"{k} = {{ emission = {{ light = {v} }} }}\n" for k, v in (("a", 1.0), ("b", 0.4)))
    jobs = f'[[job]]\nname = "held"\nmodel = "{model}"\nstates_mesh = "merge"\n[job.states]\n{states}'
    calls, held = [], {}

    def on_result(r):  # the tasks whose results the client still refers to, and its Scene
        client.sync(asyncio.sleep, 0)  # after the releases queued on the client's event loop
        keys = [k for k in client.futures if k.startswith(("held", "load-heldbox-"))]
        held[r.name] = {"load" if k.startswith("load-") else k.rsplit("-", 2)[0] for k in keys}

    p = _jobs(tmp_path, jobs)
    report = run_batch(
        parse_jobs(p), client=client, progress=lambda f, s: calls.append((f, s)), on_result=on_result
    )
    assert all(r.status == "ok" for r in report.results)
    done = list(held)  # completion order
    assert [f for f, _ in calls] == [k / 5 for k in range(1, 6)]
    assert [s.split(" ")[0] for _, s in calls] == [f"{k}/5" for k in range(1, 6)]
    assert [s.split(" ")[-1] for _, s in calls] == done
    assert calls[-1][1] == f"5/5 eta 0:00 {done[-1]}"
    assert all(re.fullmatch(r"\d/5 eta (\?|\d+:\d\d) \S+", s) for _, s in calls)
    assert set(done[:2]) == {"held.own-a", "held.own-b"} and done[2] == "held.mesh"
    own = {"held.own-a", "held.own-b"}
    assert held[done[0]] == own | {"load"}  # the merge needs both; the states the Scene
    assert held[done[1]] == own | {"load", "held.mesh"}  # the merge submitted before the report
    assert held["held.mesh"] == {"held.mesh", "held-a", "held-b"}  # the Scene: in the states' hands
    assert held[done[3]] == {"held.mesh", done[4]}
    assert held[done[4]] == set()
    calls.clear()
    again = run_batch(parse_jobs(p), client=client, progress=lambda f, s: calls.append((f, s)))
    assert [r.status for r in again.results] == ["skipped"] * 5 and calls == []
