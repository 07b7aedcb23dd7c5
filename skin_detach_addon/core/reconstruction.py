"""The rebuild of the detail mesh from a deformed proxy (paper eq. 10/11) as one sparse product.

With rest-area weights every detail vertex is a fixed linear combination of proxy vertices
and per-face scaled normals: X = W [P'; N'] with W (n, m + k) sparse, P' (m, 3) the deformed
proxy and N' (k, 3) its face normals scaled by sqrt(|cross|) (see :mod:`.skin`).
"""

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp

from .geometry import face_cross


def scaled_normals(points, triangles):
    """(k, 3) face cross products divided by the square root of their length (zero if degenerate)."""
    cross = face_cross(points, triangles)
    length = np.sqrt(np.sqrt(np.einsum("ij,ij->i", cross, cross)))
    return cross / np.where(length > 0.0, length, 1.0)[:, None]


def rebuild_matrix(skin, proxy_triangles, n_proxy, weld):
    """(n, m + k) CSR matrix W of the rebuild; row i is detail vertex i (``weld`` (n,) maps it
    to its welded row of ``skin``)."""
    k = proxy_triangles.shape[0]
    u = skin.case.shape[0]
    corners = proxy_triangles[skin.face]
    rows = np.concatenate([np.repeat(skin.vertex, 3), skin.vertex])
    cols = np.concatenate([corners.ravel(), n_proxy + skin.face])
    data = np.concatenate([(skin.bary * skin.weight[:, None]).ravel(), skin.height * skin.weight])
    welded = sp.csr_matrix((data, (rows, cols)), shape=(u, n_proxy + k))
    welded.sum_duplicates()
    matrix = welded if weld.size == u and np.array_equal(weld, np.arange(u)) else welded[weld]
    matrix = sp.csr_matrix(matrix)
    matrix.sort_indices()
    matrix.indptr = matrix.indptr.astype(np.int32)
    matrix.indices = matrix.indices.astype(np.int32)
    return matrix


#: Row blocks rebuilt in parallel (scipy's sparse product releases the GIL) for meshes of at
#: least PARALLEL_MIN_ROWS vertices.
PARALLEL_BLOCKS = max(1, min(4, os.cpu_count() or 1))
PARALLEL_MIN_ROWS = 100_000
_POOL = None


def _pool():
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=PARALLEL_BLOCKS, thread_name_prefix="skin_detach_rebuild")
    return _POOL


class Rebuild:
    """Holds W and rebuilds detail vertices from deformed proxy vertices.

    ``__call__(points (m, 3))`` returns (n, 3) float64; ``out`` may be a preallocated array,
    and a float32 ``out`` (what Blender stores) runs the product in float32 (half the memory
    traffic; rounding at the level of float32 storage itself).
    One single-vector product per coordinate runs about a third faster than one three-column
    product in scipy; large meshes split their rows over :data:`PARALLEL_BLOCKS` threads.
    """

    def __init__(self, matrix, proxy_triangles):
        self.triangles = proxy_triangles
        self.n_detail = matrix.shape[0]
        self.nnz = matrix.nnz
        self.n_proxy = matrix.shape[1] - proxy_triangles.shape[0]
        self._stacked = np.empty((3, matrix.shape[1]))
        blocks = PARALLEL_BLOCKS if self.n_detail >= PARALLEL_MIN_ROWS else 1
        bounds = np.linspace(0, self.n_detail, blocks + 1).astype(int)
        # Only the row blocks are kept (one block is the matrix itself), never the matrix twice;
        # their float32 copies are made on first float32 use.
        self._blocks = [(0, self.n_detail, matrix)] if blocks == 1 else \
            [(a, b, matrix[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
        self._blocks32 = None

    def _rebuild_rows(self, block, stacked, out):
        start, stop, rows = block
        for axis in range(3):
            out[start:stop, axis] = rows @ stacked[axis]

    def __call__(self, points, out=None):
        stacked = self._stacked
        stacked[:, :self.n_proxy] = points.T
        stacked[:, self.n_proxy:] = scaled_normals(points, self.triangles).T
        if out is None:
            out = np.empty((self.n_detail, 3))
        blocks = self._blocks
        if out.dtype == np.float32:
            if self._blocks32 is None:
                self._blocks32 = [(a, b, rows.astype(np.float32)) for a, b, rows in self._blocks]
            blocks, stacked = self._blocks32, stacked.astype(np.float32)
        if len(blocks) == 1:
            self._rebuild_rows(blocks[0], stacked, out)
        else:
            for done in [_pool().submit(self._rebuild_rows, block, stacked, out) for block in blocks]:
                done.result()
        return out
