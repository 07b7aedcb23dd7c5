"""Bugs 4, 5 and 6: a second scene, deleting the bound mesh, a save during a drag."""

import os
import tempfile

import bpy
import numpy as np

import gui
import rigs


def test_a_new_scene_shows_only_its_own_rig(ui):
    yield from ui.setup()
    first_obj, _ = rigs.rig(ui)
    first = bpy.context.scene
    first_rig = {o.name for o in first.objects} - {first_obj.name}
    # New scene from the top bar's New Scene button (its menu: New).
    x0, y0, x1, y1 = ui.topbar_box()
    yield from ui.find_button("bpy.ops.scene.new", box=(x1 - 450, y0, x1 - 150, y1), step=12,
                              columns=[k / 60 for k in range(60)])
    assert ui.found, "no New Scene button in the top bar"
    yield from ui.click(*ui.found, wait=0.5)
    yield from ui.press('RET', wait=1.0)  # its menu's first entry: New
    second = ui.window.scene
    assert second != first, "no new scene"
    yield from ui.menu_search("uv sphere", wait=1.0)
    yield from ui.menu_search("build skin", wait=2.0)
    shown = {o.name for o in second.objects}
    assert not shown & first_rig, f"the new scene shows the first scene's rig: {sorted(shown & first_rig)}"
    assert len(rigs.api().bound_objects(second.objects)) == 1
    extra = {o.name for o in first.objects} - first_rig - {first_obj.name}
    assert not extra, f"the first scene now shows {sorted(extra)}"


def test_deleting_the_bound_mesh(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    name = obj.name
    proxy = rigs.api().proxy_of(obj)
    proxy.hide_select = False  # as the panel's Select Proxy toggle leaves it
    rigs.activate(ui, obj)
    yield from ui.hover_view()
    yield from ui.press('DEL', wait=0.5)
    assert name not in bpy.context.scene.objects, "Delete left the mesh"
    # The proxy clicked in the viewport: Clear Skin, then Build.
    yield from ui.click(*ui.on_screen(proxy.matrix_world @ proxy.data.vertices[0].co))
    assert bpy.context.view_layer.objects.active == proxy, bpy.context.view_layer.objects.active
    yield from ui.menu_search("build skin", wait=2.0)
    yield from ui.reports()
    assert not any("bound to a proxy" in line for line in ui.last_reports), \
        f"Build bound the deleted mesh: {ui.last_reports[-1]}"
    yield from ui.menu_search("clear skin", wait=1.0)
    yield from ui.reports()
    assert not any("Traceback" in line or "RuntimeError" in line for line in ui.last_reports), ui.last_reports[-4:]
    left = [o.name for o in bpy.context.scene.objects if o.name.startswith(name)]
    assert not left, f"Clear Skin left the deleted mesh's rig: {left}"


def test_a_save_during_a_drag_opens_consistent(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    path = os.path.join(tempfile.mkdtemp(), "mid_drag.blend")
    yield from rigs.drag(ui, 60, 0, confirm=None)  # the drag goes on
    with bpy.context.temp_override(window=ui.window):
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)  # a script's or autosave's save
    yield from ui.press('RIGHTMOUSE', wait=0.5)  # cancel the drag
    assert np.array_equal(rigs.positions(obj), rigs.api().rest_positions(obj)), "the cancel did not restore"
    # The saved file, opened in this Blender with its add-on: Apply Handles takes it.
    opened = rigs.in_blender(path, "obj = bpy.data.objects['Sphere']; print('SOLVED', api.deform(obj)['converged'])")
    assert "SOLVED True" in opened, f"the saved file refuses its mesh: {opened[-600:]}"


def test_undo_redo_and_save_by_keys(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    rest = rigs.positions(obj).copy()
    path = os.path.join(tempfile.mkdtemp(), "keys.blend")
    with bpy.context.temp_override(window=ui.window):
        bpy.ops.wm.save_as_mainfile(filepath=path)  # set-up: the file has a name, so Ctrl+S saves it
    yield from rigs.drag(ui, 60, 20)
    posed = rigs.positions(obj).copy()
    assert not np.allclose(posed, rest)
    yield from ui.hover_view()
    yield from ui.press('Z', ctrl=True, wait=1.0)
    obj = bpy.data.objects["Sphere"]
    assert np.array_equal(rigs.positions(obj), rest), "Ctrl+Z did not bring the rest shape back"
    yield from ui.press('Z', ctrl=True, shift=True, wait=1.0)
    obj = bpy.data.objects["Sphere"]
    assert np.array_equal(rigs.positions(obj), posed), "Ctrl+Shift+Z did not bring the drag back"
    yield from ui.press('S', ctrl=True, wait=1.5)
    opened = rigs.in_blender(path, "import numpy as np; obj = bpy.data.objects['Sphere']; "
                                   "before = np.array([v.co[:] for v in obj.data.vertices]); api.deform(obj); "
                                   "after = np.array([v.co[:] for v in obj.data.vertices]); "
                                   "print('SAVED', float(np.abs(after - before).max()))")
    assert "SAVED" in opened, f"the file saved by Ctrl+S does not solve: {opened[-600:]}"
    change = float(opened.split("SAVED", 1)[1].split()[0])
    assert change < 1e-3, f"the saved pose and its handles disagree by {change}"
