"""Best-fit rotations of many small point sets at once (the local step of as-rigid-as-possible
methods), without a Python loop and without LAPACK's per-matrix overhead.

Arrays: ``covariance`` (r, 3, 3), one matrix C = sum_j w_j current_j rest_j^T per set (current
and rest vectors as columns); the rotation R of set i maximises trace(R^T C_i), i.e. minimises
sum_j w_j |current_j - R rest_j|^2 (Kabsch; always a proper rotation, also for rank-deficient
or reflected C).

Method: the eigenvectors V of the symmetric C^T C by cyclic Jacobi sweeps (vectorised over the
r matrices; converged when the off-diagonal is below :data:`JACOBI_OFF` of the trace, at most
:data:`MAX_SWEEPS` sweeps), then U from C V column by column (Gram-Schmidt, the third column
the cross product, so det U = det V = 1) and R = U V^T.
"""

import numpy as np


#: Jacobi sweeps at most (quadratic convergence: 3x3 matrices converge in about four) ...
MAX_SWEEPS = 8
#: ... stopping when every off-diagonal sum is below this fraction of the trace (the rotations
#: then agree with an SVD's to about 1e-13: U is recomputed from C V).
JACOBI_OFF = 1e-13
_PAIRS = ((0, 1), (0, 2), (1, 2))


def _jacobi(a, r):
    """Eigenvectors of symmetric 3x3 matrices given as a dict (i, j) -> (r,) of the six entries
    i <= j (changed in place): returns v[row][col], lists of (r,) arrays. After each sweep only
    the matrices not yet converged take the next one (warm-started calls mostly need one)."""
    v = [[np.ones(r) if i == j else np.zeros(r) for j in range(3)] for i in range(3)]
    scale = np.abs(a[0, 0]) + np.abs(a[1, 1]) + np.abs(a[2, 2]) + 1e-300
    todo = None  # None: all r matrices; else the indices still sweeping
    for _ in range(MAX_SWEEPS):
        part_scale = scale if todo is None else scale[todo]
        part = a if todo is None else {key: value[todo] for key, value in a.items()}
        off = np.abs(part[0, 1]) + np.abs(part[0, 2]) + np.abs(part[1, 2])
        busy = off > JACOBI_OFF * part_scale
        if not busy.any():
            break
        if busy.mean() < 0.5:  # sweep only the unconverged ones from here on
            todo = np.flatnonzero(busy) if todo is None else todo[busy]
            part = {key: value[todo] for key, value in a.items()}
        rows = v if todo is None else [[column[todo] for column in row] for row in v]
        _sweep(part, rows)
        if todo is not None:
            for key, value in part.items():
                a[key][todo] = value
            for row, part_row in zip(v, rows):
                for column, values in zip(row, part_row):
                    column[todo] = values
    return v


def _sweep(a, v):
    """One cyclic Jacobi sweep over the matrices in ``a`` (dict of six entries), turning the
    eigenvector columns ``v`` (v[row][col]) along; both changed in place."""
    r = a[0, 0].shape[0]
    for p, q in _PAIRS:
        o = 3 - p - q  # the third index
        apq = a[p, q]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            tau = (a[q, q] - a[p, p]) / (2.0 * apq)
            # apq = 0 gives tau = +-inf and t = 0 (no turn); 0/0 (a zero matrix) is cleared below.
            t = np.copysign(1.0, tau) / (np.abs(tau) + np.sqrt(1.0 + tau * tau))
        t[np.isnan(t)] = 0.0
        c = 1.0 / np.sqrt(1.0 + t * t)
        sn = t * c
        a[p, p] = a[p, p] - t * apq
        a[q, q] = a[q, q] + t * apq
        a[p, q] = np.zeros(r)
        po, qo = (min(p, o), max(p, o)), (min(q, o), max(q, o))
        apo, aqo = a[po], a[qo]
        a[po] = c * apo - sn * aqo
        a[qo] = sn * apo + c * aqo
        for row in v:
            vp, vq = row[p], row[q]
            row[p] = c * vp - sn * vq
            row[q] = sn * vp + c * vq


def _unit(x, y, z):
    n = np.sqrt(x * x + y * y + z * z)
    return n, np.where(n > 0.0, n, 1.0)


def best_rotations(covariance):
    """(r, 3, 3) proper rotations R_i maximising trace(R_i^T C_i) for ``covariance`` (r, 3, 3)."""
    return _fit(covariance, None)[0]


class WarmRotations:
    """:func:`best_rotations` for a sequence of nearby covariances of the same r sets (the
    iterations of a solve): each call starts the Jacobi sweeps from the eigenvectors of the
    last, so one sweep usually suffices; the rotations are the same as a cold call's."""

    def __init__(self):
        self._guess = None

    def __call__(self, covariance):
        return self.decompose(covariance)[0]

    def reset(self):
        """Forget the last eigenvectors: the next call is a cold one (bit for bit what a fresh
        object gives, whatever was fitted before)."""
        self._guess = None

    def decompose(self, covariance):
        """(R, U, V (r, 3, 3), sigma (r, 3)): R = U V^T and C = U diag(sigma) V^T with U, V proper
        rotations whose columns run from the largest singular value down (sigma_3 < 0 where
        det C < 0): sigma_i = u_i . C v_i."""
        guess = self._guess if self._guess is not None and self._guess.shape[0] == len(covariance) else None
        rotations, self._guess, u, v, sigma = _fit(covariance, guess)
        return rotations, u, v, sigma


def _fit(covariance, guess):
    """(rotations (r, 3, 3), eigenvectors of C^T C (r, 3, 3), U, V (r, 3, 3), sigma (r, 3)) for
    ``covariance`` (r, 3, 3) (as in :meth:`WarmRotations.decompose`); the sweeps start
    from the orthonormal ``guess`` (r, 3, 3) when given."""
    c = np.ascontiguousarray(covariance, dtype=np.float64).reshape(-1, 9)
    r = c.shape[0]
    cc = [c[:, k] for k in range(9)]  # cc[3 i + j] = C_ij
    work = cc
    if guess is not None:
        g = np.ascontiguousarray(guess, dtype=np.float64).reshape(-1, 9)
        gg = [g[:, k] for k in range(9)]
        work = [cc[3 * i] * gg[j] + cc[3 * i + 1] * gg[3 + j] + cc[3 * i + 2] * gg[6 + j]
                for i in range(3) for j in range(3)]
    # The six entries of W^T W (W = C G), then its eigenvectors (columns of v).
    a = {(i, j): work[i] * work[j] + work[3 + i] * work[3 + j] + work[6 + i] * work[6 + j]
         for i in range(3) for j in range(i, 3)}
    v = _jacobi(a, r)
    if guess is not None:  # back to eigenvectors of C^T C: G v
        v = [[gg[3 * i] * v[0][j] + gg[3 * i + 1] * v[1][j] + gg[3 * i + 2] * v[2][j] for j in range(3)]
             for i in range(3)]
    lam = [a[0, 0], a[1, 1], a[2, 2]]
    # Column of the largest eigenvalue (first) and of the middle one (second).
    first = np.where(lam[0] >= lam[1], np.where(lam[0] >= lam[2], 0, 2), np.where(lam[1] >= lam[2], 1, 2))
    last = np.where(lam[0] < lam[1], np.where(lam[0] < lam[2], 0, 2), np.where(lam[1] < lam[2], 1, 2))
    second = 3 - first - last
    second = np.where(first == last, (first + 1) % 3, second)
    col = np.array(v)  # (row, col, r)
    idx = np.arange(r)
    v1 = [col[k, first, idx] for k in range(3)]
    v2 = [col[k, second, idx] for k in range(3)]
    v3 = [v1[1] * v2[2] - v1[2] * v2[1], v1[2] * v2[0] - v1[0] * v2[2], v1[0] * v2[1] - v1[1] * v2[0]]
    u1 = [cc[3 * k] * v1[0] + cc[3 * k + 1] * v1[1] + cc[3 * k + 2] * v1[2] for k in range(3)]
    u2 = [cc[3 * k] * v2[0] + cc[3 * k + 1] * v2[1] + cc[3 * k + 2] * v2[2] for k in range(3)]
    n1, safe1 = _unit(*u1)
    fallback = n1 <= 1e-300
    u1 = [np.where(fallback, v1[k], u1[k] / safe1) for k in range(3)]
    d = u1[0] * u2[0] + u1[1] * u2[1] + u1[2] * u2[2]
    u2 = [u2[k] - d * u1[k] for k in range(3)]
    n2, safe2 = _unit(*u2)
    weak = n2 <= 1e-12 * np.maximum(n1, 1e-300)
    if weak.any():  # rank one (or zero): any unit vector orthogonal to u1
        px = np.abs(u1[0]) < 0.9  # cross with x unless u1 is close to it, else with y
        other = [np.where(px, 0.0, -u1[2]), np.where(px, u1[2], 0.0), np.where(px, -u1[1], u1[0])]
        no, safe_o = _unit(*other)
        u2 = [np.where(weak, other[k] / safe_o, u2[k] / safe2) for k in range(3)]
    else:
        u2 = [u2[k] / safe2 for k in range(3)]
    u3 = [u1[1] * u2[2] - u1[2] * u2[1], u1[2] * u2[0] - u1[0] * u2[2], u1[0] * u2[1] - u1[1] * u2[0]]
    out = np.empty((r, 3, 3))
    for i in range(3):
        for j in range(3):
            out[:, i, j] = u1[i] * v1[j] + u2[i] * v2[j] + u3[i] * v3[j]
    eigenvectors = np.empty((r, 3, 3))
    for i in range(3):
        for j in range(3):
            eigenvectors[:, i, j] = v[i][j]
    left, right = np.empty((r, 3, 3)), np.empty((r, 3, 3))
    for i in range(3):
        left[:, i, 0], left[:, i, 1], left[:, i, 2] = u1[i], u2[i], u3[i]
        right[:, i, 0], right[:, i, 1], right[:, i, 2] = v1[i], v2[i], v3[i]
    # sigma_k = u_k . C v_k (sigma_1, sigma_2 are the lengths Gram-Schmidt divided by).
    cv3 = [cc[3 * k] * v3[0] + cc[3 * k + 1] * v3[1] + cc[3 * k + 2] * v3[2] for k in range(3)]
    sigma = np.stack([np.where(fallback, 0.0, n1), np.where(weak, 0.0, n2) if weak.any() else n2,
                      u3[0] * cv3[0] + u3[1] * cv3[1] + u3[2] * cv3[2]], axis=1)
    return out, eigenvectors, left, right, sigma
