"""Location of the test shapes: ``../shared/data`` beside the repository, else the bundled copy; and the
vertex noise and the needle vertices the robustness tests add to them."""

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
_SHARED = ROOT.parent / "shared" / "data"
DATA = _SHARED if (_SHARED / "tosca").is_dir() else ROOT / "resources" / "data"
TOSCA = DATA / "tosca"
SUMNER = DATA / "sumner"
SKETCH2D = DATA / "sketch2d"
SILHOUETTES = DATA / "silhouettes"
assert TOSCA.is_dir(), f"test data not found in {DATA}"


def with_vertex_noise(mesh, seed: int, fraction: float = 1e-3):
    """``mesh`` (a TriMesh) with Gaussian noise on every vertex, of standard deviation ``fraction`` of its
    bounding-box diagonal; the same faces."""
    from corrlib.shapes import TriMesh

    diagonal = np.linalg.norm(mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0))
    noise = np.random.default_rng(seed).normal(scale=fraction * diagonal, size=mesh.vertices.shape)
    return TriMesh(mesh.vertices + noise, mesh.faces, name=f"{mesh.name}-noise{seed}")


def with_needle_vertex(vertices, faces, fraction: float):
    """``(vertices, faces)`` with the edge of the first face split at ``fraction`` of its length from one end:
    a vertex of next to no mass whose two needle triangles have huge cotangents (as an edge collapse can leave).
    The new vertex is the last one."""
    vertices, faces = np.asarray(vertices), np.asarray(faces)
    a, b = faces[0, 0], faces[0, 1]
    new = len(vertices)
    out = []
    for tri in faces.tolist():
        if a in tri and b in tri:
            c = next(x for x in tri if x not in (a, b))
            forward = tri[(tri.index(a) + 1) % 3] == b
            out += [[a, new, c], [new, b, c]] if forward else [[b, new, c], [new, a, c]]
        else:
            out.append(tri)
    return np.vstack([vertices, vertices[a] + fraction * (vertices[b] - vertices[a])]), np.array(out)
