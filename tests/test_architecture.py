"""The package's shape, read statically with ``ast`` (docs/architecture.md, "Habits"): no function in ``polyjax/`` or
``baselines/`` longer than 80 lines unless the first paragraph of its docstring says why, in the words
``Over 80 lines because``; ``polyjax`` never imports ``baselines``."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("polyjax", "baselines")
MAX_LINES = 80
#: the words that, in the first paragraph of a long function's docstring, say why it is long
WHY_LONG = "Over 80 lines because"


def _sources(packages=PACKAGES):
    for package in packages:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


def long_functions(source: str, max_lines: int = MAX_LINES) -> list[tuple[str, int, int]]:
    """``(name, first line, length)`` of every function (nested ones and methods too) longer than ``max_lines``
    lines, from ``def`` to its last line (decorators not counted, the docstring counted), whose docstring's first
    paragraph (its line breaks read as spaces) does not contain :data:`WHY_LONG`."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        length = node.end_lineno - node.lineno + 1
        first_paragraph = " ".join((ast.get_docstring(node) or "").split("\n\n")[0].split())  # wrapping folded
        if length > max_lines and WHY_LONG not in first_paragraph:
            found.append((node.name, node.lineno, length))
    return found


def imported_modules(source: str, package: str) -> list[tuple[str, int]]:
    """``(absolute module name, line)`` of every import in ``source``, a module of ``package``: top-level and
    function-local ``import``/``from ... import``, relative imports resolved against the package (a relative
    import that leaves it is reported as ``"<outside>"``), and ``importlib.import_module("...")`` with a literal."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                found.append((node.module or "", node.lineno))
            else:  # ``from . import x`` inside the package: its own module; ``level`` beyond the package: outside
                depth = len(package.split("/"))
                name = package.split("/")[0] if node.level <= depth else "<outside>"
                found.append((name, node.lineno))
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) ==
              "import_module" and node.args and isinstance(node.args[0], ast.Constant)):
            found.append((str(node.args[0].value), node.lineno))
    return found


def _imports_baselines(rel: str, source: str) -> list[str]:
    package = str(Path(rel).parent.as_posix())
    return [f"{rel}:{line} imports {name}" for name, line in imported_modules(source, package)
            if name == "<outside>" or name == "baselines" or name.startswith("baselines.")]


def test_no_function_longer_than_80_lines_without_saying_why():
    offenders = [f"{rel}:{line} {name} ({length} lines)"
                 for rel, source in _sources() for name, line, length in long_functions(source)]
    assert offenders == [], (
        f"functions over {MAX_LINES} lines: split them into named steps, or begin the docstring with a first "
        f"paragraph that says '{WHY_LONG} ...': " + "; ".join(offenders))


def test_polyjax_never_imports_baselines():
    found = [hit for rel, source in _sources(("polyjax",)) for hit in _imports_baselines(rel, source)]
    assert found == []
    # the scan itself sees the package's own imports (it is not vacuous)
    sources = dict(_sources(("polyjax",)))
    assert any(name == "polyjax" for name, _ in imported_modules(sources["polyjax/__init__.py"], "polyjax"))


LONG_BODY = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES))


@pytest.mark.parametrize("doc, flagged", [
    ("", True),
    ('    """Does a thing."""\n', True),
    ('    """Does a thing.\n\n    Over 80 lines because the second paragraph is too late.\n    """\n', True),
    (f'    """Does a thing. {WHY_LONG} every argument is documented.\n\n    More.\n    """\n', False),
    ('    """Does a thing. Over 80\n    lines because every argument is documented.\n    """\n', False),
])
def test_long_function_check_reads_the_first_paragraph(doc, flagged):
    source = f"def f():\n{doc}{LONG_BODY}\n"
    assert (long_functions(source) != []) is flagged
    assert long_functions("def g():\n    return 1\n") == []
    nested = f"def outer():\n    def inner():\n{doc.replace('    ', '        ')}" + LONG_BODY.replace(
        "    ", "        ") + "\n    return inner\n"
    assert [name for name, _, _ in long_functions(nested)] == (["outer", "inner"] if flagged else ["outer"])


@pytest.mark.parametrize("source, package, hit", [
    ("import baselines\n", "polyjax", True),
    ("import baselines._fit as bf\n", "polyjax/render", True),
    ("def f():\n    from baselines import fit\n    return fit\n", "polyjax", True),
    ("from ... import baselines\n", "polyjax/render", True),
    ("import importlib\nm = importlib.import_module('baselines')\n", "polyjax", True),
    ("from .. import _fit\n", "polyjax/render", False),
    ("import numpy as np\nfrom polyjax import fit_polynomial\n", "polyjax/data", False),
])
def test_import_scan_finds_baselines(source, package, hit):
    assert (_imports_baselines(f"{package}/m.py", source) != []) is hit
