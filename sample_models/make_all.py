"""Regenerate every sample model: ``python sample_models/make_all.py [-o DIR] [--check]``.

Runs each model script's ``build(path)`` (Cornell box, house, cave, lava pit,
pool, and the house's daylight variant) and writes ``NAME.glb`` into ``DIR``
(default: this folder, replacing the kept files). ``--check`` builds into a
temporary folder instead and exits 1 when a kept file differs from what its
script makes now (a stale model).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import tempfile
from pathlib import Path

_HERE = Path(__file__).resolve().parent
if str(_HERE.parent) not in sys.path:  # run as a script: make `sample_models` and `iat` importable
    sys.path.insert(0, str(_HERE.parent))

#: the sample models, in the order they are built
MODELS = ("cornell_box", "house", "cave", "lavapit", "pool", "house_day")
#: models made by another model's script: name -> (script, build keywords)
VARIANTS = {"house_day": ("house", {"daylight": True})}


def build_one(name: str, path: str | Path) -> Path:
    """Build the model ``name`` into ``path``; returns the path."""
    script, kw = VARIANTS.get(name, (name, {}))
    return importlib.import_module(f"sample_models.{script}").build(path, **kw)


def build_all(out_dir: str | Path = _HERE, names=MODELS) -> list[Path]:
    """Build the named models into ``out_dir`` as ``NAME.glb``; returns the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [build_one(n, out_dir / f"{n}.glb") for n in names]


def stale(names=MODELS) -> list[str]:
    """Names of the models whose kept ``.glb`` differs from (or is missing against) a fresh build."""
    with tempfile.TemporaryDirectory() as tmp:
        fresh = build_all(tmp, names)
        return [
            n
            for n, p in zip(names, fresh, strict=True)
            if not (_HERE / f"{n}.glb").is_file() or (_HERE / f"{n}.glb").read_bytes() != p.read_bytes()
        ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Regenerate the sample models (GLB) from their scripts.")
    ap.add_argument(
        "-o", "--output-dir", default=str(_HERE), help="folder for the .glb files (default: %(default)s)"
    )
    ap.add_argument(
        "--check", action="store_true", help="only report kept files that are stale; exit 1 if any"
    )
    ap.add_argument(
        "models", nargs="*", metavar="MODEL", help=f"which models (default: all of {', '.join(MODELS)})"
    )
    args = ap.parse_args(argv)
    unknown = [n for n in args.models if n not in MODELS]
    if unknown:
        ap.error(f"unknown model(s) {', '.join(unknown)}; choose from {', '.join(MODELS)}")
    names = tuple(args.models) or MODELS
    if args.check:
        bad = stale(names)
        for n in bad:
            print(f"stale: sample_models/{n}.glb (run python sample_models/make_all.py)")
        return 1 if bad else 0
    for p in build_all(args.output_dir, names):
        print(f"{p}  ({p.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
