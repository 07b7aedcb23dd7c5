"""Headless bpy: the panel's operators as the window drives them (issue 43, items 14, 15, 17)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, band, import_spot, rig, select_vertices  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import mesh_io  # noqa: E402


def _operators():
    from skin_detach_addon import ui
    return [cls for cls in ui.CLASSES if issubclass(cls, bpy.types.Operator)]


def test_no_operator_remembers_a_value_into_the_next_press(scene):
    """The Group field's + sets ``group`` for its press; Blender remembers a press's properties
    into the next one of the same operator (the panel's plain Add Handle then built from the
    group) unless they are SKIP_SAVE. The panel's values are the defaults of every other."""
    remembered = [f"{cls.bl_idname}.{prop.identifier}" for cls in _operators()
                  for prop in getattr(bpy.ops, cls.bl_idname.split(".")[0]).__getattr__(
                      cls.bl_idname.split(".")[1]).get_rna_type().properties
                  if prop.identifier != "rna_type" and not prop.is_skip_save]
    assert not remembered, f"remembered into the next press: {remembered}"


def test_the_group_field_is_for_its_own_press_only(scene):
    obj = import_spot()
    rig(obj, axis=1)
    top = np.flatnonzero(band(obj, 0.85, 1.0, axis=1))
    group = obj.vertex_groups.new(name="head")
    group.add(top.tolist(), 1.0, 'REPLACE')
    assert bpy.ops.skin_detach.add_handle(group="head", mirror='X') == {'FINISHED'}   # the Group field's +
    side = band(obj, 0.4, 0.5, axis=1)
    activate(obj)
    select_vertices(obj, side)
    before = set(api.handles_of(obj))
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}                    # the plain button
    made = set(api.handles_of(obj)) - before
    assert len(made) == 1, f"the plain Add Handle made {len(made)} handles (the last press's mirror?)"
    empty = made.pop()
    assert api.handle_group(empty) == "", f"the plain Add Handle used the group {api.handle_group(empty)!r}"
    assert np.array_equal(np.sort(empty["_skin_detach_handle"]["detail_ids"]), np.flatnonzero(side))


def test_removing_a_handle_puts_the_mesh_where_the_rig_left_says(scene):
    obj = import_spot()
    top = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data).copy()
    activate(obj)
    select_vertices(obj, band(obj, 0.45, 0.55, axis=1))
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    middle = bpy.context.view_layer.objects.active
    top.location.z += 0.3
    api.deform(obj)
    posed = mesh_io.read_positions(obj.data).copy()
    assert np.abs(posed - rest).max() > 0.1
    # The moved handle removed (the panel's X): the rest shape, bit-exact (the others are at rest).
    assert bpy.ops.skin_detach.remove_handle(name=top.name) == {'FINISHED'}
    assert np.array_equal(mesh_io.read_positions(obj.data), rest), "the removed handle's pose stayed on the mesh"
    # A pose of the handle left stays when an unmoved one goes; the anchor removed: solved without it.
    middle.location.x += 0.2
    api.deform(obj)
    expected = mesh_io.read_positions(obj.data).copy()
    anchor = [e for e in api.handles_of(obj) if api.handle_kind(e) == api.ANCHOR][0]
    assert bpy.ops.skin_detach.remove_handle(name=anchor.name) == {'FINISHED'}
    without_anchor = mesh_io.read_positions(obj.data).copy()
    api.deform(obj)                                           # what Apply gives for the rig left
    assert np.abs(mesh_io.read_positions(obj.data) - without_anchor).max() <= 1e-6
    assert np.abs(without_anchor - expected).max() > 1e-4    # the anchor held the bottom before
    # The last one removed: the rest shape.
    activate(middle)
    assert bpy.ops.skin_detach.remove_handle() == {'FINISHED'}
    assert api.handles_of(obj) == [] and np.array_equal(mesh_io.read_positions(obj.data), rest)


def test_removing_a_handle_of_a_sculpted_mesh_keeps_the_sculpt(scene):
    obj = import_spot()
    top = rig(obj, axis=1)
    sculpted = mesh_io.read_positions(obj.data).copy()
    sculpted[:10] += 0.05
    obj.data.vertices.foreach_set("co", sculpted.ravel())
    obj.data.update()
    assert bpy.ops.skin_detach.remove_handle(name=top.name) == {'FINISHED'}
    assert np.array_equal(mesh_io.read_positions(obj.data), sculpted)


def test_the_lists_x_in_edit_mode_leaves_it_and_solves(scene):
    obj = import_spot()
    top = rig(obj, axis=1)
    rest = mesh_io.read_positions(obj.data).copy()
    top.location.z += 0.3
    api.deform(obj)
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.skin_detach.remove_handle(name=top.name) == {'FINISHED'}
    assert obj.mode == 'OBJECT' and np.array_equal(mesh_io.read_positions(obj.data), rest)


def test_the_rig_collection_is_not_named_after_the_add_on_and_old_files_keep_theirs(scene):
    """F3 "skin detach" listed "Add > Collection Instance > Skin Detach" (the rig's collection) first."""
    from skin_detach_addon.blender import skin_rig
    obj = import_spot()
    rig(obj, axis=1)
    proxy = api.proxy_of(obj)
    [collection] = proxy.users_collection
    assert not collection.name.lower().startswith("skin detach") and collection.name == skin_rig.RIG_COLLECTION
    # A file of an earlier version: its collection was "Skin Detach", tagged so; the next change renames it.
    collection.name = "Skin Detach"
    collection[skin_rig.COLLECTION_TAG] = "Skin Detach"
    activate(obj)
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    assert [c.name for c in api.proxy_of(obj).users_collection] == [skin_rig.RIG_COLLECTION]
    assert "Skin Detach" not in bpy.data.collections and len(scene.collection.children) == 1 + \
        sum(1 for c in scene.collection.children if c.get(skin_rig.COLLECTION_TAG) is None)


@pytest.mark.parametrize("command", ["apply", "reset", "select_handle", "clear"])
def test_commands_found_in_edit_mode_leave_it_and_run(scene, command):
    obj = import_spot()
    top = rig(obj, axis=1)
    top.location.z += 0.3
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    options = {"name": top.name} if command == "select_handle" else {}
    assert getattr(bpy.ops.skin_detach, command)(**options) == {'FINISHED'}
    assert obj.mode == 'OBJECT'
