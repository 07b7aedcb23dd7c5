"""Checks at the points where arrays enter the core.

Each function returns a clean, contiguous copy-or-view of its input with a fixed dtype, or
raises :class:`SkinDetachError` naming the argument, what was expected and what was given.
"""

import numpy as np

from .errors import SkinDetachError

#: Smallest and largest proxy face counts a build accepts.
MIN_TARGET_FACES = 4
MAX_TARGET_FACES = 200_000


def as_points(name, array, count=None):
    """``array`` as a C-contiguous (count, 3) float64 array of finite numbers."""
    try:
        points = np.ascontiguousarray(array, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SkinDetachError(f"{name}: expected an (n, 3) array of numbers, got {type(array).__name__} ({exc})") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise SkinDetachError(f"{name}: expected shape (n, 3), got {points.shape}")
    if count is not None and points.shape[0] != count:
        raise SkinDetachError(f"{name}: expected shape ({count}, 3), got {points.shape}")
    if points.shape[0] == 0:
        raise SkinDetachError(f"{name}: expected at least one point, got an empty array")
    if not np.isfinite(points).all():
        bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
        raise SkinDetachError(
            f"{name}: expected finite coordinates, got NaN or inf at {bad.size} row(s), first row {bad[0]}")
    return points


def as_triangles(name, array, n_points, narrow=False):
    """``array`` as a C-contiguous (f, 3) int64 array of indices into ``n_points`` points; with
    ``narrow``, int32 where the indices fit (Blender's own type: no copy of its triangles, half
    the memory of int64 on millions of faces)."""
    raw = np.asarray(array)
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise SkinDetachError(f"{name}: expected shape (f, 3), got {raw.shape}")
    if raw.shape[0] == 0:
        raise SkinDetachError(f"{name}: expected at least one triangle, got an empty array")
    if raw.dtype.kind not in "iu":
        if raw.dtype.kind != "f" or not np.isfinite(raw).all() or (raw != np.round(raw)).any():
            raise SkinDetachError(f"{name}: expected integer vertex indices, got dtype {raw.dtype}")
    low, high = int(raw.min()), int(raw.max())
    if low < 0 or high >= n_points:
        raise SkinDetachError(
            f"{name}: expected indices in [0, {n_points}), got values in [{low}, {high}]")
    return np.ascontiguousarray(raw, dtype=np.int32 if narrow and n_points <= 2**31 else np.int64)


def as_target_faces(target_faces):
    """``target_faces`` as an int in [MIN_TARGET_FACES, MAX_TARGET_FACES]."""
    if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)):
        raise SkinDetachError(f"target_faces: expected an integer, got {target_faces!r}")
    if not MIN_TARGET_FACES <= target_faces <= MAX_TARGET_FACES:
        raise SkinDetachError(
            f"target_faces: expected {MIN_TARGET_FACES} to {MAX_TARGET_FACES}, got {target_faces}")
    return int(target_faces)


#: Smallest preview a build makes (a clustered copy of fewer vertices is no use to look at).
MIN_PREVIEW_VERTICES = 16


def as_preview_vertices(preview_vertices):
    """``preview_vertices`` as None or an int of at least MIN_PREVIEW_VERTICES."""
    if preview_vertices is None:
        return None
    if isinstance(preview_vertices, bool) or not isinstance(preview_vertices, (int, np.integer)) \
            or preview_vertices < MIN_PREVIEW_VERTICES:
        raise SkinDetachError(f"preview_vertices: expected None or an integer of at least {MIN_PREVIEW_VERTICES}, "
                              f"got {preview_vertices!r}")
    return int(preview_vertices)


def as_ids(name, ids, limit=None, what="ids"):
    """``ids`` (any shape) as a flat int64 array of integers in [0, ``limit``) (any non-negative
    int64 when ``limit`` is None; empty stays empty); ``name`` and ``what`` name them in the
    message, which gives the values as they are (a uint64 2**63 is not read as a negative int64)."""
    raw = np.asarray(ids)
    if raw.size == 0:
        return np.zeros(0, dtype=np.int64)
    if raw.dtype.kind not in "iu":
        raise SkinDetachError(f"{name}: expected integer {what}, got dtype {raw.dtype}")
    low, high = int(raw.min()), int(raw.max())  # Python ints: exact whatever the dtype
    if low < 0 or high >= (2**63 if limit is None else limit):
        expected = f"{what} in [0, {limit})" if limit is not None else f"non-negative {what} below 2**63"
        raise SkinDetachError(f"{name}: expected {expected}, got values in [{low}, {high}]")
    return raw.astype(np.int64).ravel()


def as_vertex_ids(name, ids, n_points):
    """``ids`` as a 1-D int64 array of at least one index in [0, n_points)."""
    if np.asarray(ids).size == 0:
        raise SkinDetachError(f"{name}: expected at least one vertex id, got none")
    return as_ids(name, ids, n_points, "vertex ids")
