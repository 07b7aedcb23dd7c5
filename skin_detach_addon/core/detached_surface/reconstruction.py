"""The rebuild of the detail mesh from a deformed proxy (paper eq. 10/11) as one sparse product.

Every association (detail vertex, proxy face f, barycentrics b, height h, weight w) gives the
candidate sum_c b_c P'_(f_c) + h N'_f: the drop point plus the deformed face's scaled normal
N'_f = c / sqrt(|c|) (c its cross product), which commutes with rigid motions and uniform scales,
so every candidate rebuilds its vertex exactly at rest and under both. With the weights of
the skin as :mod:`.seam_weights` diffuses them (smooth over the detail mesh: no crease where the
proxy bends) the rebuild is X = W [P'; N'] with W (n, m + k) fixed and sparse.
"""

import numpy as np
import scipy.sparse as sp

from ..errors import SkinDetachError
from ..geometry import face_cross, flat_ranges
from .. import threads
from ..threads import map_blocks


def scaled_normals(points, triangles):
    """(k, 3) face cross products divided by the square root of their length (zero if degenerate)."""
    cross = face_cross(points, triangles)
    length = np.sqrt(np.sqrt(np.einsum("ij,ij->i", cross, cross)))
    return cross / np.where(length > 0.0, length, 1.0)[:, None]


def rebuild_matrix(skin, proxy_triangles, n_proxy, weld):
    """(n, m + k) CSR matrix W of the rebuild; row i is detail vertex i (``weld`` (n,) maps it
    to its welded row of ``skin``), column j < m proxy vertex j, column m + f face f's scaled
    normal. Four entries per association of the rows asked for (the skin is grouped by vertex);
    associations of a vertex sharing a proxy corner are summed into one entry; int32 column
    indices."""
    start, stop = np.searchsorted(skin.vertex, weld), np.searchsorted(skin.vertex, weld, side="right")
    if weld.size and weld[-1] - weld[0] == weld.size - 1 and (np.diff(weld) == 1).all():
        rows = slice(start[0], stop[-1])  # consecutive welded rows: their associations in one run
    else:
        rows = flat_ranges(start, stop)[0]
    face, weight = skin.face[rows], skin.weight[rows]
    entries = np.empty((face.shape[0], 4), dtype=np.int32)
    entries[:, :3] = proxy_triangles[face]
    entries[:, 3] = n_proxy + face
    data = np.empty((face.shape[0], 4))
    data[:, :3] = skin.bary[rows] * weight[:, None]
    data[:, 3] = weight * skin.height[rows]
    # int32 row pointers where the entries allow: scipy would otherwise widen the indices to int64 (copies).
    indptr = np.zeros(weld.size + 1, dtype=np.int32 if 4 * face.shape[0] < 2**31 - 1 else np.int64)
    np.cumsum(4 * (stop - start), out=indptr[1:])
    shape = (weld.size, n_proxy + proxy_triangles.shape[0])
    matrix = sp.csr_matrix((data.ravel(), entries.ravel(), indptr), shape=shape, copy=False)
    matrix.sum_duplicates()
    if matrix.nnz < 2**31 - 1:  # scipy keeps int32 indices only when the row pointer is int32 too
        matrix.indptr = matrix.indptr.astype(np.int32, copy=False)
        matrix.indices = matrix.indices.astype(np.int32, copy=False)
    return matrix


#: Detail rows per block of a rebuild at most: blocks are made and multiplied side by side on
#: the core's threads, and making one block at a time bounds the scratch memory.
BLOCK_ROWS = 1 << 19


class Rebuild:
    """Holds W and rebuilds detail vertices from deformed proxy vertices.

    ``__call__(points (m, 3), out=None)`` returns (n, 3) float64; ``out`` may be a preallocated array,
    and a float32 ``out`` (what Blender stores) runs the product in float32 (half the memory
    traffic; rounding at the level of float32 storage itself).
    One single-vector product per coordinate runs about a third faster than one three-column
    product in scipy; large meshes split their rows into blocks over :data:`~..threads.WORKERS`
    threads.
    """

    def __init__(self, skin, weld, proxy_vertices, proxy_triangles):
        """W of the detail rows ``weld`` (n,) (their welded rows of the :class:`.skin.Skin`
        ``skin``; see :func:`rebuild_matrix`) over the proxy."""
        self.triangles = proxy_triangles
        self.n_detail = weld.shape[0]
        self.n_proxy = proxy_vertices.shape[0]
        self._stacked = np.empty((3, self.n_proxy + proxy_triangles.shape[0]))

        # Each block holds its rows sorted by their entry count: scipy's product loop mispredicts
        # a branch whenever the row length changes, which made the diffused skin's rows (4 to 16
        # entries, mixed) twice as slow per entry (measured at 300K: 2.35 ms against 1.04 ms for
        # one product sorted); the result goes back to the detail's order in one scatter.
        def block(rows):
            matrix = rebuild_matrix(skin, proxy_triangles, self.n_proxy, weld[rows[0]:rows[1]])
            order = np.argsort(np.diff(matrix.indptr), kind="stable")
            index = np.int32 if self.n_detail < 2**31 else np.int64  # the detail rows: half of int64's memory
            return (rows[0] + order).astype(index), sp.csr_matrix(matrix[order])

        self._blocks = map_blocks(block, threads.row_blocks(self.n_detail, most=BLOCK_ROWS))
        self.nnz = sum(rows.nnz for _, rows in self._blocks)
        self._blocks32 = None

    def float32_blocks(self):
        """The row blocks (pairs (order (r,), (r, m + k) CSR)) with a float32 copy of the values,
        the indices shared: what a float32 ``out`` multiplies (made on first use, or ahead by
        :meth:`.surface.SkinDetachedSurface.prepare_layout`)."""
        if self._blocks32 is None:
            self._blocks32 = [(order, sp.csr_matrix((rows.data.astype(np.float32), rows.indices, rows.indptr),
                                                    shape=rows.shape, copy=False)) for order, rows in self._blocks]
        return self._blocks32

    @property
    def float32_ready(self):
        """Whether the float32 copy is made (:meth:`float32_blocks`)."""
        return self._blocks32 is not None

    def _rebuild_rows(self, block, stacked, out):
        order, rows = block
        part = np.empty((order.size, 3), dtype=out.dtype)
        for axis in range(3):
            part[:, axis] = rows @ stacked[axis]
        out[order] = part

    def __call__(self, points, out=None):
        stacked = self._stacked
        stacked[:, :self.n_proxy] = points.T
        stacked[:, self.n_proxy:] = scaled_normals(points, self.triangles).T
        # W is finite (checked where it is loaded), so finite inputs give a finite result: checking
        # the m + k inputs here spares a pass over all n outputs on every drag move.
        if not np.isfinite(stacked).all():
            raise SkinDetachError("proxy_vertices: expected positions whose rebuild frames are finite, got NaN or inf "
                                  "(degenerate or absurd proxy); nothing was rebuilt")
        if out is None:
            out = np.empty((self.n_detail, 3))
        blocks = self._blocks
        if out.dtype == np.float32:
            blocks, stacked = self.float32_blocks(), stacked.astype(np.float32)
        map_blocks(lambda block: self._rebuild_rows(block, stacked, out), blocks)
        return out


class LayoutRebuild:
    """The rebuild of one layout of held vertices: the free rebuild (every detail row, the free
    diffusion's; one for all layouts) with the rows the layout changes rebuilt by its own matrices.

    free_of :class:`Rebuild` of the n detail rows, from ``free_of()`` (waiting for it while a
            background job makes it); ``free_of(wait=False)`` gives None until it is made
    rows    (r,) int64 sorted detail rows the layout changes that no group holds (within the
            diffusion's reach of a held vertex)
    own     :class:`Rebuild` of those r rows
    held    (h,) int64 sorted detail rows the layout's groups hold (their selections)
    held_rebuild  a callable giving (rows (h',) of ``held`` the layout changes, their
            :class:`Rebuild`), called once, when a rebuild is asked for without ``place``

    ``__call__(points (m, 3), out=None, place=None)`` returns (n, 3) as :class:`Rebuild` does;
    the rows the layout changes are those its own matrices give, the others the free rebuild's,
    bit for bit. ``place``, a callable writing the held rows into ``out`` (a caller that puts them
    where their handles' motions say), replaces the held rows' product. Preparing a layout makes
    only ``own``: its cost follows the border of the held vertices, not the mesh nor the selections.
    """

    def __init__(self, free_of, rows, own, held, held_rebuild):
        self._free_of = free_of
        self.rows, self.own = rows, own
        self.held = held
        self._held_rebuild = held_rebuild
        self._own_held = None

    @property
    def free(self):
        """The free :class:`Rebuild` (waits while a background job makes it)."""
        return self._free_of()

    @property
    def nnz(self):
        """Entries of the matrices made so far."""
        free = self._free_of(wait=False)
        return (0 if free is None else free.nnz) + self.own.nnz + (0 if self._own_held is None else self._own_held[1].nnz)

    def float32_blocks(self):
        """The float32 copies (see :meth:`Rebuild.float32_blocks`) of the layout's own rows and of
        the free rebuild once it is made (a background job makes its own; the held rows' once they
        were asked for)."""
        free = self._free_of(wait=False)
        return (None if free is None else free.float32_blocks()), self.own.float32_blocks()

    @property
    def float32_ready(self):
        """Whether every float32 copy made so far is made."""
        free = self._free_of(wait=False)
        return (free is None or free.float32_ready) and self.own.float32_ready

    def __call__(self, points, out=None, place=None):
        out = self.free(points, out=out)
        if self.rows.size:
            out[self.rows] = self.own(points, out=np.empty((self.rows.size, 3), dtype=out.dtype))
        if place is not None:
            place(out)
        elif self.held.size:
            if self._own_held is None:
                self._own_held = self._held_rebuild()
            rows, own_held = self._own_held
            if rows.size:
                out[rows] = own_held(points, out=np.empty((rows.size, 3), dtype=out.dtype))
        return out
