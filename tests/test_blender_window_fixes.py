"""Headless bpy: what the window's bugs came down to, on the API (the GUI tests in tests/gui
drive the same through a real window): the Redo panel's motion, Reset after a rigid pose and
after Apply Rotation, a rig collection per scene, a deleted mesh's rig, a save during a drag."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import TopView, activate, import_spot, rig  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import DragSession  # noqa: E402


def test_the_drag_motion_redoes_the_drag_exactly(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.matrix_world.copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (30, 20))
    session.event("R", "PRESS", (30, 20))
    session.event("MOUSEMOVE", "NOTHING", (10, 40))
    session.event("RET", "PRESS", (10, 40))
    redone = api.moved_matrix(start, *session.motion)
    assert np.allclose(np.array(redone), np.array(handle.matrix_world), atol=1e-6)


def test_a_typed_scale_is_in_the_motion(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.matrix_world.copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    for key in ("S", "Z", "ONE", "PERIOD", "FIVE", "RET"):  # scale 1.5 along Z
        session.event(key, "PRESS", (0, 0))
    assert np.allclose(session.motion[2], (1.0, 1.0, 1.5))
    assert np.allclose(np.array(api.moved_matrix(start, *session.motion)), np.array(handle.matrix_world), atol=1e-6)


def test_typed_numbers_are_bounded_by_the_mesh_size(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.matrix_world.translation.copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    for key in ("ONE", "ZERO", "ZERO", "ZERO"):     # 1000 and 100: beyond ten sizes of spot
        session.event(key, "PRESS", (0, 0))
    assert session.size < 10 and session.typed == "10" and "refused" in session.refused
    assert len(session.refused) < 120
    assert abs((handle.matrix_world.translation - start).x - 10.0) < 1e-5
    for key in ("PERIOD",) + ("ONE",) * 9:          # more than ten digits
        session.event(key, "PRESS", (0, 0))
    assert len(session.typed) <= 11 and "digits" in session.refused
    session.event("ESC", "PRESS", (0, 0))


def test_reset_after_a_rigid_pose(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data)
    for anchor in [e for e in api.handles_of(obj) if api.handle_kind(e) == api.ANCHOR]:
        api.remove_handle(anchor)
    handle.rotation_euler.z += 0.8
    api.deform(obj)
    api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)


def test_reset_after_apply_rotation_on_a_posed_mesh_is_refused(scene):
    obj = import_spot()
    obj.rotation_euler.x = 0.5
    handle = rig(obj, axis=1)
    handle.location.x += 0.2
    api.deform(obj)
    activate(obj)
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=False)
    applied = mesh_io.read_positions(obj.data)
    with pytest.raises(api.SkinDetachError, match="Rebuild"):
        api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), applied)


def test_a_sculpted_mesh_still_resets(scene):
    obj = import_spot()
    rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data)
    bent = rest.copy()
    bent[:50] += 0.01
    mesh_io.write_positions(obj.data, bent)
    api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)


def test_each_scene_has_its_own_rig_collection(scene):
    first = import_spot()
    rig(first, axis=1)
    other = bpy.data.scenes.new("Other")
    second = bpy.data.objects.new("second", first.data.copy())
    other.collection.objects.link(second)
    with bpy.context.temp_override(scene=other):
        api.build(second, target_faces=200)
    first_rig = {o.name for o in bpy.context.scene.objects}
    shown = {o.name for o in other.objects}
    assert api.proxy_of(second).name in shown and api.proxy_of(first).name not in shown
    assert api.proxy_of(second).name not in first_rig


def test_the_rig_of_a_deleted_mesh(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    proxy = api.proxy_of(obj)
    name = obj.name
    bpy.context.scene.collection.objects.unlink(obj)  # deleted in the viewport: in no scene, kept by the rig's pointers
    assert api.mesh_of(proxy) is None and api.mesh_of(handle) is None
    assert api.orphan_owner(proxy).name == name
    with pytest.raises(api.SkinDetachError, match="expected a mesh object"):
        api.build(proxy)
    assert api.clear_orphan(handle) == name
    assert not [o for o in bpy.context.scene.objects if o.name.startswith(name)]


def test_a_save_during_a_drag_records_the_pose(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    before = binding.written_state(obj)[0]
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (20, 10))
    api.before_save()                                # what Blender's save_pre runs
    binding.check_unedited(obj)                      # the pose holds its digest
    session.event("ESC", "PRESS", (20, 10))
    assert binding.written_state(obj)[0] == before   # the cancel restores it with the rest
    binding.check_unedited(obj)
