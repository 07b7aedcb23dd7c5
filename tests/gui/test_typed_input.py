"""Issue 43, items 4 and 16: numbers typed during a drag, against Blender's own transform."""

import bpy
import numpy as np

import rigs


def _turn(before, after):
    """(3, 3) rotation taking the world matrix ``before`` to ``after`` (about the origin)."""
    return np.array(after.to_3x3()) @ np.linalg.inv(np.array(before.to_3x3()))


def test_typed_r_turns_the_way_blenders_r_turns(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    with rigs.override(ui):
        bpy.ops.object.empty_add(location=handle.matrix_world.translation)
    empty = bpy.context.view_layer.objects.active
    rigs.undo_push(ui, "Empty")
    # Blender's own R 90 on the empty, in the view the drag uses.
    before = empty.matrix_world.copy()
    yield from ui.hover_view()
    yield from ui.press('R', wait=0.3)
    yield from ui.type("90")
    yield from ui.press('RET', wait=0.5)
    blenders = _turn(before, bpy.data.objects[empty.name].matrix_world)
    assert np.allclose(blenders @ blenders.T, np.eye(3), atol=1e-5) and not np.allclose(blenders, np.eye(3)), \
        f"Blender's R 90 did not turn the empty: {blenders}"
    # The mesh clicked, the handle picked in the panel's list, then R 90 typed in its drag.
    yield from ui.click(*ui.on_screen(obj.matrix_world @ obj.data.vertices[len(obj.data.vertices) // 3].co))
    yield from ui.click_button(f'bpy.ops.skin_detach.select_handle(name="{handle.name}")')
    assert bpy.context.view_layer.objects.active == handle, bpy.context.view_layer.objects.active
    start = handle.matrix_world.copy()
    yield from rigs.drag(ui, 0, 0, steps=1, keys=('R', 'NINE', 'ZERO'))
    dragged = _turn(start, handle.matrix_world)
    assert np.abs(dragged - blenders).max() < 1e-4, \
        f"typed R 90 in the drag turned {dragged.round(4).tolist()}, Blender's R 90 {blenders.round(4).tolist()}"


def test_a_mode_switch_clears_the_typed_number(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    start = handle.matrix_world.copy()
    # R, 30, then G: the 30 degrees stay a turn, G starts with nothing typed (the mouse moves it).
    yield from rigs.drag(ui, 40, 0, steps=2, keys=('R', 'THREE', 'ZERO', 'G'))
    now = handle.matrix_world
    angle = np.degrees(np.arccos(np.clip((np.trace(_turn(start, now)) - 1) / 2, -1, 1)))
    moved = (now.translation - start.translation).length
    assert abs(angle - 30.0) < 1e-3, f"R 30 then G turned the handle {angle:.4f} degrees"
    assert 0.0 < moved < 5.0, f"R 30 then G and a 40-pixel mouse move moved the handle {moved}"
