"""``python -m viewer [SOL|MODEL]``: the IAT viewer (``iat view`` does the same).

Options: ``--size WxH``, ``--max-depth N`` (solve depth for a model without a
solution), ``--bench`` (frame times while re-baking, JSON), ``--screenshots DIR``
(the README's pictures).
"""

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
    p.add_argument("--max-depth", type=int, default=None, help="solve depth for a model without a solution")
    p.add_argument("--bench", action="store_true", help="frame times while re-baking; prints JSON")
    p.add_argument("--screenshots", metavar="DIR", help="write the README's screenshots to DIR and exit")
    args = p.parse_args(argv)

    from iat.radiosity import SolveOptions

    opts = None if args.max_depth is None else SolveOptions(max_depth=args.max_depth)
    try:
        if args.bench:
            from viewer.bench import benchmark_rebake_frames

            res = benchmark_rebake_frames(args.path, size=args.size, max_depth=args.max_depth or 4)
            print(json.dumps(res, indent=1))
            return 0 if res["ok"] else 1
        if args.screenshots:
            from viewer.bench import capture_screenshots

            for f in capture_screenshots(args.screenshots, args.path, size=args.size, solve_options=opts):
                print(f)
            return 0
    except RuntimeError as e:
        print(f"python -m viewer: {e}", file=sys.stderr)
        return 2
    from viewer.app import main

    return main(args.path, size=args.size, solve_options=opts)


if __name__ == "__main__":
    sys.exit(cli())
