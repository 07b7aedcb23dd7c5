"""Small geometric and topological building blocks shared by the core modules.

Conventions: ``points`` is (n, 3) float64, indexed by vertex id; ``triangles`` is (f, 3) int,
indexed by face id, each row the three vertex ids of one face in counter-clockwise order.
"""

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from . import threads
from .threads import map_blocks


def cross_rows(a, b):
    """(r, 3) row-wise cross products of (r, 3) arrays (np.cross is slow on many rows)."""
    out = np.empty(a.shape)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


#: Faces per block in :func:`face_cross` (bounds its scratch memory on millions of faces).
FACE_BLOCK = 1 << 20


def face_cross(points, triangles):
    """(f, 3) cross products (P1 - P0) x (P2 - P0): the face normal scaled by twice its area.
    Blocks of :data:`FACE_BLOCK` faces run on the core's threads (the gathers dominate)."""
    out = np.empty((triangles.shape[0], 3))

    def block(start):
        rows = triangles[start:start + FACE_BLOCK]
        p0 = points[rows[:, 0]]
        out[start:start + FACE_BLOCK] = cross_rows(points[rows[:, 1]] - p0, points[rows[:, 2]] - p0)

    map_blocks(block, list(range(0, triangles.shape[0], FACE_BLOCK)))
    return out


def unit_rows(vectors, eps=0.0):
    """(r, 3) rows scaled to unit length; rows of length <= eps stay zero. Also returns the lengths."""
    lengths = np.sqrt(np.einsum("ij,ij->i", vectors, vectors))
    safe = np.where(lengths > eps, lengths, 1.0)
    unit = vectors / safe[:, None]
    unit[lengths <= eps] = 0.0
    return unit, lengths


def vertex_normals(points, triangles, cross=None):
    """(n, 3) unit area-weighted vertex normals; zero for vertices without a face of non-zero area.

    ``cross`` (f, 3), if given, is :func:`face_cross` of the same mesh.
    """
    if cross is None:
        cross = face_cross(points, triangles)
    n = points.shape[0]
    acc = np.zeros((n, 3))
    corners = [np.ascontiguousarray(triangles[:, corner], dtype=np.intp) for corner in range(3)]  # once, not per axis

    def axis_sum(axis):  # bincounts run side by side on the core's threads
        weights = np.ascontiguousarray(cross[:, axis])
        for corner in corners:
            acc[:, axis] += np.bincount(corner, weights=weights, minlength=n)

    map_blocks(axis_sum, [0, 1, 2])
    return unit_rows(acc)[0]


def bbox_diagonal(points):
    """Length of the diagonal of the axis-aligned bounding box of ``points`` (n, 3) (numpy's own
    arithmetic, not BLAS's dot product, whose kernel differs per CPU)."""
    side = column_max(points) - column_min(points)
    return float(np.sqrt(side[0] * side[0] + side[1] * side[1] + side[2] * side[2]))


def column_min(values):
    """(c,) the smallest value of each column of ``values`` (r, c): one pass per column (numpy's
    reduction over axis 0 of a narrow array walks it row by row, ten times slower)."""
    return np.array([values[:, k].min() for k in range(values.shape[1])])


def rows_any(values):
    """(r,) bool: the row of ``values`` (r, c) has an entry that is not zero (or False), read one
    column at a time (numpy's any over axis 1 of a narrow array walks it row by row, five times
    slower)."""
    out = values[:, 0] != 0
    for k in range(1, values.shape[1]):
        out |= values[:, k] != 0
    return out


def column_max(values):
    """(c,) the largest value of each column of ``values`` (r, c) (see :func:`column_min`)."""
    return np.array([values[:, k].max() for k in range(values.shape[1])])


def vertex_faces(triangles, n_points):
    """CSR incidence: faces around each vertex. Returns (indptr (n+1,), face ids (3f,))."""
    ids = triangles.ravel()
    order = np.argsort(ids, kind="stable")
    counts = np.bincount(ids, minlength=n_points)
    indptr = np.zeros(n_points + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    return indptr, (order // 3).astype(np.int64)


def half_edge_graph(triangles, n_points):
    """(n, n) CSR graph with an entry (int8 one) for every directed edge (a, b) of a face: both
    directions of an edge two faces share, one for a border edge."""
    index = np.int32 if n_points < 2**31 - 1 else np.int64
    tail = triangles.astype(index).ravel()
    head = np.empty_like(tail)
    for corner in range(3):  # each corner's next one, written straight into the index type
        head[corner::3] = triangles[:, (corner + 1) % 3]
    return sp.coo_matrix((np.ones(tail.size, dtype=np.int8), (tail, head)), shape=(n_points, n_points)).tocsr()


def component_labels(triangles, n_points, graph=None):
    """(n,) connected-component label of every vertex (edge connectivity); loose vertices get their
    own. ``graph``, if given, is :func:`half_edge_graph` of the same mesh."""
    if graph is None:
        graph = half_edge_graph(triangles, n_points)
    # The strong components of the symmetric pattern (every edge both ways): the weak components
    # of the directed graph, labelled the same (by first vertex), in 0.6x the time of scipy's
    # undirected components (which transpose the graph and walk both) and a sixth of its weak ones.
    pattern = sp.csr_matrix(graph + graph.T)
    return connected_components(pattern, directed=True, connection="strong")[1]


def flat_ranges(starts, stops):
    """Concatenated ranges [starts[i], stops[i]): (positions, owner) where owner[k] = i."""
    counts = stops - starts
    ends = threads.cumsum(counts)
    total = int(ends[-1]) if ends.size else 0
    positions = np.empty(total, dtype=np.result_type(starts.dtype, np.int64))
    owner = np.empty(total, dtype=np.int64)
    # In pieces: numpy keeps the GIL through a repeat (the background thread's diffusion).
    for a, b in threads.pieces(ends):
        first, last = int(ends[a] - counts[a]), int(ends[b - 1])
        owner[first:last] = np.repeat(np.arange(a, b), counts[a:b])
        positions[first:last] = np.repeat(starts[a:b] - (ends[a:b] - counts[a:b]), counts[a:b])
        positions[first:last] += np.arange(first, last)
    return positions, owner


def segment_ranges(indptr, rows):
    """Flattened CSR positions for ``rows``: (positions, owner) where owner[k] indexes ``rows``."""
    return flat_ranges(indptr[rows], indptr[rows + 1])


def unique_edges(triangles):
    """(e, 2) sorted vertex pairs of the mesh edges (sorted rows), and (e,) how many faces use each."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    return np.unique(edges, axis=0, return_counts=True)


def first_of_each_triple(triangles):
    """(q,) sorted indices of the first row of ``triangles`` (f, 3) with each unordered vertex triple
    (repeated faces in any order or orientation are dropped). Rows are grouped by a 64-bit hash
    (one sort) and only rows whose hash repeats are compared in full, so a collision never
    drops a face."""
    if triangles.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    # A symmetric hash (the same for any order of the three ids: no per-row sort of millions of
    # rows): the sum of a non-linear 64-bit mix of each id.
    hashed = np.zeros(triangles.shape[0], dtype=np.uint64)
    for k in range(3):
        mixed = triangles[:, k].astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        mixed ^= mixed >> np.uint64(31)
        mixed *= np.uint64(0xBF58476D1CE4E5B9)
        mixed ^= mixed >> np.uint64(29)
        hashed += mixed
    order = np.argsort(hashed)
    ordered = hashed[order]
    same = ordered[1:] == ordered[:-1]
    if not same.any():
        return np.arange(triangles.shape[0])
    in_run = np.zeros(order.size, dtype=bool)
    in_run[1:] |= same
    in_run[:-1] |= same
    candidates = np.sort(order[in_run])
    rows = np.sort(triangles[candidates], axis=1).astype(np.int64)
    n = int(rows.max()) + 1
    exact = np.lexsort((rows[:, 2], rows[:, 0] * n + rows[:, 1]))
    first = np.ones(exact.size, dtype=bool)
    first[1:] = (rows[exact[1:]] != rows[exact[:-1]]).any(axis=1)
    keep = np.ones(triangles.shape[0], dtype=bool)
    keep[candidates] = False
    keep[candidates[exact[first]]] = True
    return np.flatnonzero(keep)


def barycentric_from_dots(uu, uv, vv, wu, wv, valid=None):
    """(r, 3) barycentric weights of drop points in triangles (P1, P2, P3) from dot products only
    (paper eq. 5): with u = P2 - P1, v = P3 - P1 and w = point - P1, every argument (r,) is the
    dot product its name says. Triangles with a zero denominator, or False in ``valid`` (r,),
    divide by one instead (their weights are meaningless; callers mask them)."""
    denom = uv * uv - uu * vv
    ok = denom != 0.0 if valid is None else valid
    denom = np.where(ok, denom, 1.0)
    s = (uv * wv - vv * wu) / denom
    t = (uv * wu - uu * wv) / denom
    return np.stack([1.0 - s - t, s, t], axis=1)


def barycentric(p, a, b, c):
    """(r, 3) barycentric weights of the drop points of ``p`` in triangles (a, b, c), each (r, 3)."""
    u, v, w = b - a, c - a, p - a
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    return barycentric_from_dots(dot(u, u), dot(u, v), dot(v, v), dot(w, u), dot(w, v))


def signed_volumes(points, triangles, face_label=None, labels=None):
    """Enclosed signed volume of a closed, consistently oriented triangle mesh: a float, or with
    per-face ``face_label`` (f,) and sorted ``labels`` (c,), a (c,) array, one per label (faces
    whose label is not listed are ignored)."""
    p0, p1, p2 = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    per_face = np.einsum("ij,ij->i", p0, cross_rows(p1, p2)) / 6.0
    if labels is None:
        return float(per_face.sum())
    if labels.size == 0:
        return np.zeros(0)
    index = np.searchsorted(labels, face_label)
    valid = (index < labels.size) & (labels[np.minimum(index, labels.size - 1)] == face_label)
    return np.bincount(index[valid], weights=per_face[valid], minlength=labels.size)


def cotangent_weights(points, triangles, edges):
    """(e,) cotangent weights (cot alpha + cot beta) / 2 of ``edges`` (e, 2) (sorted rows, as
    :func:`unique_edges` gives them), clamped below at a small positive share of their mean and
    normalised to mean one."""
    m = points.shape[0]
    key = edges[:, 0] * m + edges[:, 1]
    weight = np.zeros(edges.shape[0])
    for j in range(3):
        a, b, c = triangles[:, j], triangles[:, (j + 1) % 3], triangles[:, (j + 2) % 3]
        u, v = points[a] - points[c], points[b] - points[c]
        cot = np.einsum("ij,ij->i", u, v) / np.maximum(np.linalg.norm(cross_rows(u, v), axis=1), 1e-300)
        weight += np.bincount(np.searchsorted(key, np.minimum(a, b) * m + np.maximum(a, b)), weights=cot / 2,
                              minlength=weight.size)
    mean = np.abs(weight).mean() if weight.size else 1.0
    weight = np.maximum(weight, 0.05 * max(mean, 1e-300))
    return weight / weight.mean() if weight.size else weight
