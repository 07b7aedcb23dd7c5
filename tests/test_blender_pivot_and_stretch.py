"""Handles pivot on their selection's median point; the detail's stretch as an attribute."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from mathutils import Matrix  # noqa: E402

from blender_support import activate, quad_sphere  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import handles, mesh_io  # noqa: E402


def world_positions(obj):
    local = mesh_io.read_positions(obj.data).astype(np.float64)
    world = np.array(obj.matrix_world)
    return local @ world[:3, :3].T + world[:3, 3]


def test_the_empty_sits_at_the_selections_median_point_in_world_space_under_any_transform(scene):
    obj = quad_sphere()
    obj.matrix_world = Matrix.LocRotScale((0.3, -2.0, 1.0), Matrix.Rotation(0.7, 3, (1, 2, 3)).to_quaternion(),
                                          (1.5, 0.5, 2.0))
    bpy.context.view_layer.update()
    api.build(obj, target_faces=200)
    local = mesh_io.read_positions(obj.data)
    cap = np.flatnonzero((local[:, 2] > 0.5) & (local[:, 0] > 0.2))  # off-centre: proxy corners average elsewhere
    empty = api.add_handle(obj, cap, mirror="")
    median = world_positions(obj)[cap].mean(axis=0)
    size = np.ptp(world_positions(obj), axis=0).max()
    assert np.linalg.norm(np.array(empty.matrix_world.translation) - median) < 1e-4 * size
    assert not handles.has_old_pivot(empty)


def test_a_self_symmetric_cap_pivots_on_the_mirror_plane_and_s_2_widens_it_in_place(scene):
    obj = quad_sphere()
    obj.data.use_mirror_x = True
    api.build(obj, target_faces=200)
    rest = mesh_io.read_positions(obj.data).astype(np.float64)
    cap = np.flatnonzero(rest[:, 2] > 0.8)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.8))
    empty = api.add_handle(obj, cap)
    assert len(api.handles_of(obj)) == 2                      # its own mirror image: no twin
    assert empty.matrix_world.translation.x == 0.0
    assert np.linalg.norm(np.array(empty.matrix_world.translation) - rest[cap].mean(axis=0)) < 1e-4
    empty.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    api.deform(obj)
    moved = mesh_io.read_positions(obj.data).astype(np.float64)
    assert np.abs(moved[cap].mean(axis=0) - rest[cap].mean(axis=0)).max() < 1e-5
    assert np.ptp(moved[cap, 0]) == pytest.approx(2 * np.ptp(rest[cap, 0]), rel=1e-5)


def test_twins_empties_mirror_each_other_exactly_also_after_a_rebuild(scene):
    obj = quad_sphere()
    api.build(obj, target_faces=200)
    rest = mesh_io.read_positions(obj.data)
    first = api.add_handle(obj, np.flatnonzero((rest[:, 0] > 0.6) & (rest[:, 2] > 0.0)), mirror="X")
    twin = api.mirror_twin(first)
    for _ in range(2):
        a, b = np.array(first.matrix_world.translation), np.array(twin.matrix_world.translation)
        assert a[0] == -b[0] and a[1] == b[1] and a[2] == b[2] and a[0] > 0.5
        api.build(obj, target_faces=150)
        bpy.context.view_layer.update()


def test_stretch_is_zero_at_rest_larger_where_it_bends_and_written_by_each_step_while_shown(scene):
    obj = quad_sphere(segments=48, rings=24)
    api.build(obj, target_faces=300)
    rest = mesh_io.read_positions(obj.data).astype(np.float64)
    assert np.array_equal(api.stretch(obj), np.zeros(len(rest), dtype=np.float32))
    bottom, top = rest[:, 2] < -0.7, rest[:, 2] > 0.7
    api.add_anchor(obj, np.flatnonzero(bottom))
    handle = api.add_handle(obj, np.flatnonzero(top))
    handle.location.x += 0.8
    handle.rotation_euler.y = 0.6
    bpy.context.view_layer.update()
    api.deform(obj)
    stretch = api.stretch(obj)
    assert mesh_io.STRETCH not in obj.data.attributes       # nothing added until it is shown
    assert stretch.dtype == np.float32 and np.isfinite(stretch).all() and stretch.min() >= 0
    middle = np.abs(rest[:, 2]) < 0.3
    assert stretch[middle].mean() > 2 * stretch[bottom].mean() and stretch[middle].mean() > 1e-3
    api.show_stretch(obj)
    colors = obj.data.color_attributes[mesh_io.STRETCH_COLORS]
    assert obj.data.color_attributes.active_color == colors
    assert obj.data.attributes[mesh_io.STRETCH].domain == 'POINT'
    assert np.array_equal(mesh_io.read_point_floats(obj.data, mesh_io.STRETCH), stretch)
    api.reset(obj)
    assert np.array_equal(api.stretch(obj), np.zeros(len(rest), dtype=np.float32))
    assert np.array_equal(mesh_io.read_point_floats(obj.data, mesh_io.STRETCH), api.stretch(obj))
    red = np.empty(4 * len(rest), dtype=np.float32)
    colors.data.foreach_get("color", red)
    assert np.abs(red[0::4]).max() == 0.0                     # the colours follow the reset
    api.show_stretch(obj, False)
    assert obj.data.color_attributes.get(mesh_io.STRETCH_COLORS) is None and mesh_io.STRETCH not in obj.data.attributes


def test_a_drag_cancel_puts_the_stretch_back_as_it_was(scene):
    from blender_support import TopView
    from skin_detach_addon.blender.drag_session import DragSession
    obj = quad_sphere()
    api.build(obj, target_faces=200)
    rest = mesh_io.read_positions(obj.data)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.7))
    handle = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.7))
    handle.location.x += 0.5
    bpy.context.view_layer.update()
    api.deform(obj)
    api.show_stretch(obj)
    before = api.stretch(obj).copy()
    colors = np.empty(4 * len(rest), dtype=np.float32)
    obj.data.color_attributes[mesh_io.STRETCH_COLORS].data.foreach_get("color", colors)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (40, 0))
    api.before_save()                                         # a save mid-drag writes the shown pose
    session.event("RIGHTMOUSE", "PRESS", (40, 0))
    assert np.array_equal(api.stretch(obj), before)
    assert np.array_equal(mesh_io.read_point_floats(obj.data, mesh_io.STRETCH), before)  # the map too
    after = np.empty_like(colors)
    obj.data.color_attributes[mesh_io.STRETCH_COLORS].data.foreach_get("color", after)
    assert np.array_equal(after, colors)
