"""Quadric edge-collapse simplification that remembers where every detail vertex went.

:func:`simplify` turns a prepared detail mesh into a proxy and the (u,) map from welded
detail vertex to the proxy vertex it collapsed into. Components that are too small to
simplify are copied whole; the others are simplified one by one with fast-simplification,
each to its share of the face budget.
"""

from dataclasses import dataclass

import fast_simplification
import numpy as np
from scipy.spatial import cKDTree

#: A component is never simplified below this many faces; one at or below it is kept whole.
MIN_COMPONENT_FACES = 8


@dataclass
class Simplified:
    """Proxy mesh and collapse map.

    points      (m, 3) float64  proxy vertex positions
    triangles   (k, 3) int64    proxy faces
    carrier     (u,) int64      proxy vertex each welded detail vertex collapsed into; -1 for
                                vertices no kept face uses
    component   (m,) int64      detail component label of every proxy vertex
    kept_whole  int             number of components copied without simplification
    """

    points: np.ndarray
    triangles: np.ndarray
    carrier: np.ndarray
    component: np.ndarray
    kept_whole: int


def component_targets(face_components, target_faces):
    """Face budget of each component (labels (t,)): shares of ``target_faces`` by face count.

    Returns (labels (c,), face counts (c,), targets (c,)); a target equal to the count means
    "keep whole".
    """
    labels, counts = np.unique(face_components, return_counts=True)
    share = np.round(target_faces * counts / counts.sum()).astype(np.int64)
    targets = np.minimum(counts, np.maximum(share, MIN_COMPONENT_FACES))
    return labels, counts, targets


def collapse_roots(collapses, n_points):
    """(n,) surviving vertex of every vertex after the collapses ``(c, 2)`` [kept, removed]."""
    parent = np.arange(n_points, dtype=np.int64)
    if collapses.size:
        parent[collapses[:, 1]] = collapses[:, 0]
    while True:
        grand = parent[parent]
        if np.array_equal(grand, parent):
            return parent
        parent = grand


def follow_nearest(carrier, triangles, points, proxy_points):
    """``carrier`` (u,) made whole: a vertex that some face of ``triangles`` uses but whose survivor
    lost all its faces (carrier -1 or out of range) follows the proxy vertex nearest to it;
    vertices no face uses get -1."""
    in_faces = np.zeros(points.shape[0], dtype=bool)
    in_faces[triangles.ravel()] = True
    lost = in_faces & ((carrier < 0) | (carrier >= proxy_points.shape[0]))
    if lost.any():
        carrier = carrier.copy()
        carrier[lost] = cKDTree(proxy_points).query(points[lost])[1]
    return np.where(in_faces, carrier, -1)


def simplify_component(points, triangles, target):
    """Simplify one mesh to ``target`` faces: (points (m, 3), faces (k, 3), carrier (n,)).

    ``carrier`` maps every vertex of ``points`` to the output vertex it collapsed into, or -1
    for vertices no face uses.
    """
    out_points, out_faces, collapses = fast_simplification.simplify(
        points, triangles.astype(np.int32), target_count=int(target), return_collapses=True)
    out_faces = out_faces.astype(np.int64)
    n = points.shape[0]
    root = collapse_roots(np.asarray(collapses, dtype=np.int64), n)
    # A face survives when its three roots are distinct; the library keeps survivors in order
    # and numbers the vertices they use in ascending id order.
    face_roots = root[triangles]
    alive = ((face_roots[:, 0] != face_roots[:, 1]) & (face_roots[:, 1] != face_roots[:, 2])
             & (face_roots[:, 2] != face_roots[:, 0]))
    used = np.unique(face_roots[alive])
    rank = np.full(n, -1, dtype=np.int64)
    rank[used] = np.arange(used.size)
    if used.size != out_points.shape[0] or not np.array_equal(rank[face_roots[alive]], out_faces):
        _, _, rank_map = fast_simplification.replay_simplification(points, triangles.astype(np.int32), collapses)
        carrier = np.asarray(rank_map, dtype=np.int64)
    else:
        carrier = rank[root]
    carrier = follow_nearest(carrier, triangles, points, out_points)
    return out_points, out_faces, carrier


def simplify(points, triangles, components, target_faces, oversample=1.0):
    """Proxy of a mesh with about ``target_faces * oversample`` faces: ``points`` (u, 3),
    ``triangles`` (t, 3) (no degenerate or repeated faces), ``components`` (u,) labels.

    Each component gets ``oversample`` times its share of ``target_faces`` (never more faces
    than it has); components at or below their share are copied whole.
    """
    face_comp = components[triangles[:, 0]]
    labels, counts, targets = component_targets(face_comp, target_faces)
    goals = np.minimum(counts, np.round(targets * oversample).astype(np.int64))
    u = points.shape[0]
    carrier = np.full(u, -1, dtype=np.int64)
    parts = []

    whole = np.isin(face_comp, labels[goals >= counts])
    if whole.any():
        ids, local = np.unique(triangles[whole], return_inverse=True)
        parts.append((ids, points[ids], local.reshape(-1, 3), np.arange(ids.size)))
    simplified = labels[goals < counts]
    if simplified.size == 1 and not whole.any() and np.bincount(triangles.ravel(), minlength=u).all():
        # One component using every vertex (the usual scan or sculpt): no re-indexing needed.
        parts.append((np.arange(u), *simplify_component(points, triangles, goals[goals < counts][0])))
    else:
        for label, goal in zip(simplified, goals[goals < counts]):
            ids, local = np.unique(triangles[face_comp == label], return_inverse=True)
            parts.append((ids, *simplify_component(points[ids], local.reshape(-1, 3), goal)))

    offset = 0
    all_points, all_faces = [], []
    for ids, out_points, out_faces, local_carrier in parts:
        carrier[ids] = np.where(local_carrier >= 0, local_carrier + offset, -1)
        all_points.append(out_points)
        all_faces.append(out_faces + offset)
        offset += out_points.shape[0]
    proxy_points = np.ascontiguousarray(np.concatenate(all_points), dtype=np.float64)
    proxy_triangles = np.ascontiguousarray(np.concatenate(all_faces), dtype=np.int64)
    component = np.zeros(proxy_points.shape[0], dtype=np.int64)
    used = carrier >= 0
    component[carrier[used]] = components[used]
    return Simplified(points=proxy_points, triangles=proxy_triangles, carrier=carrier, component=component,
                      kept_whole=int((goals >= counts).sum()))
