"""The package's shape, read statically with ``ast`` (docs/architecture.md, "Habits"): no function in ``polyjax/`` or
``baselines/`` longer than 80 lines unless the first paragraph of its docstring says why, in the words
``Over 80 lines because``; ``polyjax`` never imports ``baselines``; no import circle in either package (imports
inside functions counted); imports of the project's own modules inside functions only in the command dispatcher
and the lazy package faces; at most 16 modules at the root of ``polyjax``; ``baselines`` imports nothing private of
``polyjax``; the tests reach polyjax and baselines through their public faces, ``polyjax.internal`` and their
switches (no private module imported, no private attribute monkeypatched). Each check has a self-test that shows it
can fail."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("polyjax", "baselines")
MAX_LINES = 80
#: the words that, in the first paragraph of a long function's docstring, say why it is long
WHY_LONG = "Over 80 lines because"
#: modules at the root of ``polyjax`` besides ``__init__.py`` and ``__main__.py``
MAX_ROOT_MODULES = 16
#: where a function may import the project's own modules: the command dispatcher (one lazy import per command) and,
#: in every package's ``__init__.py``, the lazy face ``__getattr__``
LOCAL_IMPORTS_ALLOWED = ("polyjax/cli/_main.py",)


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


# ---------------------------------------------------------------- the import graph: circles, local imports

def module_name(rel: str) -> str:
    """``polyjax/_fit/log.py`` -> ``polyjax._fit.log``; a package's ``__init__.py`` is the package."""
    parts = list(Path(rel).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    """The absolute name of ``from <level dots><name> import ...`` in ``module``."""
    if level == 0:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def import_edges(sources: dict[str, str]) -> dict[str, set[str]]:
    """The import graph of the modules ``sources`` (``{path: text}``): module -> the modules of ``sources`` it
    imports, at the top or inside a function: ``import a.b`` is an edge to ``a.b``; ``from a import b`` to ``a.b`` when
    that is a module, else to ``a``; ``importlib.import_module`` with a literal name (resolved against its
    ``package``) too. A package's ``__init__.py`` is a node like any module (its imports are edges)."""
    modules = {module_name(rel): rel for rel in sources}
    edges: dict[str, set[str]] = {m: set() for m in modules}

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    for mod, rel in modules.items():
        is_package = rel.endswith("__init__.py")
        for node in ast.walk(ast.parse(sources[rel])):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_package, node.level, node.module)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) ==
                  "import_module" and node.args and isinstance(node.args[0], ast.Constant)):
                name = str(node.args[0].value)
                level = len(name) - len(name.lstrip("."))
                targets = [_resolve(mod, is_package, level, name.lstrip(".") or None) if level else name]
            edges[mod] |= {t for t in map(known, targets) if t is not None and t != mod}
    return edges


def import_circles(sources: dict[str, str]) -> list[list[str]]:
    """Every import circle of ``sources``: the strongly connected components of :func:`import_edges` with more
    than one module (Tarjan's algorithm), each sorted."""
    edges = import_edges(sources)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return circles


def local_own_imports(rel: str, source: str, own=PACKAGES) -> list[str]:
    """``path:line module`` of every import of the project's own modules (``own``, or relative) inside a function of
    ``source``, but in :data:`LOCAL_IMPORTS_ALLOWED` and in a package face's ``__getattr__``."""
    if rel in LOCAL_IMPORTS_ALLOWED:
        return []
    found = []
    for func in ast.walk(ast.parse(source)):
        if not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        if func.name == "__getattr__" and rel.endswith("__init__.py"):
            continue
        for node in ast.walk(func):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = ["." * node.level + (node.module or "")]
            else:
                continue
            found += [f"{rel}:{node.lineno} {n}" for n in names if n.startswith(".") or n.split(".")[0] in own]
    return sorted(set(found))


def root_modules(names) -> list[str]:
    """The modules among the file names ``names`` of the package root, but ``__init__.py`` and ``__main__.py``."""
    return sorted(n for n in names if n.endswith(".py") and n not in ("__init__.py", "__main__.py"))


def private_polyjax_imports(rel: str, source: str) -> list[str]:
    """``path:line module`` of every import of a private polyjax module in ``source`` (a module outside polyjax):
    a module path with a part that starts with ``_`` (``polyjax._io``, ``from polyjax import _io``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
        else:
            continue
        found += [f"{rel}:{node.lineno} {n}" for n in names
                  if n.split(".")[0] == "polyjax" and any(p.startswith("_") for p in n.split(".")[1:])]
    return found


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circle(package):
    sources = dict(_sources((package,)))
    assert import_circles(sources) == []
    edges = import_edges(sources)  # the graph is read (not vacuous): the face imports its modules
    assert len(edges) == len(sources) and len(edges[package]) >= 5


def test_own_modules_imported_inside_functions_only_by_the_dispatcher_and_lazy_faces():
    found = [hit for rel, source in _sources() for hit in local_own_imports(rel, source)]
    assert found == [], "import at the top of the module (or lazily in a package face's __getattr__): " + "; ".join(
        found)


def test_at_most_16_modules_at_the_package_root():
    found = root_modules(p.name for p in (ROOT / "polyjax").glob("*.py"))
    assert 10 <= len(found) <= MAX_ROOT_MODULES, found


def test_baselines_imports_nothing_private_of_polyjax():
    found = [hit for rel, source in _sources(("baselines",)) for hit in private_polyjax_imports(rel, source)]
    assert found == []
    sources = dict(_sources(("baselines",)))  # the scan sees baselines' imports of polyjax (it is not vacuous)
    assert any("polyjax" in n for n, _ in imported_modules(sources["baselines/_fit.py"], "baselines"))


@pytest.mark.parametrize("sources, circle", [
    ({"p/__init__.py": "", "p/a.py": "from . import b\n", "p/b.py": "def f():\n    from .a import x\n"},
     ["p.a", "p.b"]),
    ({"p/__init__.py": "from .a import x\n", "p/a.py": "import p\n"}, ["p", "p.a"]),
    ({"p/__init__.py": "", "p/a.py": "from .b import c\n", "p/b.py": "import importlib\n"
      "def f():\n    return importlib.import_module('p.a')\n"}, ["p.a", "p.b"]),
    ({"p/__init__.py": "", "p/q/__init__.py": "", "p/q/a.py": "from ..b import x\n", "p/b.py": "from .q import a\n"},
     ["p.b", "p.q.a"]),
    ({"p/__init__.py": "from .a import x\n", "p/a.py": "from .b import y\n", "p/b.py": "import numpy\n"}, None),
])
def test_circle_check_finds_circles_through_functions_and_faces(sources, circle):
    assert import_circles(sources) == ([circle] if circle else [])


@pytest.mark.parametrize("rel, source, flagged", [
    ("polyjax/_x.py", "def f():\n    from ._fit import polynomial\n", True),
    ("polyjax/render/_x.py", "def f():\n    import polyjax as pj\n", True),
    ("baselines/_x.py", "class A:\n    def m(self):\n        from ._result import BaselineFit\n", True),
    ("polyjax/render/__init__.py", "def build():\n    from . import _brdf\n", True),
    ("polyjax/render/__init__.py", "def __getattr__(name):\n    from . import _brdf\n", False),
    ("polyjax/cli/_main.py", "def f():\n    from . import _fit\n", False),
    ("polyjax/_x.py", "from ._fit import polynomial\ndef f():\n    import mitsuba\n", False),
])
def test_local_import_check_reads_functions(rel, source, flagged):
    assert (local_own_imports(rel, source) != []) is flagged


@pytest.mark.parametrize("names, over", [
    ([f"_m{i}.py" for i in range(MAX_ROOT_MODULES)] + ["__init__.py", "__main__.py", "page.html"], False),
    ([f"_m{i}.py" for i in range(MAX_ROOT_MODULES + 1)] + ["__init__.py"], True),
])
def test_root_module_count_leaves_out_the_package_files(names, over):
    assert (len(root_modules(names)) > MAX_ROOT_MODULES) is over


@pytest.mark.parametrize("source, flagged", [
    ("from polyjax._io import module_kind\n", True),
    ("from polyjax import _io\n", True),
    ("import polyjax._fit.saved as saved\n", True),
    ("def f():\n    from polyjax.render._brdf import rgb_brdf\n", True),
    ("from polyjax.internal import prepare_inputs\nimport polyjax.render as pr\nfrom polyjax import RESULTS\n", False),
    ("from ._result import BaselineFit\n", False),
])
def test_private_import_check(source, flagged):
    assert (private_polyjax_imports("baselines/_x.py", source) != []) is flagged


# ---------------------------------------------------------------- tests reach the library through its public faces

#: the one module with a leading-underscore-free name that is nevertheless not the user's API: allowed in tests
TEST_ALLOWED_PRIVATE = ("polyjax.internal",)
#: the receivers of ``setattr``/``delattr`` calls read as pytest's monkeypatch fixture
MONKEYPATCH_NAMES = ("monkeypatch", "mp")


def _test_sources():
    """``(path, text)`` of the test modules (``tests/test_*.py``) and their shared helpers (``tests/_*.py``), but this
    file (whose checks hold private imports as examples, in strings)."""
    for path in sorted((ROOT / "tests").glob("*.py")):
        if path.name.startswith(("test_", "_")) and path.name != "__init__.py" and path.name != Path(__file__).name:
            yield f"tests/{path.name}", path.read_text(encoding="utf-8")


def _is_private(dotted: str) -> bool:
    """Whether ``dotted`` (``polyjax._io``, ``baselines._models.openpbr``, ``polyjax.data._merl``) names something
    private of polyjax or baselines: a component after the package that starts with ``_`` (dunders such as
    ``__version__`` are public), and not :data:`TEST_ALLOWED_PRIVATE`."""
    parts = dotted.split(".")
    if parts[0] not in PACKAGES or dotted in TEST_ALLOWED_PRIVATE:
        return False
    return any(p.startswith("_") and not (p.startswith("__") and p.endswith("__")) for p in parts[1:])


def _dotted(node) -> str | None:
    """``a.b.c`` of a name or attribute chain, else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id] + parts[::-1])


def private_test_access(rel: str, source: str) -> list[str]:
    """``path:line what`` of every way ``source`` (a test file) reaches past the public faces of polyjax and
    baselines: an import of a private module or name (``import polyjax._fit.log``, ``from polyjax.data import
    _merl``, ``from baselines._models.openpbr import open_pbr_surface``, ``importlib.import_module`` of one), the same
    in Python code held in a string (a subprocess's script), and ``monkeypatch.setattr``/``delattr`` of a private
    attribute (``"_x"``), of a private module or attribute (``pj._fit.stream``) or of a name imported from one.
    :data:`TEST_ALLOWED_PRIVATE` is public for this purpose."""
    found: list[str] = []
    tree = ast.parse(source)
    private_names: set[str] = set()  # local names bound to private modules or names
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if _is_private(a.name):
                    found.append(f"{rel}:{node.lineno} import {a.name}")
                    private_names.add(a.asname or a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                if _is_private(node.module) or _is_private(full):
                    found.append(f"{rel}:{node.lineno} from {node.module} import {a.name}")
                    private_names.add(a.asname or a.name)
        elif isinstance(node, ast.Call) and (_dotted(node.func) or "").endswith("import_module") and node.args \
                and isinstance(node.args[0], ast.Constant) and _is_private(str(node.args[0].value)):
            found.append(f"{rel}:{node.lineno} import_module({node.args[0].value!r})")
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and ("polyjax" in node.value
                                                                               or "baselines" in node.value):
            try:  # Python code in a string, e.g. the script of a subprocess
                inner = ast.parse(node.value)
            except SyntaxError:
                continue
            if any(isinstance(n, (ast.Import, ast.ImportFrom)) for n in ast.walk(inner)):
                found += [f"{rel}:{node.lineno} (in a string) {hit.split(' ', 1)[1]}"
                          for hit in private_test_access(rel, node.value)]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in (
                "setattr", "delattr") and (_dotted(node.func.value) or "").split(".")[-1] in MONKEYPATCH_NAMES \
                and node.args:
            target, name = node.args[0], node.args[1] if len(node.args) > 1 else None
            where = _dotted(target) or ""
            private = (
                (isinstance(target, ast.Constant) and _is_private(str(target.value)))
                or (isinstance(name, ast.Constant) and str(name.value).startswith("_")
                    and not str(name.value).startswith("__"))
                or _is_private("polyjax." + where.partition(".")[2]) or where.split(".")[0] in private_names
            )  # a private name set; a private module or attribute patched (pj._fit.stream); a private import's
            if private:
                found.append(f"{rel}:{node.lineno} monkeypatch.{node.func.attr}({ast.unparse(target)}, "
                             f"{ast.unparse(name) if name is not None else ''})")
    return found


def test_tests_reach_the_library_through_its_public_faces():
    """Tests use the public API, ``polyjax.internal`` and the switches the library offers (environment variables,
    config calls); never private modules, nor monkeypatches of private attributes (docs/testing.md)."""
    found = [hit for rel, source in _test_sources() for hit in private_test_access(rel, source)]
    assert found == [], "tests reach private parts of the library: " + "; ".join(found)
    sources = dict(_test_sources())  # the scan sees the tests' imports of the library (it is not vacuous)
    assert len(sources) > 40 and "tests/_problems.py" in sources
    assert private_test_access("t.py", "from polyjax.internal import prepare_inputs\nimport polyjax._io\n") != []


@pytest.mark.parametrize("source, flagged", [
    ("import polyjax._fit.log\n", True),
    ("import baselines._aot as aot\n", True),
    ("from polyjax._cache.memo import GridMemo\n", True),
    ("from polyjax.data import _merl\n", True),
    ("from polyjax import _io as kinds\n", True),
    ("def f():\n    from baselines._models import mx_microfacet as mx\n", True),
    ("from polyjax.render._mitsuba import mitsuba_bsdf_eval\n", True),
    ("import importlib\nm = importlib.import_module('polyjax.cli._main')\n", True),
    ("CODE = 'import sys; from polyjax.cli._main import build_parser'\n", True),
    ("CHILD = '''\nimport baselines._aot as aot\naot._compile = None\n'''\n", True),
    ("def test(monkeypatch):\n    monkeypatch.setattr(pj, '_REGISTRY', {})\n", True),
    ("def test(monkeypatch):\n    monkeypatch.setattr('polyjax._fit.stream.BLOCK', 512)\n", True),
    ("def test(monkeypatch):\n    monkeypatch.setattr(pj._fit.stream, 'BLOCK', 512)\n", True),
    ("import polyjax._fit.stream as s\ndef test(monkeypatch):\n    monkeypatch.setattr(s, 'BLOCK', 512)\n", True),
    ("def test(monkeypatch):\n    monkeypatch.delattr(bl, '_LOADED')\n", True),
    ("import polyjax as pj\nimport polyjax.render as pr\nfrom polyjax.internal import prepare_inputs\n", False),
    ("from polyjax import __version__, internal\nfrom baselines import fit\n", False),
    ("import jax._src.compilation_cache as cc\nfrom numpy import _NoValue\n", False),
    ("def test(monkeypatch):\n    monkeypatch.setattr(pj, 'fit_polynomial', None)\n    monkeypatch.setenv('X', '1')\n",
     False),
    ('"""A docstring naming polyjax._fit.log and baselines._aot."""\n', False),
    ("CODE = 'import polyjax, sys; print(polyjax.internal.TALL_ROWS)'\n", False),
])
def test_private_test_access_check(source, flagged):
    assert (private_test_access("tests/test_x.py", source) != []) is flagged
