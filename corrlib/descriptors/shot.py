"""SHOT (Signature of Histograms of OrienTations) local shape descriptor.

Reference
---------
F. Tombari, S. Salti, L. Di Stefano, "Unique Signatures of Histograms for
Local Surface Description", ECCV 2010, LNCS 6313, pp. 356-369.
The binning and interpolation follow the reference implementation in PCL
(``pcl::SHOTEstimation`` and ``pcl::SHOTLocalReferenceFrameEstimation``).

Conventions
-----------
* All computations are float64. Distances are in the units of ``vertices``.
* Support: the neighbours of vertex ``p`` are the *other* vertices ``q`` with
  ``0 < ||q - p|| <= radius`` (Euclidean ball, found with
  :class:`scipy.spatial.cKDTree`; the vertex itself and exact duplicates of it
  are ignored).
* Local reference frame (LRF), returned as a ``(3, 3)`` matrix whose **rows**
  are the x, y and z axes: eigenvectors of the weighted covariance
  ``sum_q w_q (q - p)(q - p)^T / sum_q w_q`` with ``w_q = radius - ||q - p||``,
  centred at ``p`` (not at the centroid). ``x`` is the eigenvector of the
  largest eigenvalue, ``z`` that of the smallest. The sign of ``x`` (resp.
  ``z``) is chosen so that the majority of neighbours satisfy
  ``(q - p) . x >= 0``; on an exact tie the sign of ``sum_q (q - p) . x`` is
  used instead (a rotation-invariant tie-break). ``y = z x x`` so the frame is
  proper and right-handed (``det = +1``).
* Descriptor layout: 32 spatial cells x ``n_bins`` cosine bins, flattened as
  ``index = cell * n_bins + bin`` with
  ``cell = 4 * sector + 2 * shell + elevation`` where ``sector`` in ``0..7``
  is the azimuth sector (sector ``k`` covers azimuths
  ``[-pi + k pi/4, -pi + (k+1) pi/4)`` in the LRF x-y plane), ``shell`` is 0
  for ``||q - p|| <= radius/2`` and 1 beyond, and ``elevation`` is 1 for
  neighbours above the LRF x-y plane (``z > 0``) and 0 otherwise.
  The cosine ``n_q . z`` in ``[-1, 1]`` is mapped to ``(1 + cos)/2 *
  (n_bins - 1)``, i.e. bin centres are equally spaced with the first at
  ``cos = -1`` and the last at ``cos = +1``.
* Interpolation follows PCL: every neighbour casts, in its nearest cosine bin
  of its cell, the sum of four linear weights (cosine, radial, elevation,
  azimuth), and the complementary part of each weight goes to the adjacent
  cosine bin, the adjacent radial shell, the other elevation half and the
  adjacent (circular) azimuth sector respectively. Unlike PCL the cosine
  interpolation does not wrap around from the last bin to the first one.
* Each descriptor is L2-normalised over all ``32 * n_bins`` entries.
* Degenerate neighbourhoods: a vertex with fewer than ``min_neighbors``
  neighbours, with zero total LRF weight, or with an empty histogram gets an
  all-zero descriptor row (no exception is raised). Rows of vertices whose
  covariance has (nearly) repeated eigenvalues are valid but their LRF, hence
  their descriptor, is unstable under perturbations.
* Errors: malformed arrays raise :class:`corrlib.errors.InputError`, bad
  parameters :class:`corrlib.errors.ParameterError`; both derive from
  :class:`ValueError` and their messages name the offending argument.
"""

from __future__ import annotations

import math
import numbers

import numba
import numpy as np
from scipy.spatial import cKDTree

from corrlib.errors import InputError, ParameterError
from corrlib.shapes import area_weighted_normals, readonly_view, triangle_areas

__all__ = ["shot", "local_reference_frame", "vertex_normals"]

N_SECTORS = 8
N_CELLS = 32


# --------------------------------------------------------------------------- #
# Validation helpers
# --------------------------------------------------------------------------- #
def _as_points(arr, name, n=None):
    try:
        a = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a numeric (n, 3) array: {exc}") from None
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3), got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise InputError(
            f"{name} must have shape ({n}, 3) to match vertices, got {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} contains non-finite values (NaN or inf)")
    return np.ascontiguousarray(a)


def _as_faces(faces, n_vertices):
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3:
        raise InputError(f"faces must have shape (f, 3), got {f.shape}")
    if f.dtype.kind not in "iu":
        if f.dtype.kind == "f" and np.all(np.isfinite(f)) and np.all(f == np.round(f)):
            f = f.astype(np.int64)
        else:
            raise InputError(f"faces must be an integer array, got dtype {f.dtype}")
    f = f.astype(np.int64, copy=False)
    if f.size and (f.min() < 0 or f.max() >= n_vertices):
        raise InputError(
            f"faces contains vertex indices outside [0, {n_vertices - 1}] "
            f"(min {f.min()}, max {f.max()})"
        )
    return np.ascontiguousarray(f)


def _positive_float(x, name):
    if isinstance(x, bool) or not isinstance(x, (numbers.Real, np.floating, np.integer)):
        raise ParameterError(f"{name} must be a positive real number, got {x!r}")
    x = float(x)
    if not math.isfinite(x) or x <= 0.0:
        raise ParameterError(f"{name} must be a finite number > 0, got {x!r}")
    return x


def _int_at_least(x, name, lo):
    if isinstance(x, bool) or not isinstance(x, (numbers.Integral, np.integer)):
        raise ParameterError(f"{name} must be an integer >= {lo}, got {x!r}")
    x = int(x)
    if x < lo:
        raise ParameterError(f"{name} must be >= {lo}, got {x}")
    return x


# --------------------------------------------------------------------------- #
# Geometry helpers
# --------------------------------------------------------------------------- #
def vertex_normals(vertices, faces):
    """Area-weighted unit vertex normals.

    Parameters
    ----------
    vertices : (n, 3) float
        Vertex positions.
    faces : (f, 3) int
        Triangle vertex indices (orientation defines the normal direction).

    Returns
    -------
    (n, 3) float64
        Unit normals; vertices not referenced by any non-degenerate face get
        a zero normal.
    """
    v = _as_points(vertices, "vertices")
    f = _as_faces(faces, v.shape[0])
    return area_weighted_normals(v, f)


def _neighbour_csr(vertices, radius):
    """CSR adjacency (indptr, indices) of all pairs with distance <= radius."""
    n = vertices.shape[0]
    tree = cKDTree(vertices)
    pairs = tree.query_pairs(radius, output_type="ndarray")
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.argsort(rows, kind="stable")
    indices = np.ascontiguousarray(cols[order], dtype=np.int64)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, indices


# --------------------------------------------------------------------------- #
# Numba kernels
# --------------------------------------------------------------------------- #
@numba.njit(cache=True)
def _lrf_kernel(rel, radius, min_neighbors, frame):
    """Fill ``frame`` (3, 3; rows x, y, z) from offsets ``rel`` (m, 3) = q - p.

    Offsets with norm 0 or > radius are ignored. Returns the number of used
    neighbours, or -1 when the frame is undefined (fewer than
    ``min_neighbors`` neighbours or zero total weight).
    """
    m = rel.shape[0]
    cov = np.zeros((3, 3))
    wsum = 0.0
    count = 0
    for j in range(m):
        dx = rel[j, 0]
        dy = rel[j, 1]
        dz = rel[j, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d <= 0.0 or d > radius:
            continue
        count += 1
        w = radius - d
        wsum += w
        cov[0, 0] += w * dx * dx
        cov[0, 1] += w * dx * dy
        cov[0, 2] += w * dx * dz
        cov[1, 1] += w * dy * dy
        cov[1, 2] += w * dy * dz
        cov[2, 2] += w * dz * dz
    if count < min_neighbors or count == 0 or not (wsum > 0.0):
        return -1
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    for a in range(3):
        for b in range(3):
            cov[a, b] /= wsum
    evals, evecs = np.linalg.eigh(cov)  # ascending eigenvalues
    x0 = evecs[0, 2]
    x1 = evecs[1, 2]
    x2 = evecs[2, 2]
    z0 = evecs[0, 0]
    z1 = evecs[1, 0]
    z2 = evecs[2, 0]
    # sign disambiguation: majority of neighbours on the positive side
    plus_x = 0
    plus_z = 0
    sum_x = 0.0
    sum_z = 0.0
    for j in range(m):
        dx = rel[j, 0]
        dy = rel[j, 1]
        dz = rel[j, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d <= 0.0 or d > radius:
            continue
        px = dx * x0 + dy * x1 + dz * x2
        pz = dx * z0 + dy * z1 + dz * z2
        sum_x += px
        sum_z += pz
        if px >= 0.0:
            plus_x += 1
        if pz >= 0.0:
            plus_z += 1
    minus_x = count - plus_x
    minus_z = count - plus_z
    if plus_x < minus_x or (plus_x == minus_x and sum_x < 0.0):
        x0, x1, x2 = -x0, -x1, -x2
    if plus_z < minus_z or (plus_z == minus_z and sum_z < 0.0):
        z0, z1, z2 = -z0, -z1, -z2
    frame[0, 0] = x0
    frame[0, 1] = x1
    frame[0, 2] = x2
    # y = z cross x
    frame[1, 0] = z1 * x2 - z2 * x1
    frame[1, 1] = z2 * x0 - z0 * x2
    frame[1, 2] = z0 * x1 - z1 * x0
    frame[2, 0] = z0
    frame[2, 1] = z1
    frame[2, 2] = z2
    return count


@numba.njit(cache=True)
def _histogram_kernel(rel, nrm, frame, radius, n_bins, desc):
    """Accumulate the (unnormalised) SHOT histogram of one vertex into desc."""
    pi = math.pi
    half_pi = 0.5 * pi
    quarter_pi = 0.25 * pi
    r_half = 0.5 * radius
    r_quarter = 0.25 * radius
    r_3quarter = 0.75 * radius
    for j in range(rel.shape[0]):
        dx = rel[j, 0]
        dy = rel[j, 1]
        dz = rel[j, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d <= 0.0 or d > radius:
            continue
        lx = dx * frame[0, 0] + dy * frame[0, 1] + dz * frame[0, 2]
        ly = dx * frame[1, 0] + dy * frame[1, 1] + dz * frame[1, 2]
        lz = dx * frame[2, 0] + dy * frame[2, 1] + dz * frame[2, 2]
        if abs(lx) < 1e-30:
            lx = 0.0
        if abs(ly) < 1e-30:
            ly = 0.0
        if abs(lz) < 1e-30:
            lz = 0.0

        # cosine between neighbour normal and LRF z
        c = nrm[j, 0] * frame[2, 0] + nrm[j, 1] * frame[2, 1] + nrm[j, 2] * frame[2, 2]
        if c > 1.0:
            c = 1.0
        elif c < -1.0:
            c = -1.0
        bd = 0.5 * (1.0 + c) * (n_bins - 1)
        step = int(math.floor(bd + 0.5))
        if step > n_bins - 1:
            step = n_bins - 1
        frac = bd - step  # in [-0.5, 0.5]

        # spatial cell
        if lx != 0.0 or ly != 0.0:
            az = math.atan2(ly, lx)
            sector = int(math.floor((az + pi) / quarter_pi))
            if sector > N_SECTORS - 1:
                sector = N_SECTORS - 1
            elif sector < 0:
                sector = 0
            has_az = True
        else:
            az = 0.0
            sector = 0
            has_az = False
        shell = 1 if d > r_half else 0
        elev = 1 if lz > 0.0 else 0
        cell = 4 * sector + 2 * shell + elev

        # cosine interpolation (adjacent bins, no wrap-around)
        weight = 1.0 - abs(frac)
        if frac > 0.0:
            desc[cell * n_bins + step + 1] += frac
        elif frac < 0.0:
            desc[cell * n_bins + step - 1] -= frac

        # radial interpolation (adjacent shells)
        if shell == 1:
            rd = (d - r_3quarter) / r_half
            if d > r_3quarter:
                weight += 1.0 - rd
            else:
                weight += 1.0 + rd
                desc[(cell - 2) * n_bins + step] -= rd
        else:
            rd = (d - r_quarter) / r_half
            if d < r_quarter:
                weight += 1.0 + rd
            else:
                weight += 1.0 - rd
                desc[(cell + 2) * n_bins + step] += rd

        # elevation interpolation (the other half-sphere)
        ic = lz / d
        if ic > 1.0:
            ic = 1.0
        elif ic < -1.0:
            ic = -1.0
        incl = math.acos(ic)
        if elev == 0:
            idist = (incl - 0.75 * pi) / half_pi
            if incl > 0.75 * pi:
                weight += 1.0 - idist
            else:
                weight += 1.0 + idist
                desc[(cell + 1) * n_bins + step] -= idist
        else:
            idist = (incl - quarter_pi) / half_pi
            if incl < quarter_pi:
                weight += 1.0 + idist
            else:
                weight += 1.0 - idist
                desc[(cell - 1) * n_bins + step] += idist

        # azimuth interpolation (adjacent sectors, circular)
        if has_az:
            centre = -pi + (sector + 0.5) * quarter_pi
            adist = (az - centre) / quarter_pi
            if adist > 0.5:
                adist = 0.5
            elif adist < -0.5:
                adist = -0.5
            base = cell - 4 * sector
            if adist > 0.0:
                weight += 1.0 - adist
                other = base + 4 * ((sector + 1) % N_SECTORS)
                desc[other * n_bins + step] += adist
            else:
                weight += 1.0 + adist
                other = base + 4 * ((sector + N_SECTORS - 1) % N_SECTORS)
                desc[other * n_bins + step] -= adist

        desc[cell * n_bins + step] += weight


@numba.njit(cache=True, parallel=True, nogil=True)
def _shot_all(vertices, normals, indptr, indices, radius, n_bins, min_neighbors, out):
    n = vertices.shape[0]
    for i in numba.prange(n):
        start = indptr[i]
        stop = indptr[i + 1]
        m = stop - start
        rel = np.empty((m, 3))
        nrm = np.empty((m, 3))
        for k in range(m):
            q = indices[start + k]
            for a in range(3):
                rel[k, a] = vertices[q, a] - vertices[i, a]
                nrm[k, a] = normals[q, a]
        frame = np.zeros((3, 3))
        if _lrf_kernel(rel, radius, min_neighbors, frame) < 0:
            continue  # out row stays zero
        desc = out[i]
        _histogram_kernel(rel, nrm, frame, radius, n_bins, desc)
        s = 0.0
        for k in range(desc.shape[0]):
            s += desc[k] * desc[k]
        if s > 0.0:
            s = 1.0 / math.sqrt(s)
            for k in range(desc.shape[0]):
                desc[k] *= s


# --------------------------------------------------------------------------- #
# Public API
# --------------------------------------------------------------------------- #
def local_reference_frame(points, center, radius):
    """SHOT local reference frame of a point set around ``center``.

    Parameters
    ----------
    points : (m, 3) float
        Candidate neighbours. Points farther than ``radius`` from ``center``,
        and points coinciding with ``center``, are ignored.
    center : (3,) float
        The keypoint ``p`` (the covariance is centred here, not at the
        centroid of the neighbours).
    radius : float
        Support radius ``R`` (> 0); neighbour weights are ``R - ||q - p||``.

    Returns
    -------
    (3, 3) float64
        Rotation matrix whose rows are the x, y, z axes of the frame
        (``det = +1``). ``x``: eigenvector of the largest eigenvalue of the
        weighted covariance, ``z``: of the smallest, each oriented towards
        the majority of the neighbours; ``y = z x x``. With fewer than three
        non-collinear points the covariance is rank-deficient and the frame,
        although returned, is not unique (:func:`shot` avoids this through
        ``min_neighbors``).

    Raises
    ------
    corrlib.errors.InputError
        (a ``ValueError``) on malformed arrays, or if no point lies at a distance in
        ``(0, radius)`` from ``center`` (the frame is then undefined).
    corrlib.errors.ParameterError
        (a ``ValueError``) if ``radius`` is not a finite number > 0.
    """
    pts = _as_points(points, "points")
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (3,):
        raise InputError(f"center must have shape (3,), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise InputError("center contains non-finite values (NaN or inf)")
    r = _positive_float(radius, "radius")
    frame = np.zeros((3, 3))
    rel = np.ascontiguousarray(pts - c)
    if _lrf_kernel(rel, r, 1, frame) < 0:
        raise InputError(
            "points: no point lies within radius of center (excluding center "
            "itself); the local reference frame is undefined"
        )
    return frame


def _unit_normals(v: np.ndarray, f: np.ndarray | None, normals) -> np.ndarray:
    """(n, 3) float: the given normals scaled to unit length (zero rows stay zero), or area-weighted ones."""
    if normals is None:
        if f is None:
            raise InputError(
                "normals and faces are both None: pass normals, or faces to "
                "compute area-weighted vertex normals"
            )
        return vertex_normals(v, f)
    nrm = _as_points(normals, "normals", n=v.shape[0])
    norm = np.linalg.norm(nrm, axis=1)
    ok = norm > 0
    nrm = nrm.copy()
    nrm[ok] /= norm[ok, None]
    return nrm


def _support_radius(v: np.ndarray, f: np.ndarray | None, radius, radius_fraction) -> float:
    """The SHOT support radius: ``radius`` if given, else ``radius_fraction · sqrt(area)``."""
    if radius is not None:
        return _positive_float(radius, "radius")
    frac = _positive_float(radius_fraction, "radius_fraction")
    if f is None:
        raise InputError(
            "radius is None and faces is None: the default radius "
            "(radius_fraction * sqrt(area)) needs faces; pass radius explicitly"
        )
    area = float(triangle_areas(v, f).sum())
    if not area > 0.0:
        raise InputError(
            "radius: the mesh has zero surface area, cannot derive the "
            "default radius; pass radius explicitly"
        )
    return frac * math.sqrt(area)


def shot(
    vertices,
    faces=None,
    *,
    normals=None,
    radius=None,
    radius_fraction=0.05,
    n_bins=11,
    min_neighbors=5,
):
    """SHOT descriptors for every vertex of a mesh or point cloud.

    Parameters
    ----------
    vertices : (n, 3) float
        Vertex positions.
    faces : (f, 3) int or None
        Triangles. Needed when ``normals`` or ``radius`` is not given.
    normals : (n, 3) float or None
        Vertex normals (normalised internally; zero normals are allowed and
        give a cosine of 0). When None, area-weighted vertex normals are
        computed from ``faces``.
    radius : float or None
        Support radius in the units of ``vertices`` (> 0). Default:
        ``radius_fraction * sqrt(total surface area)`` (requires ``faces``).
    radius_fraction : float
        Fraction of ``sqrt(area)`` used when ``radius`` is None (default
        0.05, i.e. 5 %).
    n_bins : int
        Number of cosine bins per spatial cell (>= 1, default 11 -> 352-D).
    min_neighbors : int
        Vertices with fewer neighbours than this (other vertices within
        ``radius``) get an all-zero descriptor (>= 1, default 5).

    Returns
    -------
    (n, 32 * n_bins) float64
        One descriptor per row, unit L2 norm, or all zeros for degenerate
        neighbourhoods (see module docstring for layout and conventions).

    Raises
    ------
    corrlib.errors.InputError
        (a ``ValueError``) on malformed arrays (shapes, non-finite values,
        out-of-range face indices) or if neither ``faces`` nor ``normals`` is
        given (or ``radius`` is None without ``faces``).
    corrlib.errors.ParameterError
        (a ``ValueError``) on out-of-range parameters (``radius <= 0``,
        ``radius_fraction <= 0``, ``n_bins < 1``, ``min_neighbors < 1``).
    """
    v = _as_points(vertices, "vertices")
    n = v.shape[0]
    if n == 0:
        raise InputError("vertices must contain at least one vertex, got shape (0, 3)")
    f = _as_faces(faces, n) if faces is not None else None
    n_bins = _int_at_least(n_bins, "n_bins", 1)
    min_neighbors = _int_at_least(min_neighbors, "min_neighbors", 1)

    nrm = _unit_normals(v, f, normals)
    r = _support_radius(v, f, radius, radius_fraction)
    indptr, indices = _neighbour_csr(v, r)
    out = np.zeros((n, N_CELLS * n_bins))
    _shot_all(readonly_view(v, np.float64), readonly_view(nrm, np.float64), indptr, indices, r, n_bins, min_neighbors,
              out)
    return out
