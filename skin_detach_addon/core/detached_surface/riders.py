"""Loose parts that ride on the part they touch: an eye sunk into a head, a plate on a chest, a
bracelet around a forearm, a scan's specks, a sculpt's scales.

A *part* is a connected component of the welded detail mesh that has faces. Part p *touches* a
part q of at least twice its surface area (RIDE_SHARE) when some vertex of p lies within p's
*reach* of a vertex of q, widened by q's spacing (q's mean edge length, at most RIDE_CAP D: a
point on a face lies within about an edge of one of its corners, so a coarse part's wide faces
count as near):

    reach(p) = max(RIDE_REACH D, min(RIDE_OWN d(p), RIDE_CAP D))

with D the bounding-box diagonal of the whole mesh and d(p) that of the part: 1 % of the mesh
for specks and small parts, a quarter of the part's own size for a bracelet that hangs loose
around an arm, never more than 5 % of the mesh (a second figure standing apart stays apart).
Of the larger parts it touches, a part rides on the largest; a part that touches none is free.
The artist overrides it per part: a part holding an ``attach`` vertex rides on the nearest
larger part however far it is (the largest part has none and stays free), a part holding a
``detach`` vertex is free.

A free part gets its own proxy; a rider gets none: its vertices are carried by the proxy of the
free part at the end of its chain (its *root*: a button on a belt on a body rides the body's
proxy), each by the proxy vertex the nearest vertex of the root collapsed into, so the skin
binds it to the root's proxy faces under it and it follows that surface as the root's own skin
does (:func:`ride_carriers`).

Cost: vertices are hashed into cubic cells as wide as the largest reach plus spacing; only parts
sharing or neighbouring a cell are compared, each host's vertices near its candidates in one k-d
tree: about linear in the vertex count, whatever the number of parts. A mesh of one part costs
nothing.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..errors import SkinDetachError
from ..geometry import bbox_diagonal, face_cross
from .simplification import MIN_COMPONENT_FACES

#: A part rides only on parts of at least 1 / RIDE_SHARE times its surface area (two halves of a
#: cracked scan, or two hands that touch, stay free).
RIDE_SHARE = 0.5
#: The least reach, over the whole mesh's bounding-box diagonal.
RIDE_REACH = 0.01
#: The reach as a share of the part's own bounding-box diagonal ...
RIDE_OWN = 0.25
#: ... capped at this share of the whole mesh's diagonal.
RIDE_CAP = 0.05

#: Free detail vertices under each rider vertex (:class:`RigidRiders`).
NEAREST = 8
#: The size of a rider's pieces, over the whole mesh's diagonal (:class:`RigidRiders`): an eye, a
#: plate, a bracelet is one piece and moves rigidly; a belt round a waist follows its bend.
PIECE = 0.2
#: The most pieces a rider vertex's motion blends.
BLEND = 8

#: The 27 offsets of a cell and its neighbours.
_NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], dtype=np.int64)


@dataclass
class Riders:
    """Which part rides on which.

    labels  (p,) int64  the connected-component label of each part
    part    (u,) int64  the part of every welded vertex (-1: a vertex no face uses)
    host    (p,) int64  the part each part rides on directly (-1: free)
    root    (p,) int64  the free part that carries each part (itself when free)
    area    (p,) float  each part's surface area
    forced  (p,) int8   1 where ``attach`` made the part a rider, -1 where ``detach`` freed it, else 0
    still   (p,) bool   free parts too small for a share of the proxy (:meth:`settle_still`), and
                        the riders whose root is one: they keep their rest unless a handle holds them
    """

    labels: np.ndarray
    part: np.ndarray
    host: np.ndarray
    root: np.ndarray
    area: np.ndarray
    forced: np.ndarray
    still: np.ndarray = None

    def settle_still(self, face_part, target):
        """Mark the free parts whose share of ``target`` proxy faces (by their face count among the
        free parts' faces; ``face_part`` (t,) the part of every face) is under
        :data:`.simplification.MIN_COMPONENT_FACES` as still (a scan's floating specks: each would
        take that many proxy faces, a proxy of thousands of components), and the riders whose root
        is one. The largest free part never is."""
        p = self.host.size
        counts = np.bincount(face_part, minlength=p)
        free = ~self.riding
        share = target * counts / max(int(counts[free].sum()), 1)
        still = free & (share < MIN_COMPONENT_FACES)
        largest = np.flatnonzero(free)[np.argmax(self.area[free])]
        still[largest] = False
        self.still = still[self.root]

    @property
    def riding(self):
        """(p,) bool: the part rides on another."""
        return self.host >= 0

    def free_faces(self, triangles, components):
        """(t,) bool: the faces of ``triangles`` whose component (``components`` the labels of their
        vertices: the detail's, or a clustered copy's) is a free part that is not still: they make
        the proxy."""
        out = ~self.riding if self.still is None else ~self.riding & ~self.still
        return np.isin(components[triangles[:, 0]], self.labels[out])

    def summary(self):
        """Figures for the build's stats: parts, riders, the free parts they ride on, and the
        overrides that decided a part."""
        riding = self.riding
        return {"parts": int(self.host.size), "riders": int(riding.sum()),
                "parts_still": 0 if self.still is None else int(self.still.sum()),
                "rider_hosts": int(np.unique(self.root[riding]).size),
                "riders_attached": int((self.forced == 1).sum()), "parts_detached": int((self.forced == -1).sum())}


def find_riders(points, triangles, components, attach=None, detach=None):
    """The :class:`Riders` of a welded mesh: ``points`` (u, 3), ``triangles`` (t, 3) welded ids,
    ``components`` (u,) connected-component labels; ``attach`` and ``detach`` (k,) welded vertex ids
    (or None) of parts the artist made riders or free (a part named in both is free)."""
    u = points.shape[0]
    part = np.full(u, -1, dtype=np.int64)
    face_label = components[triangles[:, 0]]
    labels, face_part = np.unique(face_label, return_inverse=True)
    p = labels.size
    part[triangles.ravel()] = np.repeat(face_part.ravel(), 3)
    cross = face_cross(points, triangles)
    area = np.bincount(face_part.ravel(), weights=0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross)), minlength=p)
    forced = np.zeros(p, dtype=np.int8)
    for ids, mark in ((attach, 1), (detach, -1)):
        if ids is not None and len(ids):
            ids = np.asarray(ids, dtype=np.int64)
            if ids.min() < 0 or ids.max() >= u:
                raise SkinDetachError(f"{'attach' if mark == 1 else 'detach'}: expected welded vertex ids in "
                                      f"[0, {u}), got {int(ids.min())} to {int(ids.max())}")
            named = part[ids]
            forced[named[named >= 0]] = mark
    host = np.full(p, -1, dtype=np.int64)
    # rank: 0 for the largest part (more area first, the lower label on a tie).
    order = np.lexsort((np.arange(p), -area))
    rank = np.empty(p, dtype=np.int64)
    rank[order] = np.arange(p)
    if p > 1:
        used = np.flatnonzero(part >= 0)
        whole = bbox_diagonal(points[used])
        low = points[used].min(axis=0)
        own = _part_diagonals(points[used], part[used], p)
        reach = np.maximum(RIDE_REACH * whole, np.minimum(RIDE_OWN * own, RIDE_CAP * whole))
        spacing = np.minimum(_mean_edges(points, triangles, face_part.ravel(), p), RIDE_CAP * whole)
        host = _touching(points[used], part[used], spacing, reach, rank, area, low)
        attached = np.flatnonzero(forced == 1)
        if attached.size:
            host[attached] = _nearest_larger(points[used], part[used], attached, rank)
        host[forced == -1] = -1
    root = np.arange(p, dtype=np.int64)
    for index in order:  # larger parts first: a host is always settled before its riders
        if host[index] >= 0:
            root[index] = root[host[index]]
    return Riders(labels=labels, part=part, host=host, root=root, area=area, forced=forced)


def ride_carriers(riders, points, carrier, part=None):
    """``carrier`` (v,) with every rider vertex carried as the nearest vertex of its root part is
    (that vertex's carrier; vertices of the root without a carrier are skipped): the skin then
    binds the rider to the root's proxy faces under it. ``points`` (v, 3) positions and ``part``
    (v,) the part of each vertex: the welded detail's (``riders.part``, the default) or a clustered
    copy's (the part of each cluster's representative)."""
    part = riders.part if part is None else part
    out = carrier.copy()
    moving = riders.riding if riders.still is None else riders.riding & ~riders.still
    riding = np.flatnonzero((part >= 0) & moving[np.maximum(part, 0)])
    if not riding.size:
        return out
    roots = riders.root[part[riding]]
    for root in np.unique(roots):
        mine = riding[roots == root]
        carried = np.flatnonzero((part == root) & (carrier >= 0))
        if not carried.size:
            raise SkinDetachError(f"riders: expected the part they ride on (component {int(riders.labels[root])}) "
                                  f"to have a proxy, it has none; detach them")
        nearest = cKDTree(points[carried]).query(points[mine])[1]
        out[mine] = carrier[carried[nearest]]
    return out


def _mean_edges(points, triangles, face_part, p):
    """(p,) the mean edge length of each part (every face's three edges; ``face_part`` (t,))."""
    total = np.zeros(p)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        total += np.bincount(face_part, weights=np.linalg.norm(points[triangles[:, a]] - points[triangles[:, b]],
                                                                axis=1), minlength=p)
    return total / np.maximum(3 * np.bincount(face_part, minlength=p), 1)


def _boxes(points, group, count):
    """(low (g, 3), high (g, 3)): the bounding box of each of ``count`` groups of ``points`` (v, 3),
    ``group`` (v,) the group of each point."""
    low = np.full((count, 3), np.inf)
    high = np.full((count, 3), -np.inf)
    np.minimum.at(low, group, points)
    np.maximum.at(high, group, points)
    return low, high


def _part_diagonals(points, part, p):
    """(p,) the bounding-box diagonal of each part (``part`` (v,) labels of ``points`` (v, 3))."""
    low, high = _boxes(points, part, p)
    return np.linalg.norm(high - low, axis=1)


def _cells(points, low, size):
    """(v,) int64 key of the cubic cell of side ``size`` holding each point, and the grid's extent
    (3,) (one cell of margin on each side, so every neighbour of a cell has a key)."""
    cell = np.floor((points - low) / size).astype(np.int64) + 1
    extent = cell.max(axis=0) + 2
    return (cell[:, 0] * extent[1] + cell[:, 1]) * extent[2] + cell[:, 2], extent


def _touching(points, part, spacing, reach, rank, area, low):
    """(p,) the largest part each part touches among those of at least 1 / RIDE_SHARE its area (-1:
    none); ``points`` (v, 3) of the vertices in parts, ``part`` (v,), per part ``spacing``, ``reach``,
    ``rank`` (0 the largest) and ``area`` (p,), ``low`` (3,) the corner of their box."""
    p = reach.size
    host = np.full(p, -1, dtype=np.int64)
    size = float(reach.max() + spacing.max())
    if not size > 0.0:
        return host
    key, extent = _cells(points, low, size)
    # Each (cell, part) once, then the parts of every neighbouring cell: the candidate pairs.
    cell_part = np.unique(key * p + part)
    keys, owners = cell_part // p, cell_part % p
    shifts = (_NEIGHBOURS[:, 0] * extent[1] + _NEIGHBOURS[:, 1]) * extent[2] + _NEIGHBOURS[:, 2]
    pairs = []
    for shift in shifts:
        first = np.searchsorted(keys, keys + shift, side="left")
        count = np.searchsorted(keys, keys + shift, side="right") - first
        if not count.any():
            continue
        rows = np.repeat(np.arange(keys.size), count)
        skip = np.repeat(first - (np.cumsum(count) - count), count)
        pairs.append(owners[rows] * p + owners[np.arange(rows.size) + skip])
    pairs = np.unique(np.concatenate(pairs))
    rider, larger = pairs // p, pairs % p
    keep = (rank[larger] < rank[rider]) & (area[rider] <= RIDE_SHARE * area[larger])
    rider, larger = rider[keep], larger[keep]
    if not rider.size:
        return host
    members = np.argsort(part, kind="stable")
    bounds = np.searchsorted(part[members], np.arange(p + 1))
    for big in np.unique(larger):
        candidates = rider[larger == big]
        rows = np.concatenate([members[bounds[c]:bounds[c + 1]] for c in candidates])
        # Only the big part's vertices in or next to the candidates' cells are searched.
        around = np.unique((np.unique(key[rows])[:, None] + shifts[None, :]).ravel())
        mine = members[bounds[big]:bounds[big + 1]]
        mine = mine[np.isin(key[mine], around)]
        if not mine.size:
            continue
        limit = reach[part[rows]] + spacing[big]
        distance = cKDTree(points[mine]).query(points[rows], distance_upper_bound=float(limit.max()))[0]
        for touched in np.unique(part[rows][distance <= limit]):
            if host[touched] < 0 or rank[big] < rank[host[touched]]:
                host[touched] = big
    return host


def _nearest_larger(points, part, attached, rank):
    """(a,) the larger part nearest to each of the ``attached`` parts (-1 for the largest part):
    the least distance between a vertex of the part and one of the larger part."""
    out = np.full(attached.size, -1, dtype=np.int64)
    for index, which in enumerate(attached):
        larger = rank[part] < rank[which]
        if not larger.any():
            continue
        candidates = np.flatnonzero(larger)
        distance, nearest = cKDTree(points[candidates]).query(points[part == which])
        out[index] = part[candidates[nearest[np.argmin(distance)]]]
    return out


def rider_groups(riders, part):
    """(ids (r,) int64, starts (k + 1,) int64): the vertices of each rider, rider after rider (rider
    j's are ``ids[starts[j]:starts[j + 1]]``), of a mesh whose vertices lie in parts ``part`` (n,)
    (the detail's: ``riders.part[weld]``; a clustered copy's: the parts of its representatives)."""
    moving = riders.riding if riders.still is None else riders.riding & ~riders.still
    mine = np.flatnonzero((part >= 0) & moving[np.maximum(part, 0)])
    order = np.argsort(part[mine], kind="stable")
    ids = mine[order]
    _, counts = np.unique(part[ids], return_counts=True)
    return ids.astype(np.int64), np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def still_vertices(riders, part):
    """(s,) int64 the vertices of still parts (:meth:`Riders.settle_still`) of a mesh whose vertices
    lie in parts ``part`` (n,)."""
    if riders.still is None:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero((part >= 0) & riders.still[np.maximum(part, 0)]).astype(np.int64)


class RigidRiders:
    """Riders keep their shape where the surface under them keeps its own: each rider is cut into
    *pieces* (cubes of :data:`PIECE` times the whole mesh's diagonal; an eye, a plate or a bracelet
    is one piece), each piece moves by the rigid motion that best fits how the surface under it
    moved, and each rider vertex by the blend of the motions of its rider's pieces near it. A
    rider of one piece moves rigidly (an eye stays a sphere); a belt round a bending waist follows
    the bend piece by piece. (The skin alone would let a thick part over a bending surface stretch
    as a layer over a bend does.)

    ids (r,) int64 detail vertex ids, rider after rider; starts (k + 1,) int64 their bounds; rest
    (n, 3) the detail's rest positions; ``free`` (n,) bool the vertices of free parts. Under each
    rider vertex lie the :data:`NEAREST` free vertices nearest it at rest: a piece's *patch* is
    those of all its vertices (with repeats).

    Minimised, per piece: sum over its patch of |R p + t - p'|^2 with R a rotation (det +1), p the
    patch at rest and p' as rebuilt: t = mean(p') - R mean(p) and R from the SVD of the 3 x 3
    covariance (Kabsch), in closed form (no iteration); a patch that alone leaves R free (points on
    a line) takes it from a thousandth of the rider's own vertices as the skin put them
    (:meth:`_steady`). A vertex's weights on the pieces of its
    rider whose centres lie within 2 PIECE D of it (at most :data:`BLEND` of them) are
    (1 - (d / 2 PIECE D)^2)^2, summing to one: a rigid motion of the surface moves every rider by
    exactly that motion."""

    def __init__(self, rest, ids, starts, free, still=None):
        self.still = np.zeros(0, dtype=np.int64) if still is None else np.asarray(still, dtype=np.int64)
        self._still_rest = np.asarray(rest[self.still], dtype=np.float64)
        self.ids = np.asarray(ids, dtype=np.int64)
        self.starts = np.asarray(starts, dtype=np.int64)
        self.count = np.diff(self.starts)
        self.rest = rest
        self.points = np.asarray(rest[self.ids], dtype=np.float64)
        self._rider = np.repeat(np.arange(self.count.size), self.count)
        self.under, under_rest, under_index = _under(rest, self.points, free)
        if not self.under.size or not self.ids.size:
            return
        size = PIECE * bbox_diagonal(np.asarray(rest, dtype=np.float64)) + 1e-300
        # Cubes from each rider's own corner, as many along an axis as its extent needs: a rider
        # smaller than a piece is one piece, whatever its place.
        low, high = _boxes(self.points, self._rider, self.count.size)
        across = np.maximum(np.ceil((high - low) / size), 1.0)
        step = np.maximum((high - low) / across, 1e-300)
        cell = np.minimum(np.floor((self.points - low[self._rider]) / step[self._rider]),
                          across[self._rider] - 1).astype(np.int64)
        key = np.stack([self._rider, cell[:, 0], cell[:, 1], cell[:, 2]], axis=1)
        _, piece = np.unique(key, axis=0, return_inverse=True)
        piece = piece.ravel()
        p = int(piece.max()) + 1
        order = np.argsort(piece, kind="stable")
        bounds = np.searchsorted(piece[order], np.arange(p + 1))
        # A piece's patch as counts on the free vertices under it: (p, q) sparse, one row a piece.
        q = self.under.size
        counts = sp.csr_matrix((np.ones(under_index.size), (np.repeat(piece, under_index.shape[1]),
                                                              under_index.ravel())), shape=(p, q))
        counts.sum_duplicates()
        self._patch_count = np.asarray(counts.sum(axis=1)).ravel()
        self._patch_mean = sp.csr_matrix(counts.multiply(1.0 / self._patch_count[:, None]))
        self._patch_centre = self._patch_mean @ under_rest
        # covariance[:, a, b] = sum_j counts[p, j] (u_j - centre_p)_a out_j_b: one sparse product per a.
        rows, cols = counts.nonzero()
        values = np.asarray(counts[rows, cols]).ravel()
        spread = under_rest[cols] - self._patch_centre[rows]
        self._patch_axes = [sp.csr_matrix((values * spread[:, a], (rows, cols)), shape=(p, q)) for a in range(3)]
        self._patch_size = np.bincount(rows, weights=values * np.einsum("ij,ij->i", spread, spread), minlength=p)
        own_centre = np.add.reduceat(self.points, self.starts[:-1], axis=0) / self.count[:, None]
        own_local = self.points - own_centre[self._rider]
        r = self.ids.size
        self._own_size = np.maximum(np.add.reduceat(np.einsum("ri,ri->r", own_local, own_local), self.starts[:-1]),
                                    1e-300)
        # The rider's own covariance, rest against the skin's placing, the same way (k, r) a row a rider.
        self._own_axes = [sp.csr_matrix((own_local[:, a], (self._rider, np.arange(r))), shape=(self.count.size, r))
                          for a in range(3)]
        # Each vertex's pieces: the nearest of its own rider (the rider's id as a far fourth axis).
        centres = np.add.reduceat(self.points[order], bounds[:-1], axis=0) / np.diff(bounds)[:, None]
        piece_rider = self._rider[order][bounds[:-1]]
        self._piece_rider = piece_rider
        far = 1e3 * (float(np.abs(self.points).max()) + size)
        k = min(BLEND, p)
        distance, near = cKDTree(np.column_stack([centres, piece_rider * far])).query(
            np.column_stack([self.points, self._rider * far]), k=k)
        distance, near = distance.reshape(-1, k), near.reshape(-1, k)
        weight = np.clip(1.0 - (distance / (2.0 * size)) ** 2, 0.0, None) ** 2
        weight[np.arange(near.shape[0]), 0] = np.maximum(weight[:, 0], 1e-12)  # its own piece, at least
        weight /= weight.sum(axis=1, keepdims=True)
        used = max(int((weight > 0).sum(axis=1).max()), 1)  # columns that carry weight (one: rigid riders)
        order_by_weight = np.argsort(-weight, axis=1, kind="stable")[:, :used]
        self._near = np.take_along_axis(near, order_by_weight, axis=1)
        self._weight = np.take_along_axis(weight, order_by_weight, axis=1)

    def _steady(self, out):
        """(p, 3, 3) what makes each piece's fit unique where its patch alone does not (free
        vertices on a line: any turn about it fits them): a thousandth (of the patch's size) of the
        covariance of its rider's own vertices, rest against where the skin put them in ``out``
        (the skin follows the proxy's faces, whose frames turn; a rigid motion gives the same
        rotation there), and a 1e-9 share of the identity where even that is flat."""
        skin = np.asarray(out[self.ids], dtype=np.float64)
        own = np.stack([axis @ skin for axis in self._own_axes], axis=1)  # (k, 3, 3): rest centred
        rider = self._piece_rider
        nudge = (1e-3 * self._patch_size / self._own_size[rider])[:, None, None] * own[rider]
        return nudge + (1e-9 * self._patch_size + 1e-300)[:, None, None] * np.eye(3)

    def place(self, out, keep=None):
        """Move each rider of ``out`` (n, 3) by its pieces' rigid motions fitted to their patches
        (rebuilt in ``out`` already), and put the still vertices back at rest, in place; ``keep``
        (:meth:`holding`), optional: the riders left as the skin put them and the still vertices
        left where their handle put them (a handle holds some of their vertices)."""
        riders_held, still_held = (None, None) if keep is None else keep
        if self.still.size:
            rows = slice(None) if still_held is None else ~still_held
            out[self.still[rows]] = self._still_rest[rows]
        if not self.ids.size or not self.under.size:
            return out
        moved = np.asarray(out[self.under], dtype=np.float64)
        centre = self._patch_mean @ moved
        covariance = np.stack([axis @ moved for axis in self._patch_axes], axis=1)  # (p, 3, 3)
        u, _, vt = np.linalg.svd(covariance + self._steady(out))
        flip = np.linalg.det(np.einsum("kij,kjl->kil", u, vt)) < 0
        vt[flip, 2, :] *= -1.0
        rotation = np.einsum("kji,klj->kil", vt, u)  # R = V U^T (p' = R p + t), one per piece
        # p' = R (x - c) + c' = R x + (c' - R c): one rotation and offset a piece, blended per vertex.
        offset = centre - np.einsum("kij,kj->ki", rotation, self._patch_centre)
        if self._near.shape[1] == 1:
            piece = self._near[:, 0]
            placed = np.einsum("rij,rj->ri", rotation[piece], self.points) + offset[piece]
        else:
            blended = np.einsum("rc,rcij->rij", self._weight, rotation[self._near])
            placed = np.einsum("rij,rj->ri", blended, self.points) + np.einsum("rc,rci->ri", self._weight,
                                                                               offset[self._near])
        if riders_held is not None and riders_held.any():
            rows = ~riders_held[self._rider]
            out[self.ids[rows]] = placed[rows]
        else:
            out[self.ids] = placed
        return out

    def holding(self, held):
        """(riders (k,) bool, still (s,) bool): the riders some vertex of which ``held`` (pairs
        (label, detail ids)) holds, and the still vertices it holds (for :meth:`place`'s ``keep``)."""
        riders, still = np.zeros(self.count.size, dtype=bool), np.zeros(self.still.size, dtype=bool)
        if held:
            ids = np.unique(np.concatenate([np.asarray(i, dtype=np.int64) for _, i in held]))
            riders[np.unique(self._rider[np.isin(self.ids, ids)])] = True
            still = np.isin(self.still, ids)
        return riders, still


def _under(rest, points, free):
    """(q,) the free detail vertices under some rider vertex, (q, 3) their rest, (r, NEAREST) which
    of them lie under each of the rider vertices ``points`` (r, 3): the nearest at rest among the
    ``free`` (n,) bool vertices within the riders' box widened by a tenth of its diagonal (more
    when none is there)."""
    candidates = np.flatnonzero(free)
    if not candidates.size or not points.size:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((points.shape[0], NEAREST), dtype=np.int64)
    low, high = points.min(axis=0), points.max(axis=0)
    margin = 0.1 * float(np.linalg.norm(high - low)) + 1e-12
    while True:
        near = candidates[((rest[candidates] >= low - margin) & (rest[candidates] <= high + margin)).all(axis=1)]
        if near.size >= NEAREST or near.size == candidates.size:
            break
        margin *= 4.0
    k = min(NEAREST, near.size)
    index = cKDTree(np.asarray(rest[near], dtype=np.float64)).query(points, k=k)[1].reshape(points.shape[0], k)
    used, inverse = np.unique(index, return_inverse=True)
    return near[used], np.asarray(rest[near[used]], dtype=np.float64), inverse.reshape(index.shape)
