"""Issue 51, part 2: several meshes posed as one rig, as an artist does it in the window: Build with
them selected, a handle from vertices selected in two objects in multi-object Edit Mode, a drag,
and Ctrl+Z giving every object back bit for bit."""

import math
import time

import bpy
import numpy as np

import gui
import rigs


def _character(ui):
    """A body (a UV sphere), an eye half sunk into it, a belt (a torus turned 90 degrees about X,
    scaled 0.5, around the middle); every one selected, the body active."""
    with rigs.override(ui):
        cube = bpy.data.objects.get("Cube")
        if cube is not None:
            bpy.data.objects.remove(cube)
        bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
        body = bpy.context.view_layer.objects.active
        body.name = "Body"
        bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=8, radius=0.2, location=(0.0, -0.8, 0.6))
        eye = bpy.context.view_layer.objects.active
        eye.name = "Eye"
        bpy.ops.mesh.primitive_torus_add(major_radius=2.04, minor_radius=0.16, rotation=(0.0, 0.0, 0.0))
        belt = bpy.context.view_layer.objects.active
        belt.name = "Belt"
    from mathutils import Matrix
    belt.data.transform(Matrix.Rotation(-math.pi / 2, 4, 'X'))
    belt.rotation_euler = (math.pi / 2, 0.0, 0.0)
    belt.scale = (0.5, 0.5, 0.5)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (body, eye, belt))
    bpy.context.view_layer.objects.active = body
    rigs.undo_push(ui, "Character")
    return body, eye, belt


def _state(names):
    return {name: rigs.positions(bpy.data.objects[name]).tobytes() for name in names}


def test_several_meshes_build_one_rig_a_handle_over_two_objects_drags_and_undoes(ui):
    yield from ui.setup()
    body, eye, belt = _character(ui)
    names = ("Body", "Eye", "Belt")
    sd = rigs.api()
    builds = gui.addon().ui.operators.BUILDS
    yield from ui.click_button("bpy.ops.skin_detach.build()", wait=0.5)
    begun = time.monotonic()
    while builds or not sd.is_bound(bpy.data.objects["Body"]):
        assert time.monotonic() - begun < 120, "the build did not end"
        yield 0.2
    yield 0.5
    yield from ui.reports()
    assert any("3 objects, " in line and "vertices bound" in line for line in ui.last_reports), ui.last_reports[-3:]
    body, eye, belt = (bpy.data.objects[name] for name in names)
    assert [o.name for o in sd.members(body)] == ["Body", "Belt", "Eye"]
    # Tab with the body and the eye selected: both in Edit Mode; select the head's cap and the eye.
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (body, eye))
    bpy.context.view_layer.objects.active = body
    rest = sd.rest_positions(body)
    ranges = sd.member_ranges(body)
    cap = np.flatnonzero(rest[ranges[body][0]:ranges[body][1], 2] > 0.7)
    rigs.select_vertices(body, cap)
    rigs.select_vertices(eye, np.arange(len(eye.data.vertices)))
    rigs.select_vertices(belt, [])
    rigs.undo_push(ui, "Selection")
    yield from ui.hover_view()
    yield from ui.press('TAB', wait=0.8)
    assert body.mode == 'EDIT' and eye.mode == 'EDIT', "Tab did not put both meshes in Edit Mode"
    yield from ui.click_button("bpy.ops.skin_detach.add_handle()", wait=1.5)
    yield from ui.reports()
    handle = bpy.context.view_layer.objects.active
    assert sd.is_handle(handle), f"Add Handle made no handle: {ui.last_reports[-2:]}"
    expected = np.sort(np.concatenate([cap + ranges[body][0], np.arange(*ranges[eye])]))
    assert np.array_equal(np.sort(np.array(handle["_skin_detach_handle"]["detail_ids"])), expected), \
        "the handle does not hold the vertices selected in both objects"
    before = _state(names)
    yield from rigs.drag(ui, 90, 40)
    after = _state(names)
    assert after["Body"] != before["Body"] and after["Eye"] != before["Eye"], "the drag did not move both objects"
    # Ctrl+Z: every object back, bit for bit.
    yield from ui.hover_view()
    yield from ui.press('Z', ctrl=True, wait=1.5)
    assert _state(names) == before, "Ctrl+Z did not give every object back bit for bit"
