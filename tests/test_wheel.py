"""The package as a user installs it: the wheel holds the top-level ``shaders/`` (as ``iat/shaders``),
and a scratch venv with only the wheel installed (its dependencies borrowed from the project's venv,
no network) renders a model headless from its own files, not from this source tree.
"""

from __future__ import annotations

import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import numpy as np
import pytest

from iat.render.gl import shader_dir

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "sample_models" / "cornell_box.glb"
SIZE = "160x120"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from this tree (hatchling from the venv, no build isolation: offline)."""
    pytest.importorskip("hatchling", reason="hatchling (the test extra) builds the wheel")
    d = tmp_path_factory.mktemp("wheel")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(d),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    (whl,) = d.glob("iat-*.whl")
    return whl


@pytest.fixture(scope="module")
def scratch(wheel, tmp_path_factory) -> Path:
    """A fresh venv holding the installed wheel; the project venv's site-packages is appended to its
    path for the dependencies (a plain path line: the editable install's own ``.pth``, which would
    put this source tree on the path, is not run)."""
    d = tmp_path_factory.mktemp("venv")
    venv.EnvBuilder(with_pip=False).create(d)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(d / "bin" / "python"),
            "install",
            "-q",
            "--no-deps",
            str(wheel),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    site = next(d.glob("lib/python*/site-packages"))
    (site / "zz_project_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return d


def test_the_wheel_holds_the_top_level_shaders(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    glsl = sorted(n for n in names if n.endswith(".glsl"))
    here = sorted(p.name for p in (ROOT / "shaders").glob("*.glsl"))
    assert glsl == [f"iat/shaders/{n}" for n in here]
    assert "color.glsl" in here and len(here) >= 8  # the one shared include and the programs
    for client in ("three/iat_lightmap.js", "babylon/iat_lightmap.js", "blender/iat_import.py"):
        assert f"iat/export/clients/{client}" in names  # the shipped client code (docs/export.md)
    assert shader_dir() == ROOT / "shaders"  # this source tree (an editable install) reads shaders/


def test_the_installed_wheel_renders_headless_from_its_own_files(scratch, tmp_path):
    py = scratch / "bin" / "python"
    r = subprocess.run(
        [str(py), "-c", "import iat, iat.render.gl as g; print(iat.__file__); print(g.shader_dir())"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    pkg, shaders = r.stdout.split()
    site = str(next(scratch.glob("lib/python*/site-packages")))
    assert pkg.startswith(site) and shaders == f"{site}/iat/shaders"  # not the source tree
    images = {}
    for who, iat in (("wheel", scratch / "bin" / "iat"), ("tree", Path(sys.executable).parent / "iat")):
        out = tmp_path / f"{who}.npy"
        args = [str(iat), "render", str(MODEL), "--mode", "preview", "--size", SIZE, "-o", str(out)]
        r = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        images[who] = np.load(out)
    img = images["wheel"]
    lit = img.max(axis=-1) > 0.05
    print(f"wheel render: {lit.mean():.3f} of the pixels lit, std {img.std():.3f}")
    assert img.shape == (120, 160, 3) and np.isfinite(img).all()
    assert lit.mean() > 0.6 and img.std() > 0.05  # the box (69 % of the frame), not a black or flat one
    assert img[60, 30, 0] > 2 * img[60, 30, 1] and img[60, 130, 1] > 2 * img[60, 130, 0]  # red | green walls
    np.testing.assert_allclose(img, images["tree"], atol=1e-6)  # the same program as the source tree's
