"""A detail mesh made ready for simplification and binding.

Raw meshes come with duplicate vertices (split UV seams), repeated or zero-area faces and
vertices no face uses. :func:`prepare_mesh` welds exact duplicates, puts the faces in a canonical
order, keeps only faces that can be simplified, and labels connected components, without
touching the caller's arrays.

The canonical order makes the build a function of the mesh, not of how its faces happen to be
stored: Blender numbers the faces of a new UV sphere differently on every call (the same
triangles, in another order), and the simplification, the normals' sums and every tie after
them follow the order of the faces.
"""

from dataclasses import dataclass

import numpy as np

from ..geometry import bbox_diagonal, component_labels, face_cross, half_edge_graph, vertex_normals
from .. import threads
from ..threads import map_blocks

#: A face is degenerate when twice its area is below this fraction of the squared bbox diagonal
#: (of the vertices that faces use).
DEGENERATE_AREA = 1e-14


@dataclass
class PreparedMesh:
    """Welded, cleaned detail mesh.

    points      (u, 3) float64   unique vertex positions, indexed by welded id
    weld        (n,) int64       welded id of every input vertex
    triangles   (t, 3) int64     faces kept for simplification, in welded ids
    cross       (t, 3) float64   face cross products of ``triangles`` (twice the area along the normal)
    normals     (u, 3) float64   unit vertex normals (zero where no face of non-zero area)
    components  (u,) int64       connected-component label of every welded vertex
    graph       (u, u) CSR       :func:`~..geometry.half_edge_graph` of ``triangles``
    degenerate  (d, 3) int64     the faces dropped for a repeated id or zero area, in welded ids
                                 (with ``graph``, the edges of every face: the one-ring of
                                 :func:`.seam_weights.one_ring_average`)
    diagonal    float            bounding-box diagonal of the input
    """

    points: np.ndarray
    weld: np.ndarray
    triangles: np.ndarray
    cross: np.ndarray
    normals: np.ndarray
    components: np.ndarray
    graph: object
    degenerate: np.ndarray
    diagonal: float
    welded_vertices: int
    dropped_faces: int


def weld_map(points):
    """(n,) welded id of every row of ``points`` (n, 3) and the (u,) first input row of each id.

    Rows are equal when their coordinates are bit-identical (after folding -0.0 into 0.0).
    Rows are grouped by a 64-bit hash and compared in full, so a hash collision can only
    leave two duplicates apart, never weld different points.
    """
    keys = np.ascontiguousarray(points + 0.0).view(np.uint64)
    # Each key's high half folded into its low one first: positions read from float32 (Blender's)
    # leave the low 29 bits of every key zero, and products of them alone repeated 146 hashes at 3.2M.
    mixed = keys ^ (keys >> np.uint64(32))
    hashed = (mixed[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (mixed[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F))
    hashed ^= mixed[:, 2] * np.uint64(0x165667B19E3779F9)
    del mixed
    identity = np.arange(points.shape[0], dtype=np.int64)
    ordered = np.sort(hashed)
    if not (ordered[1:] == ordered[:-1]).any():  # no two rows alike: nothing to weld
        return identity, identity
    del ordered
    order = np.argsort(hashed, kind="stable")
    sorted_keys = keys[order]
    new_group = np.ones(order.size, dtype=bool)
    new_group[1:] = (sorted_keys[1:] != sorted_keys[:-1]).any(axis=1)
    if new_group.all():  # only hashes repeat
        return identity, identity
    group = np.empty(order.size, dtype=np.int64)
    group[order] = np.cumsum(new_group) - 1
    first = np.minimum.reduceat(order, np.flatnonzero(new_group)).astype(np.int64)
    # Number groups by their first occurrence so that a mesh without duplicates keeps its ids.
    first_order = np.argsort(first, kind="stable")
    rank = np.empty_like(first)
    rank[first_order] = np.arange(first.size)
    return rank[group], first[first_order]


def canonical_faces(triangles, n_points):
    """The faces of ``triangles`` (f, 3) over ``n_points`` vertices in a canonical order, as a new
    (f, 3) int64 array: each row turned so that its smallest vertex id a comes first (orientation
    kept: (a, b, c)), the rows sorted by a, then by the other two ids in ascending order, then by
    orientation (b < c first). Two lists of the same faces in any order, each face starting at
    any corner, give the same array (faces with a repeated id, which the build drops, aside), and
    repeated faces (the same three ids in any order) end up next to each other.

    Each row is one int64 key, sorted as values (no permutation kept) and read back. A key holds
    2 n**2 values per a, so one int64 holds the keys of :func:`key_span` consecutive values of
    a: above about 1.66 million vertices the rows are first put in such groups (a stable
    counting sort of the group number) and each group's keys, counted from its first a, are
    sorted alone (6.4 million faces of 3.2 million vertices: 1.6-2.3 s with a two-key lexsort, 0.9-1.2 s so)."""
    t0, t1, t2 = (np.asarray(triangles[:, k], dtype=np.int64) for k in range(3))
    a = np.minimum(np.minimum(t0, t1), t2)
    b = np.where(t0 == a, t1, np.where(t1 == a, t2, t0))  # the corner after a
    c = t0 + t1 + t2 - a - b
    del t0, t1, t2
    n = max(int(n_points), 1)
    span = key_span(n)
    group = a // span
    counts = np.bincount(group)
    if counts.size > 1:
        order = np.argsort(group.astype(np.uint16 if counts.size <= 2**16 else np.int64), kind="stable")
        a = (a - group * span)[order]
        b, c = b[order], c[order]
        del order
    del group
    key = a
    key *= n
    key += np.minimum(b, c)
    key *= n
    key += np.maximum(b, c)
    key *= 2
    key += b > c
    del a, b, c
    ends = np.cumsum(counts)
    # Values: equal keys are equal rows, so the order of ties cannot show; groups side by side.
    map_blocks(lambda span: key[span[0]:span[1]].sort(), list(zip(ends - counts, ends)))
    out = np.empty((key.size, 3), dtype=np.int64)
    flipped = (key & 1).astype(bool)
    key >>= 1
    hi = key % n
    key //= n
    lo = key % n
    key //= n
    out[:, 0] = key
    if counts.size > 1:
        out[:, 0] += np.repeat(np.arange(counts.size, dtype=np.int64) * span, counts)
    out[:, 1] = np.where(flipped, hi, lo)
    out[:, 2] = np.where(flipped, lo, hi)
    return out


def key_span(n):
    """How many consecutive values of a face's first id :func:`canonical_faces` keys in one int64
    for ``n`` vertices (at least ``n`` up to 1,664,510 vertices: one group)."""
    return max((2**63 - 1) // (2 * n * n), 1)


def _first_of_repeats(faces):
    """(q,) sorted indices of the first row of each unordered vertex triple in ``faces`` (f, 3), in
    :func:`canonical_faces` order (its repeated faces are neighbours)."""
    f = faces.shape[0]
    repeated = np.zeros(f, dtype=bool)

    def mark(start):  # slices side by side, each row against the one before it (small scratch arrays)
        first, stop = max(start, 1), min(start + threads.PIECE, f)
        if first >= stop:
            return
        row, before = faces[first:stop], faces[first - 1:stop - 1]
        repeated[first:stop] = ((row[:, 0] == before[:, 0])
                                & (np.minimum(row[:, 1], row[:, 2]) == np.minimum(before[:, 1], before[:, 2]))
                                & (np.maximum(row[:, 1], row[:, 2]) == np.maximum(before[:, 1], before[:, 2])))
    map_blocks(mark, list(range(0, f, threads.PIECE)))
    return np.flatnonzero(~repeated)


def _faces_diagonal(points, triangles, diagonal):
    """Bounding-box diagonal of the ``points`` (n, 3) that ``triangles`` (f, 3) use (``diagonal``,
    that of all points, when every point is used): a stray vertex far away does not make every
    face look degenerate."""
    used = np.zeros(points.shape[0], dtype=bool)
    used[triangles.ravel()] = True
    return diagonal if used.all() else bbox_diagonal(points[used])


def prepare_mesh(points, triangles, components=True):
    """Weld and clean a validated mesh: ``points`` (n, 3) float64, ``triangles`` (f, 3) int32 or int64;
    without ``components`` the labels are not made (None: binding a skin needs none)."""
    diagonal = bbox_diagonal(points)
    weld, representatives = weld_map(points)
    if representatives.size == points.shape[0]:
        unique_points, faces = points, canonical_faces(triangles, points.shape[0])
    else:
        unique_points = points[representatives]
        faces = canonical_faces(weld[triangles], unique_points.shape[0])

    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    cross = face_cross(unique_points, faces)
    area2 = np.einsum("ij,ij->i", cross, cross)
    # Products, not ** (the C library's pow, which may round differently on another CPU).
    size = max(_faces_diagonal(unique_points, faces, diagonal), 1e-300)
    least = DEGENERATE_AREA * (size * size)
    keep = distinct & (area2 > least * least)
    del distinct, area2
    kept = faces if keep.all() else faces[keep]
    # Drop repeated faces (same three vertices in any order): they make non-manifold fans of two.
    first = np.flatnonzero(keep)[_first_of_repeats(kept)]
    if first.size == faces.shape[0]:
        kept, kept_cross = faces, cross
    else:
        kept, kept_cross = faces[first], cross[first]
    degenerate = faces[~keep]
    # What is not kept goes before the graph, its labels and the normals, the build's largest
    # scratch memory (scipy's components copy the graph in float64: 1.5 GB at 10M vertices).
    del first, keep, faces, cross
    kept = np.ascontiguousarray(kept)
    graph = half_edge_graph(kept, unique_points.shape[0])
    labels = component_labels(kept, unique_points.shape[0], graph) if components else None
    return PreparedMesh(
        points=unique_points,
        weld=weld,
        triangles=kept,
        cross=kept_cross,
        normals=vertex_normals(unique_points, kept, kept_cross),
        components=labels,
        graph=graph,
        degenerate=degenerate,
        diagonal=diagonal,
        welded_vertices=int(points.shape[0] - unique_points.shape[0]),
        dropped_faces=int(triangles.shape[0] - kept.shape[0]),
    )
