"""Edge collapses checked by the 1-ring normal test (after Lee, Moreton & Hoppe 2000).

fast-simplification has no veto hook, so the build simplifies with it to a few times the
target and :func:`collapse_with_normal_test` finishes the last collapses itself. Every proxy
vertex carries the cluster of detail vertices that collapsed into it, summarised as a
histogram of their normals over :data:`CUBE_BINS` cube-map directions (merging two clusters
adds their histograms). A collapse is refused when one of the faces it reshapes would disagree
(non-positive dot product) with more of the detail normals in its three corner clusters than
the face did before, so no proxy face starts pointing away from detail surface it stands for. Quadrics come from the detail faces
of each cluster (or of its clustered copy, for millions of faces), so placement follows the detail surface, not the
intermediate proxy.

Arrays: proxy ``points`` (m, 3) and ``triangles`` (k, 3); ``carrier`` (u,) maps welded detail
vertices to proxy vertices (-1: none); detail ``normals`` (u, 3) are unit or zero.
"""

import heapq
from dataclasses import dataclass

import numpy as np

from ..geometry import rows_any, unit_rows
from .simplification import MIN_COMPONENT_FACES, collapse_roots

#: Collapses that turn a face by more than this (cosine of the old/new normal) are flips.
FLIP_COSINE = 0.2
#: A collapse may leave a vertex with at most this many neighbours (no fans: on a thin ribbon
#: whose borders cannot move, unbounded fans made the loop quadratic in the ribbon's length).
MAX_VALENCE = 24
#: Cube-map resolution of the normal histograms: 6 * CUBE_SIDE**2 directions (about 11 degrees).
CUBE_SIDE = 8
CUBE_BINS = 6 * CUBE_SIDE * CUBE_SIDE
#: Dot products of unit vectors within this of zero have their sign decided in a fixed order (the
#: product's own rounding, under 4e-16, depends on the CPU's BLAS kernel).
SIGN_MARGIN = 1e-12


def cube_directions():
    """(CUBE_BINS, 3) unit directions of the cube-map bin centres, in :func:`cube_bin` order."""
    centres = (np.arange(CUBE_SIDE) + 0.5) / CUBE_SIDE * 2.0 - 1.0
    a, b = np.meshgrid(centres, centres, indexing="ij")
    a, b = a.ravel(), b.ravel()
    one = np.ones_like(a)
    faces = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            xyz = [None, None, None]
            xyz[axis] = sign * one
            xyz[(axis + 1) % 3] = a
            xyz[(axis + 2) % 3] = b
            faces.append(np.stack(xyz, axis=1))
    return unit_rows(np.concatenate(faces))[0]


def cube_bin(normals):
    """(r,) cube-map bin of each unit normal (r, 3) (zero rows land in an arbitrary bin)."""
    axis = np.argmax(np.abs(normals), axis=1)
    rows = np.arange(normals.shape[0])
    major = normals[rows, axis]
    sign = (major < 0).astype(np.int64)
    scale = np.where(major != 0.0, np.abs(major), 1.0)
    a = normals[rows, (axis + 1) % 3] / scale
    b = normals[rows, (axis + 2) % 3] / scale
    ia = np.clip(((a + 1.0) / 2.0 * CUBE_SIDE).astype(np.int64), 0, CUBE_SIDE - 1)
    ib = np.clip(((b + 1.0) / 2.0 * CUBE_SIDE).astype(np.int64), 0, CUBE_SIDE - 1)
    return ((axis * 2 + sign) * CUBE_SIDE + ia) * CUBE_SIDE + ib


@dataclass
class CheckedCollapse:
    """Result of :func:`collapse_with_normal_test`.

    points     (m', 3) float64  proxy vertex positions
    triangles  (k', 3) int64    proxy faces
    remap      (m,) int64       new id of every input proxy vertex
    refused    int              collapses the normal test refused
    """

    points: np.ndarray
    triangles: np.ndarray
    remap: np.ndarray
    refused: int


def cluster_quadrics(detail_points, detail_triangles, detail_cross, carrier, n_proxy):
    """(m, 10) area-weighted plane quadrics of the detail faces around each proxy vertex's cluster.

    ``detail_cross`` (t, 3) are the face cross products. Coefficients are a2 ab ac ad b2 bc bd
    c2 cd d2 of the plane (a, b, c, d). A face counts once for every corner in the cluster.
    Summed one coefficient at a time (bincounts over the corners), so no (t, 10) array is made.
    """
    normal, double_area = unit_rows(detail_cross)
    plane = [normal[:, 0], normal[:, 1], normal[:, 2], -np.einsum("ij,ij->i", normal, detail_points[detail_triangles[:, 0]])]
    del normal
    owners = []
    for corner in range(3):
        owner = carrier[detail_triangles[:, corner]]
        keep = owner >= 0
        owners.append((owner[keep], keep))
    quadrics = np.zeros((n_proxy, 10))
    column = 0
    for i in range(4):
        for j in range(i, 4):
            weight = plane[i] * plane[j]
            weight *= 0.5 * double_area
            for owner, keep in owners:
                quadrics[:, column] += np.bincount(owner, weights=weight[keep], minlength=n_proxy)
            column += 1
    return quadrics


def _quadric_error(q, x, y, z):
    return (q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y
            + 2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9])


def _optimal_point(q, pa, pb):
    """Minimiser of quadric ``q`` (10,), or the best of the endpoints and midpoint if singular."""
    a, b, c, d, e, f, g, h, i, _ = q
    det = a * (e * h - f * f) - b * (b * h - f * c) + c * (b * f - e * c)
    scale = abs(a) + abs(e) + abs(h)
    scale = scale * scale * scale  # not ** 3: the C library's pow may differ per CPU
    if scale > 0 and abs(det) > 1e-12 * scale:
        x = (-d * (e * h - f * f) + b * (g * h - f * i) - c * (g * f - e * i)) / det
        y = (-a * (g * h - i * f) + d * (b * h - f * c) - c * (b * i - g * c)) / det
        z = (-a * (e * i - f * g) + b * (b * i - g * c) - d * (b * f - e * c)) / det
        return (x, y, z), _quadric_error(q, x, y, z)
    mid = tuple((u + v) / 2 for u, v in zip(pa, pb))
    return min(((p, _quadric_error(q, *p)) for p in (pa, pb, mid)), key=lambda item: item[1])


class _CollapseState:
    """Mutable proxy during the checked collapses (pure Python lists for scalar speed)."""

    def __init__(self, points, triangles, quadrics, histograms, component):
        self.pos = [tuple(p) for p in points.tolist()]
        self.points = points.copy()
        self.quad = [np.asarray(q) for q in quadrics]
        self.hist = histograms
        self.directions = cube_directions()
        self.faces = [list(f) for f in triangles.tolist()]
        self.face_alive = [True] * len(self.faces)
        self.vfaces = [set() for _ in self.pos]
        for fid, f in enumerate(self.faces):
            for v in f:
                self.vfaces[v].add(fid)
        self.alive = [True] * len(self.pos)
        self.version = [0] * len(self.pos)
        self.component = component.tolist()
        self.comp_faces = {}
        for f in self.faces:
            c = self.component[f[0]]
            self.comp_faces[c] = self.comp_faces.get(c, 0) + 1
        self.border = self._border_vertices()
        self.face_count = len(self.faces)
        self.merges = []

    def _border_vertices(self):
        count = {}
        for f in self.faces:
            for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
                key = (a, b) if a < b else (b, a)
                count[key] = count.get(key, 0) + 1
        border = [False] * len(self.pos)
        for (a, b), n in count.items():
            if n != 2:
                border[a] = border[b] = True
        return border

    def neighbours(self, v):
        out = set()
        for fid in self.vfaces[v]:
            out.update(self.faces[fid])
        out.discard(v)
        return out

    def edge_entry(self, i, j):
        point, cost = _optimal_point(self.quad[i] + self.quad[j], self.pos[i], self.pos[j])
        return (cost, i, j, self.version[i], self.version[j], point)

    def _violations(self, face_normals, corner_rows, merged):
        """Detail normals with a non-positive dot, per face: ``face_normals`` (r, 3), each face's
        corners (r, 3) as rows of ``self.hist`` (-1 stands for the ``merged`` histogram)."""
        dots = self.directions @ face_normals.T
        away = dots <= 0.0
        # BLAS rounds these per CPU (with or without fused multiply-adds); away from zero the sign is
        # certain (unit vectors: any order errs by < 4e-16), near it numpy decides in a fixed order.
        unsure = np.abs(dots) <= SIGN_MARGIN
        if unsure.any():
            bins, faces = np.nonzero(unsure)
            d, n = self.directions[bins], face_normals[faces]
            away[bins, faces] = d[:, 0] * n[:, 0] + d[:, 1] * n[:, 1] + d[:, 2] * n[:, 2] <= 0.0
        away = away.astype(np.float64)
        rows, inverse = np.unique(corner_rows, return_inverse=True)
        hist = self.hist[np.maximum(rows, 0)]
        hist[rows < 0] = merged
        per_vertex = hist @ away  # counts times 0/1: whole numbers, exact in any kernel's order
        return per_vertex[inverse.reshape(-1, 3), np.arange(face_normals.shape[0])[:, None]].sum(axis=1)

    def try_collapse(self, i, j, point):
        """Collapse j into i at ``point`` if the checks pass; returns 'ok', 'topology' or 'normal'."""
        if self.border[i] or self.border[j]:
            return "topology"
        shared = self.vfaces[i] & self.vfaces[j]
        if len(shared) != 2:
            return "topology"
        opposite = set()
        for fid in shared:
            opposite.update(self.faces[fid])
        opposite -= {i, j}
        around_i, around_j = self.neighbours(i), self.neighbours(j)
        if around_i & around_j != opposite:
            return "topology"
        if len(around_i | around_j) - 2 > MAX_VALENCE:  # a fan: its checks and re-queued edges grow with it
            return "topology"
        comp = self.component[i]
        if self.comp_faces[comp] - 2 < max(MIN_COMPONENT_FACES, 4):
            return "topology"

        fids = list((self.vfaces[i] | self.vfaces[j]) - shared)
        if not fids:  # the edge's two faces are all i and j have: collapsing it leaves no surface
            return "topology"
        old = np.array([self.faces[f] for f in fids], dtype=np.int64)
        new = np.where(old == j, i, old)
        corners = self.points[np.concatenate([old, old])]
        corners[len(fids):][new == i] = point
        e1 = corners[:, 1] - corners[:, 0]
        e2 = corners[:, 2] - corners[:, 0]
        cross = np.empty_like(e1)
        cross[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
        cross[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
        cross[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        length = np.sqrt((cross * cross).sum(axis=1))
        if not length.all():
            return "topology"
        unit = cross / length[:, None]
        if ((unit[:len(fids)] * unit[len(fids):]).sum(axis=1) < FLIP_COSINE).any():
            return "topology"
        merged = self.hist[i] + self.hist[j]
        counts = self._violations(unit, np.concatenate([old, np.where(new == i, -1, new)]),
                                  merged)
        if (counts[len(fids):] > counts[:len(fids)]).any():
            return "normal"

        for fid in shared:
            self.face_alive[fid] = False
            for v in self.faces[fid]:
                self.vfaces[v].discard(fid)
        for fid, new_face in zip(fids, new.tolist()):
            self.faces[fid] = new_face
        self.vfaces[i] |= self.vfaces[j]
        self.vfaces[j] = set()
        self.pos[i] = point
        self.points[i] = point
        self.quad[i] = self.quad[i] + self.quad[j]
        self.hist[i] = merged
        self.alive[j] = False
        self.merges.append((i, j))
        self.version[i] += 1
        self.version[j] += 1
        self.comp_faces[comp] -= 2
        self.face_count -= 2
        return "ok"


def collapse_with_normal_test(points, triangles, component, carrier, detail, target_faces, quadrics=None):
    """Collapse edges of the proxy (cheapest quadric error first) down to ``target_faces``.

    Border vertices are never moved; collapses that break the link condition, flip a face,
    take a component under :data:`MIN_COMPONENT_FACES` faces or fail the normal test are
    refused. Stops early when no allowed collapse is left. ``detail`` is the
    :class:`~.prepared_mesh.PreparedMesh` the proxy was simplified from. ``quadrics`` (m, 10), if
    given, replace the ones summed over the detail faces (see :func:`cluster_quadrics`): a build
    through a clustered copy sums them over the copy's faces, which lie on the detail surface.
    """
    normals = detail.normals
    m = points.shape[0]
    if quadrics is None:
        quadrics = cluster_quadrics(detail.points, detail.triangles, detail.cross, carrier, m)
    has_normal = (carrier >= 0) & rows_any(normals)
    keys = carrier[has_normal] * CUBE_BINS + cube_bin(normals[has_normal])
    histograms = np.bincount(keys, minlength=m * CUBE_BINS).reshape(m, CUBE_BINS).astype(np.float64)
    state = _CollapseState(points, triangles, quadrics, histograms, component)

    heap = []
    for f in state.faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            if a < b:
                heap.append(state.edge_entry(a, b))
    heapq.heapify(heap)
    refused = 0
    while heap and state.face_count > target_faces:
        cost, i, j, vi, vj, point = heapq.heappop(heap)
        if not (state.alive[i] and state.alive[j]) or state.version[i] != vi or state.version[j] != vj:
            continue
        outcome = state.try_collapse(i, j, point)
        if outcome == "normal":
            refused += 1
        if outcome != "ok":
            continue
        for n in state.neighbours(i):
            heapq.heappush(heap, state.edge_entry(i, n) if i < n else state.edge_entry(n, i))

    keep = np.array(state.alive)
    rank = np.full(m, -1, dtype=np.int64)
    rank[keep] = np.arange(int(keep.sum()))
    root = collapse_roots(np.array(state.merges, dtype=np.int64).reshape(-1, 2), m)
    faces = np.array([f for f, ok in zip(state.faces, state.face_alive) if ok], dtype=np.int64)
    return CheckedCollapse(points=np.asarray(state.pos, dtype=np.float64)[keep], triangles=rank[faces],
                           remap=rank[root], refused=refused)
