"""How much the detail stretches against its rest, per vertex: what a tension map shows.

Arrays: proxy vertices (m,), proxy faces (k, 3), detail vertices (n,) welded to (u,)
(``surface.weld``), a deformed proxy ``points`` (m, 3).

The rebuild carries each detail vertex with the proxy faces it is bound to, so the detail
stretches as those faces do. The stretch of proxy face f is the mean over its three edges of
| |e'| / |e| - 1 |, the relative change of the edge's length (0 at rest, under a rigid motion and
within a face the solve only turned; 1.0 where the face's edges doubled or collapsed on
average); the stretch of detail vertex i is the mean of its faces' stretch under the skin's
rest-area weights (a partition of unity: 0 at rest). One product of an (n, k) sparse matrix with
seven or so entries a row, so it costs a small part of a rebuild (a per-edge measure of the
detail itself gathers twice the detail per edge and cost a 300K rebuild's time again).

Proxy points are measured as the proxy mesh stores them (rounded to float32): the stretch of a
solve's float64 proxy and of the proxy mesh it was written to are the same bits, so the figures
computed when the stretch is first shown (from the proxy mesh) and those a step writes agree,
and both are exactly 0 at rest.
"""

import numpy as np
import scipy.sparse as sp

from .. import threads
from ..validation import as_points


class SkinStretch:
    """The per-vertex stretch of one bound detail mesh (see the module). ``surface``: a
    SkinDetachedSurface; calling it with the deformed proxy ``points`` (m, 3) returns the (n,)
    float32 stretch of the detail."""

    def __init__(self, surface):
        faces = surface.proxy_faces
        rest = surface.proxy_vertices
        self.m = rest.shape[0]
        self._faces = np.asarray(faces, dtype=np.int64)
        self._rest = self._lengths(_as_stored(rest))
        self._inverse = np.divide(1.0, self._rest, out=np.zeros_like(self._rest), where=self._rest > 0)
        skin = surface.skin
        u = skin.case.shape[0]
        # The skin is grouped by vertex: its rows make the welded matrix as they stand (no sort).
        counts = np.bincount(skin.vertex, minlength=u)
        index = np.int32 if skin.vertex.size < 2**31 - 1 else np.int64
        indptr = np.zeros(u + 1, dtype=index)
        np.cumsum(counts, out=indptr[1:])
        welded = sp.csr_matrix((skin.weight.astype(np.float32), skin.face.astype(index), indptr),
                               shape=(u, faces.shape[0]))
        weld = surface.weld
        identity = weld.shape[0] == u and bool((weld == np.arange(u)).all())
        weights = welded if identity else sp.csr_matrix(welded[weld])
        # Row blocks multiplied side by side on the core's threads (a confirm at 10M shows it).
        self._blocks = [weights[a:b] for a, b in threads.row_blocks(weights.shape[0])]

    def face_stretch(self, points):
        """(k,) the stretch of every proxy face at ``points`` (m, 3)."""
        change = np.abs(self._lengths(_as_stored(as_points("points", points, self.m))) - self._rest) * self._inverse
        return change.mean(axis=1)  # exactly 0 at rest: the same lengths, computed the same way

    def _lengths(self, points):
        """(k, 3) the lengths of every face's edges (corner j to corner j + 1)."""
        return np.linalg.norm(points[self._faces] - points[np.roll(self._faces, -1, axis=1)], axis=2)

    def __call__(self, points):
        faces = self.face_stretch(points).astype(np.float32)
        return np.concatenate(threads.map_blocks(lambda block: np.asarray(block @ faces, dtype=np.float32),
                                                 self._blocks))


def _as_stored(points):
    """(m, 3) float64 ``points`` rounded to float32, as a Blender mesh stores them."""
    return np.asarray(points, dtype=np.float32).astype(np.float64)
