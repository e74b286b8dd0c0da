"""Stability catalogue (docs/stability.md), Files: bad inputs on the command line and in the viewer,
missing files, solutions from another version, writes interrupted by a full disk or SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from iat.bake.policy import BakePolicy
from iat.errors import IATError, SolutionFileError
from iat.io.load import load_scene
from iat.radiosity import Solution, solve
from tests import stability_scenes as ss
from tests.support.stability import ROOT, DiskFull, atomic_writers, opts, record

pytestmark = pytest.mark.usefixtures("stability_figures")


CORNELL = ROOT / "sample_models" / "cornell_box.glb"


def _bad_inputs(root: Path, solution: Path) -> dict[str, Path]:
    """name -> path of every bad input (models and solutions)."""
    root.mkdir(parents=True, exist_ok=True)
    files = {
        "empty.obj": b"",
        "garbage.glb": b"this is not a glb file at all" * 10,
        "truncated.glb": CORNELL.read_bytes()[:3000],
        "index_out_of_range.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
        "nan.obj": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "degenerate.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        "binary_junk.obj": bytes(range(256)) * 8,
        "points.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
        "header_only.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
        "truncated.stl": b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n",
        "model.xyz123": b"v 0 0 0\n",
        "empty.npz": b"",
        "junk.npz": bytes(range(256)) * 4,
    }
    out = {}
    for name, data in files.items():
        (root / name).write_bytes(data)
        out[name] = root / name
    (root / "a_directory.obj").mkdir(exist_ok=True)
    out["a_directory.obj"] = root / "a_directory.obj"
    out["missing.glb"] = root / "missing.glb"
    np.savez(root / "not_a_solution.npz", a=np.zeros(3))
    out["not_a_solution.npz"] = root / "not_a_solution.npz"
    with np.load(solution, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    other = dict(data, version=np.array(99))
    np.savez(root / "version99.npz", **other)
    out["version99.npz"] = root / "version99.npz"
    damaged = {k: v for k, v in data.items() if k != "vert_radiance"}
    np.savez(root / "missing_array.npz", **damaged)
    out["missing_array.npz"] = root / "missing_array.npz"
    one_triangle = ss.write_obj(root / "edited_model.obj", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    np.savez(root / "model_changed.npz", **dict(data, model_path=np.array(str(one_triangle))))
    out["model_changed.npz"] = root / "model_changed.npz"
    return out


@pytest.fixture(scope="module")
def small_solution_file(tmp_path_factory):
    """A Cornell box solution at depth 2 (its model_path points at the sample file)."""
    path = tmp_path_factory.mktemp("sol") / "cornell.npz"
    scene = load_scene(CORNELL)
    sol = solve(scene, opts(max_depth=2, samples=4))
    sol.model_path = str(CORNELL)
    sol.save(path)
    return path


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory, small_solution_file):
    return _bad_inputs(tmp_path_factory.mktemp("bad"), small_solution_file)


def _run_cli(argv, capsys, caplog) -> tuple[int, list[str], list]:
    from iat.cli.commands import main

    capsys.readouterr()
    caplog.clear()
    rc = main([str(a) for a in argv])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    return rc, err, [r for r in caplog.records if r.levelno >= 30]


def test_files_every_bad_input_is_one_line_and_exit_2(tmp_path, bad_inputs, capsys, caplog):
    """Every bad file x every command (info, solve, bake, render): exit status 2, exactly one line on
    stderr naming the file, no traceback, no warning logged (it would be a second line), no output file."""
    rows = {}
    out = {"solve": tmp_path / "s.npz", "bake": tmp_path / "o.glb", "render": tmp_path / "o.png"}
    for name, path in bad_inputs.items():
        for command in ("info", "solve", "bake", "render"):
            if command == "solve" and name.endswith(".npz"):
                pass  # a solution given to solve is an unsupported model type: still one line, exit 2
            extra = [] if command == "info" else ["-o", out[command], "--max-depth", "1", "--samples", "1"]
            if command == "render":
                extra += ["--size", "8x6"]
            rc, err, warnings = _run_cli([command, path, *extra], capsys, caplog)
            assert rc == 2, (command, name, err)
            assert len(err) == 1 and name in err[0] and "Traceback" not in err[0], (command, name, err)
            assert not warnings, (command, name, [w.getMessage() for w in warnings])
            assert not any(p.exists() for p in out.values()), (command, name)
            rows[f"{command} {name}"] = err[0]
    record(
        "cli_bad_inputs",
        cases=len(rows),
        messages={k: v.split(": error: ")[1].split(": ", 1)[1] for k, v in rows.items()},
    )


def test_files_bad_inputs_real_stderr_is_one_line(bad_inputs, tmp_path):
    """The same through a real process (what a shell sees): nothing but the one line on stderr, for a
    sample of the new bad inputs and commands."""
    cases = [
        ("info", "truncated.glb"),
        ("solve", "points.ply"),
        ("bake", "junk.npz"),
        ("render", "version99.npz"),
        ("render", "model_changed.npz"),
    ]
    for command, name in cases:
        extra = [] if command == "info" else ["-o", tmp_path / ("o.png" if command == "render" else "o.out")]
        r = subprocess.run(
            [sys.executable, "-m", "iat.cli", command, str(bad_inputs[name]), *map(str, extra)],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=120,
        )
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1 and name in lines[0], (command, name, r.stderr)
        assert r.stdout == "", (command, name, r.stdout)


def test_files_junk_npz_message_does_not_suggest_unpickling(bad_inputs):
    """D9 (fixed): a junk .npz is refused before np.load, whose message suggested allow_pickle."""
    with pytest.raises(SolutionFileError) as e:
        Solution.load(bad_inputs["junk.npz"])
    record("cli_bad_inputs", junk_npz_message=str(e.value))
    assert "pickle" not in str(e.value)


def test_files_viewer_open_job_reports_each_bad_input_on_one_line(bad_inputs, tmp_path, monkeypatch):
    """The viewer's open path (viewer.jobs.OpenJob, what `iat view FILE` runs after the window is up):
    every bad file ends in one line naming it, the job finishes, nothing is raised into the UI."""
    from viewer.jobs import OpenJob

    monkeypatch.setenv("IAT_CACHE_DIR", str(tmp_path / "cache"))
    errors = {}
    for name, path in bad_inputs.items():
        job = OpenJob(path, opts(max_depth=1, samples=1), BakePolicy())
        assert job.join(60.0), name
        assert job.result is None and job.error, (name, job.error)
        assert "\n" not in job.error and name in job.error, (name, job.error)
        errors[name] = job.error
    record("viewer_bad_inputs", cases=len(errors), version99=errors["version99.npz"])


def test_files_view_without_a_display_is_one_line_naming_the_file(bad_inputs):
    """`iat view missing.glb` with no DISPLAY, in a real process: exit 2 and one line of ours naming the
    file (D10 fixed: the file is checked and the display looked for before GLFW is loaded, so GLFW
    prints nothing)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run(
        [sys.executable, "-m", "iat.cli", "view", str(bad_inputs["missing.glb"])],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    record("view_no_display", exit_status=r.returncode, stderr_lines=len(lines), stderr=lines)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(lines) == 1 and lines[0].startswith("iat view: ") and "missing.glb" in lines[0]


def test_files_view_without_a_display_every_bad_input_is_one_line_and_exit_2(
    bad_inputs, capsys, caplog, monkeypatch
):
    """`iat view BAD` with no display, for every bad input: exit 2, one line naming the file and its
    fault, no traceback, no window: with no display `view` reads the file first (with a display the
    window's open job reads it, see the viewer row)."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    named = 0
    for name, path in bad_inputs.items():
        rc, err, warnings = _run_cli(["view", path], capsys, caplog)
        assert rc == 2 and len(err) == 1 and "Traceback" not in err[0], (name, err)
        assert not warnings, (name, [w.getMessage() for w in warnings])
        assert name in err[0] and "no display" not in err[0], (name, err)
        named += name in err[0]
    record("view_no_display", bad_inputs=len(bad_inputs), bad_inputs_named=named)


def test_files_missing_file_is_file_not_found_everywhere(tmp_path, capsys, caplog, monkeypatch):
    """G5 (fixed): a missing file is "<path>: file not found" from load_scene, open_solution and
    Solution.load, and from every command (info, solve, bake, render, view)."""
    from iat.radiosity.inputs import open_solution

    model, solution = tmp_path / "gone.glb", tmp_path / "gone.npz"
    for fn, path in (
        (load_scene, model),
        (open_solution, model),
        (open_solution, solution),
        (Solution.load, solution),
    ):
        with pytest.raises(IATError) as e:
            fn(path)
        assert str(e.value) == f"{path}: file not found", (fn, str(e.value))
    monkeypatch.delenv("DISPLAY", raising=False)  # view: never open a window here
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = {
        "solve": ["-o", tmp_path / "s.npz"],
        "bake": ["-o", tmp_path / "o.glb"],
        "render": ["-o", tmp_path / "o.png"],
    }
    for command in ("info", "solve", "bake", "render", "view"):
        for path in (model, solution):
            rc, err, _ = _run_cli([command, path, *out.get(command, [])], capsys, caplog)
            assert rc == 2 and err == [f"iat {command}: error: {path}: file not found"], (command, path, err)


def test_files_info_and_solve_on_a_solution_say_what_would_help(
    small_solution_file, tmp_path, capsys, caplog
):
    """G5 (fixed): `iat info SOL.npz` / `iat solve SOL.npz` say the file is a solution, which commands
    read models, and name the model it was solved from (was "unsupported file type '.npz'")."""
    lines = {}
    for command, extra in (("info", []), ("solve", ["-o", tmp_path / "again.npz"])):
        rc, err, _ = _run_cli([command, small_solution_file, *extra], capsys, caplog)
        assert rc == 2 and len(err) == 1, (command, err)
        head, msg = err[0].split(": error: ", 1)
        assert head == f"iat {command}", err
        assert msg.startswith(f"{small_solution_file}: a solution file, not a model"), msg
        assert f"'iat {command}' reads models (.glb" in msg and "read solutions" in msg
        assert f"run it on {CORNELL}, the model it was solved from" in msg
        lines[command] = msg
    assert not (tmp_path / "again.npz").exists()
    record("cli_bad_inputs", info_on_a_solution=lines["info"])


# -- interrupted writes --------------------------------------------------------------------------------
def test_files_interrupted_writes_leave_the_previous_file_intact(tmp_path, small_solution_file, monkeypatch):
    """The disk fills up half-way through each writer: the exception reaches the caller, the previous
    file is byte-for-byte intact, and no temporary file is left behind."""
    writers = atomic_writers(tmp_path, small_solution_file)
    real_fdopen = os.fdopen
    sizes = {}
    for name, (target, write) in writers.items():
        write(target)
        before = target.read_bytes()
        sizes[name] = len(before)
        half = len(before) // 2
        monkeypatch.setattr(os, "fdopen", lambda fd, *a, _n=half, **k: DiskFull(real_fdopen(fd, *a, **k), _n))
        with pytest.raises(OSError, match="No space left"):
            write(target)
        monkeypatch.setattr(os, "fdopen", real_fdopen)
        assert target.read_bytes() == before, name
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")) == [], name
    record("interrupted_writes", disk_full_previous_intact=True, file_bytes=sizes)


def test_files_atomic_writers_fsync_the_temporary_before_the_rename(
    tmp_path, small_solution_file, monkeypatch
):
    """G3 (fixed): Solution.save, export_glb and save_png all go through imageio.atomic_write: the
    temporary `.<name>.<random>.tmp` is fsynced, then renamed over the target, nothing else."""
    from iat.fsutil import temporary_pattern

    writers = atomic_writers(tmp_path, small_solution_file)
    real_fsync, real_replace = os.fsync, os.replace
    events = []

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        return real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", os.fspath(src), os.fspath(dst)))
        return real_replace(src, dst)

    for name, (target, write) in writers.items():
        events.clear()
        monkeypatch.setattr(os, "fsync", fsync)
        monkeypatch.setattr(os, "replace", replace)
        try:
            write(target)
        finally:
            monkeypatch.setattr(os, "fsync", real_fsync)
            monkeypatch.setattr(os, "replace", real_replace)
        assert [e[0] for e in events] == ["fsync", "replace"], (name, events)
        assert events[0][1] == events[1][1] and events[1][2] == str(target), (name, events)
        assert temporary_pattern(target).fullmatch(Path(events[1][1]).name), (name, events)
    record("interrupted_writes", fsync_then_rename=sorted(writers))


_KILLED_WRITER = r"""
import os, sys, time
sys.path.insert(0, sys.argv[1])
from tests.support.stability import DiskFull, atomic_writers
from pathlib import Path
name, target_dir, sol = sys.argv[2], Path(sys.argv[3]), Path(sys.argv[4])
target, write = atomic_writers(target_dir, sol)[name]
real = os.fdopen
class Stall(DiskFull):
    def write(self, data):
        n = len(memoryview(data).cast("B")) if not isinstance(data, (bytes, bytearray)) else len(data)
        if n > self._left:
            self._f.write(bytes(memoryview(data).cast("B")[: self._left])); self._f.flush()
            print("HALF", flush=True); time.sleep(60)
        self._left -= n
        return self._f.write(data)
os.fdopen = lambda fd, *a, **k: Stall(real(fd, *a, **k), target.stat().st_size // 2)
write(target)
"""


def test_files_killed_writers_leave_the_previous_file_intact(tmp_path, small_solution_file):
    from iat.fsutil import STALE_TEMPORARY_S, temporary_pattern

    """SIGKILL half-way through each writer (no cleanup can run): the previous file is intact; the
    half-written temporary `.<name>.<random>.tmp` stays behind next to it until the next successful
    write of the same file, which removes it once it is older than STALE_TEMPORARY_S (1 h; a younger
    one may be another process's write in progress) (G4 fixed)."""
    script = tmp_path / "killed.py"
    script.write_text(_KILLED_WRITER)
    debris = {}
    for name, (target, write) in atomic_writers(tmp_path, small_solution_file).items():
        write(target)
        before = target.read_bytes()
        p = subprocess.Popen(
            [sys.executable, str(script), str(ROOT), name, str(tmp_path), str(small_solution_file)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        try:
            line = p.stdout.readline()
            assert line.strip() == "HALF", (name, line, p.stderr.read() if p.poll() is not None else "")
        finally:
            p.send_signal(signal.SIGKILL)
            p.wait(30)
        assert target.read_bytes() == before, name
        left = [q for q in tmp_path.iterdir() if q.name.endswith(".tmp")]
        debris[name] = [[q.name, q.stat().st_size] for q in left]
        assert len(left) == 1 and temporary_pattern(target).fullmatch(left[0].name), (name, left)
        # the next write cleans it up once it is stale; a young one (a live writer's) and files of
        # other names are left alone
        stale = time.time() - 2 * STALE_TEMPORARY_S
        os.utime(left[0], (stale, stale))
        young = target.with_name(f".{target.name}.young0.tmp")
        other = target.with_name(f".{target.name}.keep.me.tmp")  # not the pattern: a dot in <random>
        for q in (young, other):
            q.write_bytes(b"x")
        os.utime(other, (stale, stale))
        write(target)
        assert not left[0].exists() and young.exists() and other.exists(), name
        assert target.read_bytes() != b"" and target.stat().st_size > 0
        young.unlink()
        other.unlink()
        assert [q.name for q in tmp_path.iterdir() if q.name.endswith(".tmp")] == [], name
    record(
        "interrupted_writes",
        sigkill_previous_intact=True,
        sigkill_debris=debris,
        debris_removed_by_next_write=True,
        stale_after_s=STALE_TEMPORARY_S,
    )
