"""Bugs 2 and 3: Reset to Rest after a rigid pose, and after Apply Rotation on a posed mesh."""

import bpy
import numpy as np

import rigs


def test_reset_after_a_rigid_pose(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui, anchor=False)
    rest = rigs.api().rest_positions(obj)
    yield from rigs.drag(ui, 0, 0, steps=1, keys=('R', 'FOUR', 'FIVE'))
    assert not np.allclose(rigs.positions(obj), rest, atol=1e-3), "R 45 did not pose the mesh"
    yield from ui.click_button("bpy.ops.skin_detach.reset")
    yield from ui.reports()
    assert any("back to the rest shape" in line for line in ui.last_reports), ui.last_reports[-3:]
    assert np.array_equal(rigs.positions(obj), rest), "Reset did not put the rest shape back"


def test_reset_after_apply_rotation_on_a_posed_mesh(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui, rotation=(0.5, 0.0, 0.0))
    yield from rigs.drag(ui, 80, 0)
    # The artist clicks the mesh, applies its rotation (Ctrl+A, Rotation), then presses Reset.
    yield from ui.click(*ui.on_screen(obj.matrix_world @ obj.data.vertices[len(obj.data.vertices) // 2].co))
    assert bpy.context.view_layer.objects.active == obj, \
        f"clicking the mesh made {bpy.context.view_layer.objects.active.name!r} active"
    yield from ui.menu_search("apply rotation")
    assert obj.rotation_euler.x == 0.0, "Apply Rotation did not run"
    applied = rigs.positions(obj).copy()
    yield from ui.click_button("bpy.ops.skin_detach.reset")
    yield from ui.reports()
    last = ui.last_reports[-1]
    assert "Rebuild" in last and "rotation" in last.lower(), f"Reset did not refuse: {last!r}"
    assert np.array_equal(rigs.positions(obj), applied), "the refused Reset changed the mesh"
