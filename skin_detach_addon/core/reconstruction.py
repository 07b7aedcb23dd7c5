"""The rebuild of the detail mesh from a deformed proxy (paper eq. 10/11) as one sparse product,
with offsets carried by a frame field that is continuous across proxy edges.

Every association (detail vertex, proxy face f, barycentrics b, height h) gives the candidate
sum_c b_c P'_(f_c) + h sum_c b_c V'_(f, c): the drop point, plus the face's rest scaled normal
N0_f = cross / sqrt(|cross|) turned and scaled by the similarity s_j R_j of each corner vertex
j = f_c, blended by the same barycentrics (V'_(f, c) = s_j R_j N0_f). R_j and s_j are the best
rotation and scale of vertex j's one-ring (cotangent-weighted rest spokes onto deformed ones),
so neighbouring faces share them and the detail has no seam where the proxy bends. At rest
V' = N0 (the rebuild is exact), under a rigid motion or a uniform scale V' is the deformed
face's own scaled normal (both are reproduced exactly). With rest-area weights the rebuild is
X = W [P'; V'] with W (n, m + 3k) fixed and sparse (row-block 3f + c of V' is corner c of face f).
"""

import numpy as np
import scipy.sparse as sp

from .errors import SkinDetachError
from .geometry import cotangent_weights, face_cross, flat_ranges, unique_edges
from .rotations import WarmRotations
from .threads import WORKERS, map_blocks


def scaled_normals(points, triangles):
    """(k, 3) face cross products divided by the square root of their length (zero if degenerate)."""
    cross = face_cross(points, triangles)
    length = np.sqrt(np.sqrt(np.einsum("ij,ij->i", cross, cross)))
    return cross / np.where(length > 0.0, length, 1.0)[:, None]


class VertexSimilarities:
    """Best similarity (scale s_j, rotation R_j) of every proxy vertex's one-ring, rest -> deformed.

    rest (m, 3), triangles (k, 3). ``__call__(points (m, 3), groups=None)`` returns scales (m,)
    and rotations (m, 3, 3) minimising sum_(j,u) c_ju |(x_u - x_j) - s_j R_j (x0_u - x0_j)|^2 over
    each one-ring (c: cotangent weights clamped positive); a vertex with no spoke keeps (1, I).
    ``groups`` (m,) int labels rigid groups (a handle's vertices, moved by one rigid motion;
    -1: none): a grouped vertex fits only its spokes into its own group (when it has any), so
    its similarity is that group's motion exactly.
    """

    def __init__(self, rest, triangles):
        m = rest.shape[0]
        edges = unique_edges(triangles)[0]
        self._tail = np.concatenate([edges[:, 0], edges[:, 1]])
        self._head = np.concatenate([edges[:, 1], edges[:, 0]])
        self._spokes = rest[self._head] - rest[self._tail]
        self._weight = np.tile(cotangent_weights(rest, triangles, edges), 2)
        self._m = m
        self._cache = {}
        self._rotations = WarmRotations()

    def _operators(self, groups):
        """(moments M_0..2 (m, m), rest norms (m,), lonely (m,)) for ``groups`` (None: all spokes)."""
        key = None if groups is None else groups.tobytes()
        if key not in self._cache:
            if len(self._cache) >= 8:
                self._cache.pop(next(iter(self._cache)))
            weight = self._weight
            if groups is not None:
                grouped = groups[self._tail] >= 0
                inside = grouped & (groups[self._head] == groups[self._tail])
                has_inside = np.bincount(self._tail[inside], minlength=self._m) > 0
                weight = np.where(grouped & has_inside[self._tail] & ~inside, 0.0, weight)
            n, tail, head = self._tail.size, self._tail, self._head
            difference = sp.csr_matrix((np.r_[weight, -weight], (np.r_[np.arange(n), np.arange(n)], np.r_[head, tail])),
                                       shape=(n, self._m))
            group = sp.csr_matrix((np.ones(n), (tail, np.arange(n))), shape=(self._m, n))
            # Covariance column j: M_j X with M_j = G diag(rest spoke coordinate j) (weighted differences).
            moments = [sp.csr_matrix(group @ sp.diags(self._spokes[:, j]) @ difference) for j in range(3)]
            norm = np.asarray(group @ (weight * np.einsum("ij,ij->i", self._spokes, self._spokes))).ravel()
            self._cache[key] = (moments, norm, norm <= 0.0)
        return self._cache[key]

    def reset(self):
        """Start the next fit cold (see :meth:`.rotations.WarmRotations.reset`)."""
        self._rotations.reset()

    def __call__(self, points, groups=None):
        moments, norm, lonely = self._operators(groups)
        covariance = np.stack([matrix @ points for matrix in moments], axis=2)
        rotations = self._rotations(covariance)
        trace = np.einsum("nij,nij->n", rotations, covariance)
        scales = np.where(lonely, 1.0, trace / np.where(lonely, 1.0, norm))
        rotations[lonely] = np.eye(3)
        return scales, rotations


def rebuild_matrix(skin, proxy_triangles, n_proxy, weld):
    """(n, m + 3k) CSR matrix W of the rebuild; row i is detail vertex i (``weld`` (n,) maps it
    to its welded row of ``skin``); column m + 3f + c is corner c of face f's frame vector.
    Built row by row from the associations (grouped by vertex already): six entries each, int32
    column indices, no sort; two associations of a vertex sharing a proxy corner leave two
    entries in that column, which every product sums."""
    u = skin.case.shape[0]
    entries = np.empty((skin.vertex.shape[0], 6), dtype=np.int32)
    entries[:, :3] = proxy_triangles[skin.face]
    entries[:, 3:] = n_proxy + 3 * skin.face[:, None] + np.arange(3)
    blend = skin.bary * skin.weight[:, None]
    data = np.empty((skin.vertex.shape[0], 6))
    data[:, :3] = blend
    data[:, 3:] = blend * skin.height[:, None]
    indptr = np.zeros(u + 1, dtype=np.int64)
    np.cumsum(6 * np.bincount(skin.vertex, minlength=u), out=indptr[1:])
    indices, data = entries.ravel(), data.ravel()
    if not (weld.size == u and np.array_equal(weld, np.arange(u))):
        positions, _ = flat_ranges(indptr[weld], indptr[weld + 1])
        indices, data = indices[positions], data[positions]
        indptr = np.zeros(weld.size + 1, dtype=np.int64)
        np.cumsum(6 * np.bincount(skin.vertex, minlength=u)[weld], out=indptr[1:])
    shape = (weld.size, n_proxy + 3 * proxy_triangles.shape[0])
    if data.size < 2**31 - 1:  # scipy keeps int32 indices only when the row pointer is int32 too
        indptr = indptr.astype(np.int32)
    else:
        indices = indices.astype(np.int64)
    return sp.csr_matrix((data, indices, indptr), shape=shape, copy=False)


#: Row blocks rebuilt in parallel (scipy's sparse product releases the GIL) for meshes of at
#: least PARALLEL_MIN_ROWS vertices.
PARALLEL_MIN_ROWS = 100_000


class Rebuild:
    """Holds W and rebuilds detail vertices from deformed proxy vertices.

    ``__call__(points (m, 3), out=None, groups=None)`` returns (n, 3) float64 (``groups``: rigid
    groups of proxy vertices, see :class:`VertexSimilarities`); ``out`` may be a preallocated array,
    and a float32 ``out`` (what Blender stores) runs the product in float32 (half the memory
    traffic; rounding at the level of float32 storage itself).
    One single-vector product per coordinate runs about a third faster than one three-column
    product in scipy; large meshes split their rows over :data:`~.threads.WORKERS` threads.
    """

    def __init__(self, matrix, proxy_vertices, proxy_triangles):
        self.triangles = proxy_triangles
        self.n_detail = matrix.shape[0]
        self.nnz = matrix.nnz
        self.n_proxy = proxy_vertices.shape[0]
        self._rest_normals = scaled_normals(proxy_vertices, proxy_triangles)
        self._similarities = VertexSimilarities(proxy_vertices, proxy_triangles)
        self._stacked = np.empty((3, matrix.shape[1]))
        blocks = WORKERS if self.n_detail >= PARALLEL_MIN_ROWS else 1
        self._bounds = np.linspace(0, self.n_detail, blocks + 1).astype(int)
        # Row blocks are views of the matrix's arrays (never a copy); the float32 blocks share the
        # column indices and add only a float32 copy of the values, made on first float32 use.
        self._matrix = matrix
        self._blocks = self._views(matrix.data)
        self._blocks32 = None

    def _views(self, data):
        """[(first row, end row, CSR over those rows)] sharing ``data`` (nnz,) and W's indices."""
        indptr, indices, columns = self._matrix.indptr, self._matrix.indices, self._matrix.shape[1]
        out = []
        for a, b in zip(self._bounds[:-1], self._bounds[1:]):
            lo, hi = indptr[a], indptr[b]
            rows = sp.csr_matrix((data[lo:hi], indices[lo:hi], indptr[a:b + 1] - lo), shape=(b - a, columns),
                                 copy=False)
            out.append((a, b, rows))
        return out

    def frame_vectors(self, points, groups=None):
        """(3k, 3) V': row 3f + c is face f's rest scaled normal under corner c's similarity
        (``groups``: see :class:`VertexSimilarities`)."""
        scales, rotations = self._similarities(points, groups)
        #: The last rebuild's proxy vertex similarities (scales (m,), rotations (m, 3, 3)).
        self.similarities = (scales, rotations)
        corner = self.triangles.ravel()
        normals = np.repeat(self._rest_normals, 3, axis=0)
        turned = np.einsum("nij,nj->ni", rotations[corner], normals)
        return turned * scales[corner][:, None]

    def forget_warm_start(self):
        """The next rebuild fits its frames cold: bit for bit the same whatever came before."""
        self._similarities.reset()

    def _rebuild_rows(self, block, stacked, out):
        start, stop, rows = block
        for axis in range(3):
            out[start:stop, axis] = rows @ stacked[axis]

    def __call__(self, points, out=None, groups=None):
        stacked = self._stacked
        stacked[:, :self.n_proxy] = points.T
        stacked[:, self.n_proxy:] = self.frame_vectors(points, groups).T
        # W is finite (checked where it is loaded), so finite inputs give a finite result: checking
        # the m + 3k inputs here spares a pass over all n outputs on every drag move.
        if not np.isfinite(stacked).all():
            raise SkinDetachError("proxy_vertices: expected positions whose rebuild frames are finite, got NaN or inf "
                                  "(degenerate or absurd proxy); nothing was rebuilt")
        if out is None:
            out = np.empty((self.n_detail, 3))
        blocks = self._blocks
        if out.dtype == np.float32:
            if self._blocks32 is None:
                self._blocks32 = self._views(self._matrix.data.astype(np.float32))
            blocks, stacked = self._blocks32, stacked.astype(np.float32)
        map_blocks(lambda block: self._rebuild_rows(block, stacked, out), blocks)
        return out
