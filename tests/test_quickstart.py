"""The README's Python quick start runs as written and gives a good map."""

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _python_quick_start() -> str:
    readme = (ROOT / "README.md").read_text()
    section = readme.split("### From Python", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.mark.slow
def test_readme_python_quick_start(tmp_path, monkeypatch, capsys):
    code = _python_quick_start()
    for name in re.findall(r'"(resources/[^"]+)"', code):  # the paths are relative to the repository
        code = code.replace(f'"{name}"', repr(str(ROOT / name)))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, "README quick start", "exec"), namespace)
    assert namespace["result"].map_xy is not None
    printed = capsys.readouterr().out
    assert "mean" in printed
    assert sorted(os.listdir(tmp_path)) == ["wolf0_to_wolf1.json", "wolf0_to_wolf1.npz"]
    import corrlib

    loaded = corrlib.MatchResult.load(tmp_path / "wolf0_to_wolf1")
    assert (loaded.map_xy == namespace["result"].map_xy).all()
    report = corrlib.evaluate(loaded, namespace["y"], namespace["rows"], namespace["rows"])
    assert report.summary()["within_0.05"] >= 0.9, report.summary()


def test_top_level_names_are_lazy():
    import subprocess
    import sys

    code = ("import sys, corrlib; heavy = 'corrlib.methods' in sys.modules; "
            "corrlib.solve; print(heavy, 'corrlib.methods' in sys.modules, callable(corrlib.load_mesh))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True", "True"]
