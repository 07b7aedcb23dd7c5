"""The iteration of the proxy solve: Newton's method on the rotated energy, projected onto the
volume constraint.

Arrays: ``points`` (m, 3) indexed by proxy vertex; ``free`` (f,) the ids of the vertices that
move (the others are held at their given positions); every step is an (f, 3) array.

Minimises E(X) (:class:`.rotated_energy.RotatedEnergy`) over the free vertices subject to every
kept closed component keeping its rest volume (:class:`.volume_constraint.VolumeConstraint`).
Each iteration solves the Newton system of the Lagrangian, H_L p = -(grad E + sum_s lambda_s
grad V_s) on the constraint's tangent space, by conjugate gradients preconditioned with P^-1
projected onto the tangent space (projected preconditioned CG); the multipliers are the
least-squares ones in the P^-1 metric. P is the energy's Hessian factored at a recent iterate
(:class:`.hessian_factor.LaggedHessian`, when it is positive definite there, turned by the
vertices' rotations since) or else K (the
factor of the energy's quadratic part, held by the caller). CG
stops at the relative residual :data:`FORCING` or on negative curvature (then the step so far, or
the preconditioned gradient, is still a descent direction). A backtracking line search on E
(after restoring the volumes along P^-1 grad V) accepts a step only when E has not risen, by the
Armijo rule (a failed trial shortened to the minimiser of the parabola through it, within 0.1-0.5
of it), so E never rises from one iterate to the next; it first tries the rule on E with the
last iterate's rotations kept (an upper bound of E: no rotation fit), and fits them only where
that bound is not low enough or the next iteration needs them.

Convergence (the certificate): the distance to the stationary point is estimated by the Newton
step, which at a point where the Hessian is positive definite (no negative curvature met) is the
error to second order. The solve has converged when a full Newton step's largest vertex move,
squared over the squared bounding-box diagonal, is at most ``tol``: either the step proposed at
the current point, or the full step just taken (the error after it is then a fraction FORCING of
it, plus its square).
"""

from dataclasses import dataclass, field

import numpy as np

from .work_budget import FACTOR_UNITS, ITERATION_UNITS

#: CG stops when its residual (in the P^-1 metric) is this fraction of the gradient's ...
FORCING = 0.05
#: ... or after this many iterations.
CG_ITERATIONS = 200
#: Past the budget, CG goes on while the rest of its step (P^-1 of its residual) would still
#: move a vertex by more than the tolerance, up to this many times the budget more: a move that
#: stopped with most of its Newton step undone showed a shape lagging behind, and the next
#: move's extrapolation carried the lag on (the shown shape flailed).
CG_OVERRUN = 2.0
#: In a solve that may refresh the lagged Hessian (a drag's settle while the mouse rests), more CG
#: steps than this make a new factor (about 30 CG steps' cost, .work_budget.FACTOR_UNITS: more
#: than it saves within one settle, so a settle without a drag never makes one): at its start
#: when a Newton step since the factor was made needed more (the drag's moves did: the first
#: slice's CG with the old factor took 30 steps and still left the shape 2e-2 of the diagonal
#: off on cow), else after such a step. 8, not 4: on the cow, whose converged path snaps late in
#: the benchmark's turn, 4 made a factor in each of the first slices (95 units to 1e-3 of the
#: diagonal, 65 with 8; the same on four other meshes).
REFRESH_STEPS = 8
#: A drag move (``catch_up``) whose accepted Newton step moved a vertex by more than this fraction of
#: the diagonal is far from its path's shape (the converged path snapped: the kept volume's pose
#: changed branch, 0.1-0.2 of the diagonal within a move or two on cow) and goes on past its
#: budget, an iteration at a time, while its steps stay that long ...
CATCH_UP_STEP = 1e-2
#: ... up to this many times its budget in all. Budgeted moves of one Newton iteration each took
#: 10+ moves to cross such a snap, and the settle 8-10 slices after them (a release that pops
#: when the mouse rests less long, or the machine is busy); now the snap's moves take longer
#: (a few frames), and the shape shown crosses it with them.
CATCH_UP_OVERRUN = 6.0
#: Armijo's sufficient decrease, and the shortenings of the step at most.
ARMIJO = 1e-4
BACKTRACKS = 20


@dataclass
class NewtonResult:
    """points (m, 3); iterations; converged; history (iterations,) largest squared vertex move of
    each accepted step over the squared diagonal; energy (iterations + 1,) E at the start and
    after every iteration (or the upper bound of it the line search accepted the step on: E with
    the rotations of the iterate before; never above the entry before it)."""

    points: np.ndarray
    iterations: int
    converged: bool
    history: list = field(default_factory=list)
    energy: list = field(default_factory=list)


def largest_step(step, diagonal):
    """Largest squared vertex move of ``step`` (r, 3) over the squared bounding-box diagonal."""
    return float(np.max(np.einsum("ij,ij->i", step, step))) / diagonal ** 2 if step.size else 0.0


class _Tangent:
    """The volume constraint seen from the free vertices at one iterate: its gradients ``a`` (f, 3),
    ``d`` = P^-1 a, and the projection of P^-1-preconditioned vectors onto the tangent space."""

    def __init__(self, volume, points, free, solve_p):
        self.volume = volume
        self.free = free
        self.slot = volume.slot[free]
        self.mask = volume.in_kept[free]
        self.a = volume.gradient(points)[free] * self.mask[:, None]
        self.d = solve_p(self.a)
        self.ad = self._sums(np.einsum("ij,ij->i", self.a, self.d))
        self.ad = np.where(np.abs(self.ad) > 1e-300, self.ad, 1.0)

    def _sums(self, values):
        return np.bincount(self.slot[self.mask], weights=values[self.mask], minlength=self.volume.size)

    def coefficients(self, y):
        """(c,) per component, a . y / a . d: the share of P^-1 a in ``y`` (f, 3)."""
        return self._sums(np.einsum("ij,ij->i", self.a, y)) / self.ad

    def project(self, y):
        """``y`` (f, 3), a P^-1-preconditioned vector, less its part along d: a . result = 0."""
        return y - (self.coefficients(y)[self.slot] * self.mask)[:, None] * self.d

    def direction(self, m):
        """(m, 3) d on the free vertices, zero elsewhere: the direction volumes are restored along."""
        out = np.zeros((m, 3))
        out[self.free] = self.d
        return out


def minimise(energy, volume, solve_k, points, free, diagonal, tol, max_iter, budget=None, lagged=None,
             refresh=False, catch_up=False):
    """Projected Newton (module docstring) from ``points`` (m, 3), whose free rows are the start
    and whose other rows are held. ``volume``: a VolumeConstraint with at least one kept component,
    or None; ``solve_k(r (f, j)) -> (f, j)`` applies K^-1 over the free vertices; ``budget``: a
    :class:`.work_budget.WorkBudget` (None: no limit) that every iteration spends its work from
    and that no iteration should end past (one that would, costing as many units as the last, is
    not started; the first always runs); ``lagged``: a
    :class:`.hessian_factor.LaggedHessian` whose factor preconditions instead of K's when it has
    one; with ``refresh``, it is made anew at the start when a Newton step it preconditioned
    needed more than :data:`REFRESH_STEPS` CG steps (:attr:`~.hessian_factor.LaggedHessian.steps`),
    else at the step accepted after CG needed that many (without, the solve is a function of its
    start and the factor it is given); a refresh spends :data:`.work_budget.FACTOR_UNITS`.
    ``catch_up`` (a drag's move): past the budget, an iteration whose accepted step moved a vertex
    by more than :data:`CATCH_UP_STEP` of the diagonal is followed by another, up to
    :data:`CATCH_UP_OVERRUN` times the budget (counted in units: the same iterates on any machine).
    Returns :class:`NewtonResult`: its energy never rises from one iterate to the next, however
    little the budget."""
    x = points.copy()
    m = x.shape[0]
    if volume is not None:
        x = volume.restore(x, _Tangent(volume, x, free, solve_k).direction(m))
    state = energy.at(x)
    if refresh and lagged is not None and lagged.steps > REFRESH_STEPS:
        lagged.refresh(state)
        if budget is not None:
            budget.spend(FACTOR_UNITS)
    history, energies = [], [state.energy]
    converged, iterations = False, 0
    most = None if budget is None else (1.0 + CATCH_UP_OVERRUN) * budget.units
    for iterations in range(1, max_iter + 1):
        begun = 0 if budget is None else budget.spent
        if budget is not None:
            budget.spend(ITERATION_UNITS)
        solve_p = (lagged.solver(state) if lagged is not None else None) or solve_k
        tangent = _Tangent(volume, x, free, solve_p) if volume is not None else None
        gradient = state.gradient[free]
        if tangent is not None:
            multipliers = -tangent.coefficients(solve_p(gradient))
            gradient = gradient + (multipliers[tangent.slot] * tangent.mask)[:, None] * tangent.a

        volume_product = volume.hessian_at(x, multipliers) if tangent is not None else None

        def hessian(p):
            full = np.zeros((m, 3))
            full[free] = p
            out = energy.hessian_product(state, full)
            if volume_product is not None:
                out += volume_product(full)
            return out[free]

        def precondition(r):
            y = solve_p(r)
            return y if tangent is None else tangent.project(y)

        step, negative, steps = _newton_step(hessian, precondition, gradient, budget, tol, diagonal)
        if lagged is not None:
            lagged.steps = max(lagged.steps, steps)
        proposed = largest_step(step, diagonal)
        slope = float(np.sum(gradient * step))
        if slope >= 0.0 or not np.isfinite(slope):
            converged = not negative and proposed <= tol
            iterations -= 1
            break
        # Backtracking on E from the full step; volumes restored along P^-1 grad V at x.
        direction = tangent.direction(m) if tangent is not None else None
        length, accepted, accepted_energy, accepted_state = 1.0, None, None, None
        for _ in range(BACKTRACKS):
            trial = x.copy()
            trial[free] += length * step
            if direction is not None:
                trial = volume.restore(trial, direction)
            target = state.energy + ARMIJO * length * slope
            bound = energy.bound(state, trial)  # E with x's rotations kept: at least E(trial)
            if bound <= target:
                accepted, accepted_energy = trial, bound
                break
            trial_state = energy.at(trial)
            if trial_state.energy <= target:
                accepted, accepted_energy, accepted_state = trial, trial_state.energy, trial_state
                break
            if proposed * length * length <= tol * 1e-4:
                break
            length = _shorter(length, slope, trial_state.energy - state.energy)
        if accepted is None:  # no decrease left to find along the step: x is as good as it gets
            converged = not negative and proposed <= tol
            iterations -= 1
            break
        moved = largest_step(accepted[free] - x[free], diagonal)
        x = accepted
        history.append(moved)
        energies.append(accepted_energy)
        converged = not negative and length == 1.0 and moved <= tol
        # The next one, costing as much as this one, would end past the budget: stop (before
        # fitting the rotations at x).
        cost = 0 if budget is None else budget.spent - begun
        last = converged or (budget is not None and budget.would_pass(cost) and not (
            catch_up and moved > CATCH_UP_STEP ** 2 and budget.make_room(cost, most)))
        # A Hessian with negative curvature would not factor positive definite: no refresh then.
        refreshing = refresh and lagged is not None and not negative and not converged and steps > REFRESH_STEPS
        if not last or refreshing:
            state = accepted_state if accepted_state is not None else energy.at(x)
        if refreshing:
            lagged.refresh(state)
            if budget is not None:
                budget.spend(FACTOR_UNITS)
        if last:
            break
    return NewtonResult(x, iterations, converged, history, energies)


def _shorter(length, slope, rise):
    """The next step length of the backtracking after ``length`` failed Armijo's rule: the minimiser
    of the parabola through E's change ``rise`` there with the ``slope`` of the full step at 0,
    kept within 0.1 to 0.5 of ``length`` (a step much too long, as after negative curvature,
    shrinks tenfold a trial instead of twofold)."""
    excess = rise - slope * length  # > 0: the parabola curves up
    guess = -slope * length * length / (2.0 * excess) if excess > 0.0 else 0.5 * length
    return min(max(guess, 0.1 * length), 0.5 * length)


def _newton_step(hessian, precondition, gradient, budget=None, tol=0.0, diagonal=1.0):
    """Approximate solution of H p = -gradient (f, 3) by preconditioned conjugate gradients, each
    step one unit of ``budget`` (a :class:`.work_budget.WorkBudget`, None: no limit), stopped
    early once it is spent (every CG iterate is a descent direction) and the rest of the step, the
    preconditioned residual, moves no vertex by more than ``tol`` (squared, over the squared
    ``diagonal``), or past :data:`CG_OVERRUN` times the budget more regardless. Returns (p,
    whether negative curvature was met, the number of Hessian products)."""
    residual = -gradient
    z = precondition(residual)
    rz = float(np.sum(residual * z))
    start = rz
    step = np.zeros_like(gradient)
    direction = z
    negative = False
    for k in range(CG_ITERATIONS):
        steps = k + 1
        product = hessian(direction)
        if budget is not None:
            budget.spend(1)
        curvature = float(np.sum(direction * product))
        if curvature <= 0.0:
            negative = True
            if k == 0:
                step = direction  # the preconditioned steepest descent direction
            break
        alpha = rz / curvature
        step = step + alpha * direction
        residual = residual - alpha * product
        z = precondition(residual)
        rz_next = float(np.sum(residual * z))
        if rz_next <= FORCING ** 2 * start:
            break
        if budget is not None and budget.over and (budget.past(CG_OVERRUN) or largest_step(z, diagonal) <= tol):
            break
        direction = z + (rz_next / rz) * direction
        rz = rz_next
    return step, negative, steps
