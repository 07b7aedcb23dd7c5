"""The volume constraint of the proxy solve: every closed component that carries a constraint
keeps its rest volume.

Arrays: ``points`` (m, 3) indexed by proxy vertex, ``faces`` (k, 3) indexed by face, ``labels``
(m,) the connected component of every vertex. The c kept components are indexed 0..c-1 (their
"slot"); the volume of component s is V_s(X) = 1/6 sum over its faces (a, b, c) of
x_a . (x_b x x_c), a cubic in X; on a closed component its gradient at a vertex is a sixth of the
sum of (x_b - x_a) x (x_c - x_a) over the faces (a, b, c) around it.
"""

import numpy as np
import scipy.sparse as sp

from ..geometry import cross_rows, signed_volumes

#: Newton steps on the cubic volume-versus-step polynomial of :meth:`VolumeConstraint.restore`.
RESTORE_NEWTON_STEPS = 3


def closed_components(faces, labels):
    """Sorted labels (from per-vertex ``labels``) of the watertight components: every directed
    edge a->b is matched by as many b->a (non-manifold edges with paired sides count as closed)."""
    face_label = labels[faces[:, 0]]
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * labels.size + np.maximum(a, b)
    unique, inverse = np.unique(key, return_inverse=True)
    balance = np.bincount(inverse, weights=np.where(a < b, 1.0, -1.0), minlength=unique.size)
    open_label = np.unique(np.repeat(face_label, 3)[balance[inverse] != 0])
    return np.setdiff1d(np.unique(face_label), open_label)


class VolumeConstraint:
    """Volumes of the closed components of the proxy (``rest`` (m, 3), ``faces`` (k, 3), ``labels``
    (m,)); the components listed in ``kept`` (labels) are constrained to their rest volume.

    ``slot`` (m,) is each vertex's kept component (0 for vertices in none; ``in_kept`` (m,) says
    which are in one); ``size`` is the number of kept components.
    """

    def __init__(self, rest, faces, labels, kept):
        m = rest.shape[0]
        self.faces = faces
        self._face_label = labels[faces[:, 0]]
        self._all_closed = closed_components(faces, labels)
        self._rest_all = signed_volumes(rest, faces, self._face_label, self._all_closed)
        self.kept = np.intersect1d(self._all_closed, kept)
        self.size = int(self.kept.size)
        self._rest = self._rest_all[np.searchsorted(self._all_closed, self.kept)]
        self.in_kept = np.isin(labels, self.kept)
        self.slot = np.where(self.in_kept, np.searchsorted(self.kept, labels), 0)
        closed = np.flatnonzero(np.isin(self._face_label, self.kept))
        self._faces = faces[closed]
        n = closed.size
        face_slot = np.searchsorted(self.kept, self._face_label[closed])
        self._face_sum = sp.csr_matrix((np.ones(n), (face_slot, np.arange(n))), shape=(self.size, n))
        #: every kept face's value scattered to its three corners: (m, n).
        self._scatter_all = sp.csr_matrix((np.ones(3 * n), (self._faces.ravel(), np.repeat(np.arange(n), 3))),
                                          shape=(m, n))

    def change(self, points):
        """V/V_rest - 1 summed over every closed component (kept or not), nan if there is none."""
        if not self._all_closed.size:
            return float("nan")
        total = signed_volumes(points, self.faces, self._face_label, self._all_closed).sum()
        return float(total / self._rest_all.sum() - 1.0)

    def gradient(self, points):
        """(m, 3) the gradient of every kept component's volume (each on its own vertices): a sixth
        of the cross products of the edges of the faces around a vertex (translation invariant)."""
        x = [points[self._faces[:, c]] for c in range(3)]
        return self._scatter_all @ cross_rows(x[1] - x[0], x[2] - x[0]) / 6.0

    def hessian_product(self, points, direction, multipliers):
        """(m, 3) sum_s multipliers[s] (Hessian of V_s) ``direction`` (m, 3): the derivative of
        :meth:`gradient` along ``direction``, weighted per component."""
        return self.hessian_at(points, multipliers)(direction)

    def hessian_at(self, points, multipliers):
        """:meth:`hessian_product` at ``points`` with ``multipliers`` as a function of the direction
        (m, 3) -> (m, 3), what does not depend on the direction made once (a CG's many products)."""
        x0 = points[self._faces[:, 0]]
        e1, e2 = points[self._faces[:, 1]] - x0, points[self._faces[:, 2]] - x0
        weight = ((multipliers[self.slot] * self.in_kept) / 6.0)[:, None]
        corner = [self._faces[:, c] for c in range(3)]

        def product(direction):
            d0 = direction[corner[0]]
            turned = cross_rows(direction[corner[1]] - d0, e2) + cross_rows(e1, direction[corner[2]] - d0)
            return (self._scatter_all @ turned) * weight
        return product

    def component_sums(self, values):
        """(c,) per kept component, the sum over its vertices of ``values`` (m,)."""
        return np.bincount(self.slot[self.in_kept], weights=values[self.in_kept], minlength=self.size)

    def restore(self, points, direction):
        """``points`` moved by lambda_s ``direction`` on every kept component s so that its volume
        returns to rest: V_s(X + lambda D) is a cubic in lambda, solved by scalar Newton steps."""
        x = [points[self._faces[:, c]] for c in range(3)]
        d = [direction[self._faces[:, c]] for c in range(3)]
        x12, d12 = cross_rows(x[1], x[2]), cross_rows(d[1], d[2])
        mixed = cross_rows(d[1], x[2]) + cross_rows(x[1], d[2])
        dot = lambda p, q: np.einsum("ij,ij->i", p, q)  # noqa: E731
        per_face = np.stack([dot(x[0], x12), dot(d[0], x12) + dot(x[0], mixed), dot(x[0], d12) + dot(d[0], mixed),
                             dot(d[0], d12)], axis=1) / 6.0
        coeffs = np.asarray(self._face_sum @ per_face)
        coeffs[:, 0] -= self._rest
        step = np.zeros(self.size)
        for _ in range(RESTORE_NEWTON_STEPS):
            value = coeffs[:, 0] + step * (coeffs[:, 1] + step * (coeffs[:, 2] + step * coeffs[:, 3]))
            slope = coeffs[:, 1] + step * (2 * coeffs[:, 2] + step * 3 * coeffs[:, 3])
            safe = np.abs(slope) > 1e-300
            step[safe] -= value[safe] / slope[safe]
        return points + (step[self.slot] * self.in_kept)[:, None] * direction
