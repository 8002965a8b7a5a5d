"""The architecture contract of docs/design.md, enforced.

- ``import asrbf_mesh`` (and the task layer, and ``asrbf --help``) load neither pymeshlab,
  matplotlib nor dask;
- a static import graph (``ast``, relative imports resolved, imports inside functions
  included) keeps the layers one-way: core -> evaluation -> front ends; each native
  library sits behind its one adapter module; no import cycles;
- the public API is consistent: every name in ``__all__`` exists, no function shadows a
  module, every type a public function returns is exported;
- modules stay small, and nothing names a file outside the repository;
- relative links of the Markdown documents resolve, anchors included.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import re
import subprocess
import sys
import types
import typing
import unicodedata
from collections.abc import Iterator
from functools import cache
from pathlib import Path

import pytest

import asrbf_mesh as am

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("asrbf_mesh", "meshlab_filter")

#: Front ends of the package: everything else in asrbf_mesh/ outside evaluate/ is core.
FRONT_ENDS = ("asrbf_mesh.cli", "asrbf_mesh.tasks", "asrbf_mesh._batch")
#: Heavy or optional libraries that ``import asrbf_mesh`` must not load.
HEAVY = ("pymeshlab", "matplotlib", "dask", "distributed", "laspy", "tifffile", "PIL")
#: Each native library and the only modules allowed to import it.
ADAPTERS = {
    "pymeshlab": ("asrbf_mesh.evaluate._meshlab", "meshlab_filter"),
    "matplotlib": ("asrbf_mesh.evaluate._plots",),
    "fast_simplification": ("asrbf_mesh.evaluate._simplify",),
    "igl": ("asrbf_mesh._igl",),
    "dask": ("asrbf_mesh._batch",),
    "distributed": ("asrbf_mesh._batch",),
    "laspy": ("asrbf_mesh._lidar",),
    "tifffile": ("asrbf_mesh._range", "asrbf_mesh._range_write"),
}
MAX_LINES = 800


# --------------------------------------------------------------------------- the graph


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@cache
def _sources() -> dict[str, Path]:
    """Every module of the two packages: dotted name -> file."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


def _is_package(name: str) -> bool:
    return _sources()[name].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """Absolute name of the module a ``from ... import`` names (relative levels resolved)."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not _is_package(module):
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _in_function(parents: list[ast.AST]) -> bool:
    return any(isinstance(p, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
               for p in parents)


def _walk(node: ast.AST, parents: list[ast.AST]) -> Iterator[tuple[ast.AST, list[ast.AST]]]:
    yield node, parents
    for child in ast.iter_child_nodes(node):
        yield from _walk(child, [*parents, node])


@cache
def _imports() -> dict[str, list[tuple[str, bool]]]:
    """Module -> [(imported module, inside a function)], every import statement.

    ``from pkg import name`` counts as an import of ``pkg.name`` when that is a module
    of the two packages, else of ``pkg``. Imports of a module's own parent packages are
    left out (Python has loaded them before the module runs).
    """
    known = _sources()
    graph: dict[str, list[tuple[str, bool]]] = {}
    for module, path in known.items():
        edges = []
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node, parents in _walk(tree, []):
            nested = _in_function(parents)
            if isinstance(node, ast.Import):
                edges += [(alias.name, nested) for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(module, node)
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    edges.append((sub if sub in known else target, nested))
        ancestors = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)}
        graph[module] = [(t, n) for t, n in edges if t not in ancestors and t != module]
    return graph


def _matches(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _layer(module: str) -> str:
    if module.startswith("meshlab_filter"):
        return "front end"
    if _matches(module, FRONT_ENDS):
        return "front end"
    if _matches(module, ("asrbf_mesh.evaluate",)):
        return "evaluation"
    return "core"


def _violations(layer: str, forbidden: tuple[str, ...]) -> list[str]:
    return [f"{m} imports {t}{' (in a function)' if nested else ''}"
            for m, edges in sorted(_imports().items()) if _layer(m) == layer
            for t, nested in edges if _matches(t, forbidden)]


def test_the_graph_sees_every_module_and_relative_import() -> None:
    graph = _imports()
    assert {"asrbf_mesh", "asrbf_mesh._piece", "asrbf_mesh.evaluate._metro",
            "meshlab_filter._filters"} <= set(graph)
    # ``from . import _network_kernels as _nk`` and ``from .errors import ConfigError``
    targets = {t for t, _ in graph["asrbf_mesh._piece"]}
    assert {"asrbf_mesh._network_kernels", "asrbf_mesh.errors", "numpy"} <= targets
    # ``from .._io import Scan`` one package up, and an import inside a function
    assert ("asrbf_mesh._io", False) in graph["asrbf_mesh.evaluate._metro"]
    assert ("asrbf_mesh._fit", True) in graph["asrbf_mesh.evaluate._som"]


def test_core_imports_neither_evaluation_nor_front_ends_nor_heavy_libraries() -> None:
    forbidden = ("asrbf_mesh.evaluate", *FRONT_ENDS, "meshlab_filter", "pymeshlab",
                 "matplotlib", "fast_simplification", "dask", "distributed")
    assert _violations("core", forbidden) == []


def test_evaluation_imports_no_front_end() -> None:
    assert _violations("evaluation", (*FRONT_ENDS, "meshlab_filter", "dask",
                                      "distributed")) == []


def test_meshlab_filter_imports_no_other_front_end() -> None:
    bad = [f"{m} imports {t}" for m, edges in sorted(_imports().items())
           if m.startswith("meshlab_filter") for t, _ in edges if _matches(t, FRONT_ENDS)]
    assert bad == []


def test_each_native_library_sits_behind_its_adapter() -> None:
    bad = [f"{m} imports {t} (only {', '.join(ADAPTERS[lib])} may)"
           for m, edges in sorted(_imports().items()) for t, _ in edges
           for lib in ADAPTERS if _matches(t, (lib,)) and not _matches(m, ADAPTERS[lib])]
    assert bad == []


def _cycles(include_functions: bool) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph = {m: sorted({t for t, nested in edges if t in _sources()
                        and (include_functions or not nested)})
             for m, edges in _imports().items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_no_import_cycle_at_module_level() -> None:
    assert _cycles(include_functions=False) == []


def test_no_import_cycle_at_all() -> None:
    assert _cycles(include_functions=True) == []


# --------------------------------------------------------------------------- what loads


def _loaded_after(code: str) -> set[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    probe = (f"{code}\nimport sys\n"
             "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, text=True,
                         capture_output=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


#: What the lazy public API keeps out of ``import asrbf_mesh`` and ``asrbf --help`` too.
COMPILED = ("numba", "scipy", "llvmlite")


def test_import_asrbf_mesh_loads_no_heavy_library() -> None:
    loaded = _loaded_after("import asrbf_mesh")
    assert loaded.isdisjoint(HEAVY + COMPILED), sorted(loaded & set(HEAVY + COMPILED))
    assert "asrbf_mesh" in loaded
    # a public name loads its module on first use, and only the core
    loaded = _loaded_after("import asrbf_mesh as am\nam.fit")
    assert "numba" in loaded and loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))


def test_import_of_the_task_layer_loads_no_heavy_library() -> None:
    if importlib.util.find_spec("asrbf_mesh.tasks") is None:
        pytest.skip("asrbf_mesh.tasks does not exist yet")
    loaded = _loaded_after("import asrbf_mesh.tasks")
    assert loaded.isdisjoint(HEAVY), sorted(loaded & set(HEAVY))


def test_cli_help_loads_no_heavy_library() -> None:
    code = ("import runpy, sys, contextlib, io\n"
            "sys.argv = ['asrbf', '--help']\n"
            "with contextlib.redirect_stdout(io.StringIO()) as buf:\n"
            "    try:\n"
            "        runpy.run_module('asrbf_mesh.cli', run_name='__main__')\n"
            "    except SystemExit as exc:\n"
            "        assert exc.code in (0, None), exc.code\n"
            "assert 'usage' in buf.getvalue()")
    loaded = _loaded_after(code)
    assert loaded.isdisjoint(HEAVY + COMPILED), sorted(loaded & set(HEAVY + COMPILED))


# --------------------------------------------------------------------------- public API


def _public_modules() -> list[str]:
    return [m for m in _sources() if m.startswith("asrbf_mesh.")
            and not m.rsplit(".", 1)[1].startswith("_")]


@pytest.mark.parametrize("package", ["asrbf_mesh", "asrbf_mesh.evaluate", "meshlab_filter"])
def test_every_name_in_all_exists(package: str) -> None:
    mod = importlib.import_module(package)
    assert len(set(mod.__all__)) == len(mod.__all__)
    assert [n for n in mod.__all__ if not hasattr(mod, n)] == []


@pytest.mark.parametrize("package", ["asrbf_mesh", "asrbf_mesh.evaluate"])
def test_no_public_name_is_also_a_module(package: str) -> None:
    mod = importlib.import_module(package)
    folder = ROOT.joinpath(*package.split("."))
    clash = [n for n in mod.__all__
             if (folder / f"{n}.py").exists() or (folder / n / "__init__.py").exists()]
    assert clash == []


def test_public_modules_are_modules_on_the_package() -> None:
    for name in _public_modules():
        importlib.import_module(name)
        parent, attr = name.rsplit(".", 1)
        assert isinstance(getattr(importlib.import_module(parent), attr), types.ModuleType), name


def _exported() -> set[int]:
    ev = importlib.import_module("asrbf_mesh.evaluate")
    return {id(getattr(mod, n)) for mod in (am, ev) for n in mod.__all__}


def _classes(hint: object) -> Iterator[type]:
    """The classes named by a type hint (unions, containers and their arguments)."""
    args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if args or origin is not None:
        if isinstance(origin, type):
            yield origin
        for a in args:
            yield from _classes(a)
    elif isinstance(hint, type):
        yield hint


def _public_functions() -> list[tuple[str, object]]:
    ev = importlib.import_module("asrbf_mesh.evaluate")
    return [(f"{mod.__name__}.{n}", getattr(mod, n)) for mod in (am, ev) for n in mod.__all__
            if inspect.isfunction(getattr(mod, n))]


@pytest.mark.parametrize("name", [n for n, _ in _public_functions()])
def test_types_returned_by_public_functions_are_exported(name: str) -> None:
    func = dict(_public_functions())[name]
    hint = typing.get_type_hints(func).get("return")
    assert hint is not None, f"{name} has no return annotation"
    ours = [c for c in _classes(hint) if c.__module__.split(".")[0] == "asrbf_mesh"]
    missing = [c.__qualname__ for c in ours if id(c) not in _exported()]
    assert missing == [], f"{name} returns {missing}, not in asrbf_mesh or asrbf_mesh.evaluate"


# --------------------------------------------------------------------------- size, paths


@pytest.mark.parametrize("path", [
    p for p in sorted(str(f.relative_to(ROOT).as_posix())
                    for f in (ROOT / "asrbf_mesh").rglob("*.py"))])
def test_no_module_exceeds_the_line_budget(path: str) -> None:
    n = len((ROOT / path).read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"{path}: {n} lines (budget {MAX_LINES}): split it by concept"


_OUTSIDE = re.compile(r"\.\./shared|/work/|DESIGN\.md")


def _text_files(top: Path) -> Iterator[Path]:
    paths = [top] if top.is_file() else sorted(p for p in top.rglob("*") if p.is_file())
    for p in paths:
        if "__pycache__" in p.parts or p.resolve() == Path(__file__).resolve():
            continue
        try:
            p.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue  # images, binary scans
        yield p


@pytest.mark.parametrize("top", [
    "README.md", "docs", "asrbf_mesh", "meshlab_filter", "scripts", "tests", "pyproject.toml",
    "BENCHMARKS.md",
])
def test_nothing_names_a_file_outside_the_repository(top: str) -> None:
    hits = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}"
            for p in _text_files(ROOT / top)
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if _OUTSIDE.search(line)]
    assert hits == []


# --------------------------------------------------------------------------- links


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"<[^>]+>", "", heading).strip().lower()
    keep = "".join(ch for ch in text if ch in " -_"
                   or unicodedata.category(ch)[0] in ("L", "M", "N"))
    return keep.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    fence = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence = not fence
        m = None if fence else re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            slug = _slug(m.group(1))
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            out.add(slug if n == 0 else f"{slug}-{n}")
    return out


@pytest.mark.parametrize("doc", ["README.md", "BENCHMARKS.md", "docs/design.md",
                                 "docs/results.md"])
def test_relative_links_resolve(doc: str) -> None:
    path = ROOT / doc
    if not path.exists():
        pytest.skip(f"{doc} does not exist")
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    bad = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+://|mailto:", target):
            continue
        file, _, anchor = target.partition("#")
        # "/X" is relative to the repository root (as GitHub renders it), "X" to the document
        dest = ((ROOT / file.lstrip("/")) if file.startswith("/") else
                (path.parent / file)).resolve() if file else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{target}: no heading with that anchor")
    assert bad == []
