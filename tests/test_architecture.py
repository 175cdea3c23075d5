"""The package's layer rule, read from the code: a stage never imports a later one, no import cycle
(function-local imports included), and function-local imports only where they buy something."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "ffdcli"

#: The stages in data-flow order; a module may import its own stage and the ones before it.
LAYERS = [
    {"errors", "settings", "progress", "jit", "_compat", "deferred", ""},
    {"mesh"},
    {"parallel"},
    {"lattice"},          # before io: the SU2 writer refreshes SU2's own FFD section with the splines
    {"io"},
    {"geometry"},
    {"box"},
    {"parameterization"},
    {"volume"},
    {"quality"},
    {"constraints"},
    {"design"},
    {"viz"},
    {"app"},
    {"api", "openmdao", "mphys"},
    {"optimize"},
    {"cli", "__main__"},
]
#: Fixtures for tests and benchmarks: they may use the whole package, nothing in it uses them
#: (``threadcomm`` stands in for MPI in the parallel layer's tests and is used by nothing else).
FIXTURES = "testing"
#: Optional third-party packages: imported where they are used, so that the core runs without them.
#: matplotlib is imported where a picture is drawn: its import reads MPLBACKEND, which ffd turns
#: into an input error (viz/plot.py).
OPTIONAL = {"pyvista", "vtk", "openmdao", "mphys", "mpi4py", "gmsh", "matplotlib", "pygeo", "pyspline"}


def _modules() -> dict[str, Path]:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = list(p.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _imports(name: str, path: Path):
    """(target module, line, function-local?) of every ``ffdcli`` import of a module, and the
    function-local imports of other packages as (top-level name, line)."""
    text = path.read_text()
    tree = ast.parse(text)
    lines = text.splitlines()
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    local_nodes = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and "noqa: PLC0415" not in lines[node.lineno - 1]:
                    local_nodes.add(id(node))     # a kept one says why on the line before
    own, other = [], []
    for node in ast.walk(tree):
        local = id(node) in local_nodes
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "ffdcli":
                other.append((mod.split(".")[0], node.lineno, local))
                continue
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                own.append((sub if sub in MODULES else mod, node.lineno, local))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "ffdcli":
                    own.append((alias.name, node.lineno, local))
                else:
                    other.append((alias.name.split(".")[0], node.lineno, local))
    return own, other


def _stage(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _layer(module: str) -> int | None:
    stage = _stage(module)
    for k, names in enumerate(LAYERS):
        if stage in names:
            return k
    return None


def test_every_stage_has_a_layer():
    stages = {_stage(m) for m in MODULES} - {FIXTURES}
    assert stages <= set().union(*LAYERS), f"stages without a layer: {sorted(stages - set().union(*LAYERS))}"


def test_no_stage_imports_a_later_one():
    wrong = []
    for name, path in MODULES.items():
        if _stage(name) == FIXTURES:
            continue
        for target, line, _ in _imports(name, path)[0]:
            if _stage(target) == FIXTURES and not (_stage(name) == "parallel" and target.endswith("threadcomm")):
                wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports the fixture {target}")
            elif _stage(target) != FIXTURES and _layer(target) > _layer(name):
                wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {target} (a later stage)")
    assert not wrong, "\n".join(wrong)


def test_no_import_cycle():
    graph = {name: {t for t, _, _ in _imports(name, path)[0] if t in MODULES and t != name}
             for name, path in MODULES.items()}
    # a package's __init__ that re-exports its own modules is its face, not a dependency of them
    for name in graph:
        graph[name] = {t for t in graph[name] if not (name.startswith(t + "."))}
    sys.setrecursionlimit(10000)
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_function_local_imports_only_in_cli_or_for_optional_packages():
    wrong = []
    for name, path in MODULES.items():
        if _stage(name) in ("cli", "__main__"):
            continue
        own, other = _imports(name, path)
        for target, line, local in own:
            if local:
                wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {target} inside a function")
        for top, line, local in other:
            if local and top not in OPTIONAL:
                wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {top} inside a function")
    assert not wrong, f"{len(wrong)} function-local imports:\n" + "\n".join(wrong)


#: Being split (issue 27): each leaves this list when it is under the limit.
SPLITTING: set[str] = set()
#: Functions over 100 lines being split (issue 27), as "module:function".
LONG_FUNCTIONS: set[str] = set()


@pytest.mark.parametrize("limit", [600])
def test_module_sizes(limit):
    """No module over 600 lines; a parser that needs more says why in a ``# size:`` line."""
    big = [f"{p.relative_to(PACKAGE.parent)} ({n})" for p in PACKAGE.rglob("*.py")
           if (n := len(p.read_text().splitlines())) > limit and "# size:" not in p.read_text()
           and str(p.relative_to(PACKAGE)) not in SPLITTING]
    assert not big, "modules over 600 lines: " + ", ".join(big)


def _compiled(fn: ast.FunctionDef) -> bool:
    """A numba kernel (``@njit``, ``@jit``, ``@intrinsic``, ffdcli.jit's ``@kernel``/``@inlined``...): one
    compiled loop, exempt from the size rule."""
    names = {ast.unparse(d).split("(")[0].split(".")[-1] for d in fn.decorator_list}
    return bool(names & {"njit", "jit", "intrinsic", "generated_jit", "vectorize", "guvectorize", "kernel",
                         "inlined"})


def test_class_and_function_sizes():
    """No class over 250 lines, no function over 100 except the named numba kernels."""
    wrong = []
    for p in PACKAGE.rglob("*.py"):
        rel = str(p.relative_to(PACKAGE))
        for node in ast.walk(ast.parse(p.read_text())):
            n = getattr(node, "end_lineno", 0) - getattr(node, "lineno", 0) + 1
            if isinstance(node, ast.ClassDef) and n > 250:
                wrong.append(f"class {rel}:{node.name} ({n} lines)")
            elif (isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and n > 100 and not _compiled(node)
                  and f"{rel}:{node.name}" not in LONG_FUNCTIONS):
                wrong.append(f"function {rel}:{node.name} ({n} lines)")
    assert not wrong, "\n".join(wrong)


def test_every_module_has_a_row_in_the_architecture_map():
    """docs/ARCHITECTURE.md names every module of the package (a row, or a list of modules in a row),
    so that the map cannot go stale silently."""
    text = (PACKAGE.parent / "docs" / "ARCHITECTURE.md").read_text()
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if path.name in ("__init__.py", "__main__.py") or rel.startswith(("testing/", "cli/")):
            continue
        if rel not in text and f"`{path.name}`" not in text and f"{path.parent.name}/" + path.name not in text:
            missing.append(rel)
    assert not missing, f"modules without a row in docs/ARCHITECTURE.md: {missing}"
