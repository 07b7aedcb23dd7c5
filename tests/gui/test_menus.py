"""Issue 43, item 14: F3 (Blender's menu search) finds every command of the add-on, in Object
Mode and in Edit Mode, and "skin detach" lists the add-on's own commands first."""

import bpy
import numpy as np

import rigs


def _ran(ui, text, idname, then=(), refusal=None):
    """Generator: F3, ``text``, Enter (then the keys ``then``); asserts the Info editor logged
    ``idname`` as run, or (``refusal``) reported that text: found, run and refused."""
    yield from ui.reports()
    before = len(ui.last_reports)
    yield from ui.menu_search(text, wait=1.5)
    for key in then:
        yield from ui.press(key, wait=1.0)
    yield from ui.reports()
    new = ui.last_reports[before:]
    ran = any(line.startswith(f"bpy.ops.skin_detach.{idname}(") for line in new)
    refused = refusal is not None and any(refusal in line for line in new)
    assert ran or refused, f"F3 {text!r} did not run skin_detach.{idname}: the Info editor says {new}"


def _rig(ui):
    """The rig with the mesh active and its side (x > 0.8) selected: (obj, handle, side ids)."""
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    side = np.flatnonzero(rigs.api().rest_positions(obj)[:, 0] > 0.8)
    rigs.select_vertices(obj, side)
    rigs.activate(ui, obj)
    rigs.undo_push(ui, "Selection")
    return obj, handle, side


def test_f3_skin_detach_lists_the_addons_commands_first(ui):
    obj, handle, side = yield from _rig(ui)
    yield from ui.reports()
    before = len(ui.last_reports)
    yield from ui.menu_search("skin detach", wait=1.5)
    instances = [o.name for o in bpy.context.scene.objects if o.instance_type == 'COLLECTION']
    assert not instances, f"F3 'skin detach' + Enter instanced a collection: {instances}"
    yield from ui.reports()
    assert any(line.startswith("bpy.ops.skin_detach.") for line in ui.last_reports[before:]), \
        f"F3 'skin detach' + Enter ran none of the add-on's commands: {ui.last_reports[before:]}"


def test_f3_finds_every_command_in_object_mode(ui):
    obj, handle, side = yield from _rig(ui)
    yield from _ran(ui, "apply handles", "apply")
    yield from _ran(ui, "show stretch", "show_stretch")
    yield from _ran(ui, f"select handle {handle.name}", "select_handle")
    assert bpy.context.view_layer.objects.active == handle
    x, y = ui.centre(ui.view)
    yield from ui.move(x - 60, y)
    yield from ui.press('F3', wait=0.5)  # Drag Handle from F3: the drag starts where the mouse is
    yield from ui.type("drag handle")
    yield 0.5
    yield from ui.press('RET', wait=0.5)
    yield from ui.move(x - 20, y + 10, steps=2, wait=0.2)
    yield from ui.press('RET', wait=1.0)
    yield from ui.reports()
    assert any(line.startswith("bpy.ops.skin_detach.drag(") for line in ui.last_reports[-3:]), ui.last_reports[-3:]
    yield from _ran(ui, "add handle", "add_handle")
    yield from _ran(ui, "add anchor", "add_anchor")
    anchor = bpy.context.view_layer.objects.active
    assert rigs.api().handle_kind(anchor) == rigs.api().ANCHOR
    yield from _ran(ui, "remove handle", "remove_handle")
    yield from _ran(ui, "reset to rest", "reset")
    yield from _ran(ui, "build skin", "build")
    yield from _ran(ui, "clear skin", "clear")
    assert not rigs.api().is_bound(obj)


def test_f3_finds_every_command_in_edit_mode(ui):
    obj, handle, side = yield from _rig(ui)

    def edit_mode():
        if bpy.context.view_layer.objects.active != obj:
            yield from ui.click(*ui.on_screen(obj.matrix_world @ obj.data.vertices[len(obj.data.vertices) // 3].co))
            assert bpy.context.view_layer.objects.active == obj, bpy.context.view_layer.objects.active
        if obj.mode != 'EDIT':
            yield from ui.hover_view()
            yield from ui.press('TAB', wait=0.5)
        assert obj.mode == 'EDIT', "Tab did not enter Edit Mode"

    # Drag Handle is listed, greyed: it drags the active handle, and in Edit Mode the mesh is active.
    for text, idname, refusal in (("show stretch", "show_stretch", None), ("apply handles", "apply", None),
                                  ("reset to rest", "reset", None),
                                  ("remove handle", "remove_handle", "expected an active handle"),
                                  (f"select handle {handle.name}", "select_handle", None),
                                  ("add anchor", "add_anchor", None), ("add handle", "add_handle", None),
                                  ("build skin", "build", None), ("clear skin", "clear", None)):
        yield from edit_mode()
        yield from _ran(ui, text, idname, refusal=refusal)
    assert not rigs.api().is_bound(obj)
