"""The docs' pictures of the add-on, taken from a real Blender window (``make docs-pictures``):
the tutorial's steps made with events as an artist makes them, on the bundled armadillo.

    window_setup.png  after Build, Add Anchor (the base) and Add Handle (the head)
    window_drag.png   a drag under way: the 3D View with its header (what the drag says)
    window_panel.png  the sidebar's Skin Detach tab after the drag
"""

import pathlib

import bpy
import numpy as np

import rigs

MESH = pathlib.Path(__file__).resolve().parent.parent / "data" / "armadillo.obj"


def _edit_select(ui, obj, ids):
    rigs.select_vertices(obj, ids)
    rigs.activate(ui, obj)
    yield from ui.hover_view()
    yield from ui.press('TAB', wait=0.5)


def take_pictures(ui):
    out = pathlib.Path(ui.pictures)
    yield from ui.setup()
    with rigs.override(ui):
        bpy.data.objects.remove(bpy.data.objects["Cube"])
        bpy.ops.wm.obj_import(filepath=str(MESH))
    obj = bpy.context.view_layer.objects.active
    rigs.undo_push(ui, "Import")
    yield from ui.hover_view()
    yield from ui.press('NUMPAD_PERIOD', wait=1.0)  # View Selected
    yield from ui.click_button("bpy.ops.skin_detach.build", wait=4.0)
    z = (np.asarray(obj.matrix_world) @ np.c_[rigs.positions(obj), np.ones(len(obj.data.vertices))].T)[2]
    low, high = np.quantile(z, [0.08, 0.88])
    yield from _edit_select(ui, obj, np.flatnonzero(z < low))
    yield from ui.click_button("bpy.ops.skin_detach.add_anchor", wait=1.5)
    yield from _edit_select(ui, obj, np.flatnonzero(z > high))
    yield from ui.click_button("bpy.ops.skin_detach.add_handle", wait=1.5)
    area = ui.area()
    whole = (area.x, area.y, area.x + area.width, area.y + area.height)
    yield from ui.hover_view()
    yield 1.0
    ui.screenshot(out / "window_setup.png", whole)
    yield from rigs.drag(ui, 160, 40, steps=12, keys=('R',), confirm=None)
    yield 1.0
    ui.screenshot(out / "window_drag.png", whole)
    yield from ui.press('RET', wait=2.0)
    side = ui.sidebar
    yield from ui.move(side.x + side.width // 2, side.y + 10)
    yield 0.5
    ui.screenshot(out / "window_panel.png", (side.x, side.y, side.x + side.width, side.y + side.height))
