"""The energy the proxy solve minimises, with its gradient and exact Hessian products.

Arrays: ``points`` (m, 3) indexed by proxy vertex; B (r, m) stacks the energy's rows, each row
belongs to one of g rotation groups (``row_group`` (r,)); the rest rows are T0 = B X0 (r, 3).

    E(X) = min over rotations R_1..R_g of sum_rows |(B X)_row - R_group(row) T0_row|^2
         = X.K X - 2 sum_g (sigma_1 + sigma_2 + sigma_3)(C_g(X)) + |T0|^2,     K = B^T B,

where C_g(X) = sum over g's rows of (B X)_row T0_row^T (3, 3) is linear in X, and sigma_i are its
singular values signed so that the best rotation R_g = U_g V_g^T is proper (C = U diag(sigma) V^T,
Kabsch). E is zero at rest, invariant under rigid motions, and scales with the square of a
uniform scale.

Gradient (Danskin): grad E = 2 B^T (B X - T(R)), T(R) the rest rows turned by their group's best
rotation. Hessian (after Smith, de Goes & Kim 2019): H D = 2 (K D - B^T T(dR)) with dR the
derivative of the best rotations along D: dR_g = U W V^T, W skew with
W_ab = (M_ab - M_ba) / (sigma_a + sigma_b), M = U^T C_g(D) V; equivalently
dR_g = sum over the pairs (a, b) of <t_ab, C_g(D)> t_ab / (sigma_a + sigma_b) with the twist
t_ab = u_a v_b^T - u_b v_a^T. Only the three twist directions of
each group bend E below the quadratic X.K X; where the true Hessian is not positive definite the
caller sees negative curvature (:mod:`.projected_newton`).
"""

import numpy as np
import scipy.sparse as sp

from .rotations import WarmRotations

#: A pair of singular values summing to less than this fraction of the largest is a degenerate
#: (rank-deficient) group: its twist along that pair carries no curvature.
DEGENERATE_TWIST = 1e-9
_PAIRS = ((0, 1), (0, 2), (1, 2))
#: Below this fraction of the energy scale E is summed from its residuals: the short form
#: X.K X - 2 sum sigma + |T0|^2 cancels to rounding noise of about 1e-16 of the scale there.
EXACT_BELOW = 1e-6


class EnergyState:
    """The energy at ``points`` (m, 3): ``energy`` (float), ``gradient`` (m, 3), and what the Hessian
    products need, made on first use: ``twists`` (g, 3, 9) the twist directions
    u_a v_b^T - u_b v_a^T of the pairs (a, b) = (0, 1), (0, 2), (1, 2) of every group, flattened in
    the layout of :meth:`RotatedEnergy.covariance_rows`, and ``weights`` (g, 3) their
    1 / (sigma_a + sigma_b) (zero for a degenerate pair)."""

    def __init__(self, points, energy, gradient, u, v, sigma, rotations):
        self.points, self.energy, self.gradient = points, energy, gradient
        self._u, self._v, self._sigma = u, v, sigma
        #: (g, 9) the best rotations U V^T, flattened in the layout of :meth:`RotatedEnergy.covariance_rows`.
        self.rotation_rows = rotations.transpose(0, 2, 1).reshape(-1, 9)
        self._twists = None

    def _make_twists(self):
        u, v, sigma = self._u, self._v, self._sigma
        g = sigma.shape[0]
        largest = np.abs(sigma).max(axis=1)
        self.weights = np.empty((g, 3))
        self._twists = np.empty((g, 3, 9))
        for k, (a, b) in enumerate(_PAIRS):
            total = sigma[:, a] + sigma[:, b]
            usable = np.abs(total) > DEGENERATE_TWIST * np.maximum(largest, 1e-300)
            self.weights[:, k] = np.where(usable, 1.0 / np.where(usable, total, 1.0), 0.0)
            # u_a v_b^T - u_b v_a^T: entry [i, j] goes to 3 j + i.
            self._twists[:, k] = (v[:, :, b, None] * u[:, None, :, a] - v[:, :, a, None] * u[:, None, :, b]).reshape(g, 9)

    def rotations(self, groups):
        """(len(groups), 3, 3) the best rotations U V^T of the rotation ``groups`` (int array)."""
        return np.einsum("gij,gkj->gik", self._u[groups], self._v[groups])

    @property
    def twists(self):
        if self._twists is None:
            self._make_twists()
        return self._twists


class RotatedEnergy:
    """E (module docstring) for the stacked rows ``b`` (r, m) (sparse), ``row_group`` (r,) in
    [0, n_groups), rest positions ``rest`` (m, 3)."""

    def __init__(self, b, row_group, n_groups, rest):
        b = sp.csr_matrix(b)
        self.n_groups = int(n_groups)
        rest_rows = b @ rest
        r = b.shape[0]
        self._b, self._row_group, self._rest_rows = b, np.asarray(row_group), rest_rows
        # Row 3 group + j of the stacked moments gives column j of C_group: C[group, :, j].
        by_column = sp.vstack([
            sp.csr_matrix((rest_rows[:, j], (np.asarray(row_group), np.arange(r))), shape=(self.n_groups, r)) @ b
            for j in range(3)])  # row j g + group
        interleaved = (np.arange(self.n_groups)[:, None] + self.n_groups * np.arange(3)[None, :]).ravel()
        self._moments = sp.csr_matrix(sp.csr_matrix(by_column)[interleaved])
        self._moments_t = self._moments.T.tocsr()
        #: K = B^T B (m, m): the Hessian of E without the twist terms, halved.
        self.gram = sp.csr_matrix(b.T @ b)
        #: |T0|^2: the energy scale (E of a shape whose rows all vanish).
        self.scale = float(np.sum(rest_rows * rest_rows))
        self._fit = WarmRotations()

    def moments_coo(self):
        """(3g, m) COO: entry (3 k + j, v) is mu_kv[j], the weight of vertex v in column j of C_k."""
        return self._moments.tocoo()

    def reset(self):
        """Start the next rotation fit cold (see :meth:`.rotations.WarmRotations.reset`)."""
        self._fit.reset()

    def covariance_rows(self, points):
        """(g, 9) C_g of ``points`` (m, 3), row g holding C_g[i, j] at 3 j + i."""
        return (self._moments @ points).reshape(self.n_groups, 9)  # row 3 k + j of the product: column j of C_k

    def covariance(self, points):
        """(g, 3, 3) C_g of ``points`` (m, 3)."""
        return self.covariance_rows(points).reshape(self.n_groups, 3, 3).transpose(0, 2, 1)

    def _pull(self, rows):
        """sum_j M_j^T R[:, :, j] (m, 3) for (g, 9) ``rows`` of rotations (or their derivatives)
        laid out as in :meth:`covariance_rows`."""
        return self._moments_t @ rows.reshape(3 * self.n_groups, 3)

    def at(self, points):
        """:class:`EnergyState` at ``points`` (m, 3) (the rotation fit is warm-started from the last
        call): E = X.K X - 2 sum_g sum_i sigma_i + |T0|^2 (or the residuals' sum of squares near a
        rigid motion of rest, see :data:`EXACT_BELOW`), grad E = 2 (K X - B^T T(R))."""
        rows = self.covariance_rows(points)
        rotations, u, v, sigma = self._fit.decompose(rows.reshape(self.n_groups, 3, 3).transpose(0, 2, 1))
        kx = self.gram @ points
        energy = float(np.sum(points * kx)) - 2.0 * float(sigma.sum()) + self.scale
        if energy < EXACT_BELOW * self.scale:  # near a rigid motion of rest: no cancellation
            energy = self._residual_energy(points, rotations)
        state = EnergyState(points, energy, None, u, v, sigma, rotations)
        state.gradient = 2.0 * (kx - self._pull(state.rotation_rows))
        return state

    def bound(self, state, points):
        """E at ``points`` (m, 3) with the rotations of ``state`` kept instead of fitted anew: an
        upper bound of E there (E minimises over the rotations), equal to it at ``state.points``;
        X.K X - 2 sum_g <R_g, C_g(X)> + |T0|^2, or the residuals' sum of squares near rest (see
        :data:`EXACT_BELOW`). No rotation fit: a line search accepts a step on it at a tenth of
        the cost of :meth:`at`."""
        value = float(np.sum(points * (self.gram @ points))) - 2.0 * float(
            np.sum(state.rotation_rows * self.covariance_rows(points))) + self.scale
        if value < EXACT_BELOW * self.scale:
            value = self._residual_energy(points, state.rotation_rows.reshape(-1, 3, 3).transpose(0, 2, 1))
        return value

    def _residual_energy(self, points, rotations):
        """|B X - T(R)|^2 at ``points`` (m, 3) with ``rotations`` (g, 3, 3): E summed from its
        residuals, without the short form's cancellation near a rigid motion of rest."""
        residual = self._b @ points - np.einsum("rij,rj->ri", rotations[self._row_group], self._rest_rows)
        return float(np.sum(residual * residual))

    def energy(self, points):
        """E at ``points`` (m, 3)."""
        return self.at(points).energy

    def hessian_product(self, state, direction):
        """(m, 3) H D at ``state`` for ``direction`` D (m, 3): dR = sum_k w_k t_k <t_k, C(D)> over
        the twists t_k of every group."""
        return 2.0 * (self.gram @ direction - self.twist_product(state, direction))

    def twist_product(self, state, direction):
        """(m, 3) B^T T(dR) along ``direction`` (m, 3) at ``state``: the twist terms of H D, halved."""
        amounts = np.einsum("gkn,gn->gk", state.twists, self.covariance_rows(direction)) * state.weights
        turned = np.einsum("gkn,gk->gn", state.twists, amounts)
        return self._pull(turned)
