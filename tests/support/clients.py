"""Drive the clients people open an export in: three.js and Babylon.js in headless Chromium (and
Blender's bpy).

``three_env()`` / ``babylon_env()`` skip the test (with the reason) when node, Chromium or the npm
packages are missing; ``draw_three(jobs)`` / ``draw_babylon(jobs)`` draw GLB files with
``tests/support/three_render.js`` / ``babylon_render.js`` in one browser session and return 8-bit
sRGB images.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from iat.color import srgb_encode
from iat.export.gltf import BABYLON_PLUGIN, BLENDER_SCRIPT, THREE_PLUGIN

__all__ = [
    "BABYLON_PLUGIN",
    "BLENDER_SCRIPT",
    "THREE_PLUGIN",
    "draw_babylon",
    "draw_blender",
    "draw_three",
    "file_codes",
    "see_through",
]

ROOT = Path(__file__).resolve().parents[2]
THREE_JS = ROOT / "tests" / "support" / "three_render.js"
BABYLON_JS = ROOT / "tests" / "support" / "babylon_render.js"
NODE_MODULES = [os.environ.get("IAT_NODE_PATH", ""), str(ROOT / ".node" / "node_modules")]
MAGENTA = np.array([255, 0, 255])
#: console lines that are Chromium's own (SwiftShader's read-back notes, the favicon request)
_NOISE = ("GL Driver Message", "Failed to load resource")


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        p = shutil.which(name)
        if p:
            return p
    return None


def _node_env(client: str, packages: tuple[str, ...]) -> dict:
    """Environment for ``node <client>_render.js``; skips (with the reason) when a part is missing."""
    if shutil.which("node") is None:
        pytest.skip(f"node is missing (apt-get install nodejs): the {client} client test is skipped")
    if chromium() is None:
        pytest.skip(f"chromium is missing (make test installs it when root): the {client} test is skipped")
    env = dict(os.environ, NODE_PATH=os.pathsep.join(d for d in NODE_MODULES if d))
    for pkg in ("puppeteer-core", *packages):
        r = subprocess.run(["node", "-e", f"require.resolve('{pkg}')"], env=env, capture_output=True)
        if r.returncode:
            pytest.skip(f"npm package {pkg} not found (`rm .stamp-node; make setup` installs it into .node)")
    return env


def three_env() -> dict:
    return _node_env("three.js", ("three",))


def babylon_env() -> dict:
    return _node_env("Babylon.js", ("babylonjs", "babylonjs-loaders"))


def package_dir(env: dict, pkg: str) -> str:
    """The folder of npm package ``pkg`` on ``env``'s NODE_PATH."""
    find = (
        "const fs = require('fs'), path = require('path');"
        f"let d = path.dirname(require.resolve('{pkg}'));"
        "const named = (d) => { const f = path.join(d, 'package.json');"
        f" return fs.existsSync(f) && JSON.parse(fs.readFileSync(f, 'utf8')).name === '{pkg}'; }};"
        "while (!named(d) && path.dirname(d) !== d) d = path.dirname(d);"
        "console.log(d)"
    )
    r = subprocess.run(
        ["node", "-e", find],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return r.stdout.strip()


def draw_three(jobs: list[dict]) -> list[tuple[np.ndarray, dict]]:
    """Draw each job (``glb``, ``width``, ``height``, optional ``camera``, ``clear``, ``plugin``)
    with three.js; returns ``(image (h, w, 3) uint8 sRGB, info)`` per job, info = ``{"warnings":
    [the page's console warnings and errors, Chromium's own notes left out], "materials": [...]}``."""
    env = three_env()
    return _draw(THREE_JS, {"three": package_dir(env, "three")}, jobs, env)


def draw_babylon(jobs: list[dict]) -> list[tuple[np.ndarray, dict]]:
    """:func:`draw_three` with Babylon.js (``plugin``: the shipped glTF loader extension)."""
    env = babylon_env()
    libs = {"babylon": package_dir(env, "babylonjs"), "loaders": package_dir(env, "babylonjs-loaders")}
    return _draw(BABYLON_JS, libs, jobs, env)


def _draw(script: Path, libs: dict, jobs: list[dict], env: dict) -> list[tuple[np.ndarray, dict]]:
    with tempfile.TemporaryDirectory(prefix="iat-client-") as tmp:
        spec = {**libs, "chromium": chromium(), "jobs": []}
        for k, j in enumerate(jobs):
            spec["jobs"].append(
                {
                    **j,
                    "glb": str(j["glb"]),
                    "plugin": str(j["plugin"]) if j.get("plugin") else None,
                    "out": str(Path(tmp) / f"{k}.png"),
                }
            )
        (Path(tmp) / "jobs.json").write_text(json.dumps(spec))
        r = subprocess.run(
            ["node", str(script), str(Path(tmp) / "jobs.json")],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert r.returncode == 0, r.stderr[-3000:]
        infos = json.loads(r.stdout.strip().splitlines()[-1])
        out = []
        for j, info in zip(spec["jobs"], infos, strict=True):
            img = np.asarray(Image.open(j["out"]).convert("RGB"))
            info["warnings"] = [w for w in info["warnings"] if not any(x in w for x in _NOISE)]
            assert not info.get("blank"), f"{script.stem} drew nothing for {j['glb']} (WebGL context lost?)"
            out.append((img, info))
        return out


def file_codes(radiance: np.ndarray, scale: float) -> np.ndarray:
    """(h, w, 3) float sRGB codes in [0, 1] of ``radiance / scale`` clipped: an image at the file's
    exposure, as a client shows it."""
    return srgb_encode(np.clip(np.asarray(radiance, np.float64) / scale, 0.0, 1.0))


def see_through(img8: np.ndarray, covered: np.ndarray) -> int:
    """Pixels of a client image cleared to magenta where the reference shows a surface."""
    return int(((img8 == MAGENTA).all(axis=-1) & covered).sum())


BLENDER_RENDER = ROOT / "tests" / "support" / "blender_render.py"


def draw_blender(glb, out_png, size, script=None) -> tuple[np.ndarray, list[str]]:
    """Import ``glb`` into Blender (Blender's importer, or ``script``'s ``import_iat``) and render
    it with Cycles from the file's first camera (``tests/support/blender_render.py``, in its own
    process); returns ``(image (h, w, 3) uint8 sRGB, names of the materials the script wired)``.
    Skips (with the reason) where ``import bpy`` fails."""
    r = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True)
    if r.returncode:
        last = (r.stderr.strip().splitlines() or ["?"])[-1]
        pytest.skip(f"bpy (Blender as a module) cannot be imported: {last}")
    job = {
        "glb": str(glb),
        "out": str(out_png),
        "width": int(size[0]),
        "height": int(size[1]),
        "camera": 0,
        "script": str(script) if script else None,
        "reader": str(BLENDER_SCRIPT),
    }
    spec = Path(out_png).with_suffix(".json")
    spec.write_text(json.dumps(job))
    r = subprocess.run(
        [sys.executable, str(BLENDER_RENDER), str(spec)], capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    info = json.loads(r.stdout.strip().splitlines()[-1])
    return np.asarray(Image.open(out_png).convert("RGB")), info["wired"]
