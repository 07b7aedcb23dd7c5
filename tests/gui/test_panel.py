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


def test_the_lists_x_puts_the_mesh_where_the_handles_left_say(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    sd = rigs.api()
    rest = sd.rest_positions(obj).copy()
    side = sd.add_handle(obj, np.flatnonzero(rest[:, 0] > 0.8), mirror="")
    rigs.activate(ui, handle)
    rigs.undo_push(ui, "Side")
    names = obj.name, handle.name, side.name
    yield from rigs.drag(ui, 60, 30)
    posed = rigs.positions(obj).copy()
    assert np.abs(posed - rest).max() > 0.1, "the drag did not pose the mesh"
    yield from ui.find_button(f'bpy.ops.skin_detach.remove_handle(name="{handle.name}")', columns=(0.8, 0.82))
    assert ui.found, f"no X beside {handle.name} in the panel's list"
    yield from ui.click(*ui.found, wait=1.5)
    assert names[1] not in bpy.data.objects, "the X did not remove the handle"
    now = rigs.positions(obj)
    assert np.array_equal(now, rest), \
        f"the removed handle's pose stayed on the mesh ({np.abs(now - rest).max():.4f} from the rest shape)"
    # The side handle dragged a little: nothing jumps back (the mesh already is where the rig says).
    yield from ui.click_button(f'bpy.ops.skin_detach.select_handle(name="{side.name}")')
    start = side.matrix_world.translation.copy()
    yield from rigs.drag(ui, 4, 0, steps=1)
    step = (bpy.data.objects[names[2]].matrix_world.translation - start).length
    moved = rigs.positions(bpy.data.objects[names[0]])
    cap = np.flatnonzero(rest[:, 2] > 0.6)  # where the removed handle was
    jump = np.abs(moved[cap] - rest[cap]).max()
    assert 0 < step and jump < 2 * step, f"a 4-pixel drag ({step:.4f}) of the side handle moved the cap by {jump:.4f}"
    # Ctrl+Z three times: the drag, the pick in the list, the removal (one step each): the
    # handle and its pose are back.
    yield from ui.hover_view()
    for _ in range(3):
        yield from ui.press('Z', ctrl=True, wait=1.0)
    assert names[1] in bpy.data.objects, "Ctrl+Z did not bring the removed handle back"
    assert np.array_equal(rigs.positions(bpy.data.objects[names[0]]), posed), "Ctrl+Z did not bring the pose back"


def test_every_other_button_of_the_panel(ui):
    """Rebuild, Add Anchor, Drag Handle (the button: the drag goes on in the view), Apply Handles,
    Live Update, Select Proxy and Clear Skin, pressed in the panel (the list's buttons, Add
    Handle, the Group field's +, Reset and Show Stretch have tests of their own)."""
    yield from ui.setup()
    obj, handle = rigs.rig(ui, anchor=False)
    sd = rigs.api()
    rest = sd.rest_positions(obj).copy()
    rigs.select_vertices(obj, np.flatnonzero(rest[:, 2] < -0.6))
    rigs.activate(ui, obj)
    rigs.undo_push(ui, "Selection")
    yield from ui.click_button("bpy.ops.skin_detach.build()", wait=2.0)
    assert sd.is_bound(obj) and len(sd.handles_of(obj)) == 1, "Rebuild lost the handle"
    yield from ui.click_button("bpy.ops.skin_detach.add_anchor()", wait=1.5)
    anchors = [e for e in sd.handles_of(obj) if sd.handle_kind(e) == sd.ANCHOR]
    assert len(anchors) == 1, f"Add Anchor made {len(anchors)} anchors"
    yield from ui.click_button(f'bpy.ops.skin_detach.select_handle(name="{handle.name}")')
    start = handle.matrix_world.copy()
    # Drag Handle pressed in the sidebar, R at once, the mouse a quarter turn about the handle
    # (as the view shows it), Enter.
    yield from ui.click_button("bpy.ops.skin_detach.drag()", wait=0.5)
    yield from ui.press('R', wait=0.3)
    centre = np.array(ui.on_screen(start.translation), dtype=float)
    arm = np.array(ui.mouse, dtype=float) - centre
    x, y = centre + 0.3 * np.array((-arm[1], arm[0]))
    yield from ui.move(x, y, steps=4, wait=0.2)
    yield 0.5
    yield from ui.press('RET', wait=1.0)
    turn = np.array(handle.matrix_world.to_3x3()) @ np.linalg.inv(np.array(start.to_3x3()))
    angle = np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
    assert abs(angle - 90) < 3, f"a quarter turn of the mouse about the handle turned it {angle:.1f} degrees " \
                                f"(the drag started from the panel's button)"
    posed = rigs.positions(obj).copy()
    assert np.abs(posed - rest).max() > 0.1, "the drag did not pose the mesh"
    handle.location.z += 0.2  # as a keyframe or a driver would move it
    yield from ui.click_button("bpy.ops.skin_detach.apply()", wait=1.5)
    assert np.abs(rigs.positions(obj) - posed).max() > 0.05, "Apply Handles did not follow the handle"
    yield from ui.click_button("skin_detach.live_update", wait=0.5)
    assert bpy.context.scene.skin_detach.live_update, "the Live Update toggle did not turn it on"
    applied = rigs.positions(obj).copy()
    handle.location.z -= 0.2
    yield 1.5
    assert np.abs(rigs.positions(obj) - applied).max() > 0.05, "Live Update did not follow the handle"
    yield from ui.click_button("skin_detach.live_update", wait=0.5)
    assert not bpy.context.scene.skin_detach.live_update
    proxy = sd.proxy_of(obj)
    yield from ui.click_button("hide_select", wait=0.5)
    assert not proxy.hide_select, "Select Proxy did not make the proxy selectable"
    names = {e.name for e in sd.handles_of(obj)} | {proxy.name}
    yield from ui.click_button("bpy.ops.skin_detach.clear()", wait=1.5)
    assert not sd.is_bound(obj) and not names & set(bpy.data.objects.keys()), "Clear Skin left the rig"
