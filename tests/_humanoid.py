"""A synthetic humanoid in three poses with exact vertex correspondence, for 2D-to-3D checks on people.

The bundled data hold animals only; people are seen from the front, across
their plane of symmetry, where the outline holds both arms and both legs.
The rest pose is the zero set of a smooth union of capsules (marching
cubes, exactly mirror-symmetric in x); the other poses move its vertices by
linear blend skinning, so vertex i is the same point in every pose and the
left–right mirror of vertex i is known from the rest pose.

``python tests/_humanoid.py OUT`` writes ``human{0,1,2}.off`` with
``.vts`` (identity rows), ``.sym.vts`` (mirrored rows) and
``_segmentation.txt`` (body parts in the vocabulary of the bundled human
sketches, :func:`part_labels`), a dataset for ``corr bench-contour``
(``--sketches resources/data/sketch2d`` scores the sketches against it).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

#: joint positions (x right, y up, z forward), metres
JOINTS = {k: np.array(v, dtype=float) for k, v in {
    "pelvis": (0, 1.0, 0), "chest": (0, 1.42, 0), "neck": (0, 1.55, 0), "head": (0, 1.72, 0),
    "lsh": (0.2, 1.45, 0), "lel": (0.45, 1.25, 0), "lha": (0.68, 1.05, 0),
    "rsh": (-0.2, 1.45, 0), "rel": (-0.45, 1.25, 0), "rha": (-0.68, 1.05, 0),
    "lhip": (0.1, 0.97, 0), "lkn": (0.12, 0.52, 0), "lan": (0.12, 0.1, 0), "lto": (0.12, 0.04, 0.17),
    "rhip": (-0.1, 0.97, 0), "rkn": (-0.12, 0.52, 0), "ran": (-0.12, 0.1, 0), "rto": (-0.12, 0.04, 0.17)}.items()}
#: bones: name, start joint, end joint, radius, parent bone
BONES = [("torso", "pelvis", "chest", 0.16, None), ("neck", "chest", "neck", 0.06, "torso"),
         ("head", "neck", "head", 0.11, "neck"),
         ("lua", "lsh", "lel", 0.055, "torso"), ("lfa", "lel", "lha", 0.045, "lua"),
         ("rua", "rsh", "rel", 0.055, "torso"), ("rfa", "rel", "rha", 0.045, "rua"),
         ("lth", "lhip", "lkn", 0.08, "torso"), ("lsn", "lkn", "lan", 0.06, "lth"), ("lft", "lan", "lto", 0.045, "lsn"),
         ("rth", "rhip", "rkn", 0.08, "torso"), ("rsn", "rkn", "ran", 0.06, "rth"), ("rft", "ran", "rto", 0.045, "rsn"),
         ("shoulders", "lsh", "rsh", 0.07, "torso"), ("hips", "lhip", "rhip", 0.09, "torso")]


#: a front for the capsule body (``front=True``): a nose, a chest and buttocks. Without them the upper body is
#: front-back symmetric as well as left-right, so a half turn about the vertical axis is an orientation-preserving
#: near-isometry of it, which no intrinsic method can tell from the right map (docs/decisions.md)
FRONT_JOINTS = {k: np.array(v, dtype=float) for k, v in {
    "nose0": (0, 1.71, 0.08), "nose1": (0, 1.69, 0.135), "chl": (0.07, 1.32, 0.05), "chr": (-0.07, 1.32, 0.05),
    "bul": (0.07, 0.93, -0.05), "bur": (-0.07, 0.93, -0.05)}.items()}
FRONT_BONES = [("nose", "nose0", "nose1", 0.03, "head"), ("chestfront", "chl", "chr", 0.12, "torso"),
               ("buttocks", "bul", "bur", 0.1, "torso")]
JOINTS.update(FRONT_JOINTS)


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


#: joint rotations of the posed shapes (bone -> rotation about its start joint)
POSES = {
    "human0": {},
    "human1": {"lua": _rotation((0, 0, 1), 1.1), "rua": _rotation((1, 0, 0), -1.0), "rfa": _rotation((1, 0, 0), -0.9),
               "lth": _rotation((1, 0, 0), -0.6), "lsn": _rotation((1, 0, 0), 0.9), "head": _rotation((0, 1, 0), 0.4)},
    "human2": {"lua": _rotation((0, 0, 1), -0.7), "rua": _rotation((0, 0, 1), 0.7), "lfa": _rotation((0, 0, 1), -0.5),
               "rth": _rotation((1, 0, 0), -0.9), "rsn": _rotation((1, 0, 0), 1.2), "torso": _rotation((1, 0, 0), -0.25)},
}


#: a fourth pose, only in the studio's bundled retrieval collection (``resources/people``): arms and legs spread
RETRIEVAL_POSE = {"lua": _rotation((0, 0, 1), 0.5), "rua": _rotation((0, 0, 1), -1.2), "lth": _rotation((0, 0, 1), 0.35),
                  "rth": _rotation((0, 0, 1), -0.35), "head": _rotation((1, 0, 0), 0.3)}


def _segment_distance(points, a, b):
    ab = b - a
    t = np.clip(((points - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[..., None] * ab), axis=-1)


def _smooth_min(a, b, k=0.04):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def rest_pose(spacing: float = 0.025, bones=BONES, joints=None):
    """(vertices (n, 3), faces (f, 3)) of the rest pose, about 4,900 vertices at the default spacing.
    ``joints``: another body's joint positions (:data:`GORILLA_JOINTS`), in a grid around its bones; None:
    :data:`JOINTS`, in the fixed grid of the bundled people."""
    import trimesh
    from skimage.measure import marching_cubes

    if joints is None:
        joints, lo, hi = JOINTS, np.array([-0.85, -0.05, -0.3]), np.array([0.85, 1.9, 0.35])
    else:
        ends = np.array([joints[j] for _, a, b, _, _ in bones for j in (a, b)])
        margin = max(radius for _, _, _, radius, _ in bones) + 0.08
        lo, hi = ends.min(axis=0) - margin, ends.max(axis=0) + margin
    grid = np.stack(np.meshgrid(*[np.arange(a, b, spacing) for a, b in zip(lo, hi)], indexing="ij"), -1)
    sdf = None
    for _, a, b, radius, _ in bones:
        d = _segment_distance(grid, joints[a], joints[b]) - radius
        sdf = d if sdf is None else _smooth_min(sdf, d)
    vertices, faces, _, _ = marching_cubes(sdf, 0.0, spacing=(spacing,) * 3)
    # the faces as marching cubes winds them: outwards for this SDF, negative inside (turned, they were inside out)
    mesh = trimesh.Trimesh(vertices + lo, faces, process=True)
    mesh = max(mesh.split(only_watertight=False), key=lambda c: len(c.faces))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def posed(vertices: np.ndarray, rotations: dict, bones=BONES, joints=JOINTS) -> np.ndarray:
    """Linear blend skinning of rest-pose vertices ((n, 3) float) by joint rotations (forward kinematics)."""
    transforms = {}
    for name, a, _, _, parent in bones:
        rotation = rotations.get(name, np.eye(3))
        local = np.eye(4)
        local[:3, :3], local[:3, 3] = rotation, joints[a] - rotation @ joints[a]
        transforms[name] = (transforms[parent] if parent else np.eye(4)) @ local
    distance = np.stack([_segment_distance(vertices, joints[a], joints[b]) - r for _, a, b, r, _ in bones], axis=1)
    weights = np.exp(-(distance - distance.min(axis=1, keepdims=True)) / 0.02)
    weights /= weights.sum(axis=1, keepdims=True)
    homogeneous = np.c_[vertices, np.ones(len(vertices))]
    return sum(weights[:, i:i + 1] * (homogeneous @ transforms[name].T)[:, :3] for i, (name, *_) in enumerate(bones))


#: part labels of the bundled human sketches (resources/data/sketch2d): a leg, the other leg, chest, an arm,
#: head, the other arm, belly and hips (0: unlabelled). The sketches face the viewer, so their "1" leg and "6"
#: arm lie on the image's right: the person's left (+x here)
SKETCH_PARTS = {"head": 5, "neck": 5, "lua": 6, "lfa": 6, "rua": 4, "rfa": 4, "lth": 1, "lsn": 1, "lft": 1,
                "rth": 2, "rsn": 2, "rft": 2, "shoulders": 3, "hips": 7}


def part_labels(vertices: np.ndarray) -> np.ndarray:
    """(n,) int body part of rest-pose vertices ((n, 3) float) in the sketches' vocabulary.

    Each vertex belongs to its nearest bone; the torso is chest (3) above its midpoint and belly (7) below,
    with an unlabelled band of 6 cm between them, as the sketches leave one."""
    distance = np.stack([_segment_distance(vertices, JOINTS[a], JOINTS[b]) - r for _, a, b, r, _ in BONES], axis=1)
    bone = [BONES[i][0] for i in distance.argmin(axis=1)]
    labels = np.array([SKETCH_PARTS.get(name, 0) for name in bone])
    middle = 0.5 * (JOINTS["pelvis"][1] + JOINTS["chest"][1])
    torso = np.array([name == "torso" for name in bone])
    labels[torso & (vertices[:, 1] >= middle + 0.03)] = 3
    labels[torso & (vertices[:, 1] < middle - 0.03)] = 7
    return labels


def humanoids(spacing: float = 0.025, front: bool = False):
    """{name: (vertices, faces)} of the three poses and the mirror partner of every vertex ((n,) int);
    ``front``: with :data:`FRONT_BONES`, and :data:`RETRIEVAL_POSE` as a fourth pose ``human3``."""
    bones = BONES + FRONT_BONES if front else BONES
    vertices, faces = rest_pose(spacing, bones)
    _, mirror = cKDTree(vertices).query(vertices * [-1.0, 1.0, 1.0])
    poses = {**POSES, "human3": RETRIEVAL_POSE} if front else POSES
    return {name: (posed(vertices, rotations, bones), faces) for name, rotations in poses.items()}, mirror


def write_dataset(folder) -> Path:
    """Write the three poses with .vts and .sym.vts ground truth (1-based rows) and part labels into ``folder``."""
    import trimesh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shapes, mirror = humanoids()
    labels = part_labels(shapes["human0"][0])  # the rest pose: vertex i is the same body point in every pose
    for name, (vertices, faces) in shapes.items():
        trimesh.Trimesh(vertices, faces, process=False).export(folder / f"{name}.off")
        np.savetxt(folder / f"{name}.vts", np.arange(len(vertices)) + 1, fmt="%d")
        np.savetxt(folder / f"{name}.sym.vts", mirror + 1, fmt="%d")
        np.savetxt(folder / f"{name}_segmentation.txt", labels, fmt="%d")
    return folder


def capsule_people():
    """:func:`humanoids` without a front, with :data:`RETRIEVAL_POSE` as a fourth pose ``human3``: the
    people of ``resources/people``."""
    shapes, mirror = humanoids()
    rest_vertices, faces = shapes["human0"]
    shapes["human3"] = (posed(rest_vertices, RETRIEVAL_POSE), faces)
    return shapes, mirror


def write_retrieval_people(folder) -> Path:
    """``human0.off`` … ``human3.off`` (the three poses and :data:`RETRIEVAL_POSE`): ``resources/people``."""
    import trimesh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shapes, _ = capsule_people()
    for name, (vertices, pose_faces) in shapes.items():
        trimesh.Trimesh(vertices, pose_faces, process=False).export(folder / f"{name}.off")
    return folder


def mirror_image(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mirror image x -> -x (faces rewound, so the normals still point out). Vertex i of the image is the
    mirror image of vertex i, so as a person it is the mirror partner of vertex i (its left hand is the
    image of the right hand)."""
    return vertices * [-1.0, 1.0, 1.0], faces[:, ::-1]


def write_kernel_battery(folder, noise: float = 0.0, seed: int = 0, subdivide: int = 0, remesh: int = 0) -> Path:
    """The people pairs that kernel matching's left/right decisions are judged on, as two ``corr bench``
    datasets: ``capsule`` (the bundled people of ``resources/people``: no front but the feet) and ``face``
    (``front=True``: a nose, a chest and buttocks). Each holds the four poses ``human0..3``, their mirror
    images ``mirror0..3`` and ``pairs.txt``: every ordered pair of two poses, and every pose against the
    other poses' mirror images (24 pairs). Ground truth: ``.vts`` rows (vertex i is the same body point in
    every pose, the mirror partner's row in a mirror image) and ``.sym.vts`` (the mirrored rows), so that
    ``corr bench`` reports the error with and without the left/right mirror accepted.

    ``noise``: every vertex moved by Gaussian noise of that fraction of the bounding-box diagonal (each mesh
    its own draw from ``seed``); ``subdivide``: edge-midpoint subdivisions of every mesh (the rows of the
    original vertices are kept, the new vertices have no ground truth row); ``remesh``: every mesh remeshed to
    about that many vertices (:func:`corrlib.geometry.remeshing.remeshed`, each pose meshed on its own, as
    scans are), the rows carried to the remeshed vertex nearest to their vertex (within half an edge). The
    poses share one connectivity otherwise, on which a method that ends in a bijection recovers every vertex
    exactly; remeshed, no method can, and the comparison is that of shapes meshed apart."""
    import trimesh
    from scipy.spatial import cKDTree

    from corrlib.geometry.remeshing import remeshed
    from corrlib.shapes import TriMesh

    rng = np.random.default_rng(seed)
    out = Path(folder)
    for kind, front in (("capsule", False), ("face", True)):
        shapes, mirror = humanoids(front=True) if front else capsule_people()
        target = out / kind
        (target / "corres").mkdir(parents=True, exist_ok=True)
        rows = {"human": np.arange(len(mirror)), "mirror": mirror}
        for pose, (vertices, faces) in sorted(shapes.items()):
            number = pose[len("human"):]
            for prefix, (v, f) in (("human", (vertices, faces)), ("mirror", mirror_image(vertices, faces))):
                for _ in range(subdivide):
                    v, f = trimesh.remesh.subdivide(v, f)
                if noise > 0:
                    v = v + rng.normal(scale=noise * np.linalg.norm(np.ptp(v, axis=0)), size=v.shape)
                name = f"{prefix}{number}"
                other = "mirror" if prefix == "human" else "human"
                # identity rows on the original vertices: a subdivision appends its new vertices after them
                own, mirrored = rows[prefix], rows[other]
                if remesh:
                    coarse = remeshed(TriMesh(v, f, name=name), remesh).mesh
                    nearest = cKDTree(np.asarray(coarse.vertices))
                    own, mirrored = nearest.query(v[own])[1], nearest.query(v[mirrored])[1]
                    v, f = np.asarray(coarse.vertices), np.asarray(coarse.faces)
                trimesh.Trimesh(v, f, process=False).export(target / f"{name}.off")
                np.savetxt(target / "corres" / f"{name}.vts", own + 1, fmt="%d")
                np.savetxt(target / "corres" / f"{name}.sym.vts", mirrored + 1, fmt="%d")
        poses = [pose[len("human"):] for pose in sorted(shapes)]
        pairs = [f"human{a} {prefix}{b}\n" for a in poses for b in poses if a != b for prefix in ("human", "mirror")]
        (target / "pairs.txt").write_text("".join(pairs))
    return out


#: a second body for non-isometric pairs: a heavy torso, long thick arms, short legs, the head low and forward
#: (gorilla proportions; the joint names, bones and poses are the people's, so that the same pose means the same)
GORILLA_JOINTS = {k: np.array(v, dtype=float) for k, v in {
    "pelvis": (0, 0.80, 0), "chest": (0, 1.30, 0.02), "neck": (0, 1.40, 0.05), "head": (0, 1.52, 0.10),
    "lsh": (0.28, 1.33, 0.02), "lel": (0.58, 1.03, 0.0), "lha": (0.88, 0.72, 0.0),
    "rsh": (-0.28, 1.33, 0.02), "rel": (-0.58, 1.03, 0.0), "rha": (-0.88, 0.72, 0.0),
    "lhip": (0.13, 0.77, 0), "lkn": (0.16, 0.45, 0), "lan": (0.16, 0.10, 0), "lto": (0.16, 0.04, 0.19),
    "rhip": (-0.13, 0.77, 0), "rkn": (-0.16, 0.45, 0), "ran": (-0.16, 0.10, 0), "rto": (-0.16, 0.04, 0.19),
    "nose0": (0, 1.50, 0.18), "nose1": (0, 1.48, 0.22), "chl": (0.09, 1.18, 0.10), "chr": (-0.09, 1.18, 0.10),
    "bul": (0.08, 0.74, -0.08), "bur": (-0.08, 0.74, -0.08)}.items()}
#: the gorilla's bone radii relative to the people's
GORILLA_THICKNESS = {"torso": 1.45, "neck": 1.6, "head": 1.05, "lua": 1.5, "lfa": 1.5, "rua": 1.5, "rfa": 1.5,
                     "lth": 1.25, "lsn": 1.2, "rth": 1.25, "rsn": 1.2, "lft": 1.2, "rft": 1.2, "shoulders": 1.5,
                     "hips": 1.3, "nose": 1.0, "chestfront": 1.3, "buttocks": 1.2}


def bone_coordinates(vertices: np.ndarray, joints: dict, bones, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where every vertex ((n, 3) float) lies on its body: the nearest bone ((n,) int, as :func:`part_labels`
    finds it) and (n, 4) coordinates on it — the position along the bone from its start joint (0) to its end
    joint (1), times ``lengths[bone]``, and the unit direction from the bone's axis in a frame of the bone
    (its axis, and the forward direction, or up for a bone that points forward, made perpendicular to it)."""
    distance = np.stack([_segment_distance(vertices, joints[a], joints[b]) - r for _, a, b, r, _ in bones], axis=1)
    bone = distance.argmin(axis=1)
    coordinates = np.zeros((len(vertices), 4))
    for i, (_, a, b, _, _) in enumerate(bones):
        on = bone == i
        axis = joints[b] - joints[a]
        length = np.linalg.norm(axis)
        axis = axis / length
        ahead = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        first = ahead - (ahead @ axis) * axis
        first /= np.linalg.norm(first)
        frame = np.stack([axis, first, np.cross(axis, first)])
        offset = vertices[on] - joints[a]
        along = offset @ axis
        radial = offset - np.outer(along, axis)
        radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
        coordinates[on, 0] = along / length * lengths[i]
        coordinates[on, 1:] = radial @ frame.T
    return bone, coordinates


def body_correspondence(vertices_a, joints_a, bones_a, vertices_b, joints_b, bones_b) -> np.ndarray:
    """(n_a,) int: for every rest-pose vertex of body A, the vertex of body B at the same place on the same bone
    (:func:`bone_coordinates`; the two bodies share their bone names and order). The position along a bone
    is scaled by A's bone length over its radius, so that a step along the bone weighs as much as a step of
    the same length round it on A. An approximation of the natural correspondence of two bodies of
    different proportions: exact on the bones' axes and caps, a few edges off where two bones blend."""
    lengths = np.array([np.linalg.norm(joints_a[b] - joints_a[a]) / r for _, a, b, r, _ in bones_a])
    bone_a, coordinates_a = bone_coordinates(vertices_a, joints_a, bones_a, lengths)
    bone_b, coordinates_b = bone_coordinates(vertices_b, joints_b, bones_b, lengths)
    partner = np.zeros(len(vertices_a), dtype=np.int64)
    for i in np.unique(bone_a):
        on_a, on_b = np.flatnonzero(bone_a == i), np.flatnonzero(bone_b == i)
        partner[on_a] = on_b[cKDTree(coordinates_b[on_b]).query(coordinates_a[on_a])[1]]
    return partner


def write_nonisometric_battery(folder) -> Path:
    """Non-isometric pairs with ground truth, as a ``corr bench`` dataset: the face people (``front=True``)
    ``human0..3`` and a body of gorilla proportions (:data:`GORILLA_JOINTS`, meshed on its own) in the same
    four poses, ``gorilla0..3``; ``pairs.txt``: every gorilla pose to every human pose and every human pose to
    the gorilla's other poses (28 pairs). Ground truth rows are the human rest pose's vertices: the identity
    on the people, :func:`body_correspondence` on the gorilla, and the mirrored rows in ``.sym.vts``."""
    import trimesh

    bones = BONES + FRONT_BONES
    gorilla_bones = [(name, a, b, radius * GORILLA_THICKNESS[name], parent) for name, a, b, radius, parent in bones]
    human_v, human_f = rest_pose(bones=bones)
    gorilla_v, gorilla_f = rest_pose(bones=gorilla_bones, joints=GORILLA_JOINTS)
    _, mirror = cKDTree(human_v).query(human_v * [-1.0, 1.0, 1.0])
    partner = body_correspondence(human_v, JOINTS, bones, gorilla_v, GORILLA_JOINTS, gorilla_bones)
    out = Path(folder)
    (out / "corres").mkdir(parents=True, exist_ok=True)
    rows = {"human": np.arange(len(human_v)), "gorilla": partner}
    poses = {**POSES, "human3": RETRIEVAL_POSE}
    bodies = {"human": (human_v, human_f, bones, JOINTS),
              "gorilla": (gorilla_v, gorilla_f, gorilla_bones, GORILLA_JOINTS)}
    for pose, rotations in sorted(poses.items()):
        number = pose[len("human"):]
        for body, (v, f, body_bones, joints) in bodies.items():
            posed_v = posed(v, rotations, body_bones, joints)
            trimesh.Trimesh(posed_v, f, process=False).export(out / f"{body}{number}.off")
            np.savetxt(out / "corres" / f"{body}{number}.vts", rows[body] + 1, fmt="%d")
            np.savetxt(out / "corres" / f"{body}{number}.sym.vts", rows[body][mirror] + 1, fmt="%d")
    numbers = [pose[len("human"):] for pose in sorted(poses)]
    pairs = [f"gorilla{a} human{b}\n" for a in numbers for b in numbers]
    pairs += [f"human{a} gorilla{b}\n" for a in numbers for b in numbers if a != b]
    (out / "pairs.txt").write_text("".join(pairs))
    return out


def _kernel_battery_main(argv: list[str]) -> None:
    """``--kernel-battery OUT [NOISE [SUBDIVISIONS]]``: named errors and exit status 2 for a bad argument or an
    output folder that is a file, not writable or not empty, before anything is written."""
    import argparse

    parser = argparse.ArgumentParser(prog="python tests/_humanoid.py --kernel-battery",
                                     description="kernel matching's people pairs as two corr bench datasets")
    parser.add_argument("out", type=Path, help="output folder (new or empty): OUT/capsule and OUT/face")
    parser.add_argument("noise", type=float, nargs="?", default=0.0,
                        help="vertex noise, a fraction of the bounding-box diagonal (default 0)")
    parser.add_argument("subdivisions", type=int, nargs="?", default=0,
                        help="edge-midpoint subdivisions of every mesh (default 0)")
    parser.add_argument("--remesh", type=int, default=0, metavar="N",
                        help="every mesh remeshed on its own to about N vertices (default 0: the poses share "
                             "one connectivity)")
    args = parser.parse_args(argv)
    if args.remesh and not 100 <= args.remesh <= 100_000:
        parser.error(f"--remesh must be 100 to 100000 vertices, got {args.remesh}")
    if not (np.isfinite(args.noise) and args.noise >= 0):
        parser.error(f"noise must be a finite fraction >= 0 of the diagonal, got {args.noise}")
    if not 0 <= args.subdivisions <= 3:
        parser.error(f"subdivisions must be 0 to 3 (each multiplies the vertices by four), got {args.subdivisions}")
    _new_output_folders(parser, [args.out / kind for kind in ("capsule", "face")])
    print(write_kernel_battery(args.out, noise=args.noise, subdivide=args.subdivisions, remesh=args.remesh))


def _new_output_folders(parser, folders: list[Path]) -> None:
    """Ends the command with a named error (exit status 2) where a folder is not empty or cannot be made."""
    from corrlib.errors import CorrError
    from corrlib.io import ensure_output_folder

    for folder in folders:
        if folder.is_dir() and any(folder.iterdir()):
            parser.error(f"{folder} is not empty; choose a new output folder")
    for folder in folders:
        try:
            ensure_output_folder(folder)
        except CorrError as exc:
            parser.error(str(exc))


def _nonisometric_main(argv: list[str]) -> None:
    """``--nonisometric OUT``: :func:`write_nonisometric_battery` into a new or empty folder."""
    import argparse

    parser = argparse.ArgumentParser(prog="python tests/_humanoid.py --nonisometric",
                                     description="people and a body of gorilla proportions, a corr bench dataset")
    parser.add_argument("out", type=Path, help="output folder (new or empty)")
    args = parser.parse_args(argv)
    _new_output_folders(parser, [args.out])
    print(write_nonisometric_battery(args.out))


def _dataset_main(argv: list[str]) -> None:
    """``OUT`` (default ``humanoid``): :func:`write_dataset`; ``--people OUT``: :func:`write_retrieval_people`. The
    other modes (``--kernel-battery``, ``--nonisometric``) have their own options."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python tests/_humanoid.py",
        description="the synthetic people as a corr bench-contour dataset (OUT), or the retrieval people "
                    "(--people OUT); other modes: --kernel-battery OUT [NOISE [SUBDIVISIONS]] [--remesh N], "
                    "--nonisometric OUT")
    parser.add_argument("--people", action="store_true", help="write the bundled retrieval people instead")
    parser.add_argument("out", type=Path, nargs="?", default=Path("humanoid"), help="output folder (new or empty)")
    args = parser.parse_args(argv)
    _new_output_folders(parser, [args.out])
    print(write_retrieval_people(args.out) if args.people else write_dataset(args.out))


if __name__ == "__main__":
    # python tests/_humanoid.py OUT: the ground-truth dataset; --people OUT: the bundled retrieval people;
    # --kernel-battery OUT [NOISE [SUBDIVISIONS]] [--remesh N]: kernel matching's people pairs (write_kernel_battery);
    # --nonisometric OUT: people and a gorilla (write_nonisometric_battery)
    if len(sys.argv) > 1 and sys.argv[1] == "--kernel-battery":
        _kernel_battery_main(sys.argv[2:])
    elif len(sys.argv) > 1 and sys.argv[1] == "--nonisometric":
        _nonisometric_main(sys.argv[2:])
    else:
        _dataset_main(sys.argv[1:])
