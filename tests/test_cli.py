"""The command line end to end, on real files: exit codes, one-line errors, JSON outputs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_models" / "cornell_box.glb"


def iat(*args, cwd=None):
    """Run ``python -m iat.cli ARGS`` in a subprocess; returns CompletedProcess."""
    return subprocess.run(
        [sys.executable, "-m", "iat.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd or ROOT,
        timeout=600,
    )


@pytest.fixture(scope="module")
def cornell_solution(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "cornell.npz"
    r = iat("solve", CORNELL, "-o", out, "--max-depth", "4", "--json")
    assert r.returncode == 0, r.stderr
    stats = json.loads(r.stdout)
    assert stats["vertices"] > 0 and stats["elements"] > 0
    return out


def test_info_counts_the_cornell_box():
    r = iat("info", CORNELL, "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["patches"] > 10
    assert info["quads"] == info["patches"]  # every Cornell surface is a planar quad
    assert info["cameras"] >= 1
    assert info["emissive_materials"] >= 1


BAD_FILES = {
    "empty.obj": b"",
    "garbage.glb": b"this is not a glb file at all" * 10,
    "nan.obj": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "degenerate.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
    "model.xyz123": b"v 0 0 0\n",
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
@pytest.mark.parametrize("command", ["info", "solve", "bake", "render"])
def test_bad_input_gives_one_line_error_and_exit_2(tmp_path, name, command):
    bad = tmp_path / name
    bad.write_bytes(BAD_FILES[name])
    extra = {
        "info": [],
        "solve": ["-o", tmp_path / "s.npz"],
        "bake": ["-o", tmp_path / "o.glb"],
        "render": ["-o", tmp_path / "o.png"],
    }[command]
    r = iat(command, bad, *extra)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert name in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "s.npz").exists() and not (tmp_path / "o.glb").exists()


def test_missing_file_and_debug_traceback(tmp_path):
    r = iat("info", tmp_path / "nope.glb")
    assert r.returncode == 2 and "nope.glb" in r.stderr and "Traceback" not in r.stderr
    r = iat("--debug", "info", tmp_path / "nope.glb")
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_solution_of_another_version_is_refused(tmp_path, cornell_solution):
    with np.load(cornell_solution, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    data["version"] = np.array(99)
    other = tmp_path / "v99.npz"
    np.savez(other, **data)
    r = iat("bake", other, "-o", tmp_path / "o.glb")
    assert r.returncode == 2 and "version 99" in r.stderr


def test_bake_json_and_render_modes(tmp_path, cornell_solution):
    glb = tmp_path / "c.glb"
    r = iat("bake", cornell_solution, "-o", glb, "--threshold", "1", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert glb.exists() and rep["texture_bytes"] > 0 and rep["patches_textured"] > 0
    images = {}
    for mode in ("mesh", "iat"):
        out = tmp_path / f"{mode}.npy"
        r = iat(
            "render",
            cornell_solution,
            "-o",
            out,
            "--mode",
            mode,
            "--size",
            "96x72",
            "--camera",
            "0",
            "--threshold",
            "0",
        )
        assert r.returncode == 0, r.stderr
        images[mode] = np.load(out)
        assert images[mode].shape == (72, 96, 3) and images[mode].dtype == np.float32
    # IAT against mesh of the same solution: the same picture (report §4.1)
    from iat.measure.metrics import psnr

    assert psnr(images["iat"], images["mesh"]) > 30
    png = tmp_path / "c.png"
    r = iat("render", cornell_solution, "-o", png, "--mode", "iat", "--size", "64x48")
    assert r.returncode == 0 and png.stat().st_size > 100


def test_render_rejects_bad_options(tmp_path, cornell_solution):
    r = iat("render", cornell_solution, "-o", tmp_path / "x.png", "--camera", "7")
    assert r.returncode == 2 and "camera" in r.stderr
    r = iat("render", cornell_solution, "-o", tmp_path / "x.jpg")
    assert r.returncode == 2 and ".png or .npy" in r.stderr
    r = iat("render", cornell_solution, "-o", tmp_path / "x.png", "--eye", "1,2")
    assert r.returncode == 2 and "--eye" in r.stderr


def _bright_obj(tmp_path) -> Path:
    (tmp_path / "bright.mtl").write_text("newmtl bright\nKd 1.5 0.5 0.25\n")
    obj = tmp_path / "bright.obj"
    obj.write_text("mtllib bright.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl bright\nf 1 2 3\n")
    return obj


def test_clamped_albedo_is_one_warning_line_on_stderr(tmp_path):
    """G6: the loader's IATWarning comes out as one line, like errors, and the command still runs."""
    obj = _bright_obj(tmp_path)
    r = iat("info", obj, "--json")
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines() == [
        f"iat info: warning: {obj}: albedo outside [0, 1] clamped in 1 material: 'bright' (1.5, 0.5, 0.25)"
    ]
    assert json.loads(r.stdout)["patches"] == 1


def test_loader_log_warnings_have_the_command_prefix(tmp_path):
    """What the loader logs as a warning (a missing material library) is one ``iat CMD: warning:`` line."""
    obj = tmp_path / "nolib.obj"
    obj.write_text("mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 -1\nf 1 2 3\n")
    r = iat("info", obj, "--json")
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines() == [
        f"iat info: warning: {obj}: material library gone.mtl not found; default materials used"
    ]


def test_no_light_source_warns_and_still_writes_the_solution(tmp_path):
    obj = tmp_path / "dark.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 0 -1\nv 0 0 -1\nf 1 2 3 4\n")
    r = iat("info", obj, "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["light_sources"] == "no light sources"
    out = tmp_path / "dark.npz"
    r = iat("solve", obj, "-o", out, "--no-daylight")  # (without it: daylight, tests/test_site_daylight.py)
    assert r.returncode == 0 and out.is_file()
    assert r.stderr.splitlines() == [
        f"iat solve: warning: {obj}: no light sources (no lights, no sky, no emissive materials):"
        " the solution is black"
    ]


def test_negative_coordinates_in_eye_and_target(tmp_path):
    """``--eye -1,0.5,-3``: argparse alone takes a value starting with '-' for an option."""
    out = tmp_path / "neg.png"
    r = iat(
        "render",
        CORNELL,
        "--mode",
        "preview",
        "--eye",
        "-1,0.5,-3",
        "--target",
        "-0.1,0.5,0",
        "--size",
        "32x24",
        "-o",
        out,
    )
    assert r.returncode == 0, r.stderr
    assert out.is_file()


def test_load_draws_a_progress_bar_on_a_terminal(tmp_path, monkeypatch, capsys):
    """G2: ``iat info`` (and solve, bake, render through the same helper) draws the load's bar."""
    import io

    from iat.cli import commands as cli

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    assert cli.main(["info", str(CORNELL)]) == 0
    text = err.getvalue()
    assert "load cornell_box.glb" in text and "merging quads" in text and "1000/1000" in text
    assert "patches" in capsys.readouterr().out
    err.truncate(0)
    assert cli.main(["info", str(CORNELL), "--json"]) == 0
    assert err.getvalue() == ""  # --json: no bar


def test_solve_with_sun_and_sky(tmp_path):
    """``--sun LAT,LON,WHEN,TZ`` and ``--sky`` light an open box (no lights in the file)."""
    obj = tmp_path / "court.obj"
    obj.write_text(
        "v 0 0 0\nv 0 0 4\nv 4 0 4\nv 4 0 0\nv 0 2 0\nv 0 2 4\nv 4 2 4\nv 4 2 0\n"
        "f 1 2 3 4\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\n"  # floor and three walls, open to the sky
    )
    out = tmp_path / "court.npz"
    r = iat(
        "solve",
        obj,
        "-o",
        out,
        "--max-depth",
        "3",
        "--sun",
        "48.14,11.58,2026-06-21T14:00,Europe/Berlin",
        "--sky",
        "preetham:3",
        "--sky-scale",
        "0.01",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    stats = json.loads(r.stdout)
    assert stats["received_power"] > 0 and stats["shots"] > 0 and stats["sources"]["daylight"]
    # the solution reopens with the sun and the sky it was solved under (the file has neither)
    from iat.radiosity.inputs import open_solution

    scene, sol = open_solution(out)
    (sun,) = scene.lights
    assert sun.kind == "directional" and sun.direction.tolist() == stats["sources"]["suns"][0]["direction"]
    assert sun.radiant_intensity.tolist() == pytest.approx(stats["sources"]["suns"][0]["radiant_intensity"])
    assert scene.sky.kind == "preetham" and scene.sky.turbidity == 3.0
    assert scene.sky.radiance.tolist() == pytest.approx(stats["sources"]["sky"]["radiance"])
    assert scene.sky.sun_direction @ -sun.direction == pytest.approx(1.0)
    r = iat("solve", obj, "-o", out, "--sun", "48.14,11.58,2026-06-21T23:30,Europe/Berlin")
    assert r.returncode == 2 and "below the horizon" in r.stderr
    r = iat("solve", obj, "-o", out, "--sky", "cloudy")
    assert r.returncode == 2 and r.stderr.startswith("iat solve: error: --sky must be")


def test_exported_glb_keeps_cameras_and_renders_as_baked(tmp_path, cornell_solution):
    """The export carries the model's cameras; ``iat render OUT.glb`` draws the file as baked
    (it once re-solved it as an unlit model: black, exit 0)."""
    glb = tmp_path / "cornell.glb"
    assert iat("bake", cornell_solution, "-o", glb).returncode == 0
    a, b = tmp_path / "glb.npy", tmp_path / "sol.npy"
    r = iat("render", glb, "--camera", "0", "--size", "64x64", "-o", a)
    assert r.returncode == 0, r.stderr
    assert iat("render", cornell_solution, "--camera", "0", "--size", "64x64", "-o", b).returncode == 0
    img, ref = np.load(a), np.load(b)
    assert img.max() > 0
    peak = float(np.percentile(ref, 90))  # the walls (the lamp clips in the file's 8-bit scale)
    psnr = 10 * np.log10(peak**2 / np.mean((np.minimum(img, peak) - np.minimum(ref, peak)) ** 2))
    assert psnr > 30, psnr
    r = iat("render", glb, "--mode", "mesh", "-o", a)
    assert r.returncode == 2 and "exported bake" in r.stderr
