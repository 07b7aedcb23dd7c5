"""The proxy solves of one binding: which factored solver a solve uses and where it starts.

A solver is a :class:`DualLaplacian` factored for one constraint layout: the constrained proxy
ids (c,), whether the volume is preserved, and the held detail (a
:class:`..detached_surface.held_detail.Layout`). A solve follows on from the last two solutions
of its own layout (a drag) or starts from rest (the same handles give the same shape whatever was
solved before: Apply, bake).
"""

import numpy as np

from .dual_laplacian import DualLaplacian
from .pulled_energy import PullParts

#: Tolerance of the proxy solve while the mouse moves (api.DRAG_TOL: a Newton step of at
#: most 1e-4 of the diagonal, after which the shape is within about 1e-5 of the diagonal of the
#: stationary point) ...
DRAG_TOL = 1e-8
#: ... and when a result is kept (Apply, live update, confirm, bake).
SETTLE_TOL = 1e-12
#: Work of a drag move's solve, in units of :mod:`.work_budget` at a 1,000-face proxy (scaled by
#: the solver's free vertices, :meth:`DualLaplacian.units`; never read off a clock, so the same
#: events show the same shapes on any machine, busy or not): one Newton iteration (8 units) and
#: its conjugate gradients, no further iteration that would end past it; the conjugate gradients
#: go on past the budget while the rest of their step is over the tolerance, up to
#: projected_newton.CG_OVERRUN times it, so every move shows a shape near the path's; the next
#: move, or the settle while the mouse rests, continues from where it stopped. About 4 ms of one
#: core at 1,000 faces.
DRAG_BUDGET_UNITS = 12
#: Work, counted alike, of one slice of the settle while the mouse rests (a TIMER event): a new
#: Hessian factor (30 units) fits in one.
SETTLE_SLICE_UNITS = 36
#: Iterations a proxy solve may take before it reports that it did not converge.
MAX_ITERATIONS = 300
#: Factored solvers kept (one per constraint layout; the oldest goes first).
KEPT_SOLVERS = 8


def follow_start(recent, ids, targets):
    """(m, 3) where a drag's next solve starts, or None (from rest) without ``recent`` solutions
    (newest first, :class:`DualLaplacianResult`) of the same constrained ``ids`` (c,); ``targets``
    (c, 3) their new positions. The targets stand still (a settle, a confirm): the last solution,
    to go on from. They moved: the last solution plus the motion between the last two, scaled down
    so that no vertex is carried farther than the constrained vertices move now. An unbounded
    extrapolation 2 x1 - x2 doubles whatever jump the last solve made, also one the budget cut
    short or a snap of the energy's own path, and feeds it back: the shown shape flailed. Bounded,
    the start adds no more than the handles' own motion to any vertex."""
    if not recent:
        return None
    last = recent[0].vertices
    if len(recent) < 2 or np.array_equal(last[ids], targets):
        return last
    motion = last - recent[1].vertices
    largest = float(np.sqrt(np.max(np.einsum("ij,ij->i", motion, motion))))
    handles = float(np.sqrt(np.max(np.einsum("ij,ij->i", targets - last[ids], targets - last[ids]))))
    if largest <= 0.0:
        return last
    return last + min(1.0, handles / largest) * motion


class ProxySolves:
    """The solves of the proxy of ``surface`` (a
    :class:`..detached_surface.surface.SkinDetachedSurface`, m proxy vertices): a
    :class:`DualLaplacian` per constraint layout (the last :data:`KEPT_SOLVERS`), each with its
    recent results (newest first, at most two) that a following solve starts from."""

    def __init__(self, surface, pulls_of=None):
        self.surface = surface
        #: ``pulls_of(layout)``: the drop-row matrices (s_h, m) of each pair of ``layout.owned``
        #: (None: the surface's own,
        #: :meth:`..detached_surface.surface.SkinDetachedSurface.drop_rows`).
        self._pulls_of = pulls_of if pulls_of is not None else (
            lambda layout: surface.drop_rows([detail for _, detail in layout.owned], layout.groups))
        #: (ids bytes, preserve_volume, layout key) -> [DualLaplacian, recent results].
        self._solvers = {}
        #: Each pull's own parts, shared by the layouts' solvers (a new handle's pulls are made).
        self._pull_parts = PullParts()

    def solve(self, ids, targets, preserve_volume, tol, follow=False, budget=None, idle=False, layout=None,
              motions=()):
        """:class:`DualLaplacianResult` for the constrained proxy ids (c,) at ``targets`` (c, 3),
        the held detail of ``layout`` (a :class:`..detached_surface.held_detail.Layout`; each vertex
        by the group that owns it, :attr:`~..detached_surface.held_detail.Layout.owned`) pulled
        along ``motions`` (one (4, 4) per pair of ``layout.held``). With ``follow`` the solve starts
        from :func:`follow_start` of the last two solutions of the same layout, as a drag does, and
        stops after ``budget`` units of work at a 1,000-face proxy (:meth:`DualLaplacian.units`;
        None: no limit; ``idle``: see :meth:`DualLaplacian.solve`);
        without it from rest, so the same handles give the same shape whatever was solved before."""
        key = self.prepare(ids, preserve_volume, layout)
        solver, recent = self._solvers[key]
        initial = follow_start(recent, ids, targets) if follow else None
        result = solver.solve(targets, initial=initial, max_iter=MAX_ITERATIONS, tol=tol,
                              budget_units=solver.units(budget) if follow and budget is not None else None,
                              idle=idle and follow,
                              pull_motions=list(motions) if solver.n_pulls else None)
        self._solvers[key][1] = [result] + recent[:1]
        return result

    def prepare(self, ids, preserve_volume, layout=None):
        """Factor the solver of the constrained proxy ids (c,) with ``layout`` (see :meth:`solve`)
        unless it is kept already (the first solve of a layout then starts at once); returns its key."""
        key = (ids.tobytes(), bool(preserve_volume), None if layout is None else layout.key())
        if key not in self._solvers:
            if len(self._solvers) >= KEPT_SOLVERS:
                self._solvers.pop(next(iter(self._solvers)))
            pulls = [] if layout is None else self._pulls_of(layout)
            self._solvers[key] = [DualLaplacian(self.surface.proxy_vertices, self.surface.proxy_faces, ids,
                                                preserve_volume=preserve_volume, pulls=pulls,
                                                pull_parts=self._pull_parts), []]
        return key

    def forget_warm_starts(self):
        """Drop every layout's recent results: the next solve of each starts from rest."""
        for entry in self._solvers.values():
            entry[1] = []
