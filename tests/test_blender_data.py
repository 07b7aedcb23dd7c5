"""Headless bpy: only positions change; transforms, shape keys and modifiers are respected."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, all_data, band, import_spot, quad_sphere, rig, vertex_group_weights  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402

from skin_detach_addon.blender import mesh_io  # noqa: E402


@pytest.mark.parametrize("make", [quad_sphere, import_spot], ids=["quads_with_uvs", "spot"])
def test_only_positions_change(scene, make):
    obj = make()
    axis = 2 if obj.name == "quads" else 1
    before, groups = all_data(obj.data), vertex_group_weights(obj)
    polygons, vertices = len(obj.data.polygons), len(obj.data.vertices)
    rest = mesh_io.read_positions(obj.data)
    handle = rig(obj, target_faces=200, axis=axis)
    handle.location.x += 0.3
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert np.abs(mesh_io.read_positions(obj.data) - rest).max() > 0.1
    after = all_data(obj.data)
    assert before.keys() == after.keys() and mesh_io.STRETCH not in obj.data.attributes  # nothing added beside
    for key in before:
        assert np.array_equal(before[key], after[key]), key
    assert vertex_group_weights(obj) == groups
    assert (len(obj.data.polygons), len(obj.data.vertices)) == (polygons, vertices)


def test_transformed_parented_negative_scale_object(scene):
    parent = bpy.data.objects.new("parent", None)
    scene.collection.objects.link(parent)
    parent.matrix_world = Matrix.Translation((1.0, -2.0, 0.5)) @ Matrix.Rotation(0.7, 4, 'Z')
    obj = quad_sphere()
    obj.parent = parent
    obj.matrix_basis = Matrix.LocRotScale(Vector((0.3, 0.0, 0.0)), Matrix.Rotation(0.4, 3, 'X').to_quaternion(),
                                          Vector((1.5, -1.0, 2.0)))
    bpy.context.view_layer.update()
    assert obj.matrix_world.determinant() < 0
    rest = mesh_io.read_positions(obj.data)
    top = band(obj, 0.85, 1.0, axis=2)
    handle = rig(obj, target_faces=200)
    world = np.array(obj.matrix_world)
    rest_world = rest @ world[:3, :3].T + world[:3, 3]
    activate(handle)
    offset = np.array((0.25, -0.1, 0.4))
    assert bpy.ops.skin_detach.drag(offset=offset) == {'FINISHED'}
    moved = mesh_io.read_positions(obj.data)
    moved_world = moved @ world[:3, :3].T + world[:3, 3]
    # The handle's detail moves by the world offset; the result lands in local space.
    assert np.allclose(moved_world[top] - rest_world[top], offset, atol=1e-4)
    assert np.abs(moved[~top] - rest[~top]).max() > 0.01


def test_shape_keys_keep_their_offsets(scene):
    obj = import_spot()
    obj.shape_key_add(name="Basis")
    smile = obj.shape_key_add(name="smile")
    basis = mesh_io.read_positions(obj.data)
    offset = np.zeros_like(basis)
    offset[::5, 2] = 0.05
    smile.data.foreach_set("co", (basis + offset).ravel())
    handle = rig(obj, axis=1)
    handle.location.x += 0.3
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    new_basis = mesh_io.read_positions(obj.data)
    assert np.abs(new_basis - basis).max() > 0.1
    position = np.empty(basis.size, dtype=np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", position)
    assert np.array_equal(position.reshape(-1, 3), new_basis)
    new_smile = np.empty(basis.size, dtype=np.float32)
    obj.data.shape_keys.key_blocks["smile"].data.foreach_get("co", new_smile)
    assert np.allclose(new_smile.reshape(-1, 3) - new_basis, offset, atol=1e-6)
    assert bpy.ops.skin_detach.reset() == {'FINISHED'}
    assert np.array_equal(mesh_io.read_positions(obj.data), basis)


def test_modifiers_stay_and_evaluate_on_top(scene):
    obj = quad_sphere()
    obj.modifiers.new("subsurf", 'SUBSURF').levels = 1
    handle = rig(obj, target_faces=200)
    handle.location.z += 0.5
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert [m.name for m in obj.modifiers] == ["subsurf"]
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    try:
        heights = np.array([v.co.z for v in evaluated.vertices])
        assert len(evaluated.vertices) > len(obj.data.vertices)
        assert heights.max() > 1.3  # the subdivided result follows the deformed cage
    finally:
        obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
