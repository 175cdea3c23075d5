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
    {"errors", "settings", "progress", "jit", "_compat", "deferred", "registry", "schema_parts", ""},
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
    {"optimize.solvers"},  # before design: the design file's optimize: schema is assembled from the solver kinds
    {"design"},
    {"chain"},            # the derivative chain: stages over volume/ and quality/, composed; the MPI reductions
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


def _modules(package: Path = PACKAGE) -> dict[str, Path]:
    out = {}
    for p in package.rglob("*.py"):
        parts = list(p.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _imports(name: str, path: Path, modules: dict[str, Path] = MODULES, *, names: bool = False):
    """(target module, line, function-local?) of every ``ffdcli`` import of a module, and the
    function-local imports of other packages as (top-level name, line); with ``names``, also the
    (module, name, line) of every name imported from an ``ffdcli`` module."""
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
    own, other, imported = [], [], []
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
                own.append((sub if sub in modules else mod, node.lineno, local))
                if sub not in modules:
                    imported.append((mod, alias.name, node.lineno))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "ffdcli":
                    own.append((alias.name, node.lineno, local))
                else:
                    other.append((alias.name.split(".")[0], node.lineno, local))
    return (own, other, imported) if names else (own, other)


#: Sub-packages that are a stage of their own, apart from their package's.
SUBSTAGES = ("optimize.solvers",)


def _stage(module: str) -> str:
    rest = module.split(".", 1)[1] if "." in module else ""
    for sub in SUBSTAGES:
        if rest == sub or rest.startswith(sub + "."):
            return sub
    return rest.split(".")[0]


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


def _import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules its import runs: every module it imports, and the ``__init__`` of each
    package above an imported module that is not above the importer itself (Python runs
    ``a/__init__.py`` before ``a.b``, so a package's face is part of every import through it). A module
    importing its own package's face is not an edge: the face re-exports its modules (``cli``'s
    commands import ``cli``, which registers them when it runs)."""
    graph = {}
    for name, path in modules.items():
        targets = set()
        for t, _, _ in _imports(name, path, modules)[0]:
            if t not in modules or t == name or name.startswith(t + "."):
                continue
            targets.add(t)
            parts = t.split(".")
            for k in range(2, len(parts)):
                parent = ".".join(parts[:k])
                if parent in modules and parent != name and not name.startswith(parent + "."):
                    targets.add(parent)
        graph[name] = targets
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
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
    return cycles


def test_no_import_cycle():
    cycles = _cycles(_import_graph(MODULES))
    assert not cycles, f"import cycles: {cycles}"


def _write_package(root: Path, files: dict[str, str]) -> dict[str, Path]:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return _modules(root / "ffdcli")


def test_a_cycle_through_a_package_face_is_caught(tmp_path):
    """``a.x`` imports ``b.y``, which runs ``b/__init__.py``, which imports ``b.z``, which imports ``a.x``:
    a cycle although no module names the other directly (the old graph did not see it). A package face
    importing its own modules is no cycle."""
    face = {"ffdcli/__init__.py": "", "ffdcli/a/__init__.py": "", "ffdcli/a/x.py": "from ffdcli.b.y import Y\n",
            "ffdcli/b/__init__.py": "from ffdcli.b.y import Y\nfrom ffdcli.b.z import Z\n",
            "ffdcli/b/y.py": "Y = 1\n", "ffdcli/b/z.py": "Z = 2\n"}
    assert not _cycles(_import_graph(_write_package(tmp_path / "ok", face)))
    bad = {**face, "ffdcli/b/z.py": "from ffdcli.a.x import Y as Z\n"}
    assert _cycles(_import_graph(_write_package(tmp_path / "bad", bad))) == [
        ["ffdcli.a.x", "ffdcli.b", "ffdcli.b.z"]]
    deep = {**face, "ffdcli/b/z.py": "Z = 2\n", "ffdcli/c/__init__.py": "from ffdcli.a.x import Y\n",
            "ffdcli/b/y.py": "from ffdcli.c import Y\n"}       # b.y -> c's face -> a.x -> b.y
    assert _cycles(_import_graph(_write_package(tmp_path / "deep", deep))) == [
        ["ffdcli.a.x", "ffdcli.b", "ffdcli.b.y", "ffdcli.c"]]


def _private_imports(modules: dict[str, Path]) -> list[str]:
    """Every ``_name`` (not ``__dunder__``) imported from another ``ffdcli`` module, as ``module:line``."""
    wrong = []
    for name, path in modules.items():
        for mod, alias, line in _imports(name, path, modules, names=True)[2]:
            if alias.startswith("_") and not alias.startswith("__") and mod != name:
                wrong.append(f"{name}:{line} imports {alias} from {mod}")
    return sorted(wrong)


def test_no_private_name_is_imported_across_modules():
    """A name with a leading underscore is its module's own: another module that needs it means it is
    public (one home, a public name) or belongs elsewhere."""
    wrong = _private_imports(MODULES)
    assert not wrong, f"{len(wrong)} private names imported across modules:\n" + "\n".join(wrong)


def test_the_private_import_check_can_fail(tmp_path):
    modules = _write_package(tmp_path, {"ffdcli/__init__.py": "", "ffdcli/a.py": "def _helper(): pass\n",
                                        "ffdcli/b.py": "from ffdcli.a import _helper, __doc__\n",
                                        "ffdcli/c/__init__.py": "from ffdcli.c import _impl\n",
                                        "ffdcli/c/_impl.py": "def run(): pass\n"})
    assert _private_imports(modules) == ["ffdcli.b:1 imports _helper from ffdcli.a"]    # a private module: no name


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
