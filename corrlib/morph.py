"""Shape sequences between a source and a target.

A method with a deformation model (the divergence-free flow) moves the source along it. The flow starts at the
source pre-aligned to the target (turned, moved and brought to its size, which a volume-preserving flow cannot
change); the sequence undoes that alignment by the share ``1 − t`` (``Frames.alignment_undone``), so that every
kind of sequence starts at the source as given and ends at the target's place at t = 1. For any other
point-to-point map the sequence is the as-rigid-as-possible interpolation of the source towards the map's
image (:mod:`corrlib.deformation.rigid_interpolation`): each face turns and stretches by a share of its own
deformation, so a limb that swings keeps its length and the body its volume. It ends at the map's image on
the target's surface (:mod:`corrlib.deformation.surface_image`): every vertex at a point of the surface near
its partner, so that the last frame has no faces collapsed where the map sends neighbours to one vertex.
Linear interpolation of the vertex positions (``interpolation="linear"``) is kept for comparison: it ends at
the target vertices the map gives, shrinks whatever turns and folds where the map does. All kinds extrapolate
for t > 1 and keep the source's connectivity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.errors import InputError

#: how the studio and the CLI describe each kind of sequence
FLOW_DESCRIPTION = ("divergence-free flow (volume preserving; from the source as given to its alignment with the "
                    "target by t = 1, where it approximates the target's pose; t > 1 extrapolates along the same "
                    "field)")
RIGID_DESCRIPTION = ("as-rigid-as-possible interpolation through the map (each face turns and stretches by a share "
                     "of its own deformation, to the map's image on the target's surface; t > 1 extrapolates)")
LINEAR_DESCRIPTION = ("linear vertex interpolation through the map (shrinks what turns, folds where the map "
                      "does)")
#: ``interpolation`` choices: "auto" is the method's flow where it has one, else "rigid"; "flow" asks for the flow
INTERPOLATIONS = ("auto", "flow", "rigid", "linear")


def map_image(source, target_vertices: np.ndarray, map_xy: np.ndarray) -> np.ndarray:
    """(n_x, 3) float: where the map sends every source vertex, ``Y[map_xy]``.

    An unmatched vertex (-1, a partial map) moves with the matched ones round it: its displacement is the
    harmonic extension of theirs (:func:`~corrlib.geometry.laplacian.harmonic_extension` over the source), so
    that an unmatched limb follows the body instead of staying behind and stretching the faces between. A part
    of the source without a matched vertex stays where it is.

    Parameters
    ----------
    source : TriMesh
    target_vertices : (n_y, 3) float
    map_xy : (n_x,) int
    """
    from corrlib.geometry.laplacian import harmonic_extension

    mp = np.asarray(map_xy)
    if mp.shape[0] != source.n_vertices:
        raise InputError(f"the map has {mp.shape[0]} entries for {source.n_vertices} source vertices")
    matched = mp >= 0
    image = np.asarray(target_vertices, dtype=np.float64)[np.clip(mp, 0, None)]
    if matched.all():
        return image
    displacement = harmonic_extension(source.vertices, source.faces, image - source.vertices, matched)
    return np.where(matched[:, None], image, source.vertices + displacement)


def has_deformation(result) -> bool:
    """Whether a result carries a deformation model (a divergence-free flow) rather than only a map."""
    return result.deformation is not None


def sequence_kind(result, interpolation: str = "auto") -> str:
    """``"flow"``, ``"rigid"`` or ``"linear"``: what ``interpolation`` (:data:`INTERPOLATIONS`) means for a
    result; an :class:`InputError` for "flow" where the result has none."""
    if interpolation not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interpolation!r} (use {', '.join(INTERPOLATIONS)})")
    if interpolation == "auto":
        return "flow" if has_deformation(result) else "rigid"
    if interpolation == "flow" and not has_deformation(result):
        raise InputError(f"the result of {result.method!r} has no flow (a deformation model: divergence-free "
                         "fits one); use rigid or linear to interpolate through its map")
    return interpolation


@dataclass(frozen=True)
class GivenMap:
    """A bare map to move through, in the place of a method's result (what the sequence reads of one)."""

    map_xy: np.ndarray
    method: str = "a map"
    deformation: None = None


def as_result(result, source, target):
    """What a sequence moves through: a method's result (anything with ``map_xy``, ``method`` and
    ``deformation``, e.g. a :class:`~corrlib.methods.base.MatchResult`) as it is, or a bare map ((n_x,) int, -1
    unmatched, as ``corr morph --map`` reads one) as a :class:`GivenMap`; an :class:`InputError` naming what is
    wrong with the inputs (not meshes, a map of the wrong length, range or kind)."""
    from corrlib.io import checked_map
    from corrlib.shapes import TriMesh

    for role, shape in (("source", source), ("target", target)):
        if not isinstance(shape, TriMesh):
            raise InputError(f"a sequence moves a mesh onto a mesh: the {role} must be a TriMesh, got "
                             f"{type(shape).__name__}")
    if hasattr(result, "map_xy") and hasattr(result, "deformation"):
        return result
    return GivenMap(checked_map(result, source.n_vertices, target.n_vertices))


def describe_sequence(result, interpolation: str = "auto") -> str:
    """The words the studio and the CLI use for the sequence of a result."""
    return {"flow": FLOW_DESCRIPTION, "rigid": RIGID_DESCRIPTION,
            "linear": LINEAR_DESCRIPTION}[sequence_kind(result, interpolation)]


def _through_map(result, source, target, kind: str):
    if result.map_xy is None:
        raise InputError(f"the result of {result.method!r} has no point-to-point map to interpolate")
    image = map_image(source, target.vertices, result.map_xy)
    if kind == "linear":
        return lambda t: (1.0 - t) * source.vertices + t * image
    from corrlib.deformation.rigid_interpolation import rigid_interpolation
    from corrlib.deformation.surface_image import image_on_surface

    # a vertex map onto the target is known to within the target's vertex spacing
    landed = image_on_surface(source, target, result.map_xy, image)
    return rigid_interpolation(source.vertices, source.faces, landed,
                               resolution=float(np.mean(target.edge_lengths))).positions


def sequence_positions(result, source, target, t_max: float = 1.5, interpolation: str = "auto"):
    """A ``positions(t)`` callable for a result (see the module's notes).

    Parameters
    ----------
    result : MatchResult or (n_x,) int
        A method's result, or a map (-1: unmatched).
    source, target : TriMesh
    t_max : float
        Largest time the callable will be asked for (the flow is precomputed up to it).
    interpolation : {"auto", "flow", "rigid", "linear"}
        "auto": the method's flow where it has one, else "rigid".

    Returns
    -------
    callable
        ``positions(t) -> (n_x, 3)``; for the flow its RK2 trajectory (exact at its steps, linear in between).
    """
    result = as_result(result, source, target)
    kind = sequence_kind(result, interpolation)
    if kind == "flow":
        flowed, frames = result.deformation.source_interpolator(source.vertices, t_max), result.deformation.frames
        return lambda t: frames.alignment_undone(flowed(t), t)
    return _through_map(result, source, target, kind)


def frame_times(count: int, t_max: float) -> np.ndarray:
    """The times of exported frames: ``count`` evenly spaced from 0 to ``t_max``, and t = 1 (the target) added
    where they extrapolate past it without a frame at it ((count,) or (count + 1,) float, increasing)."""
    times = np.linspace(0.0, t_max, count)
    if t_max > 1.0 and not np.any(np.isclose(times, 1.0, rtol=0.0, atol=1e-9)):
        times = np.sort(np.append(times, 1.0))
    return times


def frame_positions(result, source, target, times, interpolation: str = "auto") -> list[np.ndarray]:
    """Exact positions at ``times`` (the flow integrated to each time, or the interpolation through the map); the
    times must be finite numbers (every kind extrapolates beyond 1).

    Parameters
    ----------
    result : MatchResult or (n_x,) int
        A method's result, or a map (-1: unmatched).
    source, target : TriMesh
    times : (F,) float
        E.g. :func:`frame_times`.
    interpolation : {"auto", "flow", "rigid", "linear"}
        See :func:`sequence_positions`.

    Returns
    -------
    list of (n_x, 3) float
        One frame per time, on the source's faces (:func:`export_sequence` writes them).
    """
    result = as_result(result, source, target)
    try:
        times = np.asarray(times, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"times must be numbers, got {times!r}") from None
    if not np.all(np.isfinite(times)):
        raise InputError(f"times must be finite, got {float(times[~np.isfinite(times)][0])!r}")
    kind = sequence_kind(result, interpolation)
    if kind == "flow":
        deformation = result.deformation
        return [deformation.frames.alignment_undone(deformation.positions(source.vertices, float(t)), float(t))
                for t in times]
    positions = _through_map(result, source, target, kind)
    return [positions(float(t)) for t in times]


def frame_volumes(frames, faces, closed: bool) -> list[float | None]:
    """Enclosed volume of every frame (``None`` for every frame of a mesh that is not closed)."""
    from corrlib.shapes import signed_volume

    return [signed_volume(f, faces) if closed else None for f in frames]


def folded_share(frame: np.ndarray, faces: np.ndarray, target, map_xy: np.ndarray) -> float:
    """The share of the faces ((f, 3) int) of a sequence's frame at t = 1 through a map, ``frame`` (n_x, 3),
    that face against the target's surface where they lie or have no area: their normal against the sum of
    their corners' partners' vertex normals (``map_xy``), or, where they lie on a face of the target, that
    face's winding (faces with an unmatched corner are not counted). A
    map that crosses itself or sends neighbours to one vertex folds the last frame there; the surface image
    unfolds what it can (:mod:`corrlib.deformation.surface_image`), a flow never folds."""
    from corrlib.deformation.surface_image import is_target_face

    partners = np.asarray(map_xy)[faces]
    complete = np.all(partners >= 0, axis=1)
    if not complete.any():
        return 0.0
    partners = partners[complete]
    corners = np.asarray(frame)[faces[complete]]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    facing = np.einsum("ij,ij->i", normals, target.vertex_normals[partners].sum(axis=1))
    # a face lying on a face of the target faces the way the surface does, or against it if wound the other way
    on_face = np.all(corners == target.vertices[partners], axis=(1, 2))
    along, against = on_face & is_target_face(partners, target), on_face & is_target_face(partners[:, ::-1], target)
    return float(np.mean(np.where(along | against, against, facing <= 0.0)))


def last_frame_note(result, source, target, times, frames, interpolation: str = "auto") -> str | None:
    """What the CLI and the studio say of a sequence's frame at t = 1 (taken from ``frames`` at ``times``, or
    computed): the share of its faces turned over against the target's surface (:func:`folded_share`). None
    for a flow, which never folds, or a result without a map onto a mesh."""
    from corrlib.shapes import TriMesh

    map_xy = getattr(result, "map_xy", None)
    if map_xy is None or not isinstance(target, TriMesh) or sequence_kind(result, interpolation) == "flow":
        return None
    last = next((frame for t, frame in zip(times, frames) if abs(t - 1.0) <= 1e-9), None)  # as frame_times adds it
    if last is None:
        last = frame_positions(result, source, target, [1.0], interpolation)[0]
    share = folded_share(last, source.faces, target, map_xy)
    advice = ("" if share == 0 else " where the map crosses itself or sends neighbours to one vertex (a flow, "
              "as the divergence-free method fits, does not fold)")
    return f"last frame (t = 1, on {target.name}'s surface): {100 * share:.1f} % of the faces turned over{advice}"


def largest_volume_change(volumes: list[float | None], area: float) -> float | None:
    """The largest ``|V(t) / V(0) − 1|`` over frames' enclosed volumes (:func:`frame_volumes`), or None where a
    relative change does not apply (an open mesh, or a closed one that encloses nothing;
    :func:`~corrlib.shapes.relative_volume_change`)."""
    from corrlib.shapes import relative_volume_change

    changes = [relative_volume_change(v, volumes[0], area) for v in volumes] if volumes else [None]
    return None if changes[0] is None else max(abs(c) for c in changes)


def export_sequence(folder, frames, faces, times, *, fmt: str = "obj", animation: bool = True,
                    closed: bool = True, name: str = "frame") -> dict:
    """Write a mesh sequence: one mesh per frame, a glTF animation and a volume table.

    Parameters
    ----------
    folder : path
        Created if needed.
    frames : list of (n, 3) float
        Vertex positions per frame (same connectivity).
    faces : (f, 3) int
    times : (F,) float
        The time of every frame (t = 1 is the target; t > 1 extrapolates).
    fmt : {"obj", "ply", "off"}
    animation : bool
        Also write ``animation.glb``: glTF 2.0 binary, the first frame as the
        base mesh and one morph target per further frame, with a weights
        animation (one second per unit of t) that passes through every frame
        (Blender, three.js and most viewers play it).
    closed : bool
        Whether volumes apply (the source mesh is closed).

    Returns
    -------
    dict
        ``{"frames": [paths], "animation": path or None, "volumes": path,
        "volume": [floats or None]}``.
    """
    from pathlib import Path

    from corrlib.io import atomic_write, save_mesh

    if fmt not in ("obj", "ply", "off"):
        raise InputError(f"unknown frame format {fmt!r} (use obj, ply or off)")
    if len(frames) != len(times) or len(frames) == 0:
        raise InputError(f"{len(frames)} frames for {len(times)} times")
    _check_frames(frames, faces)  # before the folder is made: a bad frame leaves nothing behind
    out = Path(folder)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the folder for the frames ({exc.strerror or exc})") from None
    digits = max(3, len(str(len(frames) - 1)))
    paths = [save_mesh(out / f"{name}_{i:0{digits}d}.{fmt}", f, faces) for i, f in enumerate(frames)]
    from corrlib.shapes import relative_volume_change, triangle_areas

    volumes = frame_volumes(frames, faces, closed)
    area = float(triangle_areas(np.asarray(frames[0]), np.asarray(faces)).sum())  # frames: at least one
    table = out / "volumes.csv"
    with atomic_write(table) as fh:
        fh.write("frame,t,volume,relative_change\n")
        for i, (t, v) in enumerate(zip(times, volumes)):
            if v is None:
                fh.write(f"{i},{t:.6g},not applicable (open mesh),\n")
                continue
            change = relative_volume_change(v, volumes[0], area)
            said = "not applicable (no volume at t = 0)" if change is None else f"{change:.3e}"
            fh.write(f"{i},{t:.6g},{v:.9g},{said}\n")
    anim = save_glb_animation(out / "animation.glb", frames, faces, times) if animation else None
    return {"frames": paths, "animation": anim, "volumes": table, "volume": volumes}


def _check_frames(frames, faces) -> None:
    """An :class:`InputError` unless ``faces`` are a mesh's triangles on the first frame's vertices
    (:class:`~corrlib.shapes.TriMesh` checks them) and every frame holds finite positions of the same shape."""
    from corrlib.shapes import TriMesh

    first = TriMesh(np.asarray(frames[0], dtype=np.float64), faces, name="frame 0")
    for index, frame in enumerate(frames):
        positions = np.asarray(frame, dtype=np.float64)
        if positions.shape != first.vertices.shape:
            raise InputError(f"frame {index} must hold positions of shape {first.vertices.shape} (the first "
                             f"frame's), got shape {positions.shape}")
        if not np.all(np.isfinite(positions)):
            raise InputError(f"frame {index} holds NaN or infinite positions")


def save_glb_animation(path, frames, faces, times):
    """Write a glTF 2.0 binary (.glb) morph-target animation of a mesh sequence.

    The first frame is the base mesh; frame ``i > 0`` is morph target ``i - 1``
    (its displacement from the base); the animation channel drives the
    morph weights linearly from one-hot vector to one-hot vector at the
    frame times (seconds = t), so playback passes through every frame.
    """
    import json
    import struct
    from pathlib import Path

    from corrlib.io import atomic_write

    base = np.asarray(frames[0], dtype=np.float32)
    faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
    n_targets = len(frames) - 1
    blobs: list[bytes] = []
    views: list[dict] = []
    accessors: list[dict] = []

    def add(array: np.ndarray, accessor: dict, target: int | None = None) -> int:
        offset = sum(len(b) for b in blobs)
        data = np.ascontiguousarray(array).tobytes()
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        blobs.append(data + b"\0" * (-len(data) % 4))
        views.append(view)
        accessors.append({"bufferView": len(views) - 1, **accessor})
        return len(accessors) - 1

    def vec3(a: np.ndarray) -> dict:
        return {"componentType": 5126, "count": len(a), "type": "VEC3",
                "min": a.min(axis=0).tolist(), "max": a.max(axis=0).tolist()}

    pos = add(base, vec3(base), 34962)
    idx = add(faces32.ravel(), {"componentType": 5125, "count": faces32.size, "type": "SCALAR"}, 34963)
    targets = []
    for f in frames[1:]:
        disp = np.asarray(f, dtype=np.float32) - base
        targets.append({"POSITION": add(disp, vec3(disp), 34962)})
    t = np.asarray(times, dtype=np.float32)
    t = t - t[0]
    weights = np.zeros((len(frames), n_targets), dtype=np.float32)
    weights[np.arange(1, len(frames)), np.arange(n_targets)] = 1.0
    primitive = {"attributes": {"POSITION": pos}, "indices": idx, "mode": 4}
    mesh = {"primitives": [primitive], "name": "sequence"}
    doc = {"asset": {"version": "2.0", "generator": "corrlib"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0, "name": "sequence"}], "meshes": [mesh]}
    if n_targets:
        primitive["targets"] = targets
        mesh["weights"] = [0.0] * n_targets
        t_acc = add(t, {"componentType": 5126, "count": len(t), "type": "SCALAR",
                        "min": [float(t.min())], "max": [float(t.max())]})
        w_acc = add(weights.ravel(), {"componentType": 5126, "count": weights.size, "type": "SCALAR"})
        doc["animations"] = [{"name": "morph", "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
                              "samplers": [{"input": t_acc, "output": w_acc, "interpolation": "LINEAR"}]}]
    binary = b"".join(blobs)
    doc["buffers"] = [{"byteLength": len(binary)}]
    doc["bufferViews"] = views
    doc["accessors"] = accessors
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fh.write(struct.pack("<III", 0x46546C67, 2, total))
        fh.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
        fh.write(struct.pack("<II", len(binary), 0x004E4942) + binary)
    return path


def load_glb_frames(path) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Read back what :func:`save_glb_animation` wrote: faces, frame positions and key times."""
    import json
    import struct
    from pathlib import Path

    from corrlib.errors import FileFormatError

    data = Path(path).read_bytes()
    if len(data) < 20 or struct.unpack_from("<I", data, 0)[0] != 0x46546C67:
        raise FileFormatError(f"{path}: not a glTF binary")
    json_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + json_len])
    binary = data[20 + json_len + 8:]
    types = {5126: np.float32, 5125: np.uint32}
    widths = {"SCALAR": 1, "VEC3": 3}

    def read(i: int) -> np.ndarray:
        acc = doc["accessors"][i]
        view = doc["bufferViews"][acc["bufferView"]]
        arr = np.frombuffer(binary, dtype=types[acc["componentType"]], count=acc["count"] * widths[acc["type"]],
                            offset=view["byteOffset"])
        return arr.reshape(acc["count"], widths[acc["type"]]) if acc["type"] != "SCALAR" else arr

    prim = doc["meshes"][0]["primitives"][0]
    base = read(prim["attributes"]["POSITION"]).astype(np.float64)
    faces = read(prim["indices"]).reshape(-1, 3).astype(np.int64)
    frames = [base] + [base + read(t["POSITION"]) for t in prim.get("targets", [])]
    times = np.zeros(1)
    if doc.get("animations"):
        times = read(doc["animations"][0]["samplers"][0]["input"]).astype(np.float64)
    return faces, frames, times
