"""The synthetic people's datasets (tests/_humanoid.py): their ground truth must say what it claims."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from _humanoid import GORILLA_JOINTS, JOINTS, write_kernel_battery, write_nonisometric_battery
from corrlib.bench import load_dataset
from corrlib.io import load_mesh, load_vts
from corrlib.resources import resource


def test_kernel_battery_rows_name_the_same_body_point_in_poses_and_mirror_images(tmp_path):
    """Every pose and mirror image is a ``corr bench`` dataset whose ``.vts`` rows are one body point across
    shapes and whose ``.sym.vts`` rows are its mirror partner: on the rest pose (exactly symmetric) the row's
    point of a mirror image lies where the same row's point of the pose lies, and the mirrored rows land on
    the other side. The capsule poses are the bundled people."""
    write_kernel_battery(tmp_path)
    for kind in ("capsule", "face"):
        dataset = load_dataset(tmp_path / kind)
        assert len(dataset.pairs) == 24 and len(dataset.shapes) == 8
        assert ("human1", "mirror2") in dataset.pairs and ("human1", "human1") not in dataset.pairs
        meshes = {name: load_mesh(tmp_path / kind / f"{name}.off") for name in ("human0", "mirror0")}
        size = np.linalg.norm(np.ptp(meshes["human0"].vertices, axis=0))
        points = {name: mesh.vertices[load_vts(dataset.gt[name], mesh.n_vertices)] for name, mesh in meshes.items()}
        mirrored = meshes["mirror0"].vertices[load_vts(dataset.gt_sym["mirror0"], meshes["mirror0"].n_vertices)]
        assert np.abs(points["mirror0"] - points["human0"]).max() < 0.02 * size  # marching cubes' symmetry
        lateral = np.abs(points["human0"][:, 0]) > 0.05 * size
        assert np.all(np.sign(mirrored[lateral, 0]) == -np.sign(points["human0"][lateral, 0]))
    bundled = load_mesh(resource("people/human3.off"))
    np.testing.assert_allclose(load_mesh(tmp_path / "capsule" / "human3.off").vertices, bundled.vertices, atol=1e-5)


def test_nonisometric_battery_rows_name_the_same_body_point_on_the_gorilla(tmp_path):
    """The people and the gorilla-proportioned body, meshed apart: a row names the same body point on both —
    the hands, feet, head and nose of the rest poses (the joints' nearest vertices) land next to the
    gorilla's own, within a few of its edges; the correspondence is continuous (neighbouring vertices of a
    person land a few gorilla edges apart at most); the mirrored rows are the gorilla's mirror partners."""
    write_nonisometric_battery(tmp_path)
    dataset = load_dataset(tmp_path)
    assert len(dataset.pairs) == 28 and len(dataset.shapes) == 8
    assert ("gorilla2", "human2") in dataset.pairs and ("human2", "gorilla2") not in dataset.pairs
    human, gorilla = load_mesh(tmp_path / "human0.off"), load_mesh(tmp_path / "gorilla0.off")
    rows = {"human": load_vts(dataset.gt["human0"], human.n_vertices),
            "gorilla": load_vts(dataset.gt["gorilla0"], gorilla.n_vertices),
            "gorilla_sym": load_vts(dataset.gt_sym["gorilla0"], gorilla.n_vertices)}
    np.testing.assert_array_equal(rows["human"], np.arange(human.n_vertices))
    edge = np.linalg.norm(np.diff(gorilla.vertices[gorilla.faces[:, :2]], axis=1), axis=2).mean()
    for joint in ("lha", "rha", "lto", "rto", "head", "nose1"):
        at_human = np.argmin(np.linalg.norm(human.vertices - JOINTS[joint], axis=1))
        at_gorilla = np.linalg.norm(gorilla.vertices - GORILLA_JOINTS[joint], axis=1).min()
        lands = np.linalg.norm(gorilla.vertices[rows["gorilla"][at_human]] - GORILLA_JOINTS[joint])
        assert lands < at_gorilla + 3 * edge, joint
    edges = np.concatenate([human.faces[:, [0, 1]], human.faces[:, [1, 2]], human.faces[:, [2, 0]]])
    apart = np.linalg.norm(np.diff(gorilla.vertices[rows["gorilla"][edges]], axis=1)[:, 0], axis=1) / edge
    assert np.percentile(apart, 99) < 6 and apart.max() < 20
    mirrored = gorilla.vertices[rows["gorilla"]] * [-1.0, 1.0, 1.0]
    assert np.median(np.linalg.norm(gorilla.vertices[rows["gorilla_sym"]] - mirrored, axis=1)) < 1.5 * edge


@pytest.mark.slow
def test_the_remeshed_battery_carries_its_rows_to_each_pose_s_own_meshing(tmp_path):
    """``remesh``: each pose and mirror image meshed on its own (no shared connectivity, as scans), every row
    moved to the nearest remeshed vertex: the rest pose's rows still land on the mirror image's within an edge
    or two, and the mirrored rows on the other side."""
    write_kernel_battery(tmp_path, remesh=1500)
    for kind in ("capsule", "face"):
        dataset = load_dataset(tmp_path / kind)
        meshes = {name: load_mesh(path) for name, path in dataset.shapes.items()}
        assert all(abs(mesh.n_vertices - 1500) <= 15 for mesh in meshes.values())
        assert not np.array_equal(meshes["human0"].faces, meshes["human1"].faces)
        size = np.linalg.norm(np.ptp(meshes["human0"].vertices, axis=0))
        edge = np.sqrt(meshes["human0"].area / 1500) * 1.5
        points = {name: meshes[name].vertices[load_vts(dataset.gt[name], meshes[name].n_vertices)]
                  for name in ("human0", "mirror0")}
        mirrored = meshes["mirror0"].vertices[load_vts(dataset.gt_sym["mirror0"], meshes["mirror0"].n_vertices)]
        assert np.median(np.linalg.norm(points["mirror0"] - points["human0"], axis=1)) < edge
        lateral = np.abs(points["human0"][:, 0]) > 0.05 * size
        assert np.mean(np.sign(mirrored[lateral, 0]) == -np.sign(points["human0"][lateral, 0])) > 0.99


@pytest.mark.parametrize("args, message", [
    (["OUT", "lots"], "invalid float value: 'lots'"),
    (["OUT", "-0.1"], "noise must be a finite fraction >= 0"),
    (["OUT", "0", "5"], "subdivisions must be 0 to 3"),
    (["OUT", "--remesh", "50"], "--remesh must be 100 to 100000 vertices"),
    (["FILE/out"], "is a file, not a folder"),
    (["FULL"], "is not empty; choose a new output folder"),
])
def test_kernel_battery_command_names_bad_arguments_and_writes_nothing(tmp_path, args, message):
    """``python tests/_humanoid.py --kernel-battery``: a bad argument or output folder is a named error with exit
    status 2, found before any mesh is written."""
    (tmp_path / "FILE").write_text("not a folder")
    (tmp_path / "FULL" / "face").mkdir(parents=True)
    (tmp_path / "FULL" / "face" / "human0.off").write_text("an earlier run")
    paths = [str(tmp_path / arg) if arg.isupper() or "/" in arg else arg for arg in args]
    script = Path(__file__).with_name("_humanoid.py")
    done = subprocess.run([sys.executable, str(script), "--kernel-battery", *paths], capture_output=True, text=True)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert not (tmp_path / "OUT").exists() and not (tmp_path / "FULL" / "capsule").exists()
    assert (tmp_path / "FULL" / "face" / "human0.off").read_text() == "an earlier run"
