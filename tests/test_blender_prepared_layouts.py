"""A handle layout is prepared when the rig changes and after a file is opened, so the first move
and the first confirm of a layout find its solver and its rebuild ready (at millions of vertices
they cost seconds); a prepared layout gives the same result as one prepared on first use."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import TopView, import_spot, quad_sphere, save_and_reopen  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import FINISHED, DragSession  # noqa: E402
from skin_detach_addon.ui import idle_preparation  # noqa: E402


def _prepared(obj):
    """(solver keys, the mesh's rebuild keys, the preview's rebuild keys) held by the binding."""
    record = binding.open_binding(obj)
    # The free rebuild, made with the binding, is every layout's base: not a layout (not among them).
    preview = set() if record.preview is None else set(record.preview.surface._rebuilds)
    return set(record.solves._solvers), set(record.surface._rebuilds), preview


def _rigged(obj):
    rest = mesh_io.read_positions(obj.data)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < np.quantile(rest[:, 2], 0.15)), mirror="")
    return api.add_handle(obj, np.flatnonzero(rest[:, 2] > np.quantile(rest[:, 2], 0.85)), mirror="")


def test_adding_and_removing_handles_prepares_the_layout_the_next_step_uses(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    assert _prepared(obj)[0] == set()
    handle = _rigged(obj)
    solvers, rebuilds, _ = _prepared(obj)
    assert len(solvers) == 1 and len(rebuilds) == 1  # anchors alone are not prepared: the rig's layout
    handle.location.x += 0.5
    api.deform(obj)
    assert _prepared(obj)[:2] == (solvers, rebuilds)  # the step found its layout ready
    rest = mesh_io.read_positions(obj.data)
    second = api.add_handle(obj, np.flatnonzero(np.abs(rest[:, 2]) < 0.1), mirror="")
    assert len(_prepared(obj)[0]) == 2
    api.remove_handle(second)
    assert len(_prepared(obj)[0]) == 2  # the layout left is the one of before: kept, nothing new
    before = _prepared(obj)
    api.deform(obj)
    assert _prepared(obj)[0] == before[0]


def test_a_prepared_layout_gives_bit_for_bit_what_an_unprepared_one_gives(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    handle = _rigged(obj)
    handle.location.x += 0.5
    handle.rotation_euler.y = 0.4
    bpy.context.view_layer.update()
    api.deform(obj)
    prepared = mesh_io.read_positions(obj.data).copy()
    record = binding.open_binding(obj)
    record.solves._solvers.clear()
    record.surface._rebuilds = {}
    api.deform(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), prepared)


def test_a_rebuild_keeps_the_handles_and_prepares_their_layout(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    _rigged(obj)
    api.build(obj, target_faces=250)
    solvers, rebuilds, _ = _prepared(obj)
    assert len(solvers) == 1 and len(rebuilds) == 1  # the rig's layout


def test_an_opened_file_is_prepared_in_idle_time_and_its_first_drag_uses_it(scene, tmp_path):
    scene.skin_detach.preview_above = 1000
    obj = import_spot()
    api.build(obj, target_faces=300, preview_above=1000)
    _rigged(obj)
    obj, handle = save_and_reopen(tmp_path / "prepared.blend")
    assert obj.name in idle_preparation.queued()
    assert _prepared(obj) == (set(), set(), set())  # opened: nothing made yet
    while idle_preparation.prepare_next() is not None:
        pass
    assert not idle_preparation.queued()
    solvers, rebuilds, previews = _prepared(obj)
    assert len(solvers) == 1 and len(rebuilds) == 1 and len(previews) == 1
    record = binding.open_binding(obj)  # with the float32 copies the drag's buffers multiply
    assert all(rebuild.float32_ready for surface in (record.surface, record.preview.surface)
               for rebuild in [surface._free, *surface._rebuilds.values()] if rebuild is not None)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=1000)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    assert session.event("RET", "PRESS", (130, 80)) == FINISHED
    assert _prepared(obj) == (solvers, rebuilds, previews)  # the drag and its confirm found it ready


def test_a_drag_digests_its_layout_once_not_once_per_move(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    handle = _rigged(obj)
    record = binding.open_binding(obj)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (5, 0))
    layout = record._layout
    key = layout.key()
    for x in (10, 15, 20):
        session.event("MOUSEMOVE", "NOTHING", (x, 0))
        assert record._layout is layout and layout.key() is key
    assert session.event("RET", "PRESS", (20, 0)) == FINISHED
    rest = mesh_io.read_positions(obj.data)
    api.add_handle(obj, np.flatnonzero(np.abs(rest[:, 2]) < 0.1), mirror="")
    api.deform(obj)
    assert record._layout is not layout and record._layout.key() != key


def test_anchors_alone_are_not_prepared_and_still_solve_to_rest(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    rest = mesh_io.read_positions(obj.data).copy()
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < np.quantile(rest[:, 2], 0.15)), mirror="")
    assert _prepared(obj) == (set(), set(), set())
    api.deform(obj)
    assert np.allclose(mesh_io.read_positions(obj.data), rest, atol=1e-6)
