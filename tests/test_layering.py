"""Architecture rules: corrlib never imports Qt, pyvista or app, and imports matplotlib only on demand."""

import ast
import subprocess
import sys
from pathlib import Path

import corrlib

FORBIDDEN = {"PySide6", "PyQt5", "PyQt6", "qtpy", "pyvista", "pyvistaqt", "superqt", "app", "vtk"}


def test_no_gui_imports_in_corrlib():
    root = Path(corrlib.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in FORBIDDEN]
    assert not offenders, offenders


def test_import_time_dependencies():
    code = ("import sys, corrlib, corrlib.methods, corrlib.io, corrlib.cli, corrlib.evaluation; "
            "print(sorted(m for m in ('matplotlib', 'PySide6', 'pyvista') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_help_texts_load_no_numerical_library():
    """`corr --help` and every command's --help (issue 19: start-up pays only for what it uses)."""
    code = ("import contextlib, io, sys\n"
            "from corrlib.cli import build_parser, main\n"
            "commands = [[]] + [[name] for name in build_parser()._subparsers._group_actions[0].choices]\n"
            "for command in commands:\n"
            "    with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
            "        main(command + ['--help'])\n"
            "print(len(commands), sorted(m for m in ('numpy', 'scipy', 'numba', 'trimesh') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    count, loaded = out.strip().split(" ", 1)
    assert int(count) > 10 and loaded == "[]", out


# ----------------------------------------------------------------------------- the import graph of corrlib

ROOT = Path(corrlib.__file__).parent.parent

#: (importer prefix, forbidden prefixes): lower layers never reach up
CONTRACTS = [
    ("corrlib.methods", ("corrlib.cli", "corrlib.perf", "corrlib.bench", "corrlib.contour_bench", "corrlib.morph",
                         "corrlib.retrieval", "corrlib.parallel", "corrlib.warmup")),
    ("corrlib.geometry", ("corrlib.methods", "corrlib.descriptors", "corrlib.deformation", "corrlib.cli",
                          "corrlib.bench", "corrlib.evaluation", "corrlib.morph")),
    ("corrlib.descriptors", ("corrlib.methods", "corrlib.deformation", "corrlib.cli", "corrlib.bench")),
    ("corrlib.deformation", ("corrlib.methods", "corrlib.descriptors", "corrlib.cli", "corrlib.bench",
                             "corrlib.morph")),
    ("corrlib.morph", ("corrlib.methods", "corrlib.cli", "corrlib.bench")),
]


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(package: str = "corrlib") -> dict[str, set[str]]:
    """Every module of ``package`` -> the modules of ``package`` it imports (also inside functions)."""
    modules = {_module_name(p): p for p in (ROOT / package).rglob("*.py")}

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in modules.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets |= {f"{node.module}.{a.name}" for a in node.names}
        graph[name] = {r for t in targets if t.startswith(package) and (r := resolve(t)) and r != name}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
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
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_in_corrlib():
    assert _cycles(_imports()) == []


def test_import_contracts():
    graph = _imports()
    broken = [f"{importer} imports {target}" for importer, targets in graph.items() for target in targets
              for prefix, forbidden in CONTRACTS
              if (importer == prefix or importer.startswith(prefix + "."))
              and any(target == f or target.startswith(f + ".") for f in forbidden)]
    assert not broken, broken


def test_no_private_names_imported_across_modules():
    offenders = []
    for package in ("corrlib", "app"):
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ("corrlib",
                                                                                                         "app"):
                    offenders += [f"{path.name}: {node.module}.{a.name}" for a in node.names
                                  if a.name.startswith("_")]
    assert not offenders, offenders


#: a module holds one concept; beyond this many lines it is split into a package of modules
MAX_MODULE_LINES = 1200


def test_modules_are_small():
    """No module of corrlib or app has more than 1200 lines (the largest had 1833: kernel matching, now a
    package with a module per stage)."""
    long = [f"{path.relative_to(ROOT)} ({count} lines)" for package in ("corrlib", "app")
            for path in (ROOT / package).rglob("*.py")
            if (count := len(path.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not long, long


#: functions may be longer only when they are numba kernels, unrolled on purpose
MAX_FUNCTION_LINES = 80


def test_functions_are_short():
    """No function outside numba kernels has more than 80 lines of code (its docstring not counted)."""
    long = []
    for package in ("corrlib", "app"):
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                if any("numba" in ast.unparse(d) for d in node.decorator_list):
                    continue
                first = node.body[0]
                docstring = (first.end_lineno - first.lineno + 1
                             if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                             and isinstance(first.value.value, str) else 0)
                lines = node.end_lineno - node.lineno + 1 - docstring
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, long
