"""The proxy's energy with the selected detail pulled towards where its handles put it.

Arrays: ``points`` (m, 3) indexed by proxy vertex; pull h has a matrix M_h (s_h, m) whose row r
gives the drop point of one selected detail vertex (the proxy-vertex part of its rebuild row:
sum over its associations of weight x barycentric on the proxy corners), and a motion A_h, b_h
(the handle's rigid motion, a (4, 4) matrix; the identity for an anchor).

    E_pull(X) = E(X) + mu sum_h |M_h X - (M_h X0) A_h^T - 1 b_h^T|^2

E is :class:`.rotated_energy.RotatedEnergy`. The pull asks the drop points of every selected
detail vertex to move with its handle; where the handle holds the proxy corners they bind to it
costs nothing (they move with it exactly), so it acts on the selection's border, whose proxy
corners are otherwise free: the proxy bends there only as much as the selection needs. Drop
points that follow a similarity carry their face frames along too, so the rebuilt detail does.

Every rebuild row's proxy coefficients sum to 1 (weights and barycentrics do), so the targets are
M_h Y_h with Y_h = X0 A_h^T + 1 b_h^T, the rest proxy moved by the handle, and the pull is
(X - Y_h) . G_h (X - Y_h) with G_h = M_h^T M_h (m, m): summed from differences (no cancellation
near rest), and a solve never touches the s_h rows again.
mu is :data:`STRENGTH` times the mean diagonal of K = B^T B over the proxy vertices the pulls
reach, divided by that of sum_h G_h: the same pull on a finer or coarser proxy. E_pull is zero at
rest, invariant under a rigid motion of every handle and anchor together, and scales with the
square of a uniform scale, like E.
"""

import threading
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp

from ..errors import SkinDetachError

#: The pull's weight against the energy's own (see the module): lower bends the proxy more
#: freely, higher leaves less difference for the skin's diffusion to blend in around the held
#: detail. Bend scenario, six meshes (docs/benchmarks.md): 1 / 3 gave edge distortion 0.068 /
#: 0.073 on the armadillo, 0.046 / 0.050 on homer, and 1,324 / 962 creases in all (full-resolution
#: ARAP 1,529; 1,273 holding every corner).
STRENGTH = 1.0


#: Pulls whose gram parts a :class:`PullParts` keeps: a rig of a few dozen handles, its last
#: layouts' pulls shared.
KEPT_PULLS = 256


class PullParts:
    """The parts of :class:`PulledEnergy` each pull's matrix M_h (s_h, m) alone gives: G_h =
    M_h^T M_h (m, m) CSR, its support (the proxy vertices it reaches, (t,) sorted) and G_h over
    them (t, t), kept for the last :data:`KEPT_PULLS` matrices by identity (each kept with them, so
    no other matrix takes its id): a layout that adds a handle makes the new pulls' parts, not
    every handle's again (the drop rows of a selection the change does not reach are the very
    same matrix, :meth:`..detached_surface.surface.SkinDetachedSurface.drop_rows`)."""

    def __init__(self):
        self._kept = OrderedDict()
        self._lock = threading.Lock()

    def of(self, matrix):
        """(G_h, support, G_h over its support) of ``matrix`` (s_h, m) sparse."""
        with self._lock:
            kept = self._kept.get(id(matrix))
            if kept is not None and kept[0] is matrix:
                self._kept.move_to_end(id(matrix))
                return kept[1]
        parts = _pull_parts(matrix)
        with self._lock:
            self._kept[id(matrix)] = (matrix, parts)
            while len(self._kept) > KEPT_PULLS:
                self._kept.popitem(last=False)
        return parts


def _pull_parts(matrix):
    """(G_h (m, m) CSR, support (t,) sorted proxy ids, G_h over the support (t, t) CSR) of one
    pull's ``matrix`` (s_h, m) sparse."""
    matrix = sp.csr_matrix(matrix)
    gram = sp.csr_matrix(matrix.T @ matrix)
    support = np.unique(gram.indices)
    return gram, support, gram[support][:, support]


class PulledEnergy:
    """E_pull (module docstring) around ``energy`` (a RotatedEnergy over ``rest`` (m, 3)) with the
    pulls ``matrices`` (list of (s_h, m) sparse); the same interface as RotatedEnergy, plus
    :meth:`set_motions`. ``parts``: a :class:`PullParts` that keeps each matrix's own parts
    (None: made here)."""

    def __init__(self, energy, matrices, rest, strength=STRENGTH, parts=None):
        m = rest.shape[0]
        for h, matrix in enumerate(matrices):
            if matrix.ndim != 2 or matrix.shape[1] != m:
                raise SkinDetachError(f"pulls[{h}]: expected an (s, {m}) matrix, got {matrix.shape}")
        if not (isinstance(strength, (int, float, np.floating)) and np.isfinite(strength) and strength > 0):
            raise SkinDetachError(f"pull_strength: expected a finite number > 0, got {strength!r}")
        self._energy = energy
        self._rest = rest
        made = [parts.of(matrix) if parts is not None else _pull_parts(matrix) for matrix in matrices]
        self._grams = [gram for gram, _, _ in made]
        gram = sum(self._grams, sp.csr_matrix((m, m)))
        reached = gram.diagonal() > 0
        self.weight = float(strength * energy.gram.diagonal()[reached].mean() / gram.diagonal()[reached].mean()) \
            if reached.any() else 0.0
        #: K of E_pull (m, m): the Hessian without the twist terms, halved.
        self.gram = sp.csr_matrix(energy.gram + self.weight * gram)
        # Every pull over the proxy vertices it reaches only, all pulls in one block-diagonal
        # matrix: the pull is then one product per evaluation, however many handles a rig has
        # (48 small handles summed one by one cost a drag move 2-3 ms).
        supports = [support for _, support, _ in made]
        #: (S,) proxy vertex of every row of the stacked supports, (S, S) their weighted grams.
        self._support = np.concatenate(supports) if supports else np.zeros(0, dtype=np.int64)
        blocks = [self.weight * block for _, support, block in made if support.size]
        self._pull = sp.block_diag(blocks, format="csr") if blocks else sp.csr_matrix((0, 0))
        self._owner = np.repeat(np.arange(len(supports)), [support.size for support in supports])
        self._spread = sp.csr_matrix((np.ones(self._support.size), (self._support, np.arange(self._support.size))),
                                     shape=(m, self._support.size))
        self._count = len(self._grams)
        del self._grams
        self.n_groups = energy.n_groups
        self.scale = energy.scale
        self.set_motions([np.eye(4)] * self._count)

    def set_motions(self, motions):
        """Pull every group's drop points towards their rest positions moved by ``motions`` (one
        (4, 4) affine motion per pull)."""
        if len(motions) != self._count:
            raise SkinDetachError(f"pull_motions: expected {self._count} (4, 4) motions, got {len(motions)}")
        motions = np.asarray([np.asarray(motion, dtype=np.float64) for motion in motions]).reshape(-1, 4, 4) \
            if self._count else np.zeros((0, 4, 4))
        if motions.shape != (self._count, 4, 4) or not np.isfinite(motions).all():
            raise SkinDetachError("pull_motions: expected finite (4, 4) matrices, got another shape or NaN")
        #: (S, 3) the rest proxy moved by each pull's motion, on the pulls' stacked supports.
        linear, shift = motions[self._owner, :3, :3], motions[self._owner, :3, 3]
        self._targets = np.einsum("sij,sj->si", linear, self._rest[self._support]) + shift

    def moments_coo(self):
        return self._energy.moments_coo()

    def reset(self):
        self._energy.reset()

    def at(self, points):
        """The energy's state at ``points`` (m, 3) with the pull's value and gradient added."""
        state = self._energy.at(points)
        away = points[self._support] - self._targets
        pulled = self._pull @ away
        state.energy += float(np.sum(away * pulled))
        state.gradient = state.gradient + 2.0 * (self._spread @ pulled)
        return state

    def _pulled(self, points):
        """The pull's value at ``points`` (m, 3): sum_h (X - Y_h) . G_h (X - Y_h)."""
        away = points[self._support] - self._targets
        return float(np.sum(away * (self._pull @ away)))

    def bound(self, state, points):
        """The energy's :meth:`.rotated_energy.RotatedEnergy.bound` with the pull's value added."""
        return self._energy.bound(state, points) + self._pulled(points)

    def energy(self, points):
        return self.at(points).energy

    def hessian_product(self, state, direction):
        return 2.0 * (self.gram @ direction - self._energy.twist_product(state, direction))
