"""Skin coefficients: every detail vertex expressed over proxy triangles (paper section 3.2).

An association binds detail vertex V to proxy triangle (P1, P2, P3) by barycentrics
(b1, b2, b3) of the drop point of V along the triangle's normal and the signed distance d,
so that V = b1 P1 + b2 P2 + b3 P3 + d n. The distance is stored as the height
h = d / sqrt(|(P2 - P1) x (P3 - P1)|), so the rebuild can use the unnormalised normal
N = c / sqrt(|c|), c the cross product, which makes the rebuild commute with uniform scale.

Candidates (the mis-attachment fix: a vertex only binds near where it collapsed to):
  tier 1  the proxy faces around the vertex's carrier (the proxy vertex it collapsed into);
  tier 2  only if no tier-1 face contains it: the faces around the carrier's neighbours.
A face *contains* V when the drop point lies in it (all barycentrics >= -CONTAIN_EPS) and its
normal agrees with V's normal (positive dot; vertices without a normal accept any face).
  case 1  exactly one containing face;
  case 3  several: keep those with |d| <= 2 |d_min| (+ DISTANCE_EPS of the diagonal);
  case 2  none: the proxy vertex nearest to V among the carrier and its neighbours, and every
          face around it whose normal agrees (all of them if none agrees), extended planes.
Loose vertices (no face of the detail uses them) take the globally nearest proxy vertex, as in
case 2, with no normal filter.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import SkinDetachError
from ..threads import map_blocks
from ..geometry import bbox_diagonal, cross_rows, face_cross, rows_any, segment_ranges, unit_rows, vertex_faces

#: Barycentric tolerance for "the drop point lies in the triangle".
CONTAIN_EPS = 1e-9
#: Distance tolerance of the case-3 rule, relative to the proxy's bounding-box diagonal.
DISTANCE_EPS = 1e-9
#: Vertices handled per vectorised batch (bounds the memory of the build; batches run on the
#: core's threads).
CHUNK = 65536
#: A proxy face whose height is under this fraction of its longest edge carries no vertex.
SLIVER = 1e-6
#: Barycentrics and heights (over the face's size) above this magnitude are absurd: the build
#: refuses to make them (a stored skin holding such values is refused as corrupt on load). A
#: loose vertex a million mesh sizes away still binds (its extended-plane barycentrics are about
#: its distance over the face's size).
MAX_COEFFICIENT = 1e12

CASE_ONE, CASE_TWO, CASE_THREE, CASE_LOOSE = 1, 2, 3, 4


@dataclass
class Skin:
    """Associations, one row each, grouped by vertex in ascending order.

    vertex  (a,) int64    welded detail vertex id (int32 in the diffused skins of :mod:`.seam_weights`)
    face    (a,) int64    proxy face id (likewise)
    bary    (a, 3) float  barycentrics over the face's three corners (may be negative in case 2)
    height  (a,) float    signed distance over sqrt(|cross|) of the rest face
    weight  (a,) float    rest-area weight, summing to one per vertex
    case    (u,) int8     CASE_* of every welded detail vertex
    """

    vertex: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    height: np.ndarray
    weight: np.ndarray
    case: np.ndarray


class ProxyFrames:
    """Rest frames of the proxy faces and the candidate tables built from them.

    points (m, 3), triangles (k, 3). ``ring`` is the vertex -> faces CSR, ``tier2`` the
    vertex -> faces-around-neighbours CSR (without the ring), ``closed`` the vertex -> itself
    and its neighbours CSR.
    """

    def __init__(self, points, triangles):
        self.points = points
        self.triangles = triangles
        self.tolerance = DISTANCE_EPS * bbox_diagonal(points)
        m, k = points.shape[0], triangles.shape[0]
        self.p0 = points[triangles[:, 0]]
        self.e1 = points[triangles[:, 1]] - self.p0
        self.e2 = points[triangles[:, 2]] - self.p0
        cross = face_cross(points, triangles)
        self.normal, self.cross_len = unit_rows(cross)
        e3 = self.e2 - self.e1
        scale = np.maximum.reduce([np.einsum("ij,ij->i", e, e) for e in (self.e1, self.e2, e3)])
        # A sliver (height under SLIVER of its longest edge) gives no frame: barycentrics over it
        # are ill-conditioned; nor does a face collapsed to a point (its longest edge within the
        # distance tolerance of the diagonal): a vertex projected onto its extended plane from
        # any distance gets barycentrics of that distance over the face's size (1e13 seen).
        self.valid = (self.cross_len > SLIVER * np.maximum(scale, 1e-300)) & (scale > self.tolerance * self.tolerance)
        # The dual basis of (e1, e2) in the face's plane: s = w . dual_s, t = w . dual_t for any w
        # (the normal part drops out), (e2 x N) / |N|^2 and (N x e1) / |N|^2 with N = e1 x e2: two
        # dot products per test, and no cancellation on thin faces (uv^2 - uu vv has it).
        squared = np.where(self.valid, self.cross_len ** 2, 1.0)[:, None]
        self.dual_s = cross_rows(self.e2, cross) / squared
        self.dual_t = cross_rows(cross, self.e1) / squared

        self.ring = vertex_faces(triangles, m)
        #: (m,) the vertex has a valid face around it (only those can carry case-2 vertices).
        self.has_face = np.bincount(triangles[self.valid].ravel(), minlength=m) > 0
        self._anchors = None
        incidence = sp.csr_matrix((np.ones(3 * k), (triangles.ravel(), np.repeat(np.arange(k), 3))), shape=(m, k))
        adjacency = ((incidence @ incidence.T) > 0).astype(np.int8).tocsr()
        adjacency.setdiag(1)
        adjacency.eliminate_zeros()
        adjacency.sort_indices()
        self.closed = (adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64))
        around = ((adjacency @ incidence) > 0).astype(np.int8) - (incidence > 0).astype(np.int8)
        around = sp.csr_matrix(around)
        around.eliminate_zeros()
        around.sort_indices()
        self.tier2 = (around.indptr.astype(np.int64), around.indices.astype(np.int64))

    def nearest_with_face(self, points):
        """(r,) the proxy vertex with a valid face nearest to each of ``points`` (r, 3)."""
        if self._anchors is None:
            ids = np.flatnonzero(self.has_face)
            self._anchors = (ids, cKDTree(self.points[ids]))
        ids, tree = self._anchors
        return ids[tree.query(points)[1]]

    def project(self, points, faces):
        """Barycentrics (a, 3) and signed distances (a,) of ``points`` (a, 3) over ``faces`` (a,).

        As paper eq. 5, dot products only, no cross product per test (against the faces' dual
        bases, which stay accurate on thin faces); invalid faces give meaningless weights (callers
        mask them).
        """
        w, s, t = self.in_plane(points, faces)
        return np.stack([1.0 - s - t, s, t], axis=1), self.height_of(w, faces)

    def in_plane(self, points, faces):
        """(w (a, 3) the offsets of ``points`` (a, 3) from the first corner of ``faces`` (a,), and
        their last two barycentrics s (a,) and t (a,)): what :meth:`project` starts from."""
        w = points - self.p0[faces]
        return w, np.einsum("ij,ij->i", w, self.dual_s[faces]), np.einsum("ij,ij->i", w, self.dual_t[faces])

    def height_of(self, w, faces):
        """(a,) signed distances of the offsets ``w`` (a, 3) (see :meth:`in_plane`) over ``faces``."""
        return np.einsum("ij,ij->i", w, self.normal[faces])


def _pairs(table, rows, owners):
    """Candidate pairs from a CSR ``table`` (indptr, ids): (owner index, id) for each row."""
    positions, which = segment_ranges(table[0], rows)
    return owners[which], table[1][positions]


def _agrees(frames, normals, vertex, face):
    """Per pair: the face normal has a positive dot with the vertex normal (or it has none)."""
    own = normals[vertex]
    dots = np.einsum("ij,ij->i", frames.normal[face], own)
    return (dots > 0.0) | ~rows_any(own)


def _contained(frames, points, normals, vertex, face):
    """For candidate pairs: (containing mask, agreeing mask, bary and distance of the containing
    pairs only: most candidates are not, and need no height)."""
    w, s, t = frames.in_plane(points[vertex], face)
    first = 1.0 - s - t
    inside = frames.valid[face] & (first >= -CONTAIN_EPS) & (s >= -CONTAIN_EPS) & (t >= -CONTAIN_EPS)
    agree = _agrees(frames, normals, vertex, face)
    ok = inside & agree
    return ok, agree, np.stack([first[ok], s[ok], t[ok]], axis=1), frames.height_of(w[ok], face[ok])


def _keep_nearest_planes(vertex, distance, n_vertices, tolerance):
    """Case 1/3 rule on containing pairs: keep |d| <= 2 |d_min| + tolerance per vertex."""
    magnitude = np.abs(distance)
    d_min = np.full(n_vertices, np.inf)
    np.minimum.at(d_min, vertex, magnitude)
    return magnitude <= 2.0 * d_min[vertex] + tolerance


def _bind_chunk(frames, points, normals, carrier, chunk, ring_disagree):
    """Associations of the welded vertices ``chunk`` (c,) (ascending), all with a carrier >= 0.

    Also marks in ``ring_disagree`` (u,) the vertices whose normal disagrees with a face
    around their carrier. Returns ((vertex, face, bary, distance) grouped by vertex in
    ascending order, case-2 vertices).
    """
    out = []
    pending = chunk
    for table in (frames.ring, frames.tier2):
        if pending.size == 0:
            break
        vertex, face = _pairs(table, carrier[pending], pending)
        ok, agree, bary, distance = _contained(frames, points, normals, vertex, face)
        if table is frames.ring:
            ring_disagree[vertex[~agree]] = True
        vertex, face = vertex[ok], face[ok]
        local = np.searchsorted(chunk, vertex)  # chunk is sorted: (c,)-sized scratch, not (u,)
        keep = _keep_nearest_planes(local, distance, chunk.size, frames.tolerance)
        out.append((vertex[keep], face[keep], bary[keep], distance[keep]))
        found = np.zeros(chunk.size, dtype=bool)
        found[local] = True
        pending = pending[~found[np.searchsorted(chunk, pending)]]
    if pending.size:
        vertex, candidate = _pairs(frames.closed, carrier[pending], pending)
        out.append(_bind_around_nearest(frames, points, normals, vertex, candidate, True))
    vertex = np.concatenate([part[0] for part in out])
    order = np.argsort(vertex, kind="stable")  # each vertex's associations come from one part
    return tuple(np.concatenate([part[k] for part in out])[order] for k in range(4)), pending


def _bind_around_nearest(frames, points, normals, vertex, candidate, filter_normals):
    """Case 2: per vertex, the nearest of its ``candidate`` proxy vertices that have a valid face
    (the nearest such proxy vertex anywhere when none has), then its faces."""
    with_face = frames.has_face[candidate]
    if not with_face.all():
        everyone = np.unique(vertex)
        vertex, candidate = vertex[with_face], candidate[with_face]
        orphans = np.setdiff1d(everyone, vertex)
        vertex = np.concatenate([vertex, orphans])
        candidate = np.concatenate([candidate, frames.nearest_with_face(points[orphans])])
    gap = points[vertex] - frames.points[candidate]
    dist2 = np.einsum("ij,ij->i", gap, gap)
    order = np.lexsort((dist2, vertex))
    first = np.ones(order.size, dtype=bool)
    first[1:] = vertex[order][1:] != vertex[order][:-1]
    chosen_vertex, nearest = vertex[order][first], candidate[order][first]
    v, face = _pairs(frames.ring, nearest, chosen_vertex)
    usable = frames.valid[face]
    if filter_normals:
        agree = _agrees(frames, normals, v, face) & usable
        local = np.searchsorted(chosen_vertex, v)  # chosen_vertex is sorted and unique
        any_agree = np.zeros(chosen_vertex.size, dtype=bool)
        any_agree[local[agree]] = True
        usable = np.where(any_agree[local], agree, usable)
    v, face = v[usable], face[usable]
    bary, distance = frames.project(points[v], face)
    return v, face, bary, distance


def bind_skin(points, normals, carrier, proxy_points, proxy_triangles):
    """Skin of welded detail ``points`` (u, 3) with unit ``normals`` (u, 3) over the proxy.

    ``carrier`` (u,) is the proxy vertex each detail vertex collapsed into (-1: loose).
    Returns (:class:`Skin`, ring_disagree (u,) bool: the vertex normal has a negative dot with
    some face around its carrier).
    """
    frames = ProxyFrames(proxy_points, proxy_triangles)
    u = points.shape[0]
    case = np.zeros(u, dtype=np.int8)
    ring_disagree = np.zeros(u, dtype=bool)
    parts = []
    bound = np.flatnonzero(carrier >= 0)
    chunks = [bound[start:start + CHUNK] for start in range(0, bound.size, CHUNK)]
    for chunk_part, case_two in map_blocks(
            lambda chunk: _bind_chunk(frames, points, normals, carrier, chunk, ring_disagree), chunks):
        parts.append(chunk_part)
        case[case_two] = CASE_TWO
    loose = np.flatnonzero(carrier < 0)
    if loose.size:
        parts.append(_bind_around_nearest(frames, points, normals, loose, frames.nearest_with_face(points[loose]),
                                          False))
        case[loose] = CASE_LOOSE

    # The chunks are grouped by vertex and follow each other in vertex order: only loose vertices
    # (after them, their ids anywhere) need a sort, as stable as the chunks' own.
    vertex, face, bary, distance = (np.concatenate([p[k] for p in parts]) for k in range(4))
    del parts  # the chunks' arrays: as large as the skin itself
    if loose.size:
        order = np.argsort(vertex, kind="stable")
        vertex, face, bary, distance = vertex[order], face[order], bary[order], distance[order]

    per_vertex = np.bincount(vertex, minlength=u)
    unset = case == 0
    case[unset & (per_vertex == 1)] = CASE_ONE
    case[unset & (per_vertex > 1)] = CASE_THREE
    area = frames.cross_len[face]
    weight = area / np.bincount(vertex, weights=area, minlength=u)[vertex]
    height = distance / np.sqrt(frames.cross_len[face])
    skin = Skin(vertex=vertex, face=face, bary=bary, height=height, weight=weight, case=case)
    check_coefficients(skin, "the built skin")
    return skin, ring_disagree & rows_any(normals)


def check_coefficients(skin, source):
    """Raise :class:`SkinDetachError` unless the skin's barycentrics, heights and weights are finite,
    of magnitude at most :data:`MAX_COEFFICIENT`, and the weights are >= 0 (a rebuild from such a
    skin is finite for every finite proxy)."""
    for name in ("bary", "height", "weight"):
        values = getattr(skin, name)
        # The smallest and the largest value alone: NaN and inf show in them (no temporaries).
        low, high = (values.min(), values.max()) if values.size else (0.0, 0.0)
        if not (np.isfinite(low) and np.isfinite(high)) or max(-low, high) > MAX_COEFFICIENT:
            raise SkinDetachError(f"{source}: expected finite skin_{name} of magnitude at most {MAX_COEFFICIENT:g}, "
                                  f"got NaN, inf or absurd values; rebuild the skin")
    if skin.weight.size and skin.weight.min() < 0:
        raise SkinDetachError(f"{source}: expected skin_weight >= 0, got {skin.weight.min():g}; rebuild the skin")


def bound_disagreement(skin, normals, proxy_points, proxy_triangles):
    """(u,) bool: the vertex normal has a negative dot with a proxy face it is bound to, in a skin
    :func:`bind_skin` made: the faces of case-1 and case-3 vertices agree with their normals
    (that is how they were chosen), so only case-2 and loose vertices are looked at."""
    face_normal = unit_rows(face_cross(proxy_points, proxy_triangles))[0]
    case = skin.case[skin.vertex]
    rows = np.flatnonzero((case == CASE_TWO) | (case == CASE_LOOSE))
    vertex = skin.vertex[rows]
    dots = np.einsum("ij,ij->i", face_normal[skin.face[rows]], normals[vertex])
    bad = np.zeros(normals.shape[0], dtype=bool)
    bad[vertex[dots < 0.0]] = True
    return bad
