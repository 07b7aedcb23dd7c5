"""Issue 43, items 15 and 17: the panel's Group field and its list's X, pressed as an artist does."""

import bpy
import numpy as np

import rigs


def _click_mesh(ui, obj):
    yield from ui.click(*ui.on_screen(obj.matrix_world @ obj.data.vertices[len(obj.data.vertices) // 3].co))
    assert bpy.context.view_layer.objects.active == obj, bpy.context.view_layer.objects.active


def test_the_group_fields_plus_does_not_stick_to_add_handle(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    sd = rigs.api()
    rest = sd.rest_positions(obj)
    group = obj.vertex_groups.new(name="head")
    group.add(np.flatnonzero(rest[:, 2] > 0.8).tolist(), 1.0, 'REPLACE')
    side = np.flatnonzero(rest[:, 0] > 0.8)
    rigs.select_vertices(obj, side)
    rigs.activate(ui, obj)
    rigs.undo_push(ui, "Group")
    # The Group field: click, type the group's name, Enter; then its +.
    yield from ui.click_button("skin_detach.handle_group", wait=0.5)
    yield from ui.type("head")
    yield from ui.press('RET', wait=0.5)
    assert bpy.context.scene.skin_detach.handle_group == "head", bpy.context.scene.skin_detach.handle_group
    before = set(sd.handles_of(obj))
    yield from ui.find_button('bpy.ops.skin_detach.add_handle(group="head")', columns=(0.76, 0.78))
    assert ui.found, "no + beside the Group field"
    yield from ui.click(*ui.found, wait=1.0)
    made = set(sd.handles_of(obj)) - before
    assert len(made) == 1 and sd.handle_group(made.pop()) == "head", "the Group field's + made no handle of 'head'"
    # The artist selects other vertices in Edit Mode and presses the plain Add Handle.
    yield from _click_mesh(ui, obj)
    yield from ui.hover_view()
    yield from ui.press('TAB', wait=0.5)
    assert obj.mode == 'EDIT', "Tab did not enter Edit Mode"
    before = set(sd.handles_of(obj))
    yield from ui.click_button("bpy.ops.skin_detach.add_handle()", wait=1.5)
    yield from ui.reports()
    made = set(sd.handles_of(obj)) - before
    assert len(made) == 1, f"the plain Add Handle made {len(made)} handles: {ui.last_reports[-1:]}"
    empty = made.pop()
    assert sd.handle_group(empty) == "", f"the plain Add Handle used the group {sd.handle_group(empty)!r}"
    assert np.array_equal(np.sort(empty["_skin_detach_handle"]["detail_ids"]), side), \
        "the plain Add Handle did not take the selection"
