"""Fuzzing every loader and every method's parameters: a valid object or the project's named error, nothing else.

Each property runs a few dozen cases in the normal suite and about a thousand in the ``slow`` one (about
10k cases in all). A failure shows the smallest input hypothesis found.
"""

import dataclasses
import io as stdio
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from corrlib.errors import CorrError
from corrlib.io import load_contour, load_labels, load_map, load_mesh, load_pairs, load_vts
from corrlib.methods import all_methods
from corrlib.methods.base import make_params
from corrlib.shapes import Contour2D, TriMesh

#: (examples in the normal suite, in the slow suite)
BUDGETS = [pytest.param(30, id="fast"), pytest.param(1000, id="slow", marks=pytest.mark.slow)]

NUMBER_TOKENS = st.one_of(
    st.integers(-3, 12).map(str),
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.sampled_from(["nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "99999999999999999999", "0x10", "1,5",
                     "", "abc", "#", "3.", ".5", "+1", "--1", "1e", "\x00", "é"]))


def _lines(rows) -> str:
    return "\n".join(" ".join(row) for row in rows) + "\n"


@st.composite
def off_text(draw) -> str:
    """OFF files that are almost right: plausible headers, counts that may lie, odd vertex and face lines."""
    header = draw(st.sampled_from(["OFF", "COFF", "NOFF", "off", "OFF3", "PLY", ""]))
    n_v = draw(st.integers(0, 8))
    n_f = draw(st.integers(0, 8))
    counts = [draw(st.sampled_from([str(n_v), str(n_v + 1), "-1", "999999999", "x"])),
              draw(st.sampled_from([str(n_f), "0", "-2", "99999999999999999999"])), "0"]
    same_line = draw(st.booleans())
    rows = [[header, *counts]] if same_line else [[header], counts]
    for _ in range(n_v):
        rows.append(draw(st.lists(NUMBER_TOKENS, min_size=0, max_size=5)))
    for _ in range(n_f):
        k = draw(st.integers(-1, 6))
        rows.append([str(k), *draw(st.lists(st.integers(-3, 12).map(str) | NUMBER_TOKENS, max_size=6))])
    return _lines(rows)


def _accepts_or_names(load, data, suffix: str, kind=None):
    """``load(path)`` returns a valid ``kind`` or raises a CorrError with a message."""
    with tempfile.TemporaryDirectory(prefix="corr-fuzz-") as folder:
        path = Path(folder) / f"input{suffix}"
        path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8", errors="surrogatepass"))
        try:
            value = load(path)
        except CorrError as exc:
            assert str(exc).strip(), "an empty message"
            return
    if kind is not None:
        assert isinstance(value, kind)


def _run(budget, strategy, check):
    """Run ``check`` on ``budget`` examples of ``strategy``."""
    @settings(max_examples=budget, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])
    @given(strategy)
    def prop(value):
        check(value)

    prop()


def _mesh_ok(path):
    mesh = load_mesh(path)
    assert mesh.n_vertices >= 3 and mesh.faces.shape[1] == 3
    assert np.all(np.isfinite(mesh.vertices)) and mesh.faces.max() < mesh.n_vertices
    return mesh


@pytest.mark.parametrize("budget", BUDGETS)
def test_off_files(budget):
    _run(budget, off_text() | st.binary(max_size=300).map(lambda b: b"OFF\n" + b),
         lambda text: _accepts_or_names(_mesh_ok, text, ".off", TriMesh))


@pytest.mark.parametrize("budget", BUDGETS)
@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_other_mesh_formats(budget, suffix):
    obj_like = st.lists(st.tuples(st.sampled_from(["v", "f", "vn", "ply", "solid", "facet", "vertex", "#", "end"]),
                                  st.lists(NUMBER_TOKENS, max_size=4)), max_size=12) \
        .map(lambda rows: _lines([[tag, *vals] for tag, vals in rows]))
    _run(budget // 3 or 1, obj_like | st.binary(max_size=400),
         lambda data: _accepts_or_names(_mesh_ok, data, suffix, TriMesh))


@pytest.mark.parametrize("budget", BUDGETS)
@pytest.mark.parametrize("suffix", [".txt", ".csv"])
def test_contour_point_files(budget, suffix):
    rows = st.lists(st.lists(NUMBER_TOKENS | st.floats(-1e3, 1e3).map(repr), min_size=0, max_size=3),
                    max_size=40).map(lambda r: "\n".join((", " if suffix == ".csv" else " ").join(x) for x in r))
    _run(budget // 2 or 1, rows | st.binary(max_size=200),
         lambda data: _accepts_or_names(load_contour, data, suffix, Contour2D))


@pytest.mark.parametrize("budget", BUDGETS)
def test_svg_files(budget):
    commands = st.lists(st.sampled_from(list("MmLlHhVvCcSsQqTtAaZz")) | NUMBER_TOKENS, max_size=40)
    svg = commands.map(lambda toks: f'<svg xmlns="http://www.w3.org/2000/svg"><path d="{" ".join(toks)}"/></svg>')
    broken = st.text(max_size=200).map(lambda t: "<svg>" + t)
    _run(budget // 2 or 1, svg | broken, lambda data: _accepts_or_names(load_contour, data, ".svg", Contour2D))


@pytest.mark.parametrize("budget", BUDGETS)
def test_silhouette_images(budget):
    from PIL import Image

    def png(args):
        width, height, seed, mode = args
        pixels = np.random.default_rng(seed).integers(0, 256, size=(height, width), dtype=np.uint8)
        if mode == "disk":
            yy, xx = np.mgrid[:height, :width]
            pixels = (((yy - height / 2) ** 2 + (xx - width / 2) ** 2) < (min(width, height) / 3) ** 2) * 255
        elif mode == "flat":
            pixels[:] = seed % 256
        buffer = stdio.BytesIO()
        Image.fromarray(np.asarray(pixels, dtype=np.uint8)).save(buffer, format="PNG")
        return buffer.getvalue()

    images = st.tuples(st.integers(1, 60), st.integers(1, 60), st.integers(0, 10 ** 6),
                       st.sampled_from(["noise", "disk", "flat"])).map(png)
    truncated = images.flatmap(lambda b: st.integers(0, len(b)).map(lambda n: b[:n]))
    _run(budget // 2 or 1, images | truncated, lambda data: _accepts_or_names(load_contour, data, ".png", Contour2D))


INDEX_TEXT = st.lists(NUMBER_TOKENS | st.integers(-5, 50).map(str), max_size=30).map(lambda t: "\n".join(t))


@pytest.mark.parametrize("budget", BUDGETS)
def test_index_files(budget):
    """``.vts`` ground truth, maps as text, label files: integers in range, or a named error."""
    def check(text):
        _accepts_or_names(lambda p: _in_range(load_vts(p, 40), 0, 40), text, ".vts")
        _accepts_or_names(lambda p: _in_range(load_map(p, n_target=40), 0, 40), text, ".txt")
        _accepts_or_names(lambda p: load_labels(p).astype(np.int64), text, ".txt")
        _accepts_or_names(lambda p: _in_range(load_pairs(p), -(2 ** 53), 2 ** 53 + 1), text, ".txt")

    _run(budget, INDEX_TEXT | st.binary(max_size=120), check)


def _in_range(values, low, high):
    values = np.asarray(values)
    assert values.dtype == np.int64 and values.size and values.min() >= low and values.max() < high
    return values


@pytest.mark.parametrize("budget", BUDGETS)
def test_npz_maps(budget):
    arrays = st.one_of(
        st.lists(st.integers(-5, 60), max_size=20).map(lambda v: np.array(v, dtype=np.int64)),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=20).map(np.array),
        st.lists(st.lists(st.integers(0, 5), min_size=2, max_size=2), max_size=6).map(np.array),
        st.sampled_from([np.array([]), np.array("text"), np.array([True, False]), np.array([2 ** 62, 1])]))

    def npz(args):
        array, key, cut = args
        buffer = stdio.BytesIO()
        np.savez(buffer, **{key: array})
        data = buffer.getvalue()
        return data[: max(1, int(len(data) * cut))] if cut < 1 else data

    archives = st.tuples(arrays, st.sampled_from(["map_xy", "other"]), st.sampled_from([1.0, 1.0, 0.5, 0.1])).map(npz)
    _run(budget, archives | st.binary(max_size=200),
         lambda data: _accepts_or_names(lambda p: _in_range(load_map(p, n_target=60), 0, 60), data, ".npz"))


ODD_VALUES = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf, -1, 0, 1, 2 ** 70, -(2 ** 70), 1e300, -1e-300,
                                        True, False, None, "", "abc", "nan", "1e999", "-3", "0.5", " 7 ", [], {}]),
                       st.integers(-10 ** 6, 10 ** 6), st.floats(allow_nan=True, allow_infinity=True),
                       st.text(max_size=8))


@pytest.mark.parametrize("budget", BUDGETS)
def test_method_parameters(budget):
    """Every parameter of every registered method: a validated dataclass or a ParameterError-like message."""
    fields = [(spec.params, f.name) for spec in all_methods() for f in dataclasses.fields(spec.params)]

    def check(args):
        index, value = args
        params_cls, name = fields[index % len(fields)]
        try:
            params = make_params(params_cls, **{name: value})
        except CorrError as exc:
            assert str(exc).strip()
            return
        default = next(f.default for f in dataclasses.fields(params_cls) if f.name == name)
        accepted = getattr(params, name)
        if isinstance(default, bool):
            assert isinstance(accepted, bool), (name, accepted)
        elif isinstance(default, int):
            assert isinstance(accepted, int) and not isinstance(accepted, bool), (name, accepted)
        elif isinstance(default, float):
            assert isinstance(accepted, (int, float)) and not isinstance(accepted, bool), (name, accepted)
            assert math.isfinite(accepted), (name, accepted)
        elif isinstance(default, str):
            assert isinstance(accepted, str), (name, accepted)

    _run(budget * 2, st.tuples(st.integers(0, 10 ** 6), ODD_VALUES), check)
