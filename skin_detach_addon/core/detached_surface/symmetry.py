"""Mirror symmetry of a mesh: which vertex is each vertex's mirror image, and making positions
exactly symmetric.

Arrays: ``points`` (n, 3) indexed by vertex id, in the mesh's local space; ``axis`` 0, 1 or 2
(the plane of symmetry is through the origin, normal to that axis, as Blender's Mesh Symmetry).
"""

import numpy as np
from scipy.spatial import cKDTree

from ..errors import SkinDetachError
from ..geometry import bbox_diagonal

#: Vertices match their mirror image within this fraction of the bounding-box diagonal.
MIRROR_TOLERANCE = 1e-4


def mirror_map(points, axis, tolerance=MIRROR_TOLERANCE):
    """(n,) int64: the vertex at the mirror image of each vertex (itself on the plane), -1 where
    no vertex lies within ``tolerance`` of the diagonal of it."""
    if axis not in (0, 1, 2):
        raise SkinDetachError(f"axis: expected 0, 1 or 2, got {axis!r}")
    points = np.asarray(points, dtype=np.float64)
    mirrored = points.copy()
    mirrored[:, axis] *= -1.0
    distance, nearest = cKDTree(points).query(mirrored, distance_upper_bound=tolerance * bbox_diagonal(points))
    out = np.where(np.isfinite(distance), nearest, -1).astype(np.int64)
    # A pair must agree both ways (no two vertices claiming the same twin).
    matched = out >= 0
    back = np.full(out.shape, -1)
    back[matched] = out[out[matched]]
    out[matched & (back != np.arange(out.size))] = -1
    return out


def is_own_mirror_image(points, axis, tolerance):
    """Whether the point set ``points`` (k, 3) is its own mirror image across the plane through
    the origin normal to ``axis`` (0, 1 or 2): the image of every point lies within ``tolerance``
    (a distance) of a point of the set, and the images pair the points one to one."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape[0] == 0:
        return False
    # A one-to-one pairing within the tolerance pairs the coordinates along the axis with their
    # negatives within it too, and sorted order is the best such pairing: a sort rules most sets
    # out before a tree is built over them (a selection of a million vertices: 0.1 s, not 1 s).
    along = points[:, axis]
    if abs(along.mean()) > tolerance:  # the pairs' coordinates cancel: their mean is within it
        return False
    along = np.sort(along)
    if np.abs(along + along[::-1]).max() > tolerance:
        return False
    mirrored = points.copy()
    mirrored[:, axis] *= -1.0
    distance, nearest = cKDTree(points).query(mirrored, distance_upper_bound=tolerance)
    return bool(np.isfinite(distance).all()) and np.unique(nearest).size == points.shape[0]


def mirrored_ids(mapping, ids, axis_name="X"):
    """Mirror images (k,) of the vertex ids (k,) under ``mapping`` (:func:`mirror_map`); raises
    naming how many have none."""
    ids = np.asarray(ids, dtype=np.int64)
    twins = mapping[ids]
    missing = int((twins < 0).sum())
    if missing:
        raise SkinDetachError(f"mirror: expected a mesh symmetric across {axis_name} (a vertex at the mirror image "
                              f"of every selected vertex, within {MIRROR_TOLERANCE:g} of the diagonal), got "
                              f"{missing} of {ids.size} selected vertices without one; turn mirror off or make "
                              f"the mesh symmetric (Mesh > Symmetrize)")
    return twins


def symmetrize(positions, mapping, axis):
    """``positions`` (n, 3) averaged with their mirror images: vertices with a twin (mapping >= 0)
    become exactly symmetric; the others keep their positions. Returns a new array of the same dtype."""
    out = np.array(positions, copy=True)
    matched = np.flatnonzero(mapping >= 0)
    image = positions[mapping[matched]].astype(np.float64)
    image[:, axis] *= -1.0
    out[matched] = (0.5 * (positions[matched].astype(np.float64) + image)).astype(out.dtype)
    return out
