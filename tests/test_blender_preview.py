"""Headless bpy: the light preview that stands in for a large mesh while handles move."""

import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import TopView, activate, import_spot, rig, save_and_reopen  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io, skin_rig  # noqa: E402
from skin_detach_addon.blender.preview_stand_in import preview_of  # noqa: E402
from skin_detach_addon.blender.drag_session import CANCELLED, FINISHED, DragSession  # noqa: E402
from skin_detach_addon.ui import live_update  # noqa: E402

#: spot has about 2,900 vertices: a low Preview Above gives it a preview of an eighth of them.
LOW = 1000


def _rigged(scene):
    scene.skin_detach.preview_above = LOW
    obj = import_spot()
    handle = rig(obj, axis=1)
    return obj, handle


def _state(obj):
    proxy = binding.proxy_of(obj)
    return (mesh_io.snapshot(obj.data)[0], mesh_io.snapshot(proxy.data)[0],
            [np.array(child.matrix_basis) for child in proxy.children], binding.written_state(obj)[0])


def _mesh_hidden(obj):
    """The mesh is hidden in the viewport: by the preview standing in (H in the view layer) or by its toggle."""
    return bool(obj.hide_get() or obj.hide_viewport)


def _diagonal(obj):
    rest = api.rest_positions(obj)
    return float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))


def _same_solve_as_from_rest(obj):
    """The proxy holds a settled solve of the handles' pose: a cold solve from rest (Apply) gives
    the same proxy (the detail of Apply is also smoothed across the skin's seams)."""
    proxy = binding.proxy_of(obj)
    shown = mesh_io.read_positions(proxy.data).copy()
    binding.open_binding(obj).solves.forget_warm_starts()
    api.deform(obj)
    assert np.abs(mesh_io.read_positions(proxy.data) - shown).max() <= 1e-5 * _diagonal(obj)


def test_build_makes_a_hidden_preview_only_above_the_threshold(scene):
    obj, _ = _rigged(scene)
    preview = preview_of(obj)
    n = len(obj.data.vertices)
    assert preview is not None and preview.hide_viewport and preview.hide_render
    assert 0.5 * n / 8 <= len(preview.data.vertices) <= 1.5 * n / 8  # an eighth of the mesh at most
    assert api.mesh_of(preview) is obj and api.figures(obj)["build"]["preview_vertices"] == len(preview.data.vertices)
    api.build(preview, target_faces=300, preview_above=LOW)  # the preview stands for its mesh: rebinds it
    assert preview_of(obj) is not None and preview_of(obj) != preview
    assert len([o for o in bpy.data.objects if o.get(binding.PREVIEW_TAG) is not None]) == 1
    api.build(obj, target_faces=300, preview_above=None)  # no preview: the old one goes
    assert preview_of(obj) is None
    assert not [o for o in bpy.data.objects if o.get(binding.PREVIEW_TAG) is not None]
    with pytest.raises(api.SkinDetachError, match="preview_above"):
        api.build(obj, preview_above=-1)


def test_preview_drag_leaves_the_mesh_alone_and_confirm_writes_the_settled_detail(scene):
    obj, handle = _rigged(scene)
    preview = preview_of(obj)
    before = mesh_io.read_positions(obj.data)
    preview_rest = mesh_io.read_positions(preview.data)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    for k in range(1, 6):
        session.event("MOUSEMOVE", "NOTHING", (100 + 4 * k, 100 - 2 * k))
        assert np.array_equal(mesh_io.read_positions(obj.data), before)
    assert np.abs(mesh_io.read_positions(preview.data) - preview_rest).max() > 0.05
    assert not preview.hide_viewport and _mesh_hidden(obj)
    assert "preview of" in session.header and "full detail on confirm" in session.header
    assert session.event("RET", "PRESS", (120, 90)) == FINISHED
    assert preview.hide_viewport and not _mesh_hidden(obj)
    confirmed = mesh_io.read_positions(obj.data)
    assert np.abs(confirmed - before).max() > 0.05
    _same_solve_as_from_rest(obj)


def test_a_preview_drag_settles_on_timer_events_and_its_confirm_writes_that_shape_in_full_detail(scene):
    obj, handle = _rigged(scene)
    preview = preview_of(obj)
    before = mesh_io.read_positions(obj.data).copy()
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    for _ in range(100):
        if session.settled:
            break
        session.event("TIMER", "NOTHING", (130, 80))
    assert session.settled and "settled" in session.header
    assert np.array_equal(mesh_io.read_positions(obj.data), before)   # the preview settled, not the mesh
    proxy = binding.proxy_of(obj)
    settled_proxy = mesh_io.read_positions(proxy.data).copy()
    assert session.event("RET", "PRESS", (130, 80)) == FINISHED
    assert preview.hide_viewport and not _mesh_hidden(obj)
    assert np.array_equal(mesh_io.read_positions(proxy.data), settled_proxy)  # no new solve: the shape shown
    confirmed = mesh_io.read_positions(obj.data)
    assert np.abs(confirmed - before).max() > 0.05
    _same_solve_as_from_rest(obj)


def _held_preview_vertices(obj, handle):
    """(preview ids, detail ids) of the preview vertices that stand for the handle's selected
    detail vertices, and those detail vertices."""
    from skin_detach_addon.blender import handles
    record = binding.open_binding(obj)
    selected = handles.detail_ids_of(handle)
    preview_ids = record.preview.held_of([(0, selected)], record.surface.weld, record.rest)[0][1]
    detail_of = np.empty(record.surface.skin.case.shape[0], dtype=np.int64)
    detail_of[record.surface.weld] = np.arange(record.surface.n_detail)
    return preview_ids, detail_of[record.preview.representatives[preview_ids]]


@pytest.mark.parametrize("reopen", [False, True])
def test_the_preview_holds_what_the_handle_holds_so_confirm_does_not_pop_there(scene, tmp_path, reopen):
    obj, handle = _rigged(scene)
    if reopen:  # the preview's representatives are stored with the binding
        obj, handle = save_and_reopen(tmp_path / "held.blend")
    preview = preview_of(obj)
    preview_ids, detail_ids = _held_preview_vertices(obj, handle)
    assert preview_ids.size >= 10
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    shown = mesh_io.read_positions(preview.data).copy()
    assert session.event("RET", "PRESS", (130, 80)) == FINISHED
    confirmed = mesh_io.read_positions(obj.data)
    # What the preview showed there is what confirm writes there (the same solve, both held
    # exactly by the handle): no jump at the selection.
    assert np.abs(confirmed[detail_ids] - api.rest_positions(obj)[detail_ids]).max() > 0.05
    assert np.abs(confirmed[detail_ids] - shown[preview_ids]).max() <= 1e-5 * _diagonal(obj)


def test_preview_cancel_restores_everything_bit_exact(scene):
    obj, handle = _rigged(scene)
    obj.hide_viewport = True  # hidden by the user before the drag: stays hidden
    before = _state(obj)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    assert preview_of(obj).hide_viewport  # nothing shows in place of a mesh the user hid
    assert session.event("ESC", "PRESS", (130, 80)) == CANCELLED
    after = _state(obj)
    assert np.array_equal(after[0], before[0]) and np.array_equal(after[1], before[1])
    assert all(np.array_equal(x, y) for x, y in zip(after[2], before[2])) and after[3] == before[3]
    assert obj.hide_viewport and preview_of(obj).hide_viewport


def test_below_the_threshold_or_without_a_preview_the_detail_follows_every_move(scene):
    obj, handle = _rigged(scene)
    before = mesh_io.read_positions(obj.data)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=10**7)
    session.event("MOUSEMOVE", "NOTHING", (120, 90))
    assert np.abs(mesh_io.read_positions(obj.data) - before).max() > 0.05
    assert preview_of(obj).hide_viewport and "preview" not in session.header
    session.event("ESC", "PRESS", (120, 90))
    skin_rig.remove_with_mesh(preview_of(obj))  # the user deleted the preview
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (120, 90))
    assert np.abs(mesh_io.read_positions(obj.data) - before).max() > 0.05
    assert session.event("RET", "PRESS", (120, 90)) == FINISHED


def test_live_update_shows_the_preview_then_writes_the_detail_when_idle(scene):
    obj, handle = _rigged(scene)
    before = mesh_io.read_positions(obj.data)
    scene.skin_detach.live_update = True
    handle.location.x += 0.2
    bpy.context.view_layer.update()
    live_update.notice(scene)
    live_update.flush()
    assert np.array_equal(mesh_io.read_positions(obj.data), before)
    assert not preview_of(obj).hide_viewport and _mesh_hidden(obj)
    assert live_update.settle(now=time.monotonic()) is not None  # not idle long enough yet: waits
    assert live_update.settle(only="another") is not None  # settling another object leaves this one
    assert not preview_of(obj).hide_viewport
    assert live_update.settle(now=time.monotonic() + 10 * live_update.IDLE_SECONDS) is None
    assert preview_of(obj).hide_viewport and not _mesh_hidden(obj)
    settled = mesh_io.read_positions(obj.data)
    assert np.abs(settled - before).max() > 0.05
    # A drag starting on a previewed object settles it at once (Drag Handle calls this first).
    handle.location.x += 0.1
    bpy.context.view_layer.update()
    live_update.notice(scene)
    live_update.flush()
    assert _mesh_hidden(obj) and np.array_equal(mesh_io.read_positions(obj.data), settled)
    assert live_update.settle(only=obj.name) is None
    assert not _mesh_hidden(obj) and np.abs(mesh_io.read_positions(obj.data) - settled).max() > 0.01
    scene.skin_detach.live_update = False
    _same_solve_as_from_rest(obj)


def test_preview_survives_save_and_reload_and_goes_with_clear(scene, tmp_path):
    obj, handle = _rigged(scene)
    obj, handle = save_and_reopen(tmp_path / "preview.blend")
    before = mesh_io.read_positions(obj.data)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (120, 90))
    assert session.previewing and np.array_equal(mesh_io.read_positions(obj.data), before)
    session.event("RET", "PRESS", (120, 90))
    activate(obj)
    api.clear(obj)
    assert not [o for o in bpy.data.objects if o.get(binding.PREVIEW_TAG) is not None]


def test_a_mesh_too_small_for_a_preview_builds_without_one(scene):
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2)  # 42 vertices: an eighth is under the minimum
    obj = bpy.context.active_object
    figures = api.build(obj, target_faces=40, preview_above=0)
    assert figures["preview_vertices"] in (0, None) and preview_of(obj) is None


def _drag_with_preview(scene):
    obj, handle = _rigged(scene)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    assert _mesh_hidden(obj) and not preview_of(obj).hide_viewport
    return obj, handle, session


@pytest.mark.parametrize("end", ["RET", "ESC"])
def test_a_preview_deleted_mid_drag_leaves_the_mesh_visible(scene, end):
    obj, _, session = _drag_with_preview(scene)
    bpy.data.objects.remove(preview_of(obj))
    session.event(end, "PRESS", (130, 80))
    assert not _mesh_hidden(obj)


def test_the_user_hiding_the_preview_does_not_hide_the_mesh_for_good(scene):
    obj, handle, session = _drag_with_preview(scene)
    preview_of(obj).hide_viewport = True
    session.event("MOUSEMOVE", "NOTHING", (140, 70))
    session.event("RET", "PRESS", (140, 70))
    assert not _mesh_hidden(obj)


def test_the_preview_stays_hidden_when_the_user_hid_the_mesh_with_h(scene):
    obj, handle = _rigged(scene)
    obj.hide_set(True)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    assert preview_of(obj).hide_viewport and obj.hide_get() and not obj.hide_viewport
    session.event("RET", "PRESS", (130, 80))
    assert obj.hide_get() and not obj.hide_viewport


@pytest.mark.parametrize("action", ["clear", "rebuild"])
def test_clear_or_rebuild_while_the_preview_stands_in_keeps_the_shown_pose_visible(scene, action):
    obj, handle = _rigged(scene)
    rest = api.rest_positions(obj).copy()
    handle.location.x += 0.3
    api.deform(obj, preview=True)
    assert _mesh_hidden(obj)
    if action == "clear":
        api.clear(obj)
    else:
        api.build(obj, target_faces=300, preview_above=LOW)
    assert not _mesh_hidden(obj)
    moved = mesh_io.read_positions(obj.data)
    assert np.abs(moved - rest).max() > 0.05 * _diagonal_of(rest)  # the pose shown, not the stale rest
    if action == "rebuild":
        assert np.array_equal(api.rest_positions(obj), moved)


def _diagonal_of(points):
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _live_preview(scene):
    obj, handle = _rigged(scene)
    rest = mesh_io.read_positions(obj.data).copy()
    scene.skin_detach.live_update = True
    handle.location.x += 0.3
    bpy.context.view_layer.update()
    live_update.notice(scene)
    live_update.flush()
    assert _mesh_hidden(obj) and np.array_equal(mesh_io.read_positions(obj.data), rest)
    return obj, rest


def test_save_and_reopen_while_live_update_shows_the_preview_keeps_the_shown_pose(scene, tmp_path):
    obj, rest = _live_preview(scene)
    obj, _ = save_and_reopen(tmp_path / "shown.blend")
    assert not _mesh_hidden(obj) and not api.preview_stands_in(obj)
    assert np.abs(mesh_io.read_positions(obj.data) - rest).max() > 0.05


def test_a_file_saved_with_the_preview_standing_in_settles_when_opened(scene, tmp_path):
    obj, rest = _live_preview(scene)
    bpy.app.handlers.save_pre.remove(live_update._settle_all)  # as a file saved by an older version
    try:
        obj, _ = save_and_reopen(tmp_path / "stale.blend")
    finally:
        bpy.app.handlers.save_pre.append(live_update._settle_all)
    assert not _mesh_hidden(obj) and np.abs(mesh_io.read_positions(obj.data) - rest).max() > 0.05


def test_a_renamed_mesh_still_settles(scene):
    obj, rest = _live_preview(scene)
    obj.name = "renamed"
    assert live_update.settle(now=time.monotonic() + 10 * live_update.IDLE_SECONDS) is None
    assert not _mesh_hidden(obj) and np.abs(mesh_io.read_positions(obj.data) - rest).max() > 0.05


def test_a_save_during_a_preview_drag_then_cancel_gives_the_mesh_back(scene, tmp_path):
    from skin_detach_addon.blender.deformation import Deformation
    obj, handle = _rigged(scene)
    before = _state(obj)
    session = DragSession(obj, handle, TopView(0.01), (100, 100), preview_above=LOW)
    session.event("MOUSEMOVE", "NOTHING", (130, 80))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "during.blend"))  # save_pre writes the shown pose
    assert not np.array_equal(mesh_io.read_positions(obj.data), before[0])
    session.event("MOUSEMOVE", "NOTHING", (140, 70))          # the drag goes on with the preview
    assert session.event("ESC", "PRESS", (140, 70)) == CANCELLED
    after = _state(obj)
    assert np.array_equal(after[0], before[0]) and np.array_equal(after[1], before[1]) and after[3] == before[3]
    Deformation(obj)                                          # not "edited since": every operator works
    assert not _mesh_hidden(obj)


def test_a_handle_no_preview_vertex_stands_for_drags_in_preview_and_lands_exactly(scene):
    """A handle of two vertices that are not preview vertices (most small selections on a large
    mesh): the preview holds the preview vertices nearest them, so preview deforms, drags and the
    confirm work, and the mesh's two vertices land where the handle puts them."""
    obj, _ = _rigged(scene)
    record = binding.open_binding(obj)
    rest = api.rest_positions(obj).astype(np.float64)
    standing = np.isin(record.surface.weld, record.preview.representatives)
    lone = np.flatnonzero(~standing)[np.argsort(rest[~standing, 1])[-2:]]
    handle = api.add_handle(obj, lone)
    handle.location.x += 0.05 * _diagonal(obj)
    preview = preview_of(obj)
    before = mesh_io.read_positions(preview.data).copy()
    assert api.deform(obj, preview=True)["preview"]
    moved = np.linalg.norm(mesh_io.read_positions(preview.data) - before, axis=1)
    nearest = np.argmin(np.linalg.norm(record.preview.points[:, None] - rest[lone][None], axis=2), axis=0)
    assert np.allclose(moved[nearest], 0.05 * _diagonal(obj), rtol=1e-4)
    api.deform(obj)
    motion = np.array(obj.matrix_world.inverted() @ handle.matrix_world) @ np.linalg.inv(
        np.array(handle["_skin_detach_handle"]["rest_local"]).reshape(4, 4))
    want = rest[lone] @ motion[:3, :3].T + motion[:3, 3]
    assert np.abs(mesh_io.read_positions(obj.data)[lone] - want).max() <= 1e-5 * _diagonal(obj)


def test_the_preview_stands_in_without_taking_the_mesh_out_of_the_dependency_graph(scene):
    """Issue 44: hiding the mesh with its viewport toggle took it out of Blender's dependency graph,
    whose relations were rebuilt and whose evaluated mesh was freed by the first move of every
    drag (54-112 ms at 1.2M vertices, 0.74 s at 8.6M); hidden in the view layer (as H hides it)
    the mesh stays evaluated and the first move costs what the others do."""
    obj, handle, session = _drag_with_preview(scene)
    layer = bpy.context.view_layer
    assert obj.hide_get(view_layer=layer) and not obj.hide_viewport
    assert obj in {id_.original for id_ in bpy.context.evaluated_depsgraph_get().ids}
    assert api.preview_stands_in(obj)
    assert session.event("RET", "PRESS", (130, 80)) == FINISHED
    assert not obj.hide_get(view_layer=layer) and not obj.hide_viewport and not api.preview_stands_in(obj)


def test_a_stand_in_recorded_by_an_earlier_version_still_ends(scene):
    from skin_detach_addon.blender import preview_stand_in
    obj, handle = _rigged(scene)
    preview = preview_of(obj)
    obj[binding.KEY][preview_stand_in.OLD_STAND_IN_KEY] = False  # as earlier versions hid the mesh
    obj.hide_viewport, preview.hide_viewport = True, False
    assert api.preview_stands_in(obj)
    preview_stand_in.end_stand_in(obj)
    assert not obj.hide_viewport and preview.hide_viewport and not api.preview_stands_in(obj)
    assert preview_stand_in.OLD_STAND_IN_KEY not in obj[binding.KEY]
