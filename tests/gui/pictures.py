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
    from bench.riders import torus, uv_sphere
    out = pathlib.Path(ui.pictures)
    yield from ui.setup()
    with rigs.override(ui):
        for obj in list(bpy.data.objects):
            bpy.data.objects.remove(obj)
        bpy.ops.wm.obj_import(filepath=str(MESH))
    body = bpy.context.view_layer.objects.active
    body.name = "Armadillo"
    points = rigs.positions(body).astype(np.float64)
    triangles = np.array([p.vertices[:] for p in body.data.polygons])
    extent = np.ptp(points, axis=0)
    longest, middle, shortest = np.argsort(extent)[::-1]
    low = points.min(axis=0)
    centre_line = np.median(points[:, middle])
    # The head: the top eighth of the height, near the middle (the raised hand is off to a side);
    # the face: the side of the shortest axis the head sticks out farther on.
    head = points[(points[:, longest] > low[longest] + 0.87 * extent[longest])
                  & (np.abs(points[:, middle] - centre_line) < 0.12 * extent[middle])]
    mid = head.mean(axis=0)
    side = 1.0 if head[:, shortest].max() - mid[shortest] > mid[shortest] - head[:, shortest].min() else -1.0
    front = head[np.argmax(side * head[:, shortest])]
    radius = 0.018 * float(np.linalg.norm(extent))
    eyes = []
    for shift in (-1.0, 1.0):
        spot = front.copy()
        spot[middle] += shift * 2.2 * radius
        spot[longest] += 1.5 * radius
        near = head[np.argmin(np.linalg.norm(head - spot, axis=1))]  # on the face there
        eyes.append(uv_sphere(near, radius))
    # The belt: round the waist (45 % up), hugging the torso's cross-section there.
    level = low[longest] + 0.45 * extent[longest]
    ring = points[(np.abs(points[:, longest] - level) <= 0.01 * extent[longest])
                  & (np.abs(points[:, middle] - centre_line) < 0.3 * extent[middle])]
    centre = ring.mean(axis=0)
    axis = np.eye(3)[longest]
    radial = np.linalg.norm((ring - centre) - np.outer((ring - centre) @ axis, axis), axis=1)
    belt, belt_faces = torus(centre, axis, 1.03 * np.percentile(radial, 90) + 0.01 * extent[longest],
                             0.015 * extent[longest], around=48, tube=8)
    made = [_mesh_object("Eye.L", *eyes[0], body), _mesh_object("Eye.R", *eyes[1], body),
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
