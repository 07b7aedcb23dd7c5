"""Issue 51, riders in Blender (headless bpy): the loose parts of one mesh follow the part they
touch; a part far from all stays; the panel's Attach / Detach decide a part and rebuild; the rig
saves and reopens with its riders. The mesh is rotated and scaled as an OBJ import leaves it."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, save_and_reopen, select_vertices  # noqa: E402
from test_core_riders import character  # noqa: E402

from bench.meshes import blender_mesh  # noqa: E402
from bench.riders import follow_figures  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import handles, mesh_io  # noqa: E402


def rigged(scene, name="character"):
    points, triangles, ids = character()
    obj = blender_mesh(name, points, triangles)
    obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
    obj.scale = (0.5, 0.5, 0.5)
    activate(obj)
    bpy.context.scene.skin_detach.target_faces = 400
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    z = points[:, 2]
    body = np.zeros(points.shape[0], dtype=bool)
    body[ids["body"]] = True
    select_vertices(obj, body & (z <= 0.5))
    assert bpy.ops.skin_detach.add_anchor() == {'FINISHED'}
    select_vertices(obj, body & (z >= 2.5))
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    handle = [e for e in handles.handles_of(obj) if handles.kind_of(e) == handles.HANDLE][0]
    return obj, handle, points, triangles, ids


def turn(obj, handle, degrees=35.0):
    from mathutils import Matrix, Vector
    centre = handle.matrix_world.to_translation()
    axis = (obj.matrix_world.to_3x3() @ Vector((1.0, 0.0, 0.0))).normalized()
    handle.matrix_world = Matrix.Translation(centre) @ Matrix.Rotation(math.radians(degrees), 4, axis) \
        @ Matrix.Translation(-centre) @ handle.matrix_world
    bpy.context.view_layer.update()


def test_the_panel_tells_the_parts_and_the_riders_follow_the_body_and_keep_their_shape(scene):
    obj, handle, points, triangles, ids = rigged(scene)
    figures = api.figures(obj)["build"]
    assert (figures["parts"], figures["riders"], figures["rider_hosts"]) == (6, 4, 1)
    turn(obj, handle)
    api.deform(obj)
    deformed = mesh_io.read_positions(obj.data).astype(np.float64)
    rows = follow_figures(points, deformed, triangles, {"body": ids["body"], "eye": ids["eye"],
                                                        "plate": ids["plate"], "bracelet": ids["bracelet"]})
    assert rows["eye"]["moved"] > 0.02  # the premise: the head moved (a tenth of its height and more)
    for name, row in rows.items():
        assert row["offset"] <= 0.01 and row["stretch"] <= row["surface_stretch"] + 1e-5, (name, row)
    # The eye and the plate are smaller than a piece: they move rigidly (float32 positions). The
    # bracelet, a belt as wide as the body round its bending middle, follows the bend piece by piece.
    assert rows["eye"]["stretch"] <= 1e-5 and rows["plate"]["stretch"] <= 1e-5
    assert np.abs(deformed[ids["prop"]] - points[ids["prop"]]).max() <= 1e-6  # unchanged (float32 rebuild)


def test_a_rider_selected_by_a_handle_lands_exactly_where_the_handle_puts_it(scene):
    obj, handle, points, triangles, ids = rigged(scene)
    mask = np.zeros(points.shape[0], dtype=bool)
    mask[ids["plate"]] = True
    select_vertices(obj, mask)
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    plate = [e for e in handles.handles_of(obj) if handles.kind_of(e) == handles.HANDLE][-1]
    plate.location.y += 0.2
    bpy.context.view_layer.update()
    api.deform(obj)
    deformed = mesh_io.read_positions(obj.data).astype(np.float64)
    motion = handles.local_motion(obj, plate)
    expected = points[ids["plate"]] @ motion[:3, :3].T + motion[:3, 3]
    diagonal = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    assert np.abs(deformed[ids["plate"]] - expected).max() <= 1e-5 * diagonal
    assert np.abs(deformed[ids["plate"]] - points[ids["plate"]]).max() > 0.1  # it moved


def test_detach_frees_a_part_and_rebuilds_attach_makes_the_far_prop_ride(scene):
    obj, handle, points, triangles, ids = rigged(scene)
    mask = np.zeros(points.shape[0], dtype=bool)
    mask[ids["eye"][:1]] = True
    select_vertices(obj, mask)
    assert bpy.ops.skin_detach.set_parts(mode='DETACH') == {'FINISHED'}
    figures = api.figures(obj)["build"]
    assert (figures["riders"], figures["parts_detached"]) == (3, 1)
    assert len(handles.handles_of(obj)) == 2  # the rebuild kept the handles
    turn(obj, handle)
    api.deform(obj)
    deformed = mesh_io.read_positions(obj.data)
    # Free with no handle on it: the eye stays where it is while the head turns away.
    assert np.abs(deformed[ids["eye"]] - points[ids["eye"]]).max() <= 1e-5
    api.reset(obj)
    mask[:] = False
    mask[ids["prop"][:1]] = True
    select_vertices(obj, mask)
    assert bpy.ops.skin_detach.set_parts(mode='ATTACH') == {'FINISHED'}
    assert api.figures(obj)["build"]["riders_attached"] == 1
    turn(obj, handle)
    api.deform(obj)
    assert np.abs(mesh_io.read_positions(obj.data)[ids["prop"]] - points[ids["prop"]]).max() > 1e-3
    mask[:] = False
    mask[ids["eye"][:1]] = True
    mask[ids["prop"][:1]] = True
    select_vertices(obj, mask)
    assert bpy.ops.skin_detach.set_parts(mode='RULE') == {'FINISHED'}
    assert api.part_overrides(obj) == (None, None)
    assert api.figures(obj)["build"]["riders"] == 4


def test_a_rig_with_riders_reopens_and_poses_the_same(scene, tmp_path):
    obj, handle, points, triangles, ids = rigged(scene)
    turn(obj, handle)
    api.deform(obj)
    posed = mesh_io.read_positions(obj.data)
    obj, handle = save_and_reopen(tmp_path / "riders.blend", name="character")
    api.deform(obj)
    diagonal = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    assert np.abs(mesh_io.read_positions(obj.data) - posed).max() <= 1e-5 * diagonal
