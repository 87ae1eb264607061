"""Shared fixtures. Every test uses a private spectra cache so runs never depend on each other."""

import gc
import os
import sys

if os.environ.get("PYTEST_XDIST_WORKER"):
    # test processes side by side (pytest -n): single-threaded BLAS in each, so that they do not oversubscribe
    # the cores; numba's threads stay, so the library's threaded code paths are still the ones tested
    for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_variable, "1")

import numpy as np  # noqa: E402
import pytest

from _data import TOSCA


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("CORRLIB_CACHE_DIR", str(tmp_path_factory.mktemp("corrlib-cache")))
    yield
    mp.undo()


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item):
    """Close the test's studio windows and widgets now, on this thread, and keep them (never delete them).

    Deleting a closed studio window (its VTK render windows) crashed the test process now and then, inside
    the test that deleted it or the next one's event loop (docs/decisions.md); the studio itself deletes its
    window only at exit. So the tests' widgets are closed (their jobs stopped, their plotters finalised) and
    kept until the process ends, and :func:`pytest_unconfigure` ends it without destructors. Other deferred
    deletions (e.g. a view's replaced plotter) are carried out here, at the end of their own test.
    """
    studio = sys.modules.get("_studio")
    if studio is not None:
        studio.close_open_widgets()
    qt_core = sys.modules.get("PySide6.QtCore")
    if qt_core is None or qt_core.QCoreApplication.instance() is None:
        return
    qt_core.QCoreApplication.sendPostedEvents(None, qt_core.QEvent.Type.DeferredDelete)
    gc.collect()
    qt_core.QCoreApplication.sendPostedEvents(None, qt_core.QEvent.Type.DeferredDelete)


_EXIT_STATUS = pytest.StashKey[int]()


def pytest_sessionfinish(session, exitstatus):
    session.config.stash[_EXIT_STATUS] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """After every report: stop pytest-xvfb's display (its exit handler would not run) and end the process
    with pytest's exit status, without the destructors of the kept studio windows (see
    :func:`pytest_runtest_teardown`)."""
    studio = sys.modules.get("_studio")
    if studio is None or not studio.CLOSED_WIDGETS:
        return
    xvfb = sys.modules.get("pytest_xvfb")
    if xvfb is not None:
        xvfb.shutdown_xvfb()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(config.stash.get(_EXIT_STATUS, 1))


@pytest.fixture(scope="session")
def wolf_pair():
    from corrlib.io import load_mesh

    return load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "wolf1.off")


def decimated(mesh, fraction: float, name: str):
    """``mesh`` decimated to about ``fraction`` of its vertices by VTK's quadric decimation (an uneven coarse
    mesh: small triangles where it bends) and, for every vertex of ``mesh``, the nearest decimated vertex."""
    pv = pytest.importorskip("pyvista")  # the studio's 3D views; installed with the test environment
    from scipy.spatial import cKDTree

    from corrlib.shapes import TriMesh

    faces = np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces]).ravel()
    coarse = pv.PolyData(mesh.vertices, faces).decimate(1.0 - fraction).clean()
    target = TriMesh(np.asarray(coarse.points, dtype=np.float64), coarse.faces.reshape(-1, 4)[:, 1:], name=name)
    assert 0.9 * fraction < target.n_vertices / mesh.n_vertices < 1.1 * fraction
    return target, cKDTree(target.vertices).query(mesh.vertices)[1]


@pytest.fixture(scope="session")
def wolf1_half(wolf_pair):
    """wolf1 at half its vertices (:func:`decimated`) and the truth of wolf0 on it, the decimated vertex nearest
    to each vertex's partner in wolf1 (wolf0 and wolf1 share their vertex order)."""
    return decimated(wolf_pair[1], 0.5, "wolf1-half")


@pytest.fixture(scope="session")
def wolf1_quarter(wolf_pair):
    """wolf1 at a quarter of its vertices, as :func:`wolf1_half`."""
    return decimated(wolf_pair[1], 0.25, "wolf1-quarter")


@pytest.fixture(scope="session")
def cat_pair():
    from corrlib.io import load_mesh, load_vts

    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    gt = {name: load_vts(TOSCA / f"{name}.vts") for name in ("cat0", "cat1", "cat0.sym", "cat1.sym")}
    return cat0, cat1, gt


def pinched_spheres():
    """Two icospheres touching at one vertex (a pinched, non-manifold vertex: the two fans of faces round it are
    separate), as a TriMesh; and the vertex."""
    import trimesh

    from corrlib.shapes import TriMesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    n = len(sphere.vertices)
    top, bottom = int(np.argmax(sphere.vertices[:, 2])), int(np.argmin(sphere.vertices[:, 2]))
    keep = np.delete(np.arange(n), bottom)
    index = np.full(n, -1)
    index[keep] = n + np.arange(keep.size)
    index[bottom] = top  # the upper sphere's lowest vertex is the lower one's highest
    vertices = np.vstack([sphere.vertices, sphere.vertices[keep] + [0.0, 0.0, 2.0]])
    return TriMesh(vertices, np.vstack([sphere.faces, index[sphere.faces]]), name="pinched.off"), top


def grid_mesh(nx, ny, periodic=False):
    """Regular triangulated grid on [0,1]^2 (vertices (x, y)), optionally periodic in both directions.

    Returns (uv (n, 2) in [0,1), faces (f, 3)).
    """
    if periodic:
        u, v = np.meshgrid(np.arange(nx) / nx, np.arange(ny) / ny, indexing="ij")
        idx = lambda i, j: (i % nx) * ny + (j % ny)  # noqa: E731
        rng_i, rng_j = range(nx), range(ny)
    else:
        u, v = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="ij")
        idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
        rng_i, rng_j = range(nx), range(ny)
    faces = []
    for i in rng_i:
        for j in rng_j:
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [(a, b, c), (a, c, d)]
    return np.column_stack([u.ravel(), v.ravel()]), np.array(faces, dtype=np.int64)


@pytest.fixture
def window(qtbot, tmp_path):
    """A shown studio window with its own settings file (GUI tests only; Qt is imported here, lazily)."""
    from _studio import make_window

    win = make_window(qtbot, tmp_path / "studio.ini")
    yield win
    win.close()
