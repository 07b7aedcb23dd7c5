"""The docs' pictures of the add-on, taken from a real Blender window (``make docs-pictures``):
the tutorial's steps made with events as an artist makes them, on the bundled armadillo.

    window_setup.png  after Build, Add Anchor (the base) and Add Handle (the head)
    window_drag.png   a drag under way: the 3D View with its header (what the drag says)
    window_panel.png  the sidebar's Skin Detach tab after the drag
    window_parts.png  two eyes and a belt as separate objects built with the body as one rig, the
                      head turned by a drag: they ride on it
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


def _mesh_object(name, points, triangles, like):
    """A mesh object of ``points`` (local to ``like``'s space) and ``triangles``, placed as ``like``."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(points.tolist(), [], triangles.tolist())
    mesh.update()
    made = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(made)
    made.matrix_world = like.matrix_world.copy()
    return made


def take_parts_picture(ui):
    """window_parts.png: the armadillo with two eyes and a belt as separate objects, all selected
    and built as one rig with the panel's Build button, then the head turned by a drag: the eyes
    and the belt ride on the body."""
    import sys
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent.parent))
    from bench.riders import body_parts, torus
    out = pathlib.Path(ui.pictures)
    with rigs.override(ui):
        for obj in list(bpy.data.objects):
            bpy.data.objects.remove(obj)
        bpy.ops.wm.obj_import(filepath=str(MESH))
    body = bpy.context.view_layer.objects.active
    body.name = "Armadillo"
    points = rigs.positions(body).astype(np.float64)
    triangles = np.array([p.vertices[:] for p in body.data.polygons])
    parts = body_parts(points, triangles, ("eye",))
    eye, eye_faces = parts["eye"]
    extent = np.ptp(points, axis=0)
    longest, middle, shortest = np.argsort(extent)[::-1]
    mirrored = eye.copy()
    mirrored[:, shortest] = 2 * points[:, shortest].mean() - mirrored[:, shortest]
    # The belt: a torus round the waist (40 % up the longest axis), a little wider than the body there.
    level = points[:, longest].min() + 0.4 * extent[longest]
    ring = points[np.abs(points[:, longest] - level) <= 0.01 * extent[longest]]
    centre = ring.mean(axis=0)
    axis = np.eye(3)[longest]
    radial = np.linalg.norm((ring - centre) - np.outer((ring - centre) @ axis, axis), axis=1)
    belt, belt_faces = torus(centre, axis, 1.04 * radial.max(), 0.02 * extent[longest], around=48, tube=8)
    made = [_mesh_object("Eye.L", eye, eye_faces, body), _mesh_object("Eye.R", mirrored, eye_faces[:, ::-1], body),
            _mesh_object("Belt", belt, belt_faces, body)]
    for obj in made + [body]:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = body
    rigs.undo_push(ui, "Parts")
    yield from ui.hover_view()
    yield from ui.press('NUMPAD_PERIOD', wait=1.0)
    yield from ui.click_button("bpy.ops.skin_detach.build", wait=6.0)
    z = (np.asarray(body.matrix_world) @ np.c_[points, np.ones(points.shape[0])].T)[2]
    low, high = np.quantile(z, [0.08, 0.88])
    yield from _edit_select(ui, body, np.flatnonzero(z < low))
    yield from ui.click_button("bpy.ops.skin_detach.add_anchor", wait=1.5)
    yield from _edit_select(ui, body, np.flatnonzero(z > high))
    yield from ui.click_button("bpy.ops.skin_detach.add_handle", wait=1.5)
    yield from rigs.drag(ui, 160, 40, steps=12, keys=('R',), confirm='RET')
    yield 2.0
    area = ui.area()
    ui.screenshot(out / "window_parts.png", (area.x, area.y, area.x + area.width, area.y + area.height))
