"""``python -m viewer [SOL|MODEL] [--size WxH] [--max-depth N] [--bench]``: the IAT viewer."""

from __future__ import annotations

import argparse
import json
import sys


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1280x800, got {text!r}") from None
    return w, h


def cli(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m viewer", description="IAT walkthrough viewer and tuning tool")
    p.add_argument("path", nargs="?", help="model or solution (.npz); default: the Cornell box")
    p.add_argument("--size", type=_size, default=(1280, 800), metavar="WxH", help="window size")
    p.add_argument("--max-depth", type=int, default=None, help="solve depth for models without a solution")
    p.add_argument("--bench", action="store_true", help="measure frame times while re-baking, print JSON")
    args = p.parse_args(argv)
    if args.bench:
        from .app import benchmark_rebake_frames

        try:
            res = benchmark_rebake_frames(args.path, size=args.size, max_depth=args.max_depth or 4)
        except RuntimeError as e:
            print(f"python -m viewer --bench: {e}", file=sys.stderr)
            return 2
        print(json.dumps(res, indent=1))
        return 0 if res["ok"] else 1
    from .app import main

    if args.max_depth is None:
        return main(args.path, size=args.size)
    from iat.radiosity import SolveOptions

    from .app import ViewerApp, default_model

    app = ViewerApp(args.path or default_model(), size=args.size, solve_options=SolveOptions(max_depth=args.max_depth))
    try:
        app.run()
    except RuntimeError as e:
        print(f"python -m viewer: cannot open a window ({e})", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(cli())
