"""The proxy solve's energy derivatives and its Newton iteration: exact Hessian products, the
certified stop, the per-move budget, and a start from rest that forgets what came before."""

import time

import numpy as np
from scipy.spatial.transform import Rotation
import pytest

from conftest import check_energy_derivatives, diagonal
from skin_detach_addon.core import DualLaplacian, SkinDetachedSurface, SkinDetachError
from skin_detach_addon.core.proxy_solve.hessian_factor import HessianFactor, LaggedHessian
from shapes import bend_constraints as bend


@pytest.fixture(scope="module")
def spot_proxy(bundled):
    points, tris = bundled("spot")
    sds = SkinDetachedSurface.build(points, tris, target_faces=300)
    return sds.proxy_vertices, sds.proxy_faces


def test_gradient_and_hessian_products_match_finite_differences(spot_proxy):
    points, tris = spot_proxy
    solver = DualLaplacian(points, tris, np.arange(0, points.shape[0], 9))
    rng = np.random.default_rng(1)
    x = points + 0.05 * diagonal(points) * rng.standard_normal(points.shape)
    direction = rng.standard_normal(points.shape)
    energy, h = solver.energy_terms, 1e-6
    check_energy_derivatives(energy, x, direction, h)
    volume = solver.volume
    bend_rate = (volume.gradient(x + h * direction) - volume.gradient(x - h * direction)) / (2 * h)
    weights = np.full(volume.size, 1.0)
    assert np.abs(bend_rate - volume.hessian_product(x, direction, weights)).max() <= 1e-6 * np.abs(bend_rate).max()


def test_the_energy_with_the_last_rotations_kept_bounds_it_from_above(spot_proxy):
    points, tris = spot_proxy
    solver = DualLaplacian(points, tris, np.arange(0, points.shape[0], 9))
    energy, rng = solver.energy_terms, np.random.default_rng(4)
    x = points + 0.05 * diagonal(points) * rng.standard_normal(points.shape)
    state = energy.at(x)
    assert energy.bound(state, x) == pytest.approx(state.energy, rel=1e-12)
    for size in (1e-4, 1e-2, 0.1):
        y = x + size * diagonal(points) * rng.standard_normal(points.shape)
        assert energy.bound(state, y) >= energy.energy(y) * (1 - 1e-12)
    # At rest with rest's rotations it is zero to rounding, from the residuals (no cancellation).
    assert energy.bound(energy.at(points), points) <= 1e-20 * energy.scale


@pytest.mark.parametrize("preserve_volume", [False, True])
def test_newton_converges_in_few_iterations_and_the_certificate_holds(spot_proxy, preserve_volume):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids, preserve_volume=preserve_volume)
    result = solver.solve(targets, max_iter=100, tol=1e-12)
    assert result.converged and result.iterations <= 30
    # Certified: continuing from the result moves no vertex by more than about sqrt(tol) of the diagonal.
    again = solver.solve(targets, initial=result.vertices, max_iter=100, tol=1e-16)
    assert np.abs(again.vertices - result.vertices).max() <= 1e-5 * diagonal(points)
    if preserve_volume:
        assert abs(result.volume_change) <= 1e-9


def test_a_budget_stops_a_solve_that_the_next_call_continues(spot_proxy):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids)
    cold = solver.solve(targets, max_iter=100, tol=1e-12)
    start = points.copy()
    start[ids] = targets
    partial = solver.solve(targets, initial=start, max_iter=100, tol=1e-12, budget_units=1)
    assert not partial.converged and partial.iterations == 1
    finished = solver.solve(targets, initial=partial.vertices, max_iter=100, tol=1e-12)
    assert finished.converged
    assert np.abs(finished.vertices - cold.vertices).max() <= 1e-5 * diagonal(points)
    with pytest.raises(SkinDetachError, match="budget_units: expected a positive integer, got 0"):
        solver.solve(targets, budget_units=0)


def test_a_start_from_rest_forgets_the_history(spot_proxy):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids)
    first = solver.solve(targets, max_iter=100, tol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(3):  # other poses in between, as a drag or another frame would solve
        solver.solve(targets + 0.05 * diagonal(points) * rng.standard_normal(targets.shape), max_iter=100, tol=1e-8)
    second = solver.solve(targets, max_iter=100, tol=1e-12)
    assert np.abs(second.vertices - first.vertices).max() <= 1e-9 * diagonal(points)


def test_crease_count_is_zero_at_rest_and_counts_a_fold():
    from bench.quality import creases
    from shapes import plane
    points, tris = plane(6)
    assert creases(points, points, tris) == 0
    folded = points.copy()
    right = folded[:, 0] > 0.5 * (folded[:, 0].min() + folded[:, 0].max())
    folded[right, 2] = folded[right, 0] - 0.5 * (folded[:, 0].min() + folded[:, 0].max())
    assert creases(points, folded, tris) > 0


def test_the_assembled_hessian_is_the_hessian_products_and_its_factor_solves_them(spot_proxy):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids)
    bent = solver.solve(targets, max_iter=100, tol=1e-12).vertices
    energy, free = solver.energy_terms, solver.free
    hessian = HessianFactor(energy, free, points.shape[0])
    state = energy.at(bent)
    direction = np.zeros_like(points)
    direction[free] = np.random.default_rng(4).standard_normal((free.size, 3))
    product = energy.hessian_product(state, direction)[free]
    assembled = (hessian.matrix(state) @ direction[free].ravel()).reshape(-1, 3)
    assert np.abs(assembled - product).max() <= 1e-12 * np.abs(product).max()
    factored = hessian.factor(state)  # at a minimum: positive definite
    assert factored is not None
    assert np.abs(factored.solve(product) - direction[free]).max() <= 1e-8 * np.abs(direction).max()


def test_the_rest_factor_is_held_until_a_refresh_and_a_reset_goes_back_to_it(spot_proxy):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids)
    lagged = solver._lagged
    residual = np.ones((solver.free.size, 3))
    rest_state = solver.energy_terms.at(points)
    assert lagged.at_rest and lagged.solver(rest_state) is not None
    at_rest = lagged.solver(rest_state)(residual)
    bent = solver.solve(targets, max_iter=100, tol=1e-12).vertices
    lagged.refresh(solver.energy_terms.at(bent))
    assert not lagged.at_rest
    assert np.abs(lagged.solver(rest_state)(residual) - at_rest).max() > 1e-6 * np.abs(at_rest).max()
    lagged.reset()
    assert lagged.at_rest
    assert np.abs(lagged.solver(solver.energy_terms.at(points))(residual) - at_rest).max() <= 1e-9 * np.abs(at_rest).max()


def test_the_factor_turns_with_the_vertices_it_is_used_at(spot_proxy):
    """A rigid turn R of a factored state: H there is W H W^T (W = diag(R)), so the turned rest
    factor solves the turned state's Hessian exactly, where the unturned one does not."""
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids)
    energy, free = solver.energy_terms, solver.free
    bent = solver.solve(targets, max_iter=100, tol=1e-12).vertices
    solver._lagged.refresh(energy.at(bent))
    turn = Rotation.from_rotvec(1.1 * np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])).as_matrix()
    turned_state = energy.at(bent @ turn.T)
    exact = HessianFactor(energy, free, points.shape[0]).factor(turned_state)
    residual = np.random.default_rng(7).standard_normal((free.size, 3))
    wanted = exact.solve(residual)
    turned = solver._lagged.solver(turned_state)(residual)
    assert np.abs(turned - wanted).max() <= 1e-7 * np.abs(wanted).max()
    unturned = LaggedHessian(HessianFactor(energy, free, points.shape[0]), energy.at(bent)).solver(turned_state)
    assert np.abs(unturned(residual) - wanted).max() > 0.1 * np.abs(wanted).max()


def _bent_start(spot_proxy):
    """(solver, targets, start): the bend's solver and targets, and rest with the handles moved."""
    points, tris = spot_proxy
    ids, targets = bend(points)
    start = points.copy()
    start[ids] = targets
    return DualLaplacian(points, tris, ids), targets, start


def test_conjugate_gradients_stop_past_the_budget_with_a_descent_step(spot_proxy):
    from skin_detach_addon.core.proxy_solve.projected_newton import CG_OVERRUN, _newton_step
    from skin_detach_addon.core.proxy_solve.work_budget import WorkBudget
    solver, targets, x = _bent_start(spot_proxy)
    state = solver.energy_terms.at(x)
    free = solver.free
    gradient = state.gradient[free]

    def hessian(p):
        full = np.zeros_like(x)
        full[free] = p
        return solver.energy_terms.hessian_product(state, full)[free]

    def precondition(r):
        return solver._solve_k(r)
    unlimited = _newton_step(hessian, precondition, gradient)
    spent = WorkBudget(1)
    spent.spend(2 + int(CG_OVERRUN))                          # spent, and past the overrun
    stopped = _newton_step(hessian, precondition, gradient, spent)
    assert stopped[2] == 1 < unlimited[2]                     # one Hessian product, then the budget
    assert np.sum(stopped[0] * gradient) < 0.0                # still a descent direction
    # Past the budget but not the overrun, CG goes on until what is left of the step is within tol.
    size = diagonal(spot_proxy[0])
    budget = WorkBudget(100)
    budget.spend(100)
    going_on = _newton_step(hessian, precondition, gradient, budget, tol=1e-6, diagonal=size)
    assert stopped[2] < going_on[2] <= unlimited[2] and budget.spent == 100 + going_on[2]
    assert np.sum(stopped[0] * gradient) > np.sum(going_on[0] * gradient)  # a longer descent
    moved = x.copy()
    partial = solver.solve(targets, initial=moved, max_iter=100, tol=1e-12, budget_units=1)
    assert partial.iterations == 1 and partial.energy[1] <= partial.energy[0]


def test_only_an_idle_solve_makes_the_hessian_factor_the_next_moves_precondition_with(spot_proxy):
    points = spot_proxy[0]
    solver, targets, start = _bent_start(spot_proxy)
    moved = solver.solve(targets, initial=start, max_iter=100, tol=1e-12, budget_units=10 ** 6)
    assert moved.converged and solver._lagged.at_rest   # a drag move never stalls on a factor
    settled = solver.solve(targets, initial=start, max_iter=100, tol=1e-12, budget_units=10 ** 6, idle=True)
    assert settled.converged and not solver._lagged.at_rest
    assert np.abs(settled.vertices - moved.vertices).max() <= 1e-5 * diagonal(points)


def test_a_failed_step_is_shortened_to_the_parabola_s_minimiser_within_a_tenth_to_a_half():
    from skin_detach_addon.core.proxy_solve.projected_newton import _shorter
    slope = -2.0
    for curvature, expected in ((4.0, 0.25), (1.5, 0.5), (100.0, 0.1)):  # E(a) - E(0) = slope a + c a^2
        rise = slope * 1.0 + curvature * 1.0
        assert _shorter(1.0, slope, rise) == pytest.approx(expected)
    assert _shorter(0.5, slope, slope * 0.5 + 4.0 * 0.25) == pytest.approx(0.25)  # the same parabola from 0.5
    assert _shorter(1.0, slope, slope - 1.0) == pytest.approx(0.5)  # curving down: halved


def _jumpy_clocks(monkeypatch, factor):
    """Make the wall clock and the thread's CPU clock run ``factor`` times fast, jumping on every
    read (another program taking the core, a slower machine)."""
    for name in ("perf_counter", "thread_time", "process_time"):
        real = getattr(time, name)
        ticks = iter(range(1, 1 << 30))
        monkeypatch.setattr(time, name, lambda real=real, ticks=ticks: factor * real() + next(ticks) * 1e-3)


def test_a_budget_in_work_units_gives_the_same_iterate_whatever_the_clock_does(spot_proxy, monkeypatch):
    points, tris = spot_proxy
    ids, targets = bend(points)
    start = points.copy()
    start[ids] = 0.5 * (points[ids] + targets)  # a move's start: the handles half way

    def moves(units):
        solver = DualLaplacian(points, tris, ids)
        results, x = [], start
        for k in range(1, 4):
            part = points[ids] + k / 3 * (targets - points[ids])
            results.append(solver.solve(part, initial=x, max_iter=100, tol=1e-12, budget_units=units))
            x = results[-1].vertices
        return results

    quiet = moves(12)
    _jumpy_clocks(monkeypatch, 1000.0)
    busy = moves(12)
    for a, b in zip(quiet, busy):
        assert np.array_equal(a.vertices, b.vertices) and a.iterations == b.iterations
    assert not quiet[-1].converged and moves(10 ** 6)[-1].converged  # the budget did stop it
    with pytest.raises(SkinDetachError, match="budget_units: expected a positive integer, got 0"):
        DualLaplacian(points, tris, ids).solve(targets, budget_units=0)


@pytest.mark.parametrize("preserve_volume", [False, True])
def test_a_budgeted_solve_never_ends_above_its_start_however_little_the_budget(spot_proxy, preserve_volume):
    points, tris = spot_proxy
    ids, targets = bend(points)
    solver = DualLaplacian(points, tris, ids, preserve_volume=preserve_volume)
    nearer = points.copy()
    nearer[ids] = points[ids] + 0.9 * (targets - points[ids])   # a move's start: one step from the targets
    for initial in (points, nearer):                           # a far jump (stages) and a near one
        at_targets = initial.copy()
        at_targets[ids] = targets
        for units in (1, 3, 10, 30, 100):
            result = solver.solve(targets, initial=initial, max_iter=100, tol=1e-12, budget_units=units)
            assert np.all(np.diff(result.energy) <= 0.0)              # no iterate above the one before
            assert solver.energy(result.vertices) <= solver.energy(at_targets)
            assert np.isfinite(result.vertices).all()


def test_a_drag_budget_is_a_fixed_number_of_units_scaled_by_the_solver_s_free_vertices(spot_proxy, monkeypatch):
    from skin_detach_addon.core.proxy_solve.work_budget import REFERENCE_FREE, scaled_units
    assert scaled_units(12, REFERENCE_FREE) == 12 and scaled_units(12, 3 * REFERENCE_FREE) == 4
    assert scaled_units(12, 100 * REFERENCE_FREE) == 1 and scaled_units(12, 0) >= 12  # at least one unit
    points, tris = spot_proxy
    ids, _ = bend(points)
    solver = DualLaplacian(points, tris, ids)
    before = solver.units(36)
    _jumpy_clocks(monkeypatch, 10.0)              # a machine ten times slower, or one busy with others
    assert DualLaplacian(points, tris, ids).units(36) == before == scaled_units(36, solver.free.size)


def test_a_slow_clock_settles_through_the_same_slices(spot_proxy, monkeypatch):
    from skin_detach_addon.core.proxy_solve.proxy_solves import DRAG_BUDGET_UNITS, SETTLE_SLICE_UNITS
    points, tris = spot_proxy
    ids, targets = bend(points)
    start = points.copy()
    start[ids] = points[ids] + 0.5 * (targets - points[ids])

    def settle():
        solver = DualLaplacian(points, tris, ids)
        moved = solver.solve(start[ids], initial=points, max_iter=100, tol=1e-8,
                             budget_units=solver.units(DRAG_BUDGET_UNITS))
        x, shown = moved.vertices, [moved.vertices]
        for _ in range(400):
            result = solver.solve(targets, initial=x, max_iter=100, tol=1e-12,
                                  budget_units=solver.units(SETTLE_SLICE_UNITS), idle=True)
            x = result.vertices
            shown.append(x)
            if result.converged:
                break
        return shown, result.converged

    quiet, settled = settle()
    _jumpy_clocks(monkeypatch, 10.0)              # every clock ten times slower, jumping on every read
    slow, _ = settle()
    assert settled and len(quiet) > 2 and len(slow) == len(quiet)
    assert all(np.array_equal(a, b) for a, b in zip(quiet, slow))
    cold = DualLaplacian(points, tris, ids).solve(targets, max_iter=100, tol=1e-12)
    assert np.abs(quiet[-1] - cold.vertices).max() <= 1e-5 * diagonal(points)


def test_a_settle_after_moves_that_needed_many_cg_steps_makes_the_factor_first(spot_proxy):
    from skin_detach_addon.core.proxy_solve.projected_newton import REFRESH_STEPS
    from bench.scenario import bend_scenario
    points, tris = spot_proxy
    scenario = bend_scenario(points, angle_degrees=120.0, shift_fraction=0.4)  # far: the rest factor struggles
    ids = np.concatenate([scenario.anchor_ids, scenario.handle_ids])
    targets = np.concatenate([points[scenario.anchor_ids], scenario.move(points[scenario.handle_ids])])
    solver = DualLaplacian(points, tris, ids)
    moved = solver.solve(targets, max_iter=100, tol=1e-8)  # the bend, every step preconditioned at rest
    assert solver._lagged.at_rest and solver._lagged.steps > REFRESH_STEPS  # a step's CG needed many steps
    # The least budget a settle slice gets: its first step is preconditioned by a factor made here.
    first = solver.solve(targets, initial=moved.vertices, max_iter=100, tol=1e-12, budget_units=1, idle=True)
    assert not solver._lagged.at_rest and solver._lagged.steps <= REFRESH_STEPS
    assert first.energy[-1] <= first.energy[0]


def test_a_proxy_with_every_vertex_constrained_solves_at_once_within_any_budget():
    from shapes import plane
    points, tris = plane(4)
    solver = DualLaplacian(points, tris, np.arange(points.shape[0]))
    result = solver.solve(points + 1.0, budget_units=12)
    assert result.converged and np.array_equal(result.vertices, points + 1.0)


def test_a_move_far_from_its_path_catches_up_past_its_budget_within_the_overrun(spot_proxy, monkeypatch):
    """A drag move (budgeted, not idle) whose Newton steps still move a vertex by more than
    CATCH_UP_STEP of the diagonal goes on past its budget, up to CATCH_UP_OVERRUN times it: the
    shown shape crosses a snap of the path with the moves, not in the settle after them; a settle
    slice (idle) keeps to its budget; counted in units, whatever the clock."""
    from skin_detach_addon.core.proxy_solve import projected_newton
    from skin_detach_addon.core.proxy_solve.projected_newton import CATCH_UP_OVERRUN, CATCH_UP_STEP
    points, tris = spot_proxy
    ids, targets = bend(points)
    start = points.copy()
    start[ids] = points[ids] + 0.8 * (targets - points[ids])   # the moves lag far behind the handles
    spent = []
    real = projected_newton.minimise

    def counted(*args, **kwargs):
        result = real(*args, **kwargs)
        spent.append(args[8].spent if len(args) > 8 else kwargs["budget"].spent)
        return result

    monkeypatch.setattr(projected_newton, "minimise", counted)
    import skin_detach_addon.core.proxy_solve.dual_laplacian as dual_laplacian
    monkeypatch.setattr(dual_laplacian, "minimise", counted)

    def solve(idle, catch_up=True):
        spent.clear()
        with monkeypatch.context() as patch:
            if not catch_up:
                patch.setattr(projected_newton, "CATCH_UP_STEP", 1e9)
            solver = DualLaplacian(points, tris, ids)
            result = solver.solve(targets, initial=start, max_iter=100, tol=1e-12, budget_units=12, idle=idle)
        return result, spent[-1]

    caught, caught_units = solve(idle=False)
    kept, kept_units = solve(idle=False, catch_up=False)
    sliced, sliced_units = solve(idle=True)
    cold = DualLaplacian(points, tris, ids).solve(targets, max_iter=100, tol=1e-12).vertices
    assert kept.history and np.sqrt(max(kept.history)) > CATCH_UP_STEP   # the first step was long
    assert caught.iterations > kept.iterations and caught_units > kept_units
    assert caught_units <= (1 + CATCH_UP_OVERRUN) * 12 + 12 * 8           # within the overrun (+ one CG overrun)
    assert np.abs(caught.vertices - cold).max() < np.abs(kept.vertices - cold).max()
    assert sliced.iterations <= kept.iterations + 1                        # a settle slice keeps its budget


def test_a_refresh_that_cannot_factor_waits_for_the_next_long_step_before_trying_again():
    """At a saddle H is indefinite and the settle's refresh makes no factor: it costs the factor's
    work all the same, so it is not tried again at the start of every slice (the ogre's settle
    spent 30 of each slice's 32 units on it) but after the next Newton step that needs more than
    REFRESH_STEPS conjugate-gradient steps."""
    from types import SimpleNamespace
    from skin_detach_addon.core.proxy_solve.projected_newton import REFRESH_STEPS
    tries = []
    indefinite = SimpleNamespace(factor=lambda state: tries.append(state))  # always None: not definite
    lagged = LaggedHessian(indefinite, "rest")
    lagged.steps = REFRESH_STEPS + 5
    assert lagged.refresh("saddle") is False and lagged.steps == 0 and lagged.solver("saddle") is None
    assert tries == ["rest", "saddle"]
