"""Dual Laplacian editing of the proxy (paper section 3.3, after Au, Tai, Liu & Fu 2006).

Arrays: proxy ``points`` (m, 3) indexed by vertex id, ``faces`` (k, 3) indexed by face id.

The dual mesh has one vertex per face, its centroid. Face i has three dual neighbours, the
faces across its edges v0v1, v1v2, v2v0 (in that order; a boundary edge contributes a ghost,
the centroid mirrored through the edge midpoint, which is still linear in the vertices; a
non-manifold edge takes the face whose normal agrees best). At rest the centroid c_i sits at
signed height h_i above the plane of its neighbours (a, b, c) with normal
n_i = unit((b - a) x (c - a)); its drop point has barycentric weights w_i in (a, b, c). With
A = D - sum_j w_ij Q_j (k, m) -- D the centroid operator, Q_j the neighbour operators -- the
rest dual Laplacian coordinates are delta0_i = (A X0)_i = h_i n_i.

Method "rotated" (the default) minimises, over the free vertices X and one rotation per dual
cell (R_i) and per vertex (R_v), with the constrained vertices held exactly,

    E(X) = sum_i |(A X)_i - R_i delta0_i|^2
         + sum_i sum_j |(Q_j X - D X)_i - R_i (Q_j X0 - D X0)_i|^2
         + rigidity * sum_v sum_(v,u) c_vu |(x_u - x_v) - R_v (x0_u - x0_v)|^2

(the paper's coordinates with their frames rotated, the dual cell's spokes that fix R_i, and
cotangent-weighted as-rigid-as-possible spokes), subject to every constrained closed component
keeping its rest volume. The energy, with the rotations eliminated, and its derivatives are in
:mod:`.rotated_energy`, the constraint in :mod:`.volume_constraint`, the iteration (projected
Newton, converged when the Newton step's largest vertex move is within ``sqrt(tol)`` of the
diagonal) in :mod:`.projected_newton`; this class assembles them and holds the factor of
K = B^T B over the free vertices that preconditions every Newton step. ``solve`` without an
initial guess starts from rest, and a far jump of the constraints is reached in stages
(continuation), so the same constraints give the same shape whatever was solved before; with
a guess (a drag's previous move) it follows from there. E is zero at rest, invariant under
rigid motions and scales with the square of a uniform scale, so the solution follows both.

Method "paper" is the paper's iteration, kept for comparison: minimise ||A X - delta||^2 with
delta_i = h_i n_i(X), the normals updated from the current neighbours each iteration (a fixed
point, not the minimiser of an energy: it can cycle, and then returns its calmest iterate),
optionally with the rigidity spokes.
"""

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import SkinDetachError
from ..geometry import barycentric, bbox_diagonal, component_labels, cotangent_weights, cross_rows, unique_edges, unit_rows
from .hessian_factor import HessianFactor, LaggedHessian
from .projected_newton import largest_step, minimise
from .pulled_energy import STRENGTH, PulledEnergy
from .rotated_energy import RotatedEnergy
from ..validation import as_points, as_triangles, as_vertex_ids
from .volume_constraint import VolumeConstraint
from .work_budget import WorkBudget, scaled_units

#: Dual triangles with |(b - a) x (c - a)| under this fraction of their squared size use a face frame.
DEGENERATE_DUAL = 1e-10
#: Proximal weight (relative to the mean diagonal of the normal equations) towards the last
#: iterate: keeps the system definite on odd meshes and vanishes at the fixed point.
PROXIMAL = 1e-10
#: The solvers: "rotated" minimises the energy in the module docstring by local-global steps;
#: "paper" is the paper's normal-update iteration (kept for comparison).
METHODS = ("rotated", "paper")
DEFAULT_METHOD = "rotated"
#: Weight of the rigidity (rotated rest vertex spoke) term against the dual rows, per method.
DEFAULT_RIGIDITY = {"rotated": 1.0, "paper": 0.0}
#: Past iterates mixed by Anderson acceleration of the paper's normal-update iteration.
ANDERSON_WINDOW = 5
#: Continuation of the "rotated" solve: constrained vertices moving more than STAGE_JUMP of the
#: diagonal from the initial guess get there in up to MAX_STAGES stages, each solved to STAGE_TOL.
STAGE_JUMP = 0.1
MAX_STAGES = 12
#: An initial guess whose constrained vertices are farther than this (over the diagonal) from
#: their targets is not followed: the solve starts from rest, as one without a guess does.
WARM_LIMIT = 0.1
STAGE_TOL = 1e-4
#: Stop when this many iterations in a row have not reached a new smallest change.
STALL_ITERATIONS = 12


class _Anderson:
    """Anderson acceleration (type II) of a fixed-point iteration x -> g(x), with a restart
    whenever the residual grows (or the caller rejects a step: :meth:`reset`)."""

    def __init__(self, window):
        self.window = window
        self.xs, self.gs, self.fs = [], [], []
        self.best = np.inf

    def reset(self):
        self.xs, self.gs, self.fs = [], [], []

    def next(self, x, g, size):
        """Next iterate from the current one ``x`` and its image ``g`` (arrays of equal shape)."""
        if size > self.best * 2.0:
            self.xs, self.gs, self.fs = [], [], []
        self.best = min(self.best, size)
        f = (g - x).ravel()
        self.gs.append(g.ravel())
        self.fs.append(f)
        self.gs, self.fs = self.gs[-self.window - 1:], self.fs[-self.window - 1:]
        if len(self.fs) < 2:
            return g
        d_f = np.diff(np.array(self.fs), axis=0).T
        d_g = np.diff(np.array(self.gs), axis=0).T
        gamma = np.linalg.lstsq(d_f, f, rcond=None)[0]
        return (g.ravel() - d_g @ gamma).reshape(g.shape)


@dataclass
class DualLaplacianResult:
    """vertices (m, 3) deformed proxy; iterations run; converged flag; volume_change
    V/V_rest - 1 over the closed components (nan if there is none); history (iterations,)
    largest squared move of a vertex per iteration over the squared bounding-box diagonal;
    energy (iterations + 1,) the energy at the start and after every iteration ("rotated" only)."""

    vertices: np.ndarray
    iterations: int
    converged: bool
    volume_change: float
    history: list = field(default_factory=list)
    energy: list = field(default_factory=list)


def dual_neighbours(points, faces):
    """(k, 3) face across edge v0v1, v1v2, v2v0 of every face; -1 on a boundary edge.

    On a non-manifold edge the neighbour is the other face whose normal agrees best.
    """
    k = faces.shape[0]
    m = points.shape[0]
    a = faces.ravel()
    b = faces[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * m + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    start = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    count = np.diff(np.r_[start, key.size])
    out = np.full(k * 3, -1, dtype=np.int64)
    pairs = start[count == 2]
    first, second = order[pairs], order[pairs + 1]
    out[first] = second // 3
    out[second] = first // 3
    crowded = start[count > 2]
    if crowded.size:
        normals = unit_rows(cross_rows(points[faces[:, 1]] - points[faces[:, 0]],
                                       points[faces[:, 2]] - points[faces[:, 0]]))[0]
        for s, c in zip(crowded, count[count > 2]):
            half_edges = order[s:s + c]
            owners = half_edges // 3
            for h, f in zip(half_edges, owners):
                others = owners[owners != f]
                if others.size:
                    out[h] = others[np.argmax(normals[others] @ normals[f])]
    return out.reshape(k, 3)


def _neighbour_operators(faces, neighbours, m):
    """(3k, m) sparse stack of Q_0, Q_1, Q_2: the neighbour centroid, or the ghost
    (2/3 (va + vb) - 1/3 vc) across a boundary edge (va vb) with opposite corner vc."""
    k = faces.shape[0]
    rows, cols, vals = [], [], []
    for j in range(3):
        va, vb, vc = faces[:, j], faces[:, (j + 1) % 3], faces[:, (j + 2) % 3]
        nb = neighbours[:, j]
        inner = nb >= 0
        r = j * k + np.arange(k)
        for corner in range(3):
            rows.append(r[inner])
            cols.append(faces[nb[inner], corner])
            vals.append(np.full(int(inner.sum()), 1.0 / 3.0))
        ghost = ~inner
        for ids, weight in ((va, 2.0 / 3.0), (vb, 2.0 / 3.0), (vc, -1.0 / 3.0)):
            rows.append(r[ghost])
            cols.append(ids[ghost])
            vals.append(np.full(int(ghost.sum()), weight))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * k, m))


def _face_frames(points, faces):
    """Orthonormal frame (e1, e2, n) of every face, each (k, 3)."""
    e1 = unit_rows(points[faces[:, 1]] - points[faces[:, 0]])[0]
    n = unit_rows(cross_rows(points[faces[:, 1]] - points[faces[:, 0]], points[faces[:, 2]] - points[faces[:, 0]]))[0]
    return e1, cross_rows(n, e1), n


class DualLaplacian:
    """Dual Laplacian solver for one proxy and one set of constrained vertices.

    proxy_vertices (m, 3) rest proxy; proxy_faces (k, 3); constrained_ids (c,) distinct proxy
    vertex ids held by handles and anchors. Components with no constrained vertex, and
    vertices no face uses, stay at rest.
    """

    def __init__(self, proxy_vertices, proxy_faces, constrained_ids, preserve_volume=True, rigidity=None,
                 method=DEFAULT_METHOD, pulls=(), pull_strength=STRENGTH, pull_parts=None):
        if method not in METHODS:
            raise SkinDetachError(f"method: expected one of {', '.join(map(repr, METHODS))}, got {method!r}")
        self.method = method
        if rigidity is None:
            rigidity = DEFAULT_RIGIDITY[method]
        self.rest = as_points("proxy_vertices", proxy_vertices)
        m = self.rest.shape[0]
        self.faces = as_triangles("proxy_faces", proxy_faces, m)
        ids = as_vertex_ids("constrained_ids", constrained_ids, m)
        if np.unique(ids).size != ids.size:
            raise SkinDetachError(f"constrained_ids: expected distinct ids, got {ids.size - np.unique(ids).size} repeated")
        self.constrained = ids
        self.preserve_volume = bool(preserve_volume)
        if isinstance(rigidity, bool) or not isinstance(rigidity, (int, float, np.floating)) or \
                not np.isfinite(rigidity) or rigidity < 0:
            raise SkinDetachError(f"rigidity: expected a finite number >= 0, got {rigidity!r}")
        self.rigidity = float(rigidity)
        self.diagonal = max(bbox_diagonal(self.rest), 1e-300)
        k = self.faces.shape[0]

        labels = component_labels(self.faces, m)
        used = np.zeros(m, dtype=bool)
        used[self.faces.ravel()] = True
        held = np.zeros(m, dtype=bool)
        held[ids] = True
        active = np.isin(labels, np.unique(labels[ids]))
        fixed = held | ~active | ~used
        self.free = np.flatnonzero(~fixed)
        self.fixed = np.flatnonzero(fixed)
        self._held_in_fixed = np.searchsorted(self.fixed, ids)

        neighbours = dual_neighbours(self.rest, self.faces)
        self._q = _neighbour_operators(self.faces, neighbours, m)
        centroid = sp.csr_matrix((np.full(3 * k, 1.0 / 3.0), (np.repeat(np.arange(k), 3), self.faces.ravel())),
                                 shape=(k, m))
        a, b, c = self._neighbour_points(self.rest)
        c_i = centroid @ self.rest
        cross = cross_rows(b - a, c - a)
        normal, length = unit_rows(cross)
        size = np.maximum.reduce([np.einsum("ij,ij->i", d, d) for d in (b - a, c - a, c - b)])
        self._paper = length > DEGENERATE_DUAL * np.maximum(size, 1e-300)
        height = np.einsum("ij,ij->i", c_i - a, normal)
        drop = c_i - height[:, None] * normal
        weights = np.full((k, 3), 1.0 / 3.0)
        weights[self._paper] = barycentric(drop, a, b, c)[self._paper]
        self._height = height
        # Degenerate dual triangles keep their rest offset in the frame of their own face.
        offset = c_i - np.einsum("ij,ijk->ik", weights, np.stack([a, b, c], axis=1))
        e1, e2, n = _face_frames(self.rest, self.faces)
        self._frame_coords = np.stack([np.einsum("ij,ij->i", offset, e) for e in (e1, e2, n)], axis=1)

        self.matrix = self._assemble(centroid, weights)
        if pulls and method != "rotated":
            raise SkinDetachError(f"pulls: expected none with method {method!r} (only 'rotated' pulls), got {len(pulls)}")
        self.n_pulls = len(pulls)
        if method == "rotated":
            self._setup_rotated(centroid, m, pulls, pull_strength, pull_parts)
        else:
            self._setup_paper(m)

        # Closed components: all are measured; those with a constraint are kept at rest volume.
        self.volume = VolumeConstraint(self.rest, self.faces, labels,
                                       np.unique(labels[ids]) if self.preserve_volume else np.zeros(0, dtype=np.int64))

    def _factor(self, normal_eq):
        """Factor the normal equations (free x free) with a tiny proximal term that keeps them
        definite on odd meshes; symmetric positive definite, so no pivoting (the order is kept)."""
        normal_eq = normal_eq.tocsc()
        self._proximal = PROXIMAL * (normal_eq.diagonal().mean() if self.free.size else 0.0)
        normal_eq = normal_eq + self._proximal * sp.identity(self.free.size, format="csc")
        self._lu = splu(normal_eq, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                        options={"SymmetricMode": True}) if self.free.size else None

    def _setup_paper(self, m):
        self._a_free = self.matrix[:, self.free].tocsc()
        self._a_fixed = self.matrix[:, self.fixed].tocsc()
        normal_eq = self._a_free.T @ self._a_free
        if self.rigidity:
            normal_eq = normal_eq + self._setup_rigidity(m)
        self._factor(normal_eq)
        self._a_free_t = self._a_free.T.tocsr()

    def _setup_rotated(self, centroid, m, pulls, pull_strength, pull_parts=None):
        """The stacked operator B (r, m) of every term of the energy: the k dual Laplacian rows,
        the 3k dual-cell spokes (neighbour centroid or ghost minus own centroid) and, weighted by
        sqrt(rigidity), the 2e cotangent-weighted vertex spokes; each row belongs to one rotation
        group (its face, or the tail vertex of its spoke). With ``pulls`` the energy is
        :class:`.pulled_energy.PulledEnergy` (each pull's own parts kept by ``pull_parts``, a
        :class:`.pulled_energy.PullParts`, if given)."""
        k = self.faces.shape[0]
        cell = self._q - sp.vstack([centroid] * 3)
        blocks, groups = [self.matrix, cell], [np.arange(k), np.tile(np.arange(k), 3)]
        n_groups = k
        if self.rigidity:
            self._setup_rigidity(m)
            blocks.append(np.sqrt(self.rigidity) * self._edges)
            groups.append(k + self._spoke_tail)
            n_groups = k + m
        b = sp.csr_matrix(sp.vstack(blocks))
        self.energy_terms = RotatedEnergy(b, np.concatenate(groups), n_groups, self.rest)
        if pulls:
            self.energy_terms = PulledEnergy(self.energy_terms, pulls, self.rest, pull_strength, pull_parts)
        self._factor(self.energy_terms.gram[self.free][:, self.free])
        #: The factored Hessian preconditioning the Newton steps (at rest until a settle refreshes it).
        vertex_groups = k + self.free if self.rigidity else None
        rest_state = self.energy_terms.at(self.rest)
        self._lagged = LaggedHessian(HessianFactor(self.energy_terms, self.free, m), rest_state,
                                     None if vertex_groups is None else lambda state: state.rotations(vertex_groups))
        self.energy_terms.reset()

    def units(self, reference_units):
        """The units of a budget of ``reference_units`` at a 1,000-face proxy for this solver
        (:func:`.work_budget.scaled_units` of its free vertices): the same on every machine."""
        return scaled_units(reference_units, self.free.size)

    def _setup_rigidity(self, m):
        """Spoke operators of the rigidity term: every edge in both directions, as a spoke of its
        tail vertex (2e, m), cotangent-weighted. Returns its part of the normal equations."""
        undirected = unique_edges(self.faces)[0]
        self._spoke_tail = np.concatenate([undirected[:, 0], undirected[:, 1]])
        spoke_head = np.concatenate([undirected[:, 1], undirected[:, 0]])
        n_spokes = self._spoke_tail.size
        spoke_weight = np.sqrt(np.tile(cotangent_weights(self.rest, self.faces, undirected), 2))
        edges = sp.csr_matrix((np.r_[spoke_weight, -spoke_weight],
                               (np.r_[np.arange(n_spokes), np.arange(n_spokes)], np.r_[spoke_head, self._spoke_tail])),
                              shape=(n_spokes, m))
        weight = np.sqrt(self.rigidity)
        self._edges = edges
        self._rest_spokes = edges @ self.rest
        self._spoke_scatter = sp.csr_matrix((np.ones(n_spokes), (self._spoke_tail, np.arange(n_spokes))),
                                            shape=(m, n_spokes))
        if self.method == "rotated":
            return None
        self._e_free = (weight * edges[:, self.free]).tocsc()
        self._e_fixed = (weight * edges[:, self.fixed]).tocsc()
        self._e_free_t = self._e_free.T.tocsr()
        return self._e_free.T @ self._e_free

    def _assemble(self, centroid, weights):
        """(k, m) CSR matrix A = D - sum_j diag(w_j) Q_j."""
        k = self.faces.shape[0]
        out = centroid.copy()
        for j in range(3):
            out = out - sp.diags(weights[:, j]) @ self._q[j * k:(j + 1) * k]
        return sp.csr_matrix(out)

    def _neighbour_points(self, points):
        k = self.faces.shape[0]
        stacked = self._q @ points
        return stacked[:k], stacked[k:2 * k], stacked[2 * k:]

    def deltas(self, points):
        """(k, 3) targets h_i n_i(points) of the dual Laplacian rows at ``points`` (m, 3)."""
        a, b, c = self._neighbour_points(points)
        normal = unit_rows(cross_rows(b - a, c - a))[0]
        out = self._height[:, None] * normal
        odd = ~self._paper
        if odd.any():
            e1, e2, n = _face_frames(points, self.faces[odd])
            coords = self._frame_coords[odd]
            out[odd] = coords[:, :1] * e1 + coords[:, 1:2] * e2 + coords[:, 2:] * n
        return out

    def edge_targets(self, points):
        """(2e, 3) rest spokes rotated by their tail vertex's best-fit rotation at ``points``."""
        current = self._edges @ points
        rest = self._rest_spokes
        outer = (rest[:, :, None] * current[:, None, :]).reshape(-1, 9)
        covariance = np.asarray(self._spoke_scatter @ outer).reshape(-1, 3, 3)
        u, _, vt = np.linalg.svd(covariance)
        rotation = np.einsum("nji,nkj->nik", vt, u)
        flip = np.linalg.det(rotation) < 0
        if flip.any():
            u[flip, :, 2] *= -1
            rotation[flip] = np.einsum("nji,nkj->nik", vt[flip], u[flip])
        return np.einsum("nij,nj->ni", rotation[self._spoke_tail], rest)

    def volume_change(self, points):
        """V/V_rest - 1 summed over the closed components (nan if there is none)."""
        return self.volume.change(points)

    def _volume_direction(self, points):
        """(m, 3) K^-1 grad V over the free vertices of the kept components (zero elsewhere): the
        direction :meth:`VolumeConstraint.restore` moves along."""
        out = np.zeros_like(points)
        gradient = self.volume.gradient(points)[self.free] * self.volume.in_kept[self.free][:, None]
        out[self.free] = self._lu.solve(np.ascontiguousarray(gradient))
        return out

    def solve(self, constrained_positions, initial=None, max_iter=50, tol=1e-6, budget_units=None, idle=False,
              pull_motions=None):
        """Deform the proxy so that the constrained vertices reach ``constrained_positions`` (c, 3)
        and the pulls' detail follows ``pull_motions`` (one (4, 4) rigid motion per pull; None:
        each holds its detail at rest).

        Without ``initial`` the solve starts from rest (the same constraints give the same shape
        whatever was solved before); ``initial`` (m, 3), e.g. the extrapolated previous moves of a
        drag, starts it there instead. "rotated": converged when the Newton step's largest vertex
        move, squared over the squared diagonal, is at most ``tol`` (:mod:`.projected_newton`);
        ``budget_units`` (None: no limit) stops it before an iteration that, costing as much work
        as the last, would end past that many units of work (:mod:`.work_budget`; the same iterate
        whatever the clock does; not converged: the next call may continue from its result; the
        first iteration always runs). "paper": stops
        when the largest squared move of a vertex in one iteration is at most ``tol``, or when
        :data:`STALL_ITERATIONS` iterations in a row found no smaller change (the iteration
        cycles, e.g. around a fold): then the iterate with the smallest change is returned.
        Either stops after ``max_iter`` iterations. ``idle`` ("rotated", with ``initial``): nobody
        waits on this solve (a drag's settle while the mouse rests), so it may factor the Hessian
        that preconditions the next solves (:class:`.hessian_factor.LaggedHessian`).
        """
        targets = as_points("constrained_positions", constrained_positions, self.constrained.size)
        points = self.rest.copy() if initial is None else as_points("initial", initial, self.rest.shape[0]).copy()
        if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
            raise SkinDetachError(f"max_iter: expected a positive integer, got {max_iter!r}")
        if not (isinstance(tol, (int, float, np.floating)) and np.isfinite(tol) and tol >= 0):
            raise SkinDetachError(f"tol: expected a finite number >= 0, got {tol!r}")
        budget = None if budget_units is None else WorkBudget(budget_units)  # checks it
        motions = [np.eye(4)] * self.n_pulls if pull_motions is None else list(pull_motions)
        if len(motions) != self.n_pulls:
            raise SkinDetachError(f"pull_motions: expected {self.n_pulls} (4, 4) motions, got {len(motions)}")
        fixed_points = self.rest[self.fixed].copy()
        fixed_points[self._held_in_fixed] = targets
        start = points[self.fixed].copy()
        points[self.fixed] = fixed_points
        if self._lu is None:
            return DualLaplacianResult(points, 0, True, self.volume_change(points))
        if self.method == "rotated":
            if initial is None:  # from rest, bit for bit the same whatever was solved before
                self.energy_terms.reset()
                self._lagged.reset()
            work = budget if budget is not None else WorkBudget(1 << 62)  # counts an unbudgeted solve's work
            return self._continue_rotated(points, start, fixed_points, int(max_iter), float(tol), budget, work,
                                          bool(idle) and initial is not None, motions)
        known = self._a_fixed @ fixed_points
        if self.rigidity:
            known_edges = self._e_fixed @ fixed_points
            weight = np.sqrt(self.rigidity)
        keep_volume = self.volume.size > 0
        free = self.free

        def step(current):
            """One fixed-point update of the free vertices (n_free, 3) -> (n_free, 3)."""
            points[free] = current
            rhs = self._a_free_t @ (self.deltas(points) - known) + self._proximal * current
            if self.rigidity:
                rhs += self._e_free_t @ (weight * self.edge_targets(points) - known_edges)
            out = points.copy()
            out[free] = self._lu.solve(np.ascontiguousarray(rhs))
            if not keep_volume:
                return out[free]
            # The volume direction K^-1 grad V at this iterate (the map depends on ``current`` alone,
            # as Anderson acceleration needs).
            return self.volume.restore(out, self._volume_direction(points))[free]

        history = []
        converged = False
        accelerator = _Anderson(ANDERSON_WINDOW)
        current = points[free].copy()
        best, best_change, best_at = current, np.inf, 0
        for iterations in range(1, int(max_iter) + 1):
            mapped = step(current)
            residual = mapped - current
            change = largest_step(residual, self.diagonal)
            history.append(change)
            if change <= tol:
                current = mapped
                converged = True
                break
            if change < best_change:
                best, best_change, best_at = mapped, change, iterations
            elif iterations - best_at >= STALL_ITERATIONS:
                current = best  # cycling (e.g. a fold whose normals flip back and forth): keep the calmest
                break
            current = accelerator.next(current, mapped, change)
        points[free] = current
        return DualLaplacianResult(points, iterations, converged, self.volume_change(points), history)

    def energy(self, points):
        """The energy (module docstring) of ``points`` (m, 3), at the best rotations ("rotated" only)."""
        if self.method != "rotated":
            raise SkinDetachError(f"method: expected 'rotated' for an energy, got {self.method!r}")
        return self.energy_terms.energy(as_points("points", points, self.rest.shape[0]))

    def _solve_k(self, values):
        """K^-1 over the free vertices for ``values`` (f, j)."""
        return self._lu.solve(np.ascontiguousarray(values))

    def _continue_rotated(self, points, start, fixed_points, max_iter, tol, budget, work, refresh, motions):
        """Where the constrained vertices jump far from ``start`` (their positions in the initial
        guess), reach ``fixed_points`` through evenly spaced intermediate constraints, each
        solved loosely from the last (continuation), so a start from rest lands on the minimum a
        drag along the way would reach, not on a fold the first step happened to fall into. The
        stages start from rest, so the pulls' ``motions`` are staged from the identity alike.
        ``budget``: the :class:`.work_budget.WorkBudget` of the solve or None; ``work`` counts the
        work done (``budget`` itself when there is one)."""
        pulled = self.n_pulls > 0
        catch_up = budget is not None and not refresh  # a drag's move (see projected_newton.minimise)
        jump = float(np.abs(fixed_points - start).max()) / self.diagonal
        if jump > WARM_LIMIT:
            # Too far for the guess to say which stationary point is meant: start from rest, so the
            # same constraints give the same shape whatever was solved before.
            points = self.rest.copy()
            start = self.rest[self.fixed]
            jump = float(np.abs(fixed_points - start).max()) / self.diagonal
        stages = int(min(MAX_STAGES, np.ceil(jump / STAGE_JUMP)))
        volume = self.volume if self.volume.size else None
        for stage in range(1, stages):
            points[self.fixed] = start + (stage / stages) * (fixed_points - start)
            if pulled:
                self.energy_terms.set_motions([np.eye(4) + (stage / stages) * (motion - np.eye(4)) for motion in motions])
            staged = minimise(self.energy_terms, volume, self._solve_k, points, self.free, self.diagonal,
                              STAGE_TOL, max_iter, work, self._lagged, refresh, catch_up)
            points = staged.points
            if budget is not None and not staged.converged:
                # Out of budget: the handles where they belong, the rest where the stages got to; the
                # next call goes on from there.
                points[self.fixed] = fixed_points
                return DualLaplacianResult(points, staged.iterations, False, self.volume_change(points),
                                           staged.history, staged.energy)
        points[self.fixed] = fixed_points
        if pulled:
            self.energy_terms.set_motions(motions)
        result = minimise(self.energy_terms, volume, self._solve_k, points, self.free, self.diagonal, tol,
                          max_iter, work, self._lagged, refresh, catch_up)
        return DualLaplacianResult(result.points, result.iterations, result.converged,
                                   self.volume_change(result.points), result.history, result.energy)


def deform_proxy(proxy_vertices, proxy_faces, constrained_ids, constrained_positions, preserve_volume=True,
                 rigidity=None, method=DEFAULT_METHOD, **solve_options):
    """One-off solve: :class:`DualLaplacian` then :meth:`DualLaplacian.solve`."""
    solver = DualLaplacian(proxy_vertices, proxy_faces, constrained_ids, preserve_volume=preserve_volume,
                           rigidity=rigidity, method=method)
    return solver.solve(constrained_positions, **solve_options)
