"""Set-up of the GUI tests (the part before the artist's steps): scenes made by script."""

import bpy
import numpy as np

import gui


def api():
    return gui.addon().api


def positions(obj):
    """(n, 3) float32 local vertex positions of a mesh object."""
    out = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
    obj.data.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


def override(ui):
    return bpy.context.temp_override(window=ui.window, area=ui.area(), region=ui.view)


def sphere(ui, name="Sphere", rotation=(0.0, 0.0, 0.0), mirror_x=False):
    """A 48x24 UV sphere of radius 1 at the origin, the only mesh in the scene (the default cube
    goes), active and selected, in Object Mode."""
    with override(ui):
        cube = bpy.data.objects.get("Cube")
        if cube is not None:
            bpy.data.objects.remove(cube)
        bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, rotation=rotation)
    obj = bpy.context.view_layer.objects.active
    obj.name = name
    obj.data.use_mirror_x = mirror_x
    undo_push(ui, "Sphere")
    return obj


def undo_push(ui, message):
    """An undo step for what the set-up made by script (bpy.ops from a script push none; an
    artist's own steps each do, and the Redo panel and Ctrl+Z go back to the last one)."""
    with override(ui):
        bpy.ops.ed.undo_push(message=message)


def select_vertices(obj, ids):
    """Select exactly the vertices ``ids`` of ``obj``'s mesh (Object Mode; no edge or face
    selected, so Edit Mode selects no more)."""
    mesh = obj.data
    chosen = np.zeros(len(mesh.vertices), dtype=bool)
    chosen[np.asarray(ids, dtype=np.int64)] = True
    mesh.vertices.foreach_set("select", chosen)
    mesh.edges.foreach_set("select", np.zeros(len(mesh.edges), dtype=bool))
    mesh.polygons.foreach_set("select", np.zeros(len(mesh.polygons), dtype=bool))
    mesh.update()


def activate(ui, obj):
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def rig(ui, anchor=True, handle_above=0.6, **sphere_options):
    """The sphere bound, its bottom (z < -0.6) anchored, its cap (z > ``handle_above``) a handle;
    the handle active. Returns (mesh object, handle empty)."""
    obj = sphere(ui, **sphere_options)
    sd = api()
    sd.build(obj, target_faces=300)
    rest = sd.rest_positions(obj)
    if anchor:
        sd.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6), mirror="")
    handle = sd.add_handle(obj, np.flatnonzero(rest[:, 2] > handle_above), mirror="")
    activate(ui, handle)
    undo_push(ui, "Rig")
    return obj, handle


def in_blender(path, code):
    """Output of ``code`` run in this Blender (in the background, the same user folder, so the
    same installed extension) on the file ``path``, with ``bpy`` and the add-on's ``api``."""
    import subprocess
    import sys
    prefix = (f"import bpy, sys; sys.path.insert(0, {str(gui.__file__.rsplit('/', 1)[0])!r}); import gui; "
              f"api = gui.addon().api; ")
    done = subprocess.run([bpy.app.binary_path, "--background", path, "--python-exit-code", "1", "--python-expr",
                           prefix + code], capture_output=True, text=True, timeout=120)
    return done.stdout + done.stderr


def drag(ui, dx, dy, steps=8, keys=(), confirm='RET'):
    """Shift+Alt+D over the 3D View, ``keys`` (R, S, X, digits...) then the mouse moved by (dx, dy)
    pixels in ``steps`` moves, then ``confirm`` (RET, LEFTMOUSE, RIGHTMOUSE, ESC, or None: the
    drag goes on)."""
    x, y = ui.centre(ui.view)
    yield from ui.move(x - 100, y)
    yield from ui.press('D', shift=True, alt=True, wait=0.3)
    for key in keys:
        yield from ui.press(key, wait=0.2)
    yield from ui.move(x - 100 + dx, y + dy, steps=steps, wait=0.1)
    yield 0.5
    if confirm:
        yield from ui.press(confirm, wait=0.5)
