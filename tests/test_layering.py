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
