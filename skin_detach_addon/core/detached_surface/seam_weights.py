"""The skin's weights diffused over the detail mesh, so the rebuild does not crease where the proxy
bends.

Arrays: welded detail vertices (u,), ``triangles`` (f, 3) over them, ``rest`` (u, 3) their rest
positions, the proxy's rest frames (:class:`.skin.ProxyFrames`, k faces), a :class:`.skin.Skin`
(associations grouped by vertex); ``keep`` (u,) bool marks held vertices.

Why the plain skin creases: neighbouring detail vertices bound to different proxy faces (or to a
different number of them) take different weights, so where the proxy bends their rebuilt
positions jump by about (weight difference) x (height) x (bend), and the detail folds along the
proxy's edges (93-98 % of the creases sat on such seams).

What this gives instead: W (u, k), the weight of face f in vertex i (the skin's rest-area
weights, a partition of unity), diffused :data:`SEAM_STEPS` times by the detail's one-ring
average S (row-normalised I + adjacency), W <- S W, with the rows of held vertices kept at their
own weights. Entries under :data:`THRESHOLD` of their row's largest are dropped and every row is
renormalised to sum to one. Each (i, f) left is an association with vertex i's own coefficients
over face f's (extended) plane, so every candidate rebuilds v_i exactly at rest and under a
rigid motion or uniform scale of the proxy: so does their blend. The weights now change over
about SEAM_STEPS rings of the detail instead of across one edge. Held vertices (carried by one
rigid group: a handle) keep their own associations, so they keep its motion exactly, and their
neighbours blend into them without a step.

Held rows change only the rows within SEAM_STEPS rings of them: :meth:`SeamWeights.skin`
re-diffuses the rows within 2 x SEAM_STEPS rings (what those depend on) and keeps the rest of
the free diffusion; the result equals the diffusion over the whole mesh (tested).
Measured (bend scenario, six scans flat-subdivided to 25-96K, 1,000 proxy faces, the rebuild
with deformed face normals): creases 5,867 with the plain skin, 1,273 diffused (ARAP at full
resolution: 1,529); 6.8 entries per row at 300K against 7.0 for the plain skin.
"""

import hashlib
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .. import threads
from ..geometry import flat_ranges, segment_ranges
from .held_detail import held_rows
from .reconstruction import rebuild_matrix, scaled_normals
from .skin import Skin
from ..threads import map_blocks

#: One-ring averaging steps of the weights: about how many rings of the detail a weight change spans.
SEAM_STEPS = 8
#: Diffused weights under this fraction of their row's largest are dropped (each row is then
#: renormalised): the rebuild reads about as many entries per row as the plain skin's.
THRESHOLD = 0.05


#: Islands of held rows kept diffused (:meth:`SeamWeights.layout_associations`): a rig of a few
#: dozen handles and anchors, its last layouts' islands shared.
KEPT_ISLANDS = 256

#: Rows per slice when the rows' entries are turned around (bounds the scratch memory).
REVERSE_ROWS = 1 << 19


def one_ring(graph):
    """(u, u) CSR of int8 ones: row i holds vertex i and its one-ring neighbours, from the (u, u)
    ``graph`` of the mesh's directed edges (:func:`..geometry.half_edge_graph`, or any pattern
    holding either direction of every edge: an edge two faces share, a vertex its own neighbour
    or a repeated face count once). Each row's columns descend: the order in which the
    diffusion adds its terms up, as it always has (the rows of the diagonal scaling's sparse
    product that made the average came out so)."""
    u = graph.shape[0]
    pattern = sp.csr_matrix(graph + graph.T + sp.identity(u, dtype=np.int8, format="csr"))
    indptr, ascending = pattern.indptr, pattern.indices
    counts = np.diff(indptr)
    # Row i's entries [s, e) turned around are backwards[nnz - e: nnz - s]: entry k reads
    # backwards[k + nnz - e - s].
    backwards = ascending[::-1]
    shift = indptr[-1] - indptr[1:] - indptr[:-1]
    indices = np.empty_like(ascending)
    for first in range(0, u, REVERSE_ROWS):
        last = min(first + REVERSE_ROWS, u)
        start, stop = indptr[first], indptr[last]
        indices[start:stop] = backwards[np.arange(start, stop) + np.repeat(shift[first:last], counts[first:last])]
    return sp.csr_matrix((np.ones(indices.size, dtype=np.int8), indices, indptr), shape=(u, u))


def one_ring_average(ring, rows, local=None):
    """(r, r) float64 CSR: the rows ``rows`` (r,) sorted ids of the average of each vertex and its
    one-ring neighbours, equal weights (``ring``: :func:`one_ring`), restricted to the columns
    ``rows``: each kept entry of row i is 1 / (the size of i's whole one-ring). ``local``: a
    (u,) int scratch array of -1 the caller keeps (given back as it came: no array as long as the
    mesh is made per call)."""
    u = ring.shape[0]
    scratch = np.full(u, -1, dtype=np.int64) if local is None else local
    scratch[rows] = np.arange(rows.size)
    starts, stops = ring.indptr[rows], ring.indptr[rows + 1]
    counts = stops - starts
    positions = np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
    columns = scratch[ring.indices[positions]]
    scratch[rows] = -1
    inside = columns >= 0
    kept = np.add.reduceat(inside, np.cumsum(counts) - counts) if rows.size else np.zeros(0, dtype=np.int64)
    kept[counts == 0] = 0
    indptr = np.zeros(rows.size + 1, dtype=np.int64)
    np.cumsum(kept, out=indptr[1:])
    data = np.repeat(1.0 / counts.astype(np.float64), kept)
    # Each row's columns keep the ring's order (descending ids, as a row slice and a column
    # slice of the ring kept them: the order the diffusion adds its terms up in).
    return sp.csr_matrix((data, columns[inside], indptr), shape=(rows.size, rows.size))


def one_ring_rows(ring, start, stop):
    """(stop - start, u) float64 CSR: rows ``start:stop`` of the average of each vertex and its
    one-ring neighbours, equal weights (``ring``: :func:`one_ring`), every column."""
    indptr = ring.indptr[start:stop + 1]
    counts = np.diff(indptr)
    return sp.csr_matrix((threads.repeat(1.0 / counts.astype(np.float64), counts), ring.indices[indptr[0]:indptr[-1]],
                          indptr - indptr[0]), shape=(stop - start, ring.shape[1]))


def _stacked(parts):
    """(r, k) CSR: the row blocks ``parts`` (CSR, r rows in all) one above the other."""
    return parts[0] if len(parts) == 1 else sp.vstack(parts, format="csr")


#: Rows of diffused weights made into associations at once (bounds the scratch memory).
ASSOCIATION_ROWS = 1 << 18


class SeamWeights:
    """The diffused skin of one detail mesh: ``skin`` (:class:`.skin.Skin`), ``graph`` (u, u) the
    directed edges of its faces over the u welded vertices (see :func:`one_ring`),
    ``frames`` the proxy's :class:`.skin.ProxyFrames`. ``steps`` 0 gives the skin itself. The
    rest positions and the skin's weights of the rows a diffusion needs are made for those rows
    when it needs them (kept for the whole mesh, they held 130 MB at 3.2M)."""

    def __init__(self, skin, graph, frames, steps=SEAM_STEPS, threshold=THRESHOLD):
        self.steps = int(steps)
        self.threshold = float(threshold)
        self._skin = skin
        self._u = skin.case.shape[0]
        self._frames = frames
        self._ring = one_ring(graph)
        self._widest = None
        self._local = None
        self._free = None
        #: The associations of the islands of recent layouts (:meth:`layout_associations`).
        self._islands = OrderedDict()
        #: The last :meth:`layout_band`'s (ids, keep, held rows, placed, associations): the next
        #: layout's band diffuses only the rows near what changed.
        self._last_band = None

    def _rest_of(self, rows):
        """(r, 3) where the skin as bound rebuilds the welded ``rows`` (r,) at rest: their own
        positions up to rounding, against which every association's coefficients are taken."""
        points, triangles = self._frames.points, self._frames.triangles
        matrix = rebuild_matrix(self._skin, triangles, points.shape[0], rows)
        return matrix @ np.vstack([points, scaled_normals(points, triangles)])

    def _base_of(self, rows):
        """(r, k) CSR: the skin's own weights of the welded ``rows`` (r,) sorted ids, each row's
        faces ascending."""
        vertex = self._skin.vertex
        start, stop = np.searchsorted(vertex, rows), np.searchsorted(vertex, rows, side="right")
        positions = flat_ranges(start, stop)[0]
        index = np.int32 if positions.size < 2**31 - 1 else np.int64  # what scipy's own conversion gave
        indptr = np.zeros(rows.size + 1, dtype=index)
        indptr[1:] = threads.cumsum(stop - start)
        base = sp.csr_matrix((self._skin.weight[positions], self._skin.face[positions].astype(index), indptr),
                             shape=(rows.size, self._frames.triangles.shape[0]))
        base.sort_indices()
        return base

    def _within(self, seeds, rings):
        """(u,) bool: the vertices within ``rings`` rings of the ``seeds`` (u,) bool (a breadth-first
        walk over the one-ring matrix's rows: work in proportion to the region, not the mesh)."""
        near = seeds.copy()
        front = np.flatnonzero(seeds)
        indptr, indices = self._ring.indptr, self._ring.indices
        for _ in range(rings):
            if not front.size:
                break
            reached = indices[segment_ranges(indptr, front)[0]]
            front = np.unique(reached[~near[reached]])
            near[front] = True
        return near

    def _diffused(self, rows, keep, held_rows=None, progress=None):
        """(len(rows), k) CSR: W diffused over the sub-mesh of ``rows`` (sorted ids) with the
        ``keep`` (len(rows),) rows held at their own weights or at ``held_rows`` (u, k);
        ``progress(fraction)`` after each step."""
        u = self._u
        base = self._base_of(rows)
        if rows.size < u:
            blocks = [one_ring_average(self._ring, rows, self._scratch())]
        else:  # the whole mesh (the build's free diffusion): row blocks multiplied side by side
            blocks = [one_ring_rows(self._ring, a, b) for a, b in threads.row_blocks(u)]
        if keep.any():
            free = sp.diags((~keep).astype(np.float64))
            source = base
            if held_rows is not None:  # its non-empty rows replace the skin's own
                replacement = sp.csr_matrix(held_rows[rows])
                replaced = np.diff(replacement.indptr) > 0
                source = sp.diags((~replaced).astype(np.float64)) @ base + replacement
            held = sp.csr_matrix(sp.diags(keep.astype(np.float64)) @ source)

            def hold(product):
                return free @ product + held
        else:  # the free diffusion (the build's): nothing to hold, no row to reset
            def hold(product):
                return product
        # Each step's row blocks are multiplied side by side on the core's threads (each row's
        # product is the one the whole matrix's would give) and stacked once the step's input is
        # let go (one copy of the weights less at once).
        weights = base
        del base  # the first step's input goes with it
        for step in range(self.steps):
            parts = map_blocks(lambda block, right=weights: block @ right, blocks)
            weights = None
            weights = hold(_stacked(parts))
            del parts
            if progress is not None:
                progress((step + 1) / self.steps)
        return sp.csr_matrix(weights)

    def _associations(self, rows, weights):
        """(vertex, face, weight, bary, height) of the diffused ``weights`` of ``rows``,
        thresholded, each row renormalised (faces without a frame dropped), with every vertex's
        own coefficients over each face's plane. :data:`ASSOCIATION_ROWS` rows at a time, side by
        side on the core's threads, into arrays of the size the kept entries were first counted
        to (the scratch memory of a few hundred thousand rows, not of millions)."""
        weights.eliminate_zeros()
        indptr = weights.indptr
        blocks = [(a, min(a + ASSOCIATION_ROWS, rows.size)) for a in range(0, rows.size, ASSOCIATION_ROWS)]
        kept = map_blocks(lambda block: self._kept_entries(weights, *block), blocks)
        ends = np.cumsum([np.count_nonzero(mask) for mask in kept], dtype=np.int64)
        total = int(ends[-1]) if ends.size else 0
        index = np.int32 if self._u < 2**31 else np.int64  # ids of the diffused skins: half of int64's 75 MB at 3.2M
        vertex, face, weight = np.empty(total, dtype=index), np.empty(total, dtype=index), np.empty(total)
        bary, height = np.empty((total, 3)), np.empty(total)

        def fill(index):
            (a, b), mask = blocks[index], kept[index]
            local = np.repeat(np.arange(b - a), np.diff(indptr[a:b + 1]))[mask]
            rest = self._rest_of(rows[a:b])
            part = slice(ends[index] - local.size, ends[index])
            vertex[part] = rows[a:b][local]
            face[part] = weights.indices[indptr[a]:indptr[b]][mask]
            values = weights.data[indptr[a]:indptr[b]][mask]
            weight[part] = values / np.bincount(local, weights=values, minlength=b - a)[local]
            bary[part], distance = self._frames.project(rest[local], face[part])
            height[part] = distance / np.sqrt(self._frames.cross_len[face[part]])

        map_blocks(fill, list(range(len(blocks))))
        return vertex, face, weight, bary, height

    def _kept_entries(self, weights, a, b):
        """(e,) bool over the entries of rows ``a:b`` of ``weights``: those on a face with a frame
        and at least :attr:`threshold` of their row's largest such entry."""
        indptr = weights.indptr
        start, stop = indptr[a], indptr[b]
        face, weight = weights.indices[start:stop], weights.data[start:stop]
        usable = self._frames.valid[face]
        largest = np.zeros(b - a)
        filled = indptr[a + 1:b + 1] > indptr[a:b]
        largest[filled] = np.maximum.reduceat(np.where(usable, weight, 0.0), (indptr[a:b] - start)[filled])
        usable &= weight >= self.threshold * np.repeat(largest, np.diff(indptr[a:b + 1]))
        return usable

    def _free_associations(self, progress=None):
        """The associations of the free diffusion, every row (made once; ``progress(fraction)``
        is called after each step of the diffusion)."""
        if self._free is None:
            u = self._u
            weights = self._diffused(np.arange(u), np.zeros(u, dtype=bool), progress=progress)
            self._free = self._associations(np.arange(u), weights)
        return self._free

    def _no_associations(self):
        """Empty (vertex, face, weight, bary, height) arrays of the associations' types."""
        index = np.int32 if self._u < 2**31 else np.int64
        return (np.zeros(0, dtype=index), np.zeros(0, dtype=index), np.zeros(0), np.zeros((0, 3)), np.zeros(0))

    def kept(self, groups):
        """(u,) bool: every proxy corner the vertex is bound to lies in one rigid group (``groups``
        (m,) labels, -1: none; None: no vertex is held)."""
        return self.carrier_group(groups) >= 0

    def carrier_group(self, groups):
        """(u,) int64: the rigid group (``groups`` (m,) labels) holding every proxy corner the vertex
        is bound to, -1 where its corners lie in no group or in several (or ``groups`` is None).
        Only the vertices with an association on a face whose corners one group holds are looked
        at (:meth:`_on_whole_faces`)."""
        carried = np.full(self._u, -1, dtype=np.int64)
        if groups is None:
            return carried
        groups = np.asarray(groups)
        candidates = np.flatnonzero(self._on_whole_faces(groups))
        carried[candidates] = self._carriers(groups, candidates)
        return carried

    def _on_whole_faces(self, groups):
        """(u,) bool: the vertices with an association on a proxy face whose three corners one
        group of ``groups`` (m,) holds (one pass over the associations, no sort)."""
        corner_groups = groups[self._frames.triangles]
        whole = np.flatnonzero((corner_groups[:, 0] >= 0) & (corner_groups == corner_groups[:, :1]).all(axis=1))
        marked = np.zeros(self._u, dtype=bool)
        if whole.size:
            on_whole = np.zeros(corner_groups.shape[0], dtype=bool)
            on_whole[whole] = True
            marked[self._skin.vertex[on_whole[self._skin.face]]] = True
        return marked

    def _carriers(self, groups, vertices):
        """(s,) int64: :meth:`carrier_group` of the welded ``vertices`` (s,) sorted ids only."""
        vertex = self._skin.vertex
        first, last = np.searchsorted(vertex, vertices), np.searchsorted(vertex, vertices, side="right")
        carried = np.full(vertices.size, -1, dtype=np.int64)
        bound = last > first
        first, last = first[bound], last[bound]
        if not first.size:
            return carried
        rows = flat_ranges(first, last)[0]
        labels = groups[self._frames.triangles[self._skin.face[rows]]]
        begins = np.cumsum(last - first) - (last - first)  # the skin's rows are grouped by vertex
        low = np.minimum.reduceat(labels.min(axis=1), begins)
        same = (low == np.maximum.reduceat(labels.max(axis=1), begins)) & (low >= 0)
        carried[np.flatnonzero(bound)[same]] = low[same]
        return carried

    def held_by(self, groups, labels=None):
        """(keep (u,) bool, rows (u, k) CSR or None) for :meth:`skin` (a non-empty row of ``rows``
        replaces that vertex's own weights): the vertices carried by one
        rigid group (:meth:`carrier_group`) at their own weights, unless ``labels`` (u,) names
        another group for them (-1: none), and the vertices ``labels`` says a group holds bound to
        a face that group holds whole (:func:`.held_detail.held_rows`). A selected vertex whose
        proxy corners all lie in another group's hands follows its own group, not that one."""
        if labels is None or groups is None:
            return self.kept(groups), None
        carried = self.carrier_group(groups)
        keep = (carried >= 0) & ((labels < 0) | (labels == carried))
        rows = held_rows(self._frames.points, self._frames.triangles, self._frames.valid, self._rest_of,
                         np.asarray(groups), np.where(keep, -1, labels))
        return keep | (np.diff(rows.indptr) > 0), rows

    def layout_associations(self, keep, held_rows=None):
        """(rows (a,) int64 sorted welded ids, their associations (vertex, face, weight, bary,
        height) grouped by vertex): the rows of :meth:`skin` that differ from the free diffusion's
        with the ``keep`` (u,) rows held (at ``held_rows`` where given, see :meth:`skin`), the
        vertices within ``steps`` rings of a held one; every other row is the free diffusion's.

        The held vertices fall into islands, the connected parts of those rows: an island's rows
        depend on its own held vertices and their rows only (a held vertex within ``steps`` rings
        of an island's row belongs to it), so each island is diffused on its own and kept, keyed
        by its rows, held vertices and held rows: a layout that adds a handle diffuses the new
        handle's island (and those its change reaches), not every other handle's again."""
        if not keep.any():
            return np.zeros(0, dtype=np.int64), self._no_associations()
        ids = np.flatnonzero(self._within(keep, max(self.steps, 1)))
        return ids, self._islands_of(ids, keep, held_rows)

    def layout_band(self, groups, labels):
        """(rows (a,) int64 sorted welded ids, their associations (vertex, face, weight, bary,
        height) grouped by vertex): the rows of the layout's diffused skin (:meth:`skin` with
        :meth:`held_by` ``(groups, labels)``) that differ from the free diffusion's, except the
        rows of the vertices ``labels`` (u,) gives a group (>= 0): their handles place them
        (:class:`.held_detail.HeldPlacement`), their rows are never rebuilt. Those are the
        rows within ``steps`` rings of a held vertex: outside a selection, a band along its
        border and around the vertices one group carries (each row the same bit for bit as
        :meth:`layout_associations` gives it). Its cost follows the band, not the selection: only
        the selection's border is walked, only the held vertices within the band's reach get
        their own rows, and each island of the band is diffused on its own and kept; after another
        layout, only the rows near what changed are diffused again (:meth:`_band_from_last`)."""
        placed = labels >= 0
        carried_free = np.zeros(self._u, dtype=bool)
        candidates = np.flatnonzero(self._on_whole_faces(np.asarray(groups)) & ~placed)
        carried_free[candidates[self._carriers(groups, candidates) >= 0]] = True
        seeds = carried_free.copy()
        seeds[self._border(placed)] = True
        near = self._within(seeds, max(self.steps, 1))
        near &= ~placed
        ids = np.flatnonzero(near)
        if not ids.size:
            return ids, self._no_associations()
        region = np.flatnonzero(self._within(near, self.steps))
        inside = region[placed[region]]
        keep = carried_free
        own = self._carriers(groups, inside) == labels[inside]
        keep[inside[own]] = True
        elsewhere = np.full(self._u, -1, dtype=np.int32)
        elsewhere[inside[~own]] = labels[inside[~own]]
        rows = held_rows(self._frames.points, self._frames.triangles, self._frames.valid, self._rest_of,
                         np.asarray(groups), elsewhere)
        keep |= np.diff(rows.indptr) > 0
        parts = self._band_from_last(ids, keep, rows, placed)
        self._last_band = (ids, keep, rows, placed, parts)
        return ids, parts

    def _band_from_last(self, ids, keep, rows, placed):
        """The associations of the band rows ``ids`` (sorted welded ids) of a layout with the
        ``keep`` (u,) rows held at ``rows`` (u, k) CSR and ``placed`` (u,) bool, from the last
        layout's band where they cannot differ. A row after ``steps`` steps reads only the rows
        within ``steps`` rings, each the same for the same held state and held row: so a row of
        the last band with no vertex within ``steps`` rings whose held state, held row or
        placement changed is the last band's row bit for bit, and only the rows within ``steps``
        rings of a change are diffused again (a new handle's neighbourhood, whatever the number
        of handles; :meth:`_islands_of`). Without a last band: every row, island by island."""
        last = self._last_band
        if last is None:
            return self._islands_of(ids, keep, rows)
        last_ids, last_keep, last_rows, last_placed, last_parts = last
        changed = (keep != last_keep) | (placed != last_placed) | _rows_differ(rows, last_rows)
        stale = self._within(changed, self.steps)
        was_band = np.zeros(self._u, dtype=bool)
        was_band[last_ids] = True
        # A band row that was not one: a change is within its reach (then it is stale already).
        redo = ids[stale[ids] | ~was_band[ids]]
        kept = np.zeros(self._u, dtype=bool)
        kept[ids] = True
        kept[redo] = False
        fresh = self._islands_of(redo, keep, rows) if redo.size else self._no_associations()
        return tuple(_merged_rows(last_parts, kept[last_parts[0]], fresh, np.ones(fresh[0].size, dtype=bool),
                                  self._u))

    def _islands_of(self, ids, keep, held_rows):
        """The associations of the rows ``ids`` (sorted welded ids) of a layout, island by island
        (the connected parts of those rows, see :meth:`layout_associations`), grouped by vertex."""
        count, label = connected_components(one_ring_average(self._ring, ids, self._scratch()), directed=False)
        order = np.argsort(label, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(np.bincount(label, minlength=count))])
        islands = [ids[order[a:b]] for a, b in zip(bounds[:-1], bounds[1:])]  # each sorted (ids are)
        parts = [self._island(island, keep, held_rows) for island in islands]
        vertex = np.concatenate([part[0] for part in parts])
        sort = np.argsort(vertex, kind="stable")  # islands interleave in vertex order; each grouped already
        return tuple(np.concatenate([part[i] for part in parts])[sort] for i in range(5))

    def _border(self, marked):
        """(b,) int64 sorted welded ids of the ``marked`` (u,) vertices with an unmarked one-ring
        neighbour (one gather over the marked vertices' rings, no sort)."""
        if not marked.any():
            return np.zeros(0, dtype=np.int64)
        # One int8 product with the one-ring (its entries are int8 ones): each vertex's count of
        # unmarked neighbours, row blocks side by side; no index array as long as the rings.
        unmarked = ~marked
        # int8 counts while no ring has 128 vertices (a fan's pole may: int32 then, its data copied)
        unmarked = unmarked.view(np.int8) if self._widest_ring() < 128 else unmarked.astype(np.int32)
        u = self._u
        ring = self._ring
        counts = np.concatenate(map_blocks(
            lambda span: sp.csr_matrix((ring.data[ring.indptr[span[0]]:ring.indptr[span[1]]],
                                        ring.indices[ring.indptr[span[0]]:ring.indptr[span[1]]],
                                        ring.indptr[span[0]:span[1] + 1] - ring.indptr[span[0]]),
                                       shape=(span[1] - span[0], u)) @ unmarked,
            threads.row_blocks(u)))
        return np.flatnonzero(marked & (counts > 0))

    def _scratch(self):
        """(u,) int64 of -1, kept for :func:`one_ring_average` (which gives it back so)."""
        if self._local is None:
            self._local = np.full(self._u, -1, dtype=np.int64)
        return self._local

    def _widest_ring(self):
        """The most vertices in one one-ring (made once)."""
        if self._widest is None:
            self._widest = int(np.diff(self._ring.indptr).max(initial=0))
        return self._widest

    def _island(self, island, keep, held_rows):
        """The associations of the rows ``island`` (sorted welded ids) of a layout (see
        :meth:`layout_associations`), from the kept islands or made and kept (the last
        :data:`KEPT_ISLANDS`)."""
        chosen = np.zeros(self._u, dtype=bool)
        chosen[island] = True
        region = np.flatnonzero(self._within(chosen, self.steps))
        held = region[keep[region]]
        digest = hashlib.blake2b(island.tobytes(), digest_size=20)
        digest.update(held.tobytes())
        if held_rows is not None:
            rows = sp.csr_matrix(held_rows[held])
            for array in (np.diff(rows.indptr), rows.indices, rows.data):
                digest.update(b"|" + np.ascontiguousarray(array).tobytes())
        key = digest.digest()
        if key in self._islands:
            self._islands.move_to_end(key)
            return self._islands[key]
        local = self._associations(region, self._diffused(region, keep[region], held_rows))
        inside = chosen[local[0]]
        made = tuple(part[inside] for part in local)
        self._islands[key] = made
        while len(self._islands) > KEPT_ISLANDS:
            self._islands.popitem(last=False)
        return made

    def skin(self, keep=None, held_rows=None, progress=None):
        """The diffused :class:`.skin.Skin` with the ``keep`` (u,) rows held (None: none), at their
        own weights or, where ``held_rows`` (u, k) CSR has a non-empty row, at that row (a vertex
        held by a handle whose proxy corners are not all held is bound to faces that are);
        ``progress(fraction)`` as the free diffusion goes."""
        if self.steps <= 0 and held_rows is None:
            return self._skin
        parts = self._free_associations(progress)
        if keep is not None and keep.any():
            affected = self._within(keep, max(self.steps, 1))
            region = np.flatnonzero(self._within(affected, self.steps))
            local = self._associations(region, self._diffused(region, keep[region], held_rows))
            parts = _merged_rows(parts, ~affected[parts[0]], local, affected[local[0]], self._u)
        vertex, face, weight, bary, height = parts
        return Skin(vertex=vertex, face=face, bary=bary, height=height, weight=weight, case=self._skin.case)

    def reach(self, vertices):
        """(u,) bool of the welded ``vertices`` (s,) and (r,) int64 sorted ids of the vertices within
        ``steps`` rings of them: what their rows in :meth:`skin_of` read."""
        chosen = np.zeros(self._u, dtype=bool)
        chosen[vertices] = True
        return chosen, np.flatnonzero(self._within(chosen, self.steps))

    def skin_of(self, vertices, keep=None, reach=None):
        """The associations of :meth:`skin` (``keep`` (u,) bool, no held rows) of the welded
        ``vertices`` (s,) only, the other vertices without any: the same rows bit for bit, made
        from the sub-mesh within ``steps`` rings of them (a row after that many steps reads only
        rows that near), so a handle's drop rows cost its neighbourhood, not the mesh.
        ``reach``: :meth:`reach` of ``vertices``, if the caller has it."""
        if self.steps <= 0:
            return self._skin
        chosen, region = self.reach(vertices) if reach is None else reach
        held = np.zeros(region.size, dtype=bool) if keep is None else keep[region]
        parts = self._associations(region, self._diffused(region, held))
        inside = chosen[parts[0]]
        vertex, face, weight, bary, height = [a[inside] for a in parts]
        return Skin(vertex=vertex, face=face, bary=bary, height=height, weight=weight, case=self._skin.case)


def _rows_differ(first, second):
    """(u,) bool: the rows of the (u, k) CSR matrices ``first`` and ``second`` that differ in
    their entries' count, columns or values (bit for bit, in stored order)."""
    count_first, count_second = np.diff(first.indptr), np.diff(second.indptr)
    differ = count_first != count_second
    same = np.flatnonzero(~differ & (count_first > 0))
    if same.size:
        positions_first = flat_ranges(first.indptr[same], first.indptr[same + 1])[0]
        positions_second = flat_ranges(second.indptr[same], second.indptr[same + 1])[0]
        unequal = (first.indices[positions_first] != second.indices[positions_second]) | \
            (first.data[positions_first].view(np.int64) != second.data[positions_second].view(np.int64))
        differ[same] = np.add.reduceat(unequal, np.cumsum(count_first[same]) - count_first[same]) > 0
    return differ


def _merged_rows(first, first_used, second, second_used, u):
    """The associations (tuples of arrays, each grouped by vertex, ``[0]`` the vertex ids < ``u``)
    of ``first`` where ``first_used`` and of ``second`` where ``second_used`` (bool), grouped by
    vertex (no vertex has rows in both): what a stable sort of their concatenation by vertex
    gives, placed by counting instead of sorting."""
    first = [a[first_used] for a in first]
    second = [a[second_used] for a in second]
    counts_first = np.bincount(first[0], minlength=u)
    counts_second = np.bincount(second[0], minlength=u)
    start = np.zeros(u + 1, dtype=np.int64)
    np.cumsum(counts_first + counts_second, out=start[1:])
    merged = [np.empty((a.shape[0] + b.shape[0],) + a.shape[1:], dtype=a.dtype) for a, b in zip(first, second)]
    for part, counts in ((first, counts_first), (second, counts_second)):
        own_start = np.zeros(u + 1, dtype=np.int64)
        np.cumsum(counts, out=own_start[1:])
        vertex = part[0]
        where = start[vertex] + np.arange(vertex.shape[0]) - own_start[vertex]
        for out, array in zip(merged, part):
            out[where] = array
    return merged
