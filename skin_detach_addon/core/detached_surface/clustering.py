"""Vertex clustering that keeps sheets apart: a coarse copy of a large detail mesh in linear time.

The build uses it twice over: fast-simplification costs 4-8 us per face and more per face the
larger the mesh, so a mesh of millions of faces is first clustered to a few hundred thousand
vertices and the library simplifies that (the collapse maps compose: detail vertex -> cluster ->
proxy vertex); and the clustered mesh, bound to the same proxy, is the light stand-in shown
while a handle is dragged.

Clusters: one seed vertex per occupied cell of a uniform grid (cell size h chosen from the
surface area so that about the target number of cells is occupied) and component; every vertex
joins the seed nearest along mesh edges (one multi-source Dijkstra: Voronoi regions along the
surface).
Regions are connected and grow along the surface, so two sheets passing close by (two fingers
touching, both sides of a thin plate) stay apart and clusters never cross components. Each cluster is represented by its seed (a real detail vertex, so the coarse
mesh lies on the detail surface). Faces map to the clusters
of their corners; faces with a repeated cluster are dropped. Clusters whose quotient is not a
clean surface (holes, non-manifold fans, repeated or inverted faces) are split, round after
round until none is left, into a few sub-clusters each: re-seeded on a grid :data:`SPLIT_FACTOR`
times finer than their own (about two sub-clusters) and their vertices re-assigned by the same
Dijkstra run only over their own vertices and edges (:func:`_subdivide`), so a round works on
the faulty clusters alone. Only a cluster split :data:`MAX_LEVEL` times already, and every
faulty one in the last of :data:`REPAIR_ROUNDS` rounds, is split back into its vertices.
Splitting straight into vertices (this module's repair before) left single vertices beside
clusters of dozens; the thin coarse faces between them fold over, so the neighbours turned
faulty and were split in turn, a cascade that did not die out on fine regular meshes. On the
armadillo split into 4.8M quads by Blender's Simple subdivision (then into triangles), 272 of
65,883 clusters are faulty at first (260 on a face facing away from its clusters' normals, 18
on a hole, 12 on a fan, 18 on a repeated face, none without faces or in a small component);
the vertex repair went on splitting about 250 clusters a round, ended after 10 rounds at
273,815 vertices with folds and holes left, while sub-clusters stop at 68,166 in 14 rounds.
A component that would keep fewer than :data:`MIN_KEPT_FACES` faces is left unclustered.

Arrays: ``points`` (u, 3) welded detail vertices, ``triangles`` (t, 3), ``normals`` (u, 3)
unit or zero, ``components`` (u,) labels.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..geometry import (column_max, column_min, face_cross, first_of_each_triple, rows_any, segment_ranges,
                        vertex_normals)
from .. import threads
from ..threads import map_blocks

#: A component is only clustered when it keeps at least this many faces afterwards.
MIN_KEPT_FACES = 64
#: Most rounds of splitting faulty clusters (into sub-clusters, see :func:`_subdivide`; in the
#: last one into their vertices). Measured on the armadillo's Simple subdivision: 7 rounds at
#: 300K quads, 11 at 1.2M, 14 at 4.8M; 8 on 1.2M triangles.
REPAIR_ROUNDS = 24
#: Each split re-seeds a cluster on a grid this many times finer than its own: about two
#: sub-clusters on a surface (a factor 2, about four, grows the armadillo's 4.8M-quad preview
#: to 70,825 vertices instead of 68,166).
SPLIT_FACTOR = 2.0 ** 0.5
#: A cluster split this many times already (its grid SPLIT_FACTOR**MAX_LEVEL = 32 times finer
#: than the first one) is split into its vertices if it is faulty again.
MAX_LEVEL = 10
#: Occupied cells per unit of area / h**2 on a typical surface (measured on scans: 1.3-1.6).
CELLS_PER_AREA = 1.3


@dataclass
class Clustered:
    """A coarse copy of a mesh and the map onto it.

    points      (c, 3) float64  cluster representatives (detail vertex positions)
    triangles   (q, 3) int64    coarse faces, in cluster ids
    normals     (c, 3) float64  unit vertex normals of the coarse mesh
    cluster     (u,) int64      cluster of every detail vertex
    components  (c,) int64      component label of every cluster (the detail's)
    representatives (c,) int64  the detail vertex each cluster's point is
    """

    points: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    cluster: np.ndarray
    components: np.ndarray
    representatives: np.ndarray


def _seeds(points, components, size):
    """(s,) one vertex per occupied grid cell of edge ``size`` and component: the one nearest to
    the cell's centre (one sort of the cell key plus the squared distance, a fraction below one)."""
    scaled = (points - column_min(points)) / size
    cells = np.floor(scaled).astype(np.int64)
    extent = column_max(cells) + 1
    key = ((cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]) * (int(components.max()) + 1)
    key += components
    scaled -= cells
    scaled -= 0.5
    # Stable: a cell's vertices equally near its centre (a regular grid has them) keep the lowest
    # id on every machine (the default sort breaks ties by the CPU's vector width).
    order = np.argsort(key + np.einsum("ij,ij->i", scaled, scaled) / 0.76, kind="stable")
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order[1:]] != key[order[:-1]]
    return order[first]


#: Edges per block when measuring the graph's edge lengths on the core's threads.
EDGE_BLOCK = 1 << 20


def _edge_lengths(points, graph):
    """``graph`` (u, u) CSR with its entries replaced by the lengths of the edges (same structure)."""
    rows = threads.repeat(np.arange(graph.shape[0], dtype=graph.indices.dtype), np.diff(graph.indptr))
    lengths = np.empty(graph.indices.size)

    def block(start):
        stop = start + EDGE_BLOCK
        gap = points[rows[start:stop]] - points[graph.indices[start:stop]]
        lengths[start:stop] = np.sqrt(np.einsum("ij,ij->i", gap, gap))

    map_blocks(block, list(range(0, lengths.size, EDGE_BLOCK)))
    np.maximum(lengths, 1e-300, out=lengths)
    return sp.csr_matrix((lengths, graph.indices, graph.indptr), shape=graph.shape, copy=False)


def _voronoi_labels(points, graph, seeds):
    """(u,) cluster of every vertex: the seed nearest along mesh edges (multi-source Dijkstra over
    the half-edge ``graph`` weighted by edge length; lengths, not hop counts, so region borders
    are not jagged by ties); cluster j is seed j. A vertex no seed reaches (one seed per
    component rules it out; a border edge is only walked along its own direction) keeps a
    cluster of its own."""
    u = graph.shape[0]
    sources = dijkstra(_edge_lengths(points, graph), directed=True, indices=seeds, min_only=True,
                       return_predecessors=True)[2]
    rank = np.full(u, -1, dtype=np.int64)
    rank[seeds] = np.arange(seeds.size)
    label = np.where(sources >= 0, rank[np.maximum(sources, 0)], -1)
    lost = np.flatnonzero(label < 0)
    label[lost] = seeds.size + np.arange(lost.size)
    return label, np.concatenate([seeds, lost])


def _split(label, rep, summed, normals, split):
    """Clusters flagged in ``split`` (c,) broken back into their vertices; returns the compacted
    (label (u,), representatives (c',), summed detail normals (c', 3))."""
    members = np.flatnonzero(split[label])
    keep = ~split
    new_id = np.cumsum(keep) - 1
    label = new_id[label]
    label[members] = int(keep.sum()) + np.arange(members.size)
    return label, np.concatenate([rep[keep], members]), np.concatenate([summed[keep], normals[members]])


def _subdivide(points, graph, normals, label, rep, summed, level, split, size):
    """Clusters flagged in ``split`` (c,) re-clustered into a few sub-clusters each; returns the
    compacted (label (u,), representatives (c',), summed detail normals (c', 3), level (c',)).

    A split cluster k of ``level`` (c,) l gets one seed per occupied cell of a grid of edge
    ``size / SPLIT_FACTOR**(l + 1)`` (about two on a surface), the vertex nearest the cell's
    centre (cells keyed by cluster too, so every split cluster has its own seeds), except
    that its own representative is the seed of its cell; its vertices then join the sub-seed
    nearest along edges inside the cluster (multi-source Dijkstra over the half-edge ``graph``
    restricted to those edges, weighted by length: only the split clusters' vertices and edges
    are visited). A cluster is a Voronoi region, so its representative reaches every member
    along the cluster's own edges and every member gets a sub-cluster (the fallback, a vertex
    left alone, never happens); the sub-clusters are connected and keep the parent's component.
    Sub-clusters get level l + 1, so a cluster split again is cut finer, down to single vertices
    once the cells are smaller than its edges."""
    members = np.flatnonzero(split[label])
    parent = label[members]
    cell = size / SPLIT_FACTOR ** (level[parent] + 1.0)
    scaled = (points[members] - column_min(points[members])) / cell[:, None]
    cells = np.floor(scaled).astype(np.int64)
    scaled -= cells
    scaled -= 0.5
    # Sorted by parent, cell, then distance to the cell's centre (the parent's representative
    # first): exact integer keys, no overflow whatever the grid's extent.
    near = np.einsum("ij,ij->i", scaled, scaled)
    near[members == rep[parent]] = -1.0
    order = np.lexsort((members, near, cells[:, 2], cells[:, 1], cells[:, 0], parent))
    same = (parent[order[1:]] == parent[order[:-1]]) & ~rows_any(cells[order[1:]] != cells[order[:-1]])
    first = np.ones(order.size, dtype=bool)
    first[1:] = ~same
    seeds = order[first]  # local ids (into members)
    # The graph restricted to edges inside one split cluster, weighted by length.
    local = np.full(graph.shape[0], -1, dtype=np.int64)
    local[members] = np.arange(members.size)
    positions, rows = segment_ranges(graph.indptr, members)
    heads = graph.indices[positions]
    inside = (local[heads] >= 0) & (label[heads] == parent[rows])
    rows, heads = rows[inside], local[heads[inside]]
    sub = sp.csr_matrix((np.ones(rows.size), (rows, heads)), shape=(members.size, members.size))
    child, local_rep = _voronoi_labels(points[members], sub, seeds)
    new_rep = members[local_rep]
    keep = ~split
    n_keep = int(keep.sum())
    new_id = np.cumsum(keep) - 1
    label = new_id[label]
    label[members] = n_keep + child
    child_summed = _summed_normals(child, normals[members], new_rep.size)
    child_level = level[parent[local_rep]] + 1
    return (label, np.concatenate([rep[keep], new_rep]), np.concatenate([summed[keep], child_summed]),
            np.concatenate([level[keep], child_level]))


def _summed_normals(label, normals, n_clusters):
    """(c, 3) sum of the detail normals of each cluster."""
    return np.stack([np.bincount(label, weights=normals[:, axis], minlength=n_clusters) for axis in range(3)], axis=1)


def _faults(label, rep, triangles, summed, points):
    """Coarse faces of a labelling (representatives ``rep`` (c,), summed detail normals ``summed``
    (c, 3)) and the clusters to split:
    (faces (q, 3), spanning (d,) indices of the ``triangles`` with corners in three clusters,
    faulty (c,) bool). A cluster is faulty when it is on a coarse edge that does not have exactly
    two faces (a hole or a non-manifold fan), on a face repeated in the quotient, on a coarse face
    facing away from its clusters' detail normals, or has no coarse face at all."""
    n_clusters = rep.size
    faces = label[triangles]
    spanning = np.flatnonzero((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
                              & (faces[:, 2] != faces[:, 0]))
    faces = faces[spanning]
    first = first_of_each_triple(faces)
    repeated = np.ones(faces.shape[0], dtype=bool)
    repeated[first] = False
    bad = [faces[repeated].ravel()]
    faces = faces[first]
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys, uses = np.unique(pairs[:, 0] * n_clusters + pairs[:, 1], return_counts=True)
    odd = keys[uses != 2]
    bad.extend([odd // n_clusters, odd % n_clusters])
    facing = np.einsum("ij,ij->i", face_cross(points[rep], faces), summed[faces].sum(axis=1))
    bad.append(faces[facing <= 0.0].ravel())
    faulty = np.ones(n_clusters, dtype=bool)
    faulty[faces.ravel()] = False  # clusters without a face stay faulty
    faulty[np.concatenate(bad)] = True
    return faces, spanning, faulty


def cluster_mesh(points, triangles, normals, components, graph, area, target_vertices):
    """:class:`Clustered` copy of the mesh with about ``target_vertices`` clusters (``graph``: its
    :func:`~..geometry.half_edge_graph`, ``area``: its surface area). The cell size is set from
    the area and corrected once from the seed count; then, until no cluster of more than one
    vertex is faulty (see :func:`_faults`) or for at most :data:`REPAIR_ROUNDS` rounds, faulty
    clusters are split into sub-clusters (:func:`_subdivide`; into their vertices in the last
    round, after :data:`MAX_LEVEL` splits, or when their component would keep fewer than
    :data:`MIN_KEPT_FACES` faces), so the coarse mesh has the detail's topology: a closed detail
    gives a closed, manifold, consistently facing copy (tested); on an open one the clusters
    along the border end as single vertices. Each round costs one pass over all faces (to find
    those touching a split cluster) plus work on the split clusters' vertices and edges only."""
    size = np.sqrt(CELLS_PER_AREA * max(area, 1e-300) / max(target_vertices, 1))
    seeds = _seeds(points, components, size)
    if not 0.8 * target_vertices <= seeds.size <= 1.25 * target_vertices:
        size *= np.sqrt(seeds.size / max(target_vertices, 1))
        seeds = _seeds(points, components, size)
    label, rep = _voronoi_labels(points, graph, seeds)
    summed = _summed_normals(label, normals, rep.size)
    # Only faces with corners in three clusters make coarse faces; after a split, those are the
    # ones that did before and the ones touching the split clusters' vertices.
    candidates = np.arange(triangles.shape[0])
    level = np.zeros(rep.size, dtype=np.int64)
    for repair in range(REPAIR_ROUNDS + 1):
        faces, spanning, faulty = _faults(label, rep, triangles[candidates], summed, points)
        # Components that would almost vanish keep their own vertices too.
        kept = np.bincount(components[rep[faces[:, 0]]], minlength=int(components.max()) + 1)
        small = kept[components[rep]] < MIN_KEPT_FACES
        split = (faulty | small) & (np.bincount(label, minlength=rep.size) > 1)
        if repair == REPAIR_ROUNDS or not split.any():
            break
        touching = np.flatnonzero(rows_any(split[label][triangles]))
        candidates = np.union1d(candidates[spanning], touching)
        whole = split & (small | (level >= MAX_LEVEL) | (repair == REPAIR_ROUNDS - 1))
        if whole.any():
            label, rep, summed = _split(label, rep, summed, normals, whole)
            added = rep.size - int(np.count_nonzero(~whole))  # single vertices: never split again
            level = np.concatenate([level[~whole], np.full(added, MAX_LEVEL)])
            split = np.concatenate([split[~whole], np.zeros(added, dtype=bool)])
        if split.any():
            label, rep, summed, level = _subdivide(points, graph, normals, label, rep, summed, level, split, size)
    coarse = np.ascontiguousarray(points[rep])
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    return Clustered(points=coarse, triangles=faces, normals=vertex_normals(coarse, faces), cluster=label,
                     components=components[rep], representatives=rep)
