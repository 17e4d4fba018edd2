"""The package's import graph follows the seam of design.md.

- ``gearjax._engine`` knows ``System`` only: it imports nothing from the gear model,
  the studies, the files, the figures or the command line;
- no import cycle, function-level imports included;
- no module imports another module's private (underscore) names;
- no module longer than ``MAX_LINES`` without the reason written in its docstring, and
  none of the command line's modules longer at all;
- the command line (``gearjax._cli``) is the top: no other module imports it;
- benchmarks and notebooks use the public API (``import gearjax``) only.
"""

from __future__ import annotations

import ast
import importlib.metadata
import json
import pathlib
import re
import types

import pytest

import gearjax

PACKAGE = pathlib.Path(gearjax.__file__).parent
ROOT = PACKAGE.parent
MAX_LINES = 600
LONG_REASON = "Why this module is long:"
CLI = "gearjax._cli"
ENGINE_MAY_NOT_IMPORT = ("gearjax._gear", "gearjax._studies", "gearjax._io", "gearjax._plot",
                         "gearjax._cli")


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _resolve(name: str, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = name.split(".") if _is_package(name) else name.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(name: str):
    """``(target module, imported name or None, line)`` of every import in module ``name``,
    at any depth (function-level imports included)."""
    tree = ast.parse(MODULES[name].read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("gearjax"):
                    yield a.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(name, node)
            if not target.startswith("gearjax"):
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                if sub in MODULES:
                    yield sub, None, node.lineno
                else:
                    yield target, a.name, node.lineno


def _edges():
    return {name: {t for t, _, _ in _imports(name) if t in MODULES and t != name}
            for name in MODULES}


def test_engine_knows_only_system():
    bad = [f"{name}:{line} imports {target}" for name in MODULES
           if name.startswith("gearjax._engine")
           for target, _, line in _imports(name) if target.startswith(ENGINE_MAY_NOT_IMPORT)]
    assert not bad, "\n".join(bad)


def test_no_import_cycles():
    edges = _edges()
    # Tarjan's strongly connected components
    index, low, stack, on, cycles, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_no_private_names_across_modules():
    """``from m import _x`` where ``_x`` is not a module, or ``m._x`` on an imported module
    ``m``, from any module other than ``m`` itself (a package's ``__init__`` may gather
    names from its own modules)."""
    bad = []
    for name in MODULES:
        tree = ast.parse(MODULES[name].read_text())
        aliases = {}
        for target, imported, line in _imports(name):
            if imported is not None and imported.startswith("_") and not imported.startswith(
                    "__"):
                if not (_is_package(name) and target.startswith(name + ".")):
                    bad.append(f"{name}:{line} imports {target}.{imported}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(name, node)
                for a in node.names:
                    if f"{target}.{a.name}" in MODULES:
                        aliases[a.asname or a.name] = f"{target}.{a.name}"
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                bad.append(f"{name}:{node.lineno} uses {aliases[node.value.id]}.{node.attr}")
    assert not bad, "\n".join(bad)


def test_long_modules_say_why():
    long = []
    for name, path in MODULES.items():
        text = path.read_text()
        n = text.count("\n")
        doc = ast.get_docstring(ast.parse(text)) or ""
        if n > MAX_LINES and LONG_REASON not in doc:
            long.append(f"{name}: {n} lines")
    assert not long, f"modules over {MAX_LINES} lines without '{LONG_REASON}': {long}"


def test_command_line_modules_are_short():
    """The command line is a package of thin commands: each module under ``MAX_LINES``."""
    lines = {name: MODULES[name].read_text().count("\n") for name in MODULES
             if name.startswith(CLI)}
    assert len(lines) > 1, "the command line is a package"
    long = [f"{name}: {n} lines" for name, n in lines.items() if n > MAX_LINES]
    assert not long, long


def test_nothing_imports_the_command_line():
    bad = [f"{name}:{line} imports {target}" for name in MODULES if not name.startswith(CLI)
           for target, _, line in _imports(name) if target.startswith(CLI)]
    assert not bad, "\n".join(bad)


def _gearjax_imports(source: str):
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names if a.name.startswith("gearjax"))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("gearjax"):
            yield node.module


def _notebook_code(path: pathlib.Path) -> str:
    cells = json.loads(path.read_text())["cells"]
    lines = []
    for c in cells:
        if c["cell_type"] == "code":
            lines += [ln for ln in "".join(c["source"]).splitlines()
                      if not ln.lstrip().startswith(("%", "!"))]
    return "\n".join(lines)


@pytest.mark.parametrize("path", sorted((ROOT / "benchmarks").glob("*.py"))
                         + sorted((ROOT / "notebooks").glob("*.ipynb")),
                         ids=lambda p: p.name)
def test_benchmarks_and_notebooks_use_the_public_api(path):
    source = _notebook_code(path) if path.suffix == ".ipynb" else path.read_text()
    private = sorted({m for m in _gearjax_imports(source) if m != "gearjax"})
    assert not private, f"{path.name} imports {private}: use `import gearjax`"


def test_version_comes_from_the_installed_distribution():
    assert gearjax.__version__ == importlib.metadata.version("gearjax")


def test_every_public_name_has_an_api_page():
    """The API reference (docs/api/*.md, mkdocstrings) lists every name gearjax exports,
    and nothing it no longer exports."""
    public = {n for n in dir(gearjax) if not n.startswith("_")
              and not isinstance(getattr(gearjax, n), types.ModuleType)}
    documented = set()
    for page in (ROOT / "docs" / "api").glob("*.md"):
        documented |= set(re.findall(r"^::: gearjax\.(\w+)", page.read_text(), re.M))
    assert not public - documented, f"no API page lists {sorted(public - documented)}"
    assert not documented - public, f"API pages list {sorted(documented - public)}"
