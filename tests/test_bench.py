"""``iat bench`` and ``iat chart`` on the Cornell box: the JSON schema, IAT against mesh, the
solution cache, the chart's panels and its Pareto fronts.

Timings are never asserted (they are noisy here); counts, image errors and dominance are.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from iat.camera import Camera
from iat.radiosity import SolveOptions
from iat.radiosity.cache import cached_solve
from iat.tools import bench, chart

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_models" / "cornell_box.glb"
SMALL = SolveOptions(max_depth=4)


def _need_egl():
    moderngl = pytest.importorskip("moderngl")
    try:
        moderngl.create_standalone_context(backend="egl").release()
    except Exception as e:
        pytest.skip(f"no EGL OpenGL context: {e}")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("bench-cache")


@pytest.fixture(scope="module")
def result(cache):
    _need_egl()
    return bench.run_bench(
        ["cornell_box"],
        frames=4,
        size=(64, 48),
        tiny_size=(32, 24),
        solve_options=SMALL,
        cache_dir=cache,
        error_frames=3,
        error_size=(160, 120),  # at 64x48 the mip-mapped textures are filtered where the mesh aliases
        repeats=1,
    )


def test_bench_json_schema(result):
    json.dumps(result, allow_nan=False)  # strict JSON: no NaN or infinity anywhere
    assert result["schema"] == bench.SCHEMA_VERSION
    assert result["settings"]["size"] == [64, 48] and result["settings"]["tiny_size"] == [32, 24]
    assert result["settings"]["solve_options"]["max_depth"] == 4
    assert result["settings"]["policy"]["threshold"] >= 0
    assert result["machine"]["cpu_cores"] >= 1
    assert set(result["report_figure3"]) == {"maus", "cave", "lavapit", "pool"}
    assert result["report_figure3"]["maus"]["triangles_mesh"] == 95536
    (row,) = result["models"]
    types = {
        "model": str,
        "patches": int,
        "triangles_mesh": int,
        "triangles_iat": int,
        "draw_calls_mesh": int,
        "draw_calls_iat": int,
        "texture_mb": float,
        "memory": dict,
        "frame_rate": dict,
        "error": dict,
        "psnr_db": float,
        "flip": float,
        "seam_error": dict,
        "solve_s": float,
        "solve_cached": bool,
        "bake_s": float,
        "rebake_s": float,
        "load_s": dict,
        "policy": dict,
    }
    for key, t in types.items():
        assert isinstance(row[key], t), f"{key}: {type(row[key]).__name__}, expected {t.__name__}"
    assert row["model"] == "cornell_box" and row["patches"] == 16
    assert set(row["frame_rate"]) == {"64x48", "32x24"}
    for rates in row["frame_rate"].values():
        assert rates["mesh"] > 0 and rates["iat"] > 0
        assert rates["mesh_frame_ms"] > 0 and rates["iat_frame_ms"] > 0
    assert set(row["load_s"]) == {"scene", "upload_mesh", "upload_iat"}
    assert row["memory"]["texture_bytes"] > 0
    assert row["texture_mb"] == pytest.approx(row["memory"]["texture_bytes"] / 2**20)
    assert {"max", "mean", "edges"} <= set(row["seam_error"]) and {"max", "mean"} <= set(
        row["seam_error_mesh"]
    )
    assert row["radiance_p99"] > 0
    assert row["report"] is None  # the report has no Cornell box


def test_bench_iat_matches_mesh_with_fewer_triangles(result):
    (row,) = result["models"]
    # the default policy textures the deep patches: far fewer triangles than the radiosity mesh
    assert 0 < row["triangles_iat"] < row["triangles_mesh"] / 10
    assert row["triangles_iat"] == row["memory"]["triangles"]
    assert row["draw_calls_iat"] == row["memory"]["draw_calls"]
    assert row["draw_calls_mesh"] == 1
    # IAT against the mesh of the same solution: the same image
    assert math.isfinite(row["psnr_db"]) and row["psnr_db"] >= 40.0
    assert row["error"]["psnr_db_min"] >= 35.0
    assert 0.0 <= row["flip"] < 0.05
    assert row["error"]["frames"] == 3


def test_bench_markdown_table(result):
    text = bench.format_table(result)
    assert "| cornell_box (polygon) | 5,024 |" in text or "| cornell_box (polygon) |" in text
    assert "| cornell_box (IAT) |" in text
    assert "fps 64x48" in text and "fps 32x24" in text
    # the report's Figure 3 is shown even when none of its models ran
    assert "maus (polygon) | 95,536 | 7.5" in text
    assert "lavapit (IAT) | 7,183 | 30.0 | 1.48" in text


def test_solution_cache(tmp_path):
    model = tmp_path / "box.glb"
    shutil.copy(CORNELL, model)
    _, sol1, info1 = cached_solve(model, SMALL, tmp_path)
    assert not info1["cached"] and Path(info1["cache_file"]).is_file()
    _, sol2, info2 = cached_solve(model, SMALL, tmp_path)
    assert info2["cached"] and info2["solve_s"] == pytest.approx(info1["solve_s"])
    np.testing.assert_array_equal(sol1.vert_radiance, sol2.vert_radiance)
    # other options: another file
    _, _, info3 = cached_solve(model, SolveOptions(max_depth=3), tmp_path)
    assert not info3["cached"] and info3["cache_file"] != info1["cache_file"]
    # the key is the file's content: a touched model is still cached, an edited one is solved again
    t = Path(info1["cache_file"]).stat().st_mtime
    os.utime(model, (t + 10, t + 10))
    assert cached_solve(model, SMALL, tmp_path)[2]["cached"]
    import pygltflib

    g = pygltflib.GLTF2().load(model)
    g.asset.generator = "edited"
    g.save(model)
    _, _, info4 = cached_solve(model, SMALL, tmp_path)
    assert not info4["cached"]


def test_interpolate_path():
    poses = [
        Camera(eye=[0, 0, 0], target=[0, 0, -1], yfov=40),
        Camera(eye=[2, 0, 0], target=[2, 0, -1], yfov=60),
        Camera(eye=[2, 0, 4], target=[2, 0, 3], yfov=60),
    ]
    cams = bench.interpolate_path(poses, 9)
    assert len(cams) == 9
    np.testing.assert_allclose(cams[0].eye, poses[0].eye)
    np.testing.assert_allclose(cams[-1].eye, poses[-1].eye)
    np.testing.assert_allclose(cams[4].eye, poses[1].eye)  # the middle frame is the middle pose
    np.testing.assert_allclose(cams[2].eye, [1, 0, 0])
    assert cams[2].yfov == pytest.approx(50)
    assert len(bench.interpolate_path(poses[:1], 5)) == 5
    assert len(bench.pick(cams, 3)) == 3 and bench.pick(cams, 3)[0] is cams[0]


def test_resolve_model_names():
    assert bench.resolve_model("cornell_box") == bench.SAMPLE_DIR / "cornell_box.glb"
    from iat.errors import LoadError

    with pytest.raises(LoadError, match="no_such_model"):
        bench.resolve_model("no_such_model")


# -- chart -------------------------------------------------------------------------------------
def test_pareto_mask_small_example():
    cost = [1, 2, 3, 2, 4, np.nan]
    err = [5, 3, 1, 4, 1, 0]
    # (2,4) is dominated by (2,3); (4,1) by (3,1); NaN is never on the front
    assert chart.pareto_mask(cost, err).tolist() == [True, True, True, False, False, False]


@pytest.fixture(scope="module")
def chart_result(tmp_path_factory, cache):
    _need_egl()
    d = tmp_path_factory.mktemp("chart")
    other = d / "cornell_copy.glb"
    shutil.copy(CORNELL, other)
    return chart.run_chart(
        ["cornell_box", other],
        d / "chart.png",
        size=(64, 48),
        frames=3,
        thresholds=(0, 5),
        scales=(1.0, 0.5),
        methods=("bilinear", "scan"),
        tolerances=(0.05, 0.2),
        solve_options=SMALL,
        cache_dir=cache,
        error_frames=2,
        reference_spp=4,
    )


def test_chart_files_and_panels(chart_result):
    png, js = Path(chart_result["png"]), Path(chart_result["json"])
    assert png.is_file() and js.is_file() and js == png.with_suffix(".json")
    data = json.loads(js.read_text())
    assert [m["model"] for m in data["models"]] == ["cornell_box", "cornell_copy"]  # one row per model
    from PIL import Image

    img = np.asarray(Image.open(png).convert("L"), dtype=np.float64)
    assert png.stat().st_size > 20_000
    assert img.shape[0] > 400 and img.shape[1] > 800 and img.std() > 5  # not blank
    for m in data["models"]:
        pts = m["points"]
        # full sweep at the tightest tolerance, scan only at the others, one mesh per tolerance
        assert len(pts) == 2 * 2 * 2 + 2 * 2 * 1 + 2
        assert sum(p["kind"] == "mesh" for p in pts) == 2
        finest = [
            p
            for p in pts
            if p["kind"] == "iat"
            and p["tolerance"] == 0.05
            and p["threshold"] == 0
            and p["scale"] == 1.0
            and p["method"] == "scan"
        ]
        assert finest and finest[0]["flip_vs_finest"] == pytest.approx(0.0, abs=1e-6)
        for p in pts:
            assert p["gpu_mb"] > 0 and p["frame_ms"] > 0 and p["triangles"] > 0
            assert 0.0 <= p["flip_vs_finest"] <= 1.0
        # the Cornell box has a Mitsuba reference, the copy (another name) does not
        has_ref = m["model"] == "cornell_box"
        assert all((p["flip_vs_reference"] is not None) == has_ref for p in pts)
        assert (m["reference"] is not None) == has_ref

        # halving the texture scale shrinks texture memory
        def tex(s, t=0, pts=pts):
            return next(
                p["texture_mb"]
                for p in pts
                if p["kind"] == "iat"
                and p["tolerance"] == 0.05
                and p["threshold"] == t
                and p["scale"] == s
                and p["method"] == "scan"
            )

        assert tex(0.5) < tex(1.0)


def test_chart_pareto_points_are_non_dominated(chart_result):
    data = json.loads(Path(chart_result["json"]).read_text())
    checked = 0
    for m in data["models"]:
        pts = m["points"]
        for key, front in m["pareto"].items():
            err, cost = key.split("/")
            valid = [i for i, p in enumerate(pts) if p[err] is not None]

            def dominates(j, i, err=err, cost=cost, pts=pts):
                a, b = pts[j], pts[i]
                return a[cost] <= b[cost] and a[err] <= b[err] and (a[cost] < b[cost] or a[err] < b[err])

            expect = [i for i in valid if not any(dominates(j, i) for j in valid)]
            assert sorted(front) == expect, key
            checked += len(front)
        assert m["pareto"]["flip_vs_finest/gpu_mb"]  # never empty
    assert checked > 0


def test_bench_main_json_and_markdown(tmp_path, monkeypatch, capsys):
    """The CLI wrapper: flags reach run_bench, stdout is JSON with --json, Markdown without."""
    _need_egl()
    import argparse
    import functools

    from iat.cli.commands import cmd_bench

    monkeypatch.chdir(tmp_path)  # the default solution cache is ./out/bench
    monkeypatch.setattr(
        bench, "run_bench", functools.partial(bench.run_bench, solve_options=SMALL, repeats=1)
    )
    args = argparse.Namespace(models=["cornell_box"], json=True, frames=2, size="48x32")
    assert cmd_bench(args) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["settings"]["frames"] == 2 and data["settings"]["size"] == [48, 32]
    assert data["models"][0]["triangles_iat"] < data["models"][0]["triangles_mesh"]
    assert data["models"][0]["solve_cached"] is False
    assert list((tmp_path / "out" / "bench").glob("cornell_box-*.npz"))
    args.json = False
    assert cmd_bench(args) == 0
    out = capsys.readouterr().out
    assert "| cornell_box (IAT) |" in out and "fps 48x32" in out and "(cached)" in out


def test_bench_cli_unknown_model(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "iat.cli", "bench", "nonexistent_model"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert r.returncode == 2
    assert "nonexistent_model" in r.stderr and len(r.stderr.strip().splitlines()) == 1
