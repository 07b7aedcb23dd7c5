"""Handles hold any transform an empty can hold: the selection lands where the handle's transform
puts it (non-uniform and negative scale, a non-uniformly scaled object, a handle parented to
another handle's empty), and an R in the world stays a rotation on a non-uniformly scaled object."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from mathutils import Matrix  # noqa: E402

from blender_support import import_spot  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import handles, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import moved_matrix  # noqa: E402

#: Every selected vertex within this share of the diagonal of where its handle puts it.
EXACT = 1e-5


def _world(obj, local):
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    return local.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]


def _diagonal(points):
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def _off(obj, empty, ids):
    """Largest distance of the mesh vertices ``ids`` from where ``empty``'s motion since it was made
    puts them, over the diagonal (object space)."""
    bpy.context.view_layer.update()
    rest = api.rest_positions(obj).astype(np.float64)
    motion = handles.local_motion(obj, empty)
    want = rest[ids] @ motion[:3, :3].T + motion[:3, 3]
    now = mesh_io.read_positions(obj.data).astype(np.float64)
    return float(np.linalg.norm(now[ids] - want, axis=1).max()) / _diagonal(rest)


def _limb(obj):
    """Anchor on the lowest 15 % along y, handle on the highest 15 %: (anchor ids, handle ids)."""
    y = api.rest_positions(obj)[:, 1]
    low, high = np.quantile(y, [0.15, 0.85])
    return np.flatnonzero(y < low), np.flatnonzero(y > high)


@pytest.mark.parametrize("scale", [(2.0, 1.0, 1.0), (1.0, 0.5, 1.0), (-1.0, 1.0, 1.0), (-1.0, -1.0, -1.0),
                                   (1.5, 1.5, 1.5)])
def test_the_selection_follows_any_scale_of_its_handle_exactly(scene, scale):
    obj = import_spot()
    api.build(obj, target_faces=300)
    anchored, top = _limb(obj)
    api.add_anchor(obj, anchored)
    handle = api.add_handle(obj, top)
    handle.rotation_euler = (0.3, 0.0, 0.4)
    handle.scale = scale
    api.deform(obj)
    assert _off(obj, handle, top) <= EXACT
    now = mesh_io.read_positions(obj.data)
    assert np.array_equal(now[anchored], api.rest_positions(obj)[anchored])  # anchors never move
    assert np.isfinite(now).all()


def test_r_in_the_world_on_a_non_uniformly_scaled_object_stays_a_rotation(scene):
    """The object's scale (1, 2, 1) is not applied: a drag's R 90 (the world matrix it sets) is kept
    by the empty as it is, and the selection turns by 90 degrees in the world."""
    obj = import_spot()
    obj.scale = (1.0, 2.0, 1.0)
    obj.rotation_euler = (0.3, 0.0, 0.5)
    bpy.context.view_layer.update()
    api.build(obj, target_faces=300)
    anchored, top = _limb(obj)
    api.add_anchor(obj, anchored)
    handle = api.add_handle(obj, top)
    bpy.context.view_layer.update()
    start = handle.matrix_world.copy()
    turned = moved_matrix(start, (0.0, 0.0, 0.0), Matrix.Rotation(math.pi / 2, 3, 'Z'), (1.0, 1.0, 1.0))
    handle.matrix_world = turned
    bpy.context.view_layer.update()
    assert np.abs(np.array(handle.matrix_world) - np.array(turned)).max() <= 1e-5 * np.abs(np.array(turned)).max()
    api.deform(obj)
    rest_world = _world(obj, api.rest_positions(obj))
    turn = np.array(turned) @ np.linalg.inv(np.array(start))
    want = rest_world[top] @ turn[:3, :3].T + turn[:3, 3]
    now = _world(obj, mesh_io.read_positions(obj.data))
    assert np.linalg.norm(now[top] - want, axis=1).max() <= EXACT * _diagonal(rest_world)
    api.reset(obj)
    bpy.context.view_layer.update()
    assert np.abs(np.array(handle.matrix_world) - np.array(start)).max() <= 1e-5 * np.abs(np.array(start)).max()
    assert np.array_equal(mesh_io.read_positions(obj.data), api.rest_positions(obj))


def test_a_handle_parented_to_another_handles_empty_follows_its_world_transform(scene):
    """A hand whose empty is parented (keep transform) to the forearm's: it stays in the rig, moves
    with the forearm, and Reset puts both back."""
    obj = import_spot()
    api.build(obj, target_faces=300)
    y = api.rest_positions(obj)[:, 1]
    anchored = np.flatnonzero(y < np.quantile(y, 0.15))
    forearm_ids = np.flatnonzero((y > np.quantile(y, 0.6)) & (y <= np.quantile(y, 0.85)))
    hand_ids = np.flatnonzero(y > np.quantile(y, 0.85))
    api.add_anchor(obj, anchored)
    forearm = api.add_handle(obj, forearm_ids)
    hand = api.add_handle(obj, hand_ids)
    bpy.context.view_layer.update()
    hand_start = hand.matrix_world.copy()
    hand.parent = forearm
    hand.matrix_parent_inverse = forearm.matrix_world.inverted()
    assert hand in api.handles_of(obj)
    forearm.rotation_euler = (0.0, 0.0, 0.5)
    forearm.location.x += 0.1
    bpy.context.view_layer.update()
    assert np.abs(np.array(hand.matrix_world) - np.array(hand_start)).max() > 0.05  # it came along
    api.deform(obj)
    assert _off(obj, forearm, forearm_ids) <= EXACT
    assert _off(obj, hand, hand_ids) <= EXACT
    api.reset(obj)
    bpy.context.view_layer.update()
    assert np.abs(np.array(hand.matrix_world) - np.array(hand_start)).max() <= 1e-6
    assert np.array_equal(mesh_io.read_positions(obj.data), api.rest_positions(obj))


def test_a_rebuild_keeps_a_hand_parented_to_its_forearm(scene):
    """Rebuild puts every handle back at rest on the new proxy; a hand parented to the forearm's
    empty stays its child, and still follows its own world transform exactly."""
    obj = import_spot()
    api.build(obj, target_faces=300)
    y = api.rest_positions(obj)[:, 1]
    api.add_anchor(obj, np.flatnonzero(y < np.quantile(y, 0.15)))
    forearm_ids = np.flatnonzero((y > np.quantile(y, 0.6)) & (y <= np.quantile(y, 0.85)))
    hand_ids = np.flatnonzero(y > np.quantile(y, 0.85))
    forearm, hand = api.add_handle(obj, forearm_ids), api.add_handle(obj, hand_ids)
    bpy.context.view_layer.update()
    hand.parent = forearm
    hand.matrix_parent_inverse = forearm.matrix_world.inverted()
    forearm.rotation_euler = (0.0, 0.0, 0.4)
    api.deform(obj)
    api.build(obj, target_faces=300)  # Rebuild: the pose is the new rest
    assert hand.parent == forearm and {forearm, hand} <= set(api.handles_of(obj))
    bpy.context.view_layer.update()
    assert _off(obj, forearm, forearm_ids) <= 1e-7 and _off(obj, hand, hand_ids) <= 1e-7  # at rest
    forearm.location.x += 0.1
    hand.rotation_euler = (0.3, 0.0, 0.0)
    api.deform(obj)
    assert _off(obj, forearm, forearm_ids) <= EXACT
    assert _off(obj, hand, hand_ids) <= EXACT
