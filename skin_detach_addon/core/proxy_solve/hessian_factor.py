"""The energy's Hessian over the free vertices, assembled and factored: the preconditioner of the
Newton iteration.

Arrays: ``free`` (f,) the ids of the vertices that move; vectors over them are (f, 3), and the
matrix is (3f, 3f) in that layout, row 3 i + c for coordinate c of free vertex i.

    H = 2 (K kron I_3 - Q^T diag(w) Q),

K = B^T B, and row (g, k) of Q (3g, 3f) the map D -> <t_gk, C_g(D)> of twist k of group g, w its
weight 1 / (sigma_a + sigma_b) (:mod:`.rotated_energy`). On vertex v the row is t_gk mu_gv, mu_gv
(3,) the moment row of v in group g (column j of C_g is sum_v mu_gv[j] X_v), so Q's pattern is
fixed: it is found once and each assembly fills its data with one batched product.

A factor of H at one iterate preconditions the conjugate gradients of the next ones (a drag's
moves change H a little at a time). H is factored without pivoting (the order keeps symmetry), so
it is positive definite exactly when every pivot is positive; an indefinite H (past a fold) gives
no factor and the caller keeps K's. A drag makes it while the mouse rests (a settle slice), never
during a move (until then the factor at rest serves, turned by the vertices' rotations): made on
another thread beside the moves, its assembly held the GIL and the moves stalled by several
milliseconds at random.
"""

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu


#: A pivot below this fraction of the largest: H is singular to rounding (a rotation the
#: constraints leave free, e.g. about a single held vertex), not positive definite.
SINGULAR = 1e-12


class Factored:
    """H^-1 at one iterate: :meth:`solve` of (f, 3) arrays."""

    def __init__(self, lu, size):
        self._lu, self._size = lu, size

    def solve(self, values):
        """H^-1 ``values`` (f, 3) -> (f, 3)."""
        return self._lu.solve(np.ascontiguousarray(values).reshape(self._size)).reshape(values.shape)


class HessianFactor:
    """H (module docstring) of ``energy`` (a :class:`.rotated_energy.RotatedEnergy`) over ``free``
    (f,) of its m vertices."""

    def __init__(self, energy, free, m):
        free = np.asarray(free)
        f = free.size
        position = np.full(m, -1)
        position[free] = np.arange(f)
        # (group, vertex) moment rows: the union of the three moment matrices' patterns, free
        # vertices only (held ones are no unknowns).
        moments = energy.moments_coo()
        g = energy.n_groups
        column, group = moments.row % 3, moments.row // 3
        keys, inverse = np.unique(group * m + moments.col, return_inverse=True)
        mu = np.zeros((keys.size, 3))
        np.add.at(mu, (inverse, column), moments.data)
        vertex = position[keys % m]
        moving = vertex >= 0
        self._group, self._mu, vertex = keys[moving] // m, mu[moving], vertex[moving]
        # Entry (n, k, c) of the batched product is Q[3 group_n + k, 3 vertex_n + c].
        three = np.arange(3)
        rows = np.broadcast_to((3 * self._group)[:, None, None] + three[None, :, None], (vertex.size, 3, 3)).ravel()
        cols = np.broadcast_to((3 * vertex)[:, None, None] + three[None, None, :], (vertex.size, 3, 3)).ravel()
        self._order = np.lexsort((cols, rows))
        self._rows = rows[self._order]
        self._q_pattern = (cols[self._order].astype(np.int32),
                           np.searchsorted(self._rows, np.arange(3 * g + 1)).astype(np.int32))
        self._q_shape = (3 * g, 3 * f)
        self._gram = sp.kron(energy.gram[free][:, free], sp.identity(3), format="csc")
        self.size = 3 * f

    def matrix(self, state):
        """(3f, 3f) CSC H at ``state`` (an EnergyState of the energy)."""
        twists = state.twists.reshape(-1, 3, 3, 3)[self._group]  # [n, k, j, c]: entry (c, j) of t_k
        q = np.einsum("nkjc,nj->nkc", twists, self._mu).ravel()[self._order]
        q_matrix = sp.csr_matrix((q, *self._q_pattern), shape=self._q_shape)
        weighted = sp.csr_matrix((q * state.weights.ravel()[self._rows], *self._q_pattern), shape=self._q_shape)
        return (2.0 * (self._gram - (q_matrix.T @ weighted))).tocsc()

    def factor(self, state):
        """:class:`Factored` H at ``state``, or None when H is not positive definite."""
        if not self.size:
            return None
        try:
            lu = splu(self.matrix(state), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
        except RuntimeError:  # exactly singular
            return None
        pivots = lu.U.diagonal()
        if not (np.all(np.isfinite(pivots)) and pivots.min() > SINGULAR * pivots.max()):
            return None
        return Factored(lu, self.size)


class LaggedHessian:
    """The factored H that preconditions a solve made at another iterate (a drag's moves): H at
    rest from the start, then the newest one a settle makes (:meth:`refresh`); :meth:`reset` goes
    back to the rest one.

    Its solve is turned by how far each free vertex has rotated since the factor was made
    (stiffness warping): ``rotations(state)`` gives (f, 3, 3) the best rotation R_v of every free
    vertex's spokes at a state; with W = diag(R_v(now) R_v(made)^T) the preconditioner is
    P^-1 = W H_made^-1 W^T. Where the proxy has turned as a whole, H(now) = W H_made W^T exactly (E
    is invariant under rotations), so a drag that turns a limb keeps a factor that knows which way
    the limb bends; an unturned H from rest stiffens the bend's directions and every move's
    conjugate gradients lag behind. ``rotations`` None: no turning."""

    def __init__(self, hessian, rest_state, rotations=None):
        self._hessian = hessian
        self._rotations = rotations
        self._rest = self._made(rest_state)
        self._held = self._rest
        #: The most CG steps a Newton step preconditioned by the held factor needed (since it was made).
        self.steps = 0

    def _made(self, state):
        """(Factored, the free vertices' rotations at ``state`` or None), or None when H is not
        positive definite at ``state``."""
        factored = self._hessian.factor(state)
        if factored is None:
            return None
        return factored, None if self._rotations is None else self._rotations(state)

    @property
    def at_rest(self):
        """Whether the held factor is the one made at rest."""
        return self._held is self._rest

    def reset(self):
        """Go back to the factor made at rest (the next solve starts as a fresh object's would)."""
        self._held = self._rest
        self.steps = 0

    def solver(self, state):
        """The held factor's solve ((f, 3) -> (f, 3)) turned to ``state`` (an EnergyState), or None
        while there is no factor."""
        if self._held is None:
            return None
        factored, made = self._held
        if made is None:
            return factored.solve
        turn = np.einsum("vij,vkj->vik", self._rotations(state), made)  # R_v(now) R_v(made)^T

        def solve(values):
            return np.einsum("vij,vj->vi", turn, factored.solve(np.einsum("vji,vj->vi", turn, values)))
        return solve

    def refresh(self, state):
        """Factor H at ``state`` (an EnergyState) and hold it, unless it is not positive definite;
        either way :attr:`steps` starts again from 0, so the next try waits for a Newton step that
        needs many CG steps with the factor held (at a saddle, where H is indefinite, every settle
        slice of a drag tried again at its start and spent 30 of its 32 units on a factor it could
        not make: the multi-part ogre settled in 7 slices). Returns whether a factor was made."""
        made = self._made(state)
        self.steps = 0
        if made is not None:
            self._held = made
        return made is not None
