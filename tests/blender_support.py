"""Shared set-up of the headless bpy tests: a fresh empty scene, small bound meshes, a fake view."""

import pathlib

import numpy as np

import bpy

from bench.views import TopView  # noqa: F401  (tests import it from here)
from skin_detach_addon.blender import handles, mesh_io

DATA = pathlib.Path(__file__).parent / "data"


def activate(obj):
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def import_spot():
    """spot.obj (triangles, UVs) as the active object."""
    bpy.ops.wm.obj_import(filepath=str(DATA / "spot.obj"))
    obj = bpy.context.selected_objects[0]
    activate(obj)
    return obj


def quad_sphere(name="quads", segments=32, rings=16):
    """UV sphere (quads with triangle fans at the poles, UVs) with a vertex group, two materials
    and custom attributes on points and faces, as the active object."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=1.0)
    obj = bpy.context.active_object
    obj.name = name
    mesh = obj.data
    group = obj.vertex_groups.new(name="weights")
    for index in range(0, len(mesh.vertices), 3):
        group.add([index], (index % 7) / 7.0, 'REPLACE')
    for label in ("red", "blue"):
        mesh.materials.append(bpy.data.materials.new(label))
    mesh.polygons.foreach_set("material_index", (np.arange(len(mesh.polygons)) % 2).astype(np.int32))
    values = np.linspace(0.0, 1.0, len(mesh.vertices), dtype=np.float32)
    mesh.attributes.new("temperature", 'FLOAT', 'POINT').data.foreach_set("value", values)
    mesh.attributes.new("region", 'INT', 'FACE').data.foreach_set(
        "value", (np.arange(len(mesh.polygons)) % 5).astype(np.int32))
    mesh.update()
    activate(obj)
    return obj


def select_vertices(obj, mask):
    obj.data.vertices.foreach_set("select", np.asarray(mask, dtype=bool))
    obj.data.update()


def band(obj, low, high, axis=2):
    """Mask of the vertices whose ``axis`` coordinate lies in [low, high] of its range (fractions)."""
    positions = mesh_io.read_positions(obj.data)[:, axis]
    span = positions.max() - positions.min()
    return (positions >= positions.min() + low * span) & (positions <= positions.min() + high * span)


def rig(obj, target_faces=300, axis=2):
    """Build ``obj``, add an anchor on its lowest 15 % and a handle on its highest 15 %."""
    bpy.context.scene.skin_detach.target_faces = target_faces
    activate(obj)
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    select_vertices(obj, band(obj, 0.0, 0.15, axis))
    assert bpy.ops.skin_detach.add_anchor() == {'FINISHED'}
    select_vertices(obj, band(obj, 0.85, 1.0, axis))
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    handle = [e for e in handles.handles_of(obj) if handles.kind_of(e) == handles.HANDLE][0]
    return handle


def save_and_reopen(path, name="spot"):
    """Save the file to ``path``, drop the runtime cache, reopen it; returns (the object ``name``,
    its first handle)."""
    from skin_detach_addon.blender import binding
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    binding._CACHE.clear()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects[name]
    return obj, [e for e in handles.handles_of(obj) if handles.kind_of(e) == handles.HANDLE][0]


def all_data(mesh):
    """Everything but positions that the add-on must leave alone, as arrays."""
    out = {}
    corner = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.attributes[".corner_vert"].data.foreach_get("value", corner)
    out["corner_vert"] = corner
    starts = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    out["loop_start"] = starts
    materials = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("material_index", materials)
    out["material_index"] = materials
    for layer in mesh.uv_layers:
        uv = np.empty(2 * len(mesh.loops), dtype=np.float32)
        layer.data.foreach_get("uv", uv)
        out[f"uv:{layer.name}"] = uv
    for attribute in mesh.attributes:
        if attribute.name == "position" or attribute.name.startswith("."):
            continue
        if attribute.data_type in ('FLOAT', 'INT', 'BOOLEAN', 'INT8'):
            field = "value"
            width = 1
        elif attribute.data_type in ('FLOAT_VECTOR',):
            field, width = "vector", 3
        elif attribute.data_type == 'FLOAT2':
            field, width = "vector", 2
        elif attribute.data_type in ('FLOAT_COLOR', 'BYTE_COLOR'):
            field, width = "color", 4
        else:
            continue
        values = np.empty(width * len(attribute.data), dtype=np.float64)
        attribute.data.foreach_get(field, values)
        out[f"attr:{attribute.name}"] = values
    out["materials"] = np.array([m.name for m in mesh.materials])
    return out


def vertex_group_weights(obj):
    mesh = obj.data
    return [[(g.group, g.weight) for g in v.groups] for v in mesh.vertices]


def imported_limb(name="limb", scale=(1.0, 1.0, 1.0)):
    """A limb of quads and ngons as an OBJ or FBX import leaves it: rotation X 90 degrees (the file's
    Y up) and the object scale ``scale`` unapplied; the active object. Two parts: an arm 4 long along
    its local X (a subdivided box, 1 x 0.6 across) and a loose bracelet near its end (a cylinder
    with octagon caps). Returns (obj, {"shoulder", "forearm", "hand"}: vertex ids along the arm)."""
    import bmesh
    from mathutils import Matrix
    mesh = bpy.data.meshes.new(name)
    made = bmesh.new()
    bmesh.ops.create_cube(made, size=1.0)
    bmesh.ops.subdivide_edges(made, edges=made.edges[:], cuts=7, use_grid_fill=True)
    bmesh.ops.scale(made, vec=(4.0, 1.0, 0.6), verts=made.verts[:])
    bmesh.ops.create_cone(made, cap_ends=True, segments=8, radius1=0.7, radius2=0.7, depth=0.3,
                          matrix=Matrix.Translation((1.2, 0.0, 0.0)) @ Matrix.Rotation(1.5708, 4, 'Y'))
    made.to_mesh(mesh)
    made.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.rotation_euler = (np.radians(90.0), 0.0, 0.0)
    obj.scale = scale
    activate(obj)
    bpy.context.view_layer.update()
    points = mesh_io.read_positions(mesh)
    x, arm = points[:, 0], np.abs(points[:, 1]) <= 0.5 + 1e-6
    arm &= np.abs(points[:, 2]) <= 0.3 + 1e-6
    parts = {"shoulder": np.flatnonzero(arm & (x < -1.6)), "forearm": np.flatnonzero(arm & (x > 0.1) & (x < 0.9)),
             "hand": np.flatnonzero(arm & (x > 1.5))}
    return obj, parts
