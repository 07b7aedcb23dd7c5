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


def imported_limb(ui, scale=(0.6, 0.6, 0.6)):
    """A limb of quads and ngons as an OBJ or FBX import leaves it (rotation X 90 degrees, an
    unapplied scale ``scale``), the only mesh in the scene: an arm 4 long along its local X (a
    subdivided box) and a loose bracelet with octagon caps near its end; bound, its shoulder
    anchored, its forearm and hand handles. Returns (obj, forearm empty, hand empty, hand ids)."""
    import bmesh
    from mathutils import Matrix
    with override(ui):
        cube = bpy.data.objects.get("Cube")
        if cube is not None:
            bpy.data.objects.remove(cube)
    mesh = bpy.data.meshes.new("limb")
    made = bmesh.new()
    bmesh.ops.create_cube(made, size=1.0)
    bmesh.ops.subdivide_edges(made, edges=made.edges[:], cuts=7, use_grid_fill=True)
    bmesh.ops.scale(made, vec=(4.0, 1.0, 0.6), verts=made.verts[:])
    bmesh.ops.create_cone(made, cap_ends=True, segments=8, radius1=0.7, radius2=0.7, depth=0.3,
                          matrix=Matrix.Translation((1.2, 0.0, 0.0)) @ Matrix.Rotation(1.5708, 4, 'Y'))
    made.to_mesh(mesh)
    made.free()
    obj = bpy.data.objects.new("limb", mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.rotation_euler = (np.radians(90.0), 0.0, 0.0)
    obj.scale = scale
    bpy.context.view_layer.update()
    points = positions(obj)
    x = points[:, 0]
    arm = (np.abs(points[:, 1]) <= 0.5 + 1e-6) & (np.abs(points[:, 2]) <= 0.3 + 1e-6)
    sd = api()
    sd.build(obj, target_faces=300)
    sd.add_anchor(obj, np.flatnonzero(arm & (x < -1.6)), mirror="")
    forearm = sd.add_handle(obj, np.flatnonzero(arm & (x > 0.1) & (x < 0.9)), mirror="")
    hand_ids = np.flatnonzero(arm & (x > 1.5))
    hand = sd.add_handle(obj, hand_ids, mirror="")
    activate(ui, hand)
    undo_push(ui, "Rig")
    return obj, forearm, hand, hand_ids


def held_off(obj, empty, ids):
    """Largest distance of the mesh vertices ``ids`` from where ``empty``'s world matrix puts them
    (its motion in the object's space from its rest frame, ``obj_world^-1 @ empty_world @
    rest_local^-1``, on their rest positions), over the rest diagonal."""
    bpy.context.view_layer.update()
    rest = api().rest_positions(obj).astype(np.float64)
    record = empty["_skin_detach_handle"]
    rest_local = np.array(record["rest_local"], dtype=np.float64).reshape(4, 4)
    motion = np.linalg.solve(np.array(obj.matrix_world), np.array(empty.matrix_world)) @ np.linalg.inv(rest_local)
    want = rest[ids] @ motion[:3, :3].T + motion[:3, 3]
    size = float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))
    return float(np.linalg.norm(positions(obj)[ids].astype(np.float64) - want, axis=1).max()) / size


def max_stretch(obj):
    """Largest ratio of an edge's length now to its rest length (the mesh's own space)."""
    edges = np.empty(2 * len(obj.data.edges), dtype=np.int32)
    obj.data.edges.foreach_get("vertices", edges)
    edges = edges.reshape(-1, 2)
    rest, now = api().rest_positions(obj).astype(np.float64), positions(obj).astype(np.float64)
    before = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
    return float((np.linalg.norm(now[edges[:, 0]] - now[edges[:, 1]], axis=1) / before).max())
