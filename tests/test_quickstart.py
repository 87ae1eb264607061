"""The README's Python quick start runs as written and gives a good map."""

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _python_quick_start(block: int = 0) -> str:
    readme = (ROOT / "README.md").read_text()
    section = readme.split("### From Python", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```python\n(.*?)```", section, re.S)[block]


def _run_block(block: int, tmp_path, monkeypatch) -> dict:
    code = _python_quick_start(block)
    for name in re.findall(r'"(resources/[^"]+)"', code):  # the paths are relative to the repository
        code = code.replace(f'"{name}"', repr(str(ROOT / name)))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, "README quick start", "exec"), namespace)
    return namespace


@pytest.mark.slow
def test_readme_python_quick_start(tmp_path, monkeypatch, capsys):
    namespace = _run_block(0, tmp_path, monkeypatch)
    assert namespace["result"].map_xy is not None
    printed = capsys.readouterr().out
    assert "mean" in printed
    assert sorted(os.listdir(tmp_path)) == ["wolf0_to_wolf1.json", "wolf0_to_wolf1.npz"]
    import corrlib

    loaded = corrlib.MatchResult.load(tmp_path / "wolf0_to_wolf1")
    assert (loaded.map_xy == namespace["result"].map_xy).all()
    report = corrlib.evaluate(loaded, namespace["y"], namespace["rows"], namespace["rows"])
    assert report.summary()["within_0.05"] >= 0.9, report.summary()


@pytest.mark.slow
def test_readme_python_journeys(tmp_path, monkeypatch, capsys):
    """The README's second block: the drawn wolf finds a wolf first and its curve is matched on it; the
    sequence between the cats is written, from cat0 as given to the map's image on cat1."""
    import corrlib

    namespace = _run_block(1, tmp_path, monkeypatch)
    hits = namespace["hits"]
    assert hits[0].label == "wolf" and [hit.label for hit in hits[:2]] == ["wolf", "wolf"], capsys.readouterr().out
    assert namespace["curve"].path is not None and namespace["curve"].map_xy.size > 0
    written = sorted(p.name for p in (tmp_path / "cat_sequence").iterdir())
    assert written == ["animation.glb", *[f"frame_{i:03d}.obj" for i in range(5)], "volumes.csv"]
    first = corrlib.load_mesh(tmp_path / "cat_sequence" / "frame_000.obj")
    assert abs(first.vertices - namespace["x"].vertices).max() < 1e-5


def test_top_level_names_are_lazy():
    import subprocess
    import sys

    code = ("import sys, corrlib; heavy = 'corrlib.methods' in sys.modules; "
            "corrlib.solve; print(heavy, 'corrlib.methods' in sys.modules, callable(corrlib.load_mesh))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True", "True"]
