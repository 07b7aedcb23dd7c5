"""Which proxy vertices a handle holds: those its selection owns.

Arrays: detail vertices (n,) and their welded ids (u,) (``surface.weld`` (n,) -> u), proxy
vertices (m,), a selection ``ids`` (k,) of detail vertex ids.

Holding every corner of every proxy face a selection binds to pins about a third of the proxy
for an armadillo's leg: the proxy bends only outside that, and stretches there. A handle holds
the proxy vertices its selection *owns* (:func:`proxy_ownership` at least :data:`OWNED`: nearly
all of the skin's weight on them comes from selected vertices); the rest of the selection pulls
the free proxy around its border towards the handle's motion
(:class:`..proxy_solve.pulled_energy.PulledEnergy`), and the rebuild binds every selected vertex
to a proxy face its handle holds whole (:func:`held_rows`), so it lands exactly where the handle
puts it; the skin's diffusion (:mod:`.seam_weights`) blends its free neighbours into it.

Which handle or anchor a detail vertex follows, the one rule (:func:`owned_pairs`,
:meth:`Layout.owned`): a vertex follows the group whose selection names it, never a neighbour's
group that merely carries its proxy faces; where selections overlap, the newest handle or anchor
wins (a handle made inside a pinned body carries its part, an anchor made inside a handle pins
its part; an anchored vertex no newer selection names never moves). The same order decides which
group holds a proxy vertex two of them claim. Every selected vertex is then placed by its group's
whole affine motion from its rest position (:func:`place_held`): exact under any transform an
empty can hold (non-uniform or negative scale, shear from parents), whatever the proxy does.
"""

import hashlib
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ..validation import as_vertex_ids

#: A proxy vertex is held by a selection that brings at least this share of the skin's weight on it.
OWNED = 0.9
#: A selection owning fewer proxy vertices than this (smaller than the proxy's faces) holds every
#: corner of the faces it binds to instead, as handles always did: three free corners could not
#: carry its rotation.
MIN_OWNED = 3


@dataclass
class Layout:
    """What a rig holds: ``groups`` (m,) int64 the rigid group of every proxy vertex (-1 free, 0
    anchors, 1, 2, ... handles) and ``held`` a list of (group label, detail ids (h,)) for the
    groups made from detail vertices (a later pair overrides an earlier one)."""

    groups: np.ndarray
    held: list
    _key: bytes = field(default=None, init=False, repr=False, compare=False)
    _owned: list = field(default=None, init=False, repr=False, compare=False)

    def key(self):
        """Bytes that differ between layouts (a solver and a rebuild are prepared per layout): a
        BLAKE2b digest of the groups and the held pairs, made once per layout (a drag move looks
        its solver, rebuild and preview up by it)."""
        if self._key is None:
            digest = hashlib.blake2b(self.groups.astype(np.int64).tobytes(), digest_size=32)
            for label, ids in self.held:
                digest.update(int(label).to_bytes(8, "little", signed=True))
                digest.update(np.ascontiguousarray(ids, dtype=np.int64).tobytes())
                digest.update(b"|")
            self._key = digest.digest()
        return self._key

    def same(self, groups, held):
        """Whether ``groups`` (m,) and ``held`` (pairs (label, detail ids)) are this layout's, entry
        for entry (a comparison, much cheaper than a new layout's :meth:`key` over every held id)."""
        return (self.groups is groups or np.array_equal(self.groups, groups)) and len(self.held) == len(held) and all(
            int(label) == int(other) and (ids is other_ids or np.array_equal(ids, other_ids))
            for (label, ids), (other, other_ids) in zip(self.held, held))


    @property
    def owned(self):
        """The held pairs as (group label, detail ids (h',)) with each detail vertex in the last pair
        that names it only (:func:`owned_pairs`), made once per layout."""
        if self._owned is None:
            self._owned = owned_pairs(self.held)
        return self._owned


def owned_pairs(held):
    """``held`` (pairs (group label, detail ids (h,)), later pairs winning) with each id kept in the
    last pair that names it only: pairs (label, ids (h',) int64 sorted), the same count and order."""
    held = [(label, np.unique(np.asarray(ids, dtype=np.int64))) for label, ids in held]
    if len(held) < 2:
        return held
    size = max((int(ids[-1]) + 1 for _, ids in held if ids.size), default=0)
    taken = np.zeros(size, dtype=bool)
    owned = []
    for label, ids in reversed(held):
        owned.append((label, ids[~taken[ids]]))
        taken[ids] = True
    return owned[::-1]


class HeldPlacement:
    """Places held vertices by their groups' motions: made once per layout from ``rest`` (n, 3)
    the rest positions and ``pairs`` (group label, ids (h,)), each vertex in one pair
    (:func:`owned_pairs`); ``__call__(out (n, 3), motions)`` writes ``out[ids] = rest[ids] A^T + b``
    for each pair and its (4, 4) motion [A b] (one per pair), in float64 from the rest gathered
    once (a drag move of a 48-handle rig: one scatter, not 49 gathers). Exact under any affine
    motion; the identity gives the rest back bit for bit."""

    def __init__(self, rest, pairs):
        self.ids = np.concatenate([ids for _, ids in pairs]).astype(np.int64) if pairs else np.zeros(0, np.int64)
        self.bounds = np.cumsum([0] + [ids.size for _, ids in pairs])
        self.rest = np.asarray(rest[self.ids], dtype=np.float64)
        self._moved = np.empty_like(self.rest)

    def __call__(self, out, motions):
        if not self.ids.size:
            return out
        moved = self._moved
        for (a, b), motion in zip(zip(self.bounds[:-1], self.bounds[1:]), motions):
            if b > a:
                motion = np.asarray(motion, dtype=np.float64)
                np.matmul(self.rest[a:b], motion[:3, :3].T, out=moved[a:b])
                moved[a:b] += motion[:3, 3]
        out[self.ids] = moved
        return out


def place_held(out, rest, pairs, motions):
    """Write into ``out`` (n, 3) float32 or float64 every held vertex where its group's motion puts
    it: ``out[ids] = rest[ids] A^T + b`` for each pair (label, ids (h,)) of ``pairs`` and its (4, 4)
    motion [A b] in ``motions`` (one per pair), from ``rest`` (n, 3) the rest positions, computed in
    float64 (a one-off :class:`HeldPlacement`). Exact under any affine motion; the identity gives
    the rest back bit for bit."""
    return HeldPlacement(rest, pairs)(out, motions)


def layout_of(last, groups, held):
    """``last`` (a :class:`Layout` or None) when ``groups`` and ``held`` are its own entry for entry,
    else a new Layout of them: a caller that keeps what this returns makes a layout's key once,
    not once per drag move."""
    return last if last is not None and last.same(groups, held) else Layout(groups, held)


def proxy_ownership(surface, ids):
    """(m,) float: the share of the skin's weight on each proxy vertex that comes from the detail
    vertices ``ids`` (k,) (0 where no detail binds). The skin's weight of an association on a
    corner is its rest-area weight times the corner's barycentric (negatives count as 0). The
    whole skin's weight per proxy vertex is summed once per surface; a selection's own from its
    associations only."""
    skin = surface.skin
    m = surface.proxy_vertices.shape[0]
    total = surface.corner_weights()
    chosen = np.zeros(skin.case.shape[0], dtype=bool)
    chosen[surface.weld[as_vertex_ids("ids", ids, surface.n_detail)]] = True
    # The selection's associations in the skin's order (grouped by vertex, ascending): a pass over
    # them, not a sort of a selection of a million vertices and two searches in the skin.
    rows = np.flatnonzero(chosen[skin.vertex])
    share = skin.weight[rows, None] * np.clip(skin.bary[rows], 0.0, None)
    mine = np.bincount(surface.proxy_faces[skin.face[rows]].ravel(), weights=share.ravel(), minlength=m)
    return np.divide(mine, total, out=np.zeros(m), where=total > 0)


def held_proxy_vertices(surface, ids):
    """(c,) sorted proxy vertex ids a handle of detail vertices ``ids`` (k,) holds: those it owns
    (:func:`proxy_ownership` >= :data:`OWNED`) when they are at least :data:`MIN_OWNED` and make
    up at least one whole proxy face (its detail is bound there, :func:`held_rows`); else, for a
    selection about as small as the proxy's faces, every corner of every face it binds to
    (``surface.proxy_vertices_for``), as handles always held."""
    owned = np.zeros(surface.proxy_vertices.shape[0], dtype=bool)
    owned[proxy_ownership(surface, ids) >= OWNED] = True
    if owned.sum() >= MIN_OWNED and owned[surface.proxy_faces].all(axis=1).any():
        return np.flatnonzero(owned)
    return surface.proxy_vertices_for(ids)


def held_rows(proxy_vertices, proxy_faces, usable, rest_of, groups, labels):
    """Where the rebuild binds held detail: (u, k) CSR, row i weight 1 on the proxy face nearest
    detail vertex i (rest centroids) among the usable faces whose three corners its group holds.

    ``proxy_vertices`` (m, 3), ``proxy_faces`` (k, 3), ``usable`` (k,) bool (faces with a frame),
    ``rest_of(ids)`` (h, 3) the welded detail vertices ``ids`` (h,) at rest, ``groups`` (m,) rigid
    group of each proxy vertex (-1 free), ``labels`` (u,) the group holding each welded detail
    vertex (-1 none). Rows of vertices
    with no label, or whose group holds no whole face, are empty. A vertex bound to such a face
    with its own coefficients over the face's plane moves exactly with the group, however far
    from it the face is (the group moves rigidly, or scales uniformly)."""
    u, k = labels.shape[0], proxy_faces.shape[0]
    corner_groups = groups[proxy_faces]
    whole = usable & (corner_groups[:, 0] >= 0) & (corner_groups == corner_groups[:, :1]).all(axis=1)
    centroids = proxy_vertices[proxy_faces].mean(axis=1)
    face = np.full(u, -1, dtype=np.int32)
    for group in np.unique(labels[labels >= 0]):
        candidates = np.flatnonzero(whole & (corner_groups[:, 0] == group))
        if not candidates.size:
            continue
        members = np.flatnonzero(labels == group)
        face[members] = candidates[cKDTree(centroids[candidates]).query(rest_of(members))[1]]
    bound = np.flatnonzero(face >= 0)
    return sp.csr_matrix((np.ones(bound.size), (bound, face[bound])), shape=(u, k))
