"""The layout rules of docs/architecture.md that import-linter does not check: no module imports
another module's private (``_name``) names, and no module (library, app or test) is over 800 lines.
(The layers, the ban on ``iat`` importing ``viewer`` and the absence of cycles are import-linter's
contracts in pyproject.toml, run by ``make test``.)"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 800


def _sources(*folders):
    return sorted(p for d in folders for p in (ROOT / d).rglob("*.py"))


def test_no_private_name_is_imported_across_modules():
    found = []
    for path in _sources("iat", "viewer", "tests", "benchmarks", "sample_models"):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ImportFrom):
                mod = node.module or ""
                names = [a.name for a in node.names]
                if any(n.startswith("_") and not n.startswith("__") for n in [*names, *mod.split(".")]):
                    where = f"{path.relative_to(ROOT)}:{node.lineno}"
                    found.append(f"{where}: from {mod} import {', '.join(names)}")
    assert not found, "private names imported across modules:\n" + "\n".join(found)


def test_no_module_is_over_800_lines():
    long = [
        f"{p.relative_to(ROOT)}: {n} lines"
        for p in _sources("iat", "viewer", "tests")
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    ]
    assert not long, "split these by topic:\n" + "\n".join(long)
