"""Headless bpy: the drag session under fake mouse events, live update, registration."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import TopView, activate, band, import_spot, rig  # noqa: E402

import skin_detach_addon  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.ui import live_update  # noqa: E402
from skin_detach_addon.blender.drag_session import CANCELLED, FINISHED, RUNNING, DragSession  # noqa: E402


def _state(obj):
    proxy = binding.proxy_of(obj)
    return (mesh_io.snapshot(obj.data)[0], mesh_io.snapshot(proxy.data)[0],
            [np.array(child.matrix_basis) for child in proxy.children], binding.written_state(obj)[0])


def _same(a, b):
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert all(np.array_equal(x, y) for x, y in zip(a[2], b[2]))
    assert a[3] == b[3]


def test_drag_moves_in_the_view_plane_and_cancel_restores_bit_exact(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    before = _state(obj)
    rest = mesh_io.read_positions(obj.data)
    session = DragSession(obj, handle, TopView(0.01), (100, 100))
    start = np.array(handle.matrix_world)
    assert session.event("MOUSEMOVE", "NOTHING", (120, 90)) == RUNNING
    moved = np.array(handle.matrix_world)
    assert np.allclose(moved[:3, 3] - start[:3, 3], (0.2, -0.1, 0.0), atol=1e-6)
    assert np.abs(mesh_io.read_positions(obj.data) - rest).max() > 0.05
    assert "ms/step" in session.header
    assert session.event("ESC", "PRESS", (120, 90)) == CANCELLED
    _same(_state(obj), before)


def test_drag_axis_and_rotate_keys_then_confirm(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    start = np.array(handle.matrix_world)
    session.event("X", "PRESS", (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (30, 50))
    moved = np.array(handle.matrix_world)
    assert np.allclose(moved[:3, 3] - start[:3, 3], (0.3, 0.0, 0.0), atol=1e-6)
    session.event("X", "PRESS", (30, 50))           # free again, the 0.3 along X is kept
    session.event("R", "PRESS", (30, 50))           # rotate about the view axis (world Z here)
    centre = np.array(session.view.to_screen(handle.matrix_world.to_translation()))
    radius = np.array((30, 50)) - centre
    quarter = centre + np.array((-radius[1], radius[0]))
    session.event("MOUSEMOVE", "NOTHING", tuple(quarter))
    turned = np.array(handle.matrix_world)
    assert np.allclose(turned[:3, :3], np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ start[:3, :3], atol=1e-5)
    assert np.allclose(turned[:3, 3], moved[:3, 3], atol=1e-5)
    assert session.event("RET", "PRESS", tuple(quarter)) == FINISHED
    result = mesh_io.read_positions(obj.data)
    assert np.abs(result - rest).max() > 0.1
    assert binding.open_binding(obj) is not None
    binding.check_unedited(obj)  # the confirmed shape is what Skin Detach wrote


def _turn_of(before, after):
    """(3, 3) rotation taking the world matrix ``before`` to ``after``."""
    return np.array(after)[:3, :3] @ np.linalg.inv(np.array(before)[:3, :3])


def test_a_mode_switch_keeps_what_the_typed_number_did_and_clears_it(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.matrix_world.copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    for key in ("R", "THREE", "ZERO"):                    # R 30: a turn of 30 degrees
        session.event(key, "PRESS", (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (50, 50))       # ignored while the number is typed
    turned = _turn_of(start, handle.matrix_world)
    session.event("G", "PRESS", (50, 50))                 # G: the turn is kept, "30" is no 30-unit move
    assert session.typed == "" and "typed" not in session.header
    assert np.allclose(_turn_of(start, handle.matrix_world), turned, atol=1e-5)
    assert np.allclose(np.array(handle.matrix_world)[:3, 3], np.array(start)[:3, 3], atol=1e-5)
    session.event("MOUSEMOVE", "NOTHING", (60, 50))       # the mouse moves it from where it is now
    assert np.allclose(np.array(handle.matrix_world)[:3, 3] - np.array(start)[:3, 3], (0.1, 0.0, 0.0), atol=1e-5)
    session.event("X", "PRESS", (60, 50))                  # an axis for the move: the turn stays about the view axis
    assert np.allclose(_turn_of(start, handle.matrix_world), turned, atol=1e-5)
    session.event("TWO", "PRESS", (60, 50))                # 2 along X, on top of the mouse's 0.1
    session.event("S", "PRESS", (60, 50))                  # S: the move is kept, the scale starts at 1
    assert session.typed == ""
    assert np.allclose(np.array(handle.matrix_world)[:3, 3] - np.array(start)[:3, 3], (2.1, 0.0, 0.0), atol=1e-5)
    assert np.allclose(_turn_of(start, handle.matrix_world), turned, atol=1e-5)
    assert session.event("RET", "PRESS", (60, 50)) == FINISHED
    angle = np.degrees(np.arccos((np.trace(turned) - 1) / 2))
    assert abs(angle - 30.0) < 1e-3


def test_typed_r_turns_as_blenders_r_clockwise_seen_from_the_view(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.matrix_world.copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))   # looking down -Z
    for key in ("R", "NINE", "ZERO"):
        session.event(key, "PRESS", (0, 0))
    # Blender's R 90 in a top view: rotation Z -90 degrees (clockwise seen from above).
    assert np.allclose(_turn_of(start, handle.matrix_world), [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-5)
    session.event("Z", "PRESS", (0, 0))                    # R Z 90: +90 about Z, as Blender's R Z 90
    assert np.allclose(_turn_of(start, handle.matrix_world), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-5)
    assert session.event("ESC", "PRESS", (0, 0)) == CANCELLED


def test_drag_operator_scripted_path_moves_the_active_handle(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data)
    top = band(obj, 0.85, 1.0, axis=1)
    activate(handle)
    assert bpy.ops.skin_detach.drag(offset=(0.0, 0.0, 0.25)) == {'FINISHED'}
    world = np.array(obj.matrix_world)
    local = np.linalg.solve(world[:3, :3], np.array((0.0, 0.0, 0.25)))
    assert np.allclose(mesh_io.read_positions(obj.data)[top] - rest[top], local, atol=1e-5)


def test_live_update_follows_moves_and_frame_changes(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data)
    handle.location.x += 0.2
    bpy.context.view_layer.update()
    assert live_update.pending() == set()          # off: nothing is watched
    scene.skin_detach.live_update = True
    bpy.context.view_layer.update()
    assert live_update.pending() == {obj.name}
    live_update.flush()                             # what the timer runs
    first = mesh_io.read_positions(obj.data)
    assert np.abs(first - rest).max() > 0.1
    bpy.context.view_layer.update()                 # its own write does not queue another solve
    assert live_update.pending() == set()

    handle.keyframe_insert("location", frame=1)
    handle.location.x += 0.2
    handle.keyframe_insert("location", frame=10)
    live_update.flush()
    scene.frame_set(10)
    assert live_update.pending() == {obj.name}
    live_update.flush()
    assert np.abs(mesh_io.read_positions(obj.data) - first).max() > 0.1
    scene.frame_set(1)
    live_update.flush()
    assert np.abs(mesh_io.read_positions(obj.data) - first).max() <= 5e-5


def test_unregister_leaves_nothing_behind(scene):
    import threading
    from skin_detach_addon.core import threads
    scene.skin_detach.live_update = True
    threads.pool().submit(sum, [1, 2]).result()              # the core's worker threads are running
    skin_detach_addon.unregister()
    try:
        assert not [t.name for t in threading.enumerate() if t.name.startswith("skin_detach")]
        handlers = bpy.app.handlers
        lists = [getattr(handlers, name) for name in dir(handlers) if isinstance(getattr(handlers, name), list)]
        modules = [f.__module__ for functions in lists for f in functions]
        assert len(lists) > 10 and not any(module.startswith("skin_detach_addon") for module in modules)
        assert not hasattr(bpy.types, "VIEW3D_MT_skin_detach")
        assert not hasattr(bpy.types.Scene, "skin_detach")
        assert not hasattr(bpy.types, "SKIN_DETACH_OT_build") and not hasattr(bpy.types, "VIEW3D_PT_skin_detach")
        assert not bpy.app.timers.is_registered(live_update.flush)
    finally:
        skin_detach_addon.register()


def test_drag_confirm_writes_what_the_last_move_showed_and_apply_forgets_the_path(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    session = DragSession(obj, handle, TopView(0.01), (100, 0))
    for k in range(1, 16):
        session.event("MOUSEMOVE", "NOTHING", (100 + 2 * k, k))
    shown = mesh_io.read_positions(obj.data).astype(np.float64)
    assert session.event("RET", "PRESS", (130, 15)) == FINISHED and session.last.converged
    written = mesh_io.read_positions(obj.data).astype(np.float64)
    size = np.ptp(written, axis=0).max()
    assert np.abs(written - shown).max() <= 2e-3 * size
    from skin_detach_addon import api
    pose = handle.matrix_world.copy()
    api.deform(obj)
    applied = mesh_io.read_positions(obj.data).copy()
    handle.location.x += 0.3
    api.deform(obj)
    handle.matrix_world = pose
    api.deform(obj)
    assert np.abs(mesh_io.read_positions(obj.data) - applied).max() <= 1e-6 * size


def test_the_object_menus_list_every_operator(scene):
    """F3 searches menus: every operator of the add-on is in the Skin Detach menu (or its
    submenus), which the Object menu and, in Edit Mode, the Mesh menu hold."""
    from skin_detach_addon import api, ui
    from skin_detach_addon.ui import menus
    obj = import_spot()
    rig(obj, axis=1)
    activate(obj)
    drawn = []

    class Layout:
        def operator(self, idname, **_):
            drawn.append(idname)
            return type("Properties", (), {})()

        def menu(self, idname, **_):
            getattr(bpy.types, idname).draw(type("Menu", (), {"layout": self})(), bpy.context)

        def operator_menu_enum(self, idname, prop, **_):  # a submenu of the operator's choices
            drawn.append(idname)

        def separator(self):
            pass

        def label(self, **_):
            pass

    menus.VIEW3D_MT_skin_detach.draw(type("Menu", (), {"layout": Layout()})(), bpy.context)
    operators = {cls.bl_idname for cls in ui.CLASSES if issubclass(cls, bpy.types.Operator)}
    assert operators - set(drawn) == set(), f"not in the menus (F3 cannot find them): {operators - set(drawn)}"
    assert drawn.count("skin_detach.select_handle") == len(api.handles_of(obj))
    for name in ("VIEW3D_MT_object", "VIEW3D_MT_object_context_menu", "VIEW3D_MT_edit_mesh"):
        assert menus._menu_entry in getattr(bpy.types, name)._dyn_ui_initialize()


def _quick_turn(monkeypatch):
    """(obj, session) after a quick R turn of spot's handle in moves that stop after one Newton
    iteration each, as on a large proxy (the first always runs): the moves cannot keep up."""
    from skin_detach_addon.blender import drag_session
    monkeypatch.setattr(drag_session, "DRAG_BUDGET_UNITS", 1)
    obj = import_spot()
    handle = rig(obj, axis=1)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("R", "PRESS", (0, 0))
    for k in range(1, 9):
        session.event("MOUSEMOVE", "NOTHING", (-20 * k, 100))
    return obj, session


def test_timer_events_settle_the_drag_while_the_mouse_rests_and_confirm_writes_what_was_shown(scene, monkeypatch):
    from skin_detach_addon.blender.deformation import Deformation
    obj, session = _quick_turn(monkeypatch)
    assert not session.settled and "settling" in session.header
    moves = len(session.step_ms)
    for _ in range(200):
        if session.settled:
            break
        assert session.event("TIMER", "NOTHING", (-160, 100)) == RUNNING
    assert session.settled and "settled" in session.header and session.last.converged
    assert len(session.step_ms) == moves                     # a settle slice is no move
    shown = mesh_io.read_positions(obj.data).copy()
    session.event("TIMER", "NOTHING", (-160, 100))           # settled: nothing more to do
    assert np.array_equal(mesh_io.read_positions(obj.data), shown)
    assert session.event("LEFTMOUSE", "PRESS", (-160, 100)) == FINISHED
    assert np.array_equal(mesh_io.read_positions(obj.data), shown)  # no pop: the settled shape as shown
    Deformation(obj)                                          # the digest is marked: not "edited since"


def test_a_drag_confirmed_before_it_settled_is_settled_by_the_confirm(scene, monkeypatch):
    _, session = _quick_turn(monkeypatch)
    assert not session.settled
    assert session.event("RET", "PRESS", (-160, 100)) == FINISHED and session.last.converged


def test_timer_events_before_any_move_do_nothing_and_cancel_after_a_settle_restores_bit_exact(scene, monkeypatch):
    from skin_detach_addon.blender import drag_session
    monkeypatch.setattr(drag_session, "DRAG_BUDGET_UNITS", 1)
    obj = import_spot()
    handle = rig(obj, axis=1)
    before = _state(obj)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    assert session.event("TIMER", "NOTHING", (0, 0)) == RUNNING and session.last is None
    _same(_state(obj), before)
    session.event("MOUSEMOVE", "NOTHING", (40, 30))
    for _ in range(50):
        session.event("TIMER", "NOTHING", (40, 30))
    assert session.event("ESC", "PRESS", (40, 30)) == CANCELLED
    _same(_state(obj), before)


def _slow_clocks(patch, factor):
    """Every clock the add-on could read runs ``factor`` times slower and jumps on every read (a
    slower machine, another program taking the core between reads)."""
    import time
    for name in ("perf_counter", "thread_time", "process_time", "monotonic", "time"):
        real, ticks = getattr(time, name), iter(range(1, 1 << 40))
        patch.setattr(time, name, lambda real=real, ticks=ticks: factor * real() + next(ticks) * 1e-3)


def _benchmark_drag():
    import pathlib
    import sys
    scripts = str(pathlib.Path(__file__).resolve().parent.parent / "scripts")
    sys.path.insert(0, scripts)
    try:
        import benchmark_drag
    finally:
        sys.path.remove(scripts)
    return benchmark_drag


def test_the_same_events_show_the_same_shapes_with_a_core_busy_and_every_clock_ten_times_slower(scene, monkeypatch):
    """A drag's shown shapes are a function of its events: a scan (beast, thin limbs, 32K, not
    subdivided) turned by R in 20 moves, then 6 TIMER events (the settle), once quiet and once
    with a process spinning on a core and every clock ten times slower: bit for bit the same
    after every move and every slice (the moves' budgets were milliseconds turned into units at
    the measured CPU time per unit: a busy or slow machine did fewer)."""
    import math
    from bench.views import AxisView
    bench = _benchmark_drag()
    points, triangles = bench.mesh("beast")
    axis = bench.view_axis(points)
    size = float(np.linalg.norm(np.ptp(points, axis=0)))

    def drag(busy):
        with monkeypatch.context() as patch, bench.spinning(busy):
            if busy:
                _slow_clocks(patch, 10.0)
            obj, handle, _ = bench.rigged("beast", points, triangles, 1000)
            view = AxisView(-axis, scale=size / 1000.0)
            centre = np.array(view.to_screen(handle.matrix_world.to_translation()))
            start = tuple(centre + (100.0, 0.0))
            session = DragSession(obj, handle, view, start, preview_above=None)
            session.event("R", "PRESS", start)
            shown = []
            for k in range(1, 21):
                angle = math.radians(90.0) * k / 60
                mouse = tuple(centre + 100.0 * np.array((math.cos(angle), math.sin(angle))))
                session.event("MOUSEMOVE", "NOTHING", mouse)
                shown.append(mesh_io.read_positions(obj.data).copy())
            for _ in range(6):
                session.event("TIMER", "NOTHING", mouse)
                shown.append(mesh_io.read_positions(obj.data).copy())
            assert session.event("ESC", "PRESS", mouse) == CANCELLED
        return shown

    quiet, busy = drag(False), drag(True)
    assert len(quiet) == len(busy) == 26
    assert np.abs(quiet[19] - points).max() > 0.01 * size  # it moved
    for k, (a, b) in enumerate(zip(quiet, busy)):
        assert np.array_equal(a, b), f"shown shape {k} differs by {np.abs(a - b).max() / size:.1e} of the diagonal"


def test_a_slower_clock_changes_no_budget_and_the_drag_settles_and_confirms_what_it_showed(scene, monkeypatch):
    from skin_detach_addon.core.proxy_solve import dual_laplacian
    units = []

    class Recorded(dual_laplacian.WorkBudget):  # every budget a solve is given, in units
        def __init__(self, n):
            super().__init__(n)
            units.append(n)

    monkeypatch.setattr(dual_laplacian, "WorkBudget", Recorded)

    def drag(factor):
        units.clear()
        with monkeypatch.context() as patch:
            bpy.ops.wm.read_homefile(use_empty=True)
            obj = import_spot()
            handle = rig(obj, target_faces=1000, axis=1)
            _slow_clocks(patch, factor)
            session = DragSession(obj, handle, TopView(0.01), (0, 0))
            session.event("R", "PRESS", (0, 0))
            for k in range(1, 5):
                session.event("MOUSEMOVE", "NOTHING", (-40 * k, 100))
            for slices in range(1, 400):
                session.event("TIMER", "NOTHING", (-160, 100))
                if session.settled:
                    break
            assert session.settled
            shown = mesh_io.read_positions(obj.data).copy()
            assert session.event("LEFTMOUSE", "PRESS", (-160, 100)) == FINISHED
            assert np.array_equal(mesh_io.read_positions(obj.data), shown)  # no pop
        return shown, slices, list(units)

    quiet, slow = drag(1.0), drag(10.0)
    assert quiet[1] > 1 and len(quiet[2]) > 5                 # moves and several slices, every one budgeted
    assert np.array_equal(quiet[0], slow[0]) and quiet[1] == slow[1] and quiet[2] == slow[2]


def test_a_moves_start_never_carries_a_vertex_farther_than_the_handles_move():
    from types import SimpleNamespace
    from skin_detach_addon.core.proxy_solve.proxy_solves import follow_start
    rng = np.random.default_rng(3)
    older = rng.normal(size=(50, 3))
    last = older + rng.normal(size=(50, 3))                  # a large jump, cut short or a snap
    ids = np.arange(5)
    recent = [SimpleNamespace(vertices=last, converged=False), SimpleNamespace(vertices=older, converged=False)]
    targets = last[ids] + 0.01
    start = follow_start(recent, ids, targets)
    assert np.linalg.norm(start - last, axis=1).max() <= np.linalg.norm(targets - last[ids], axis=1).max() + 1e-12
    assert np.array_equal(follow_start(recent, ids, last[ids]), last)  # standing still: go on from the last
    assert follow_start([], ids, targets) is None
    small = [SimpleNamespace(vertices=older + 1e-4, converged=True), SimpleNamespace(vertices=older, converged=True)]
    assert np.allclose(follow_start(small, ids, older[ids] + 1.0), older + 2e-4)  # a small motion goes on whole


def test_a_file_loaded_during_a_drag_ends_the_modal_cleanly(scene):
    from types import SimpleNamespace
    from skin_detach_addon.ui.operators import SKIN_DETACH_OT_drag
    obj = import_spot()
    handle = rig(obj, axis=1)
    removed, reports, headers = [], [], []
    context = SimpleNamespace(area=SimpleNamespace(header_text_set=headers.append),
                              window_manager=SimpleNamespace(event_timer_remove=removed.append))
    operator = SimpleNamespace(session=DragSession(obj, handle, TopView(0.01), (0, 0)), _timer="timer",
                               report=lambda level, text: reports.append((level, text)))
    operator._end_timer = lambda ctx: SKIN_DETACH_OT_drag._end_timer(operator, ctx)
    event = SimpleNamespace(type="MOUSEMOVE", value="NOTHING", mouse_region_x=10, mouse_region_y=5)
    assert SKIN_DETACH_OT_drag.modal(operator, context, event) == {'RUNNING_MODAL'}
    bpy.ops.wm.read_homefile(use_empty=True)                 # the drag's objects are gone
    event.mouse_region_x = 20
    assert SKIN_DETACH_OT_drag.modal(operator, context, event) == {'CANCELLED'}
    assert removed == ["timer"] and headers[-1] is None and reports[-1][0] == {'WARNING'}


def test_a_drag_event_solves_with_one_blas_thread_and_gives_the_counts_back(scene, monkeypatch):
    """Every event's solve runs numpy's and scipy's OpenBLAS on one thread (on a busy machine a
    small BLAS call waited milliseconds for OpenBLAS's unscheduled worker), their counts set back
    after the event."""
    from skin_detach_addon.core import blas_threads
    from skin_detach_addon.core.proxy_solve import proxy_solves
    if not blas_threads.controls():
        pytest.skip("no OpenBLAS found (another BLAS)")
    obj = import_spot()
    handle = rig(obj, axis=1)
    before = blas_threads.counts()
    seen = []
    solve = proxy_solves.ProxySolves.solve

    def watched(self, *args, **kwargs):
        seen.append(blas_threads.counts())
        return solve(self, *args, **kwargs)
    monkeypatch.setattr(proxy_solves.ProxySolves, "solve", watched)
    session = DragSession(obj, handle, TopView(0.01), (100, 100))
    for kind, value, mouse in [("MOUSEMOVE", "NOTHING", (120, 90)), ("TIMER", "NOTHING", (120, 90)),
                               ("R", "PRESS", (120, 90)), ("MOUSEMOVE", "NOTHING", (130, 110)),
                               ("RET", "PRESS", (130, 110))]:
        session.event(kind, value, mouse)
        assert blas_threads.counts() == before
    assert len(seen) >= 4 and all(counts == [1] * len(before) for counts in seen)
