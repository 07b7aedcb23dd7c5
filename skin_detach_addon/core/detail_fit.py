"""The selected detail put exactly where its handles say, the difference blended into the free
detail around it.

Arrays: detail vertices (n,) and their welded ids (u,) (``surface.weld`` (n,) -> u); held
detail ids (h,); the band (b,) of free welded vertices the difference is blended into.

After a rebuild from a proxy whose border around a selection is free (:mod:`.held_detail`), the
selection misses its targets a little where it binds to free corners. :class:`DetailFit` sets
every held detail vertex on its target and moves the band by a harmonic blend of the
difference: the displacement f on the band minimises the Dirichlet energy sum over detail edges
(i, j) of |f_i - f_j|^2 with f = target - rebuilt on the held vertices and f = 0 beyond the band
(uniform edge weights on the welded detail graph). One sparse factorisation per layout of held
vertices (``scipy.sparse.linalg.splu`` of the band's SPD graph Laplacian), one back-substitution
per rebuild; exact up to the factorisation's rounding, no iteration. The band reaches about one
proxy edge (:data:`BAND_EDGES`) into the free detail, the distance the proxy itself bends over.
"""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import SkinDetachError
from .geometry import half_edge_graph
from .validation import as_vertex_ids

#: The band reaches this many mean proxy edge lengths into the free detail (in rings of the
#: detail's mean edge length), within [MIN_RINGS, MAX_RINGS] rings.
BAND_EDGES = 1.0
MIN_RINGS, MAX_RINGS = 2, 40


def band_rings(surface, rest):
    """Rings of the detail the band spans: :data:`BAND_EDGES` mean proxy edges over the detail's
    mean edge (``rest`` (n, 3) the detail at rest), clipped to [MIN_RINGS, MAX_RINGS]."""
    def mean_edge(points, triangles):
        edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
        return float(np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1).mean())
    ratio = mean_edge(surface.proxy_vertices, surface.proxy_faces) / max(mean_edge(rest, surface.triangles), 1e-300)
    return int(np.clip(round(BAND_EDGES * ratio), MIN_RINGS, MAX_RINGS))


class DetailFit:
    """Puts held detail vertices on their targets after a rebuild and blends the difference into
    the free detail around them (see the module). ``surface``: a SkinDetachedSurface with its
    topology attached, ``rest`` (n, 3) its detail at rest; ``ids`` (h,) the held detail vertex
    ids (a layout: one fit per layout); ``rings``: the band's reach (default :func:`band_rings`)."""

    def __init__(self, surface, rest, ids, rings=None):
        if surface.triangles is None:
            raise SkinDetachError("surface: expected the detail triangles attached (attach_topology), got none")
        self.ids = np.unique(as_vertex_ids("ids", ids, surface.n_detail))
        weld = surface.weld
        u = int(weld.max()) + 1 if weld.size else 0
        graph = half_edge_graph(weld[surface.triangles], u)
        adjacency = sp.csr_matrix(graph + graph.T, dtype=np.float64)
        adjacency.data[:] = 1.0
        adjacency.setdiag(0.0)
        adjacency.eliminate_zeros()
        held = np.zeros(u, dtype=bool)
        held[weld[self.ids]] = True
        self.rings = band_rings(surface, rest) if rings is None else int(rings)
        near = held.copy()
        for _ in range(self.rings):
            near |= (adjacency @ near.astype(np.float64)) > 0
        band = np.flatnonzero(near & ~held)
        #: welded representative of each held welded vertex, the band (welded ids), the band of
        #: every detail vertex (n,) -> its row in the band or -1
        self._held = np.flatnonzero(held)
        self._rep = np.empty(u, dtype=np.int64)
        self._rep[weld[self.ids]] = self.ids
        self._band = band
        self._row = np.full(u, -1, dtype=np.int64)
        self._row[band] = np.arange(band.size)
        self._detail_band = np.flatnonzero(self._row[weld] >= 0)
        self._detail_rows = self._row[weld[self._detail_band]]
        self._coupling = sp.csr_matrix(adjacency[band][:, self._held])
        if band.size:
            degree = np.asarray(adjacency[band].sum(axis=1)).ravel()
            laplacian = sp.csc_matrix(sp.diags(degree) - adjacency[band][:, band])
            self._factor = spla.splu(laplacian, permc_spec="MMD_AT_PLUS_A")
        else:
            self._factor = None

    @property
    def band_size(self):
        """Free welded detail vertices the difference is blended into."""
        return int(self._band.size)

    def apply(self, detail, targets):
        """Put ``detail`` (n, 3) float32 or float64, in place) on ``targets`` (h, 3), one row per
        held id in ``self.ids`` order, and move the band by the harmonic blend of the
        difference; returns ``detail``."""
        targets = np.asarray(targets, dtype=np.float64)
        if targets.shape != (self.ids.size, 3):
            raise SkinDetachError(f"targets: expected ({self.ids.size}, 3), got {targets.shape}")
        if self._factor is not None:
            reps = self._rep[self._held]
            position = np.searchsorted(self.ids, reps)
            difference = targets[position] - detail[reps]
            blend = self._factor.solve(np.asarray(self._coupling @ difference))
            detail[self._detail_band] += blend[self._detail_rows].astype(detail.dtype, copy=False)
        detail[self.ids] = targets
        return detail
