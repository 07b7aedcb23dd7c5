"""Handles follow Blender's parenting conventions (issue 52): on a mesh as an OBJ or FBX import
leaves it (rotation X 90 degrees, an unapplied scale), a handle's empty has its world matrix as its
transform, as any object Blender parents has, so Ctrl+P (Object, with or without Keep Transform),
Alt+P (Clear Parent, Clear and Keep Transformation) and Shift+Ctrl+P (Keep Transform) leave it where
it is and the mesh after them where it was; the mesh then follows every empty's world matrix.
Files of earlier versions (handles under the proxy with an identity parent inverse) are migrated
once when the rig is used, their world matrices unchanged; a keyed handle is left as it was.

Blender's reason an object does not jump under Ctrl+P (no Keep Transform) or Alt+P Clear Parent:
both give it the world matrix of its own transform (parent inverse = the new parent's world
inverse, or no parent), which is where it is when its world matrix is its transform."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from mathutils import Matrix  # noqa: E402

from blender_support import activate, imported_limb  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from bench.views import TopView  # noqa: E402
from skin_detach_addon.blender import binding, handles, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import FINISHED, DragSession  # noqa: E402

#: A selection within this share of the diagonal of where its handle's world transform puts it.
EXACT = 1e-5
#: Largest ratio of an edge's length to its rest length the moves below may make (the mesh not
#: torn: the hand's vertices thrown to the floor stretch its edges to the wrist by far more).
STRETCH = 2.0
IMPORTS = {"OBJ import (rotation X 90)": (1.0, 1.0, 1.0), "FBX import (rotation X 90, scale 0.01)": (0.01,) * 3,
           "rotation X 90, scale (1, 2, 0.5)": (1.0, 2.0, 0.5)}


def rigged(scale):
    """The imported limb bound, with a shoulder anchor and forearm and hand handles:
    (obj, forearm empty, hand empty, parts)."""
    obj, parts = imported_limb(scale=scale)
    api.build(obj, target_faces=300)
    api.add_anchor(obj, parts["shoulder"])
    forearm = api.add_handle(obj, parts["forearm"])
    hand = api.add_handle(obj, parts["hand"])
    bpy.context.view_layer.update()
    return obj, forearm, hand, parts


def world(obj):
    return np.array(obj.matrix_world, dtype=np.float64)


def local(obj):
    return mesh_io.read_positions(obj.data).astype(np.float64)


def world_size(obj):
    """The rest diagonal in world units (the object's scale's mean)."""
    return diagonal(obj) * abs(float(np.linalg.det(world(obj)[:3, :3]))) ** (1.0 / 3.0)


def diagonal(obj):
    rest = api.rest_positions(obj).astype(np.float64)
    return float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))


def off(obj, empty, ids):
    """Largest distance (in the object's local space, over the rest diagonal) of the vertices
    ``ids`` from where the empty's world matrix puts them: the motion in the object's space from
    its rest frame (``rest_local``, made where the selection's median point was at rest) to its world
    matrix, ``obj_world^-1 @ empty_world @ rest_local^-1``, applied to their rest positions."""
    bpy.context.view_layer.update()
    rest = api.rest_positions(obj).astype(np.float64)
    rest_local = np.array(handles.value_of(empty, "rest_local"), dtype=np.float64).reshape(4, 4)
    motion = np.linalg.solve(world(obj), world(empty)) @ np.linalg.inv(rest_local)
    want = rest[ids] @ motion[:3, :3].T + motion[:3, 3]
    return float(np.linalg.norm(local(obj)[ids] - want, axis=1).max()) / diagonal(obj)


def max_stretch(obj):
    """Largest ratio of an edge's length now to its rest length (in the object's local space)."""
    edges = np.empty(2 * len(obj.data.edges), dtype=np.int32)
    obj.data.edges.foreach_get("vertices", edges)
    edges = edges.reshape(-1, 2)
    rest, now = api.rest_positions(obj).astype(np.float64), local(obj)
    before = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
    after = np.linalg.norm(now[edges[:, 0]] - now[edges[:, 1]], axis=1)
    return float((after / before).max())


def select_and_make_active(child, parent=None):
    """Select ``child`` (and ``parent``, made active, as Shift-click makes it) and nothing else."""
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    child.select_set(True)
    if parent is not None:
        parent.select_set(True)
    bpy.context.view_layer.objects.active = parent if parent is not None else child


def turn_forearm(forearm, size):
    """The forearm's empty moved and turned in the world (a drag's G and R), ``size`` the mesh's
    diagonal in world units."""
    motion = Matrix.Translation((0.03 * size, 0.02 * size, -0.02 * size)) @ Matrix.Rotation(0.2, 4, 'Z')
    centre = forearm.matrix_world.translation.copy()
    forearm.matrix_world = Matrix.Translation(centre) @ motion @ Matrix.Translation(-centre) @ forearm.matrix_world
    bpy.context.view_layer.update()


def assert_still(obj, hand, hand_world, mesh_before, what):
    """The hand's empty did not move, and a deform leaves the mesh where it was."""
    bpy.context.view_layer.update()
    size = diagonal(obj)
    scale = float(np.abs(world(obj)[:3, :3]).max())
    assert np.abs(world(hand) - hand_world).max() <= 1e-6 * max(1.0, size * scale), f"{what}: the hand's empty moved"
    api.deform(obj)
    assert np.abs(local(obj) - mesh_before).max() <= EXACT * size, f"{what}: the mesh moved"


@pytest.mark.parametrize("keep_transform", [False, True], ids=["Ctrl+P Object", "Ctrl+P Object (Keep Transform)"])
@pytest.mark.parametrize("imported", list(IMPORTS))
def test_ctrl_p_hand_to_forearm_keeps_the_hand_where_it_is(scene, imported, keep_transform):
    obj, forearm, hand, parts = rigged(IMPORTS[imported])
    size = diagonal(obj)
    # Blender's own reason nothing jumps: a new empty's world matrix is its transform.
    assert np.abs(np.array(hand.matrix_basis) - world(hand)).max() <= 1e-6 * max(1.0, np.abs(world(hand)).max())
    hand_world, mesh_before = world(hand), local(obj)
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_set(type='OBJECT', keep_transform=keep_transform) == {'FINISHED'}
    assert hand.parent == forearm
    assert_still(obj, hand, hand_world, mesh_before, "Ctrl+P")
    assert hand in api.handles_of(obj)
    turn_forearm(forearm, world_size(obj))
    assert np.abs(world(hand) - hand_world).max() > 1e-3 * world_size(obj)  # carried
    api.deform(obj)
    assert off(obj, hand, parts["hand"]) <= EXACT
    assert off(obj, forearm, parts["forearm"]) <= EXACT
    assert max_stretch(obj) <= STRETCH


def test_a_drag_of_the_forearm_carries_the_hand_and_its_vertices(scene):
    """The forearm's empty dragged (a DragSession: moves, then the settle while the mouse rests,
    then Enter, with nothing else evaluating Blender's depsgraph between them, as when the window
    handles a move and a timer before it redraws), the hand's parented to it with Ctrl+P: the hand's
    vertices end where the hand's empty is, not where it was one move before."""
    obj, forearm, hand, parts = rigged(IMPORTS["FBX import (rotation X 90, scale 0.01)"])
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_set(type='OBJECT') == {'FINISHED'}
    bpy.context.view_layer.update()
    view = TopView(world_size(obj) / 1000.0)
    centre = np.array(view.to_screen(forearm.matrix_world.to_translation()))
    session = DragSession(obj, forearm, view, tuple(centre))
    mouse = tuple(centre)
    for k in range(1, 6):
        mouse = tuple(centre + np.array((9.0, 6.0)) * k)
        session.event("MOUSEMOVE", "NOTHING", mouse)
    for _ in range(200):
        if session.settle_slice():
            break
    assert session.event("RET", "PRESS", mouse) == FINISHED
    assert off(obj, hand, parts["hand"]) <= EXACT
    assert off(obj, forearm, parts["forearm"]) <= EXACT
    assert max_stretch(obj) <= STRETCH


@pytest.mark.parametrize("clear", ['CLEAR_KEEP_TRANSFORM', 'CLEAR'], ids=["Alt+P Clear and Keep Transformation",
                                                                        "Alt+P Clear Parent"])
@pytest.mark.parametrize("imported", list(IMPORTS))
def test_alt_p_keeps_the_hand_where_it_is_and_in_the_rig(scene, imported, clear):
    """Alt+P on the hand parented to the forearm (Ctrl+P) and on the forearm under the proxy."""
    obj, forearm, hand, parts = rigged(IMPORTS[imported])
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_set(type='OBJECT') == {'FINISHED'}
    for empty in (hand, forearm):
        empty_world, mesh_before = world(empty), local(obj)
        select_and_make_active(empty)
        assert bpy.ops.object.parent_clear(type=clear) == {'FINISHED'}
        assert empty.parent is None
        assert_still(obj, empty, empty_world, mesh_before, f"Alt+P on {empty.name}")
        assert empty in api.handles_of(obj)  # still in the rig: the mesh follows it
    turn_forearm(hand, world_size(obj))
    api.deform(obj)
    assert off(obj, hand, parts["hand"]) <= EXACT
    assert max_stretch(obj) <= STRETCH


@pytest.mark.parametrize("keep_transform", [True, False], ids=["Keep Transform", "to the parent's origin"])
def test_shift_ctrl_p_parent_without_inverse(scene, keep_transform):
    """Shift+Ctrl+P: with Keep Transform the hand stays; without it Blender moves it (to the
    forearm's origin), and the hand's vertices follow its world matrix either way."""
    obj, forearm, hand, parts = rigged(IMPORTS["FBX import (rotation X 90, scale 0.01)"])
    hand_world, mesh_before = world(hand), local(obj)
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_no_inverse_set(keep_transform=keep_transform) == {'FINISHED'}
    assert hand.parent == forearm
    if keep_transform:
        assert_still(obj, hand, hand_world, mesh_before, "Shift+Ctrl+P")
    else:
        bpy.context.view_layer.update()
        api.deform(obj)
    assert off(obj, hand, parts["hand"]) <= EXACT


def make_old_style(obj):
    """What 0.1.0 saved: every handle and anchor under the proxy with an identity parent inverse,
    its transform the frame in the object's local space (its world matrix kept)."""
    bpy.context.view_layer.update()
    for empty in api.handles_of(obj):
        del empty[handles.TAG]["parenting"]  # 0.1.0's record had none
        kept = empty.matrix_world.copy()
        empty.matrix_parent_inverse = Matrix.Identity(4)
        empty.matrix_world = kept
    bpy.context.view_layer.update()


def test_handles_of_an_earlier_version_are_migrated_once_with_their_world_matrices(scene, tmp_path):
    obj, forearm, hand, parts = rigged(IMPORTS["FBX import (rotation X 90, scale 0.01)"])
    size = diagonal(obj)
    turn_forearm(forearm, world_size(obj))
    api.deform(obj)
    # A keyed handle: its keys are in the old space, it is left as it is.
    wrist = api.add_handle(obj, parts["hand"][:10])
    api.deform(obj)  # the pose saved, with every handle
    make_old_style(obj)
    wrist.keyframe_insert("location", frame=1)
    assert all(e.matrix_parent_inverse == Matrix.Identity(4) for e in api.handles_of(obj))
    assert all(handles.value_of(e, "parenting") is None for e in api.handles_of(obj))
    assert np.abs(np.array(hand.matrix_basis) - world(hand)).max() > 1e-3  # old style: the basis is local
    worlds = {e.name: world(e) for e in api.handles_of(obj)}
    keyed_basis = np.array(wrist.matrix_basis)
    wrist, hand, forearm = wrist.name, hand.name, forearm.name  # the objects are gone once the file is opened
    path = tmp_path / "old.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    binding._CACHE.clear()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects["limb"]
    mesh_before = local(obj)
    binding.open_binding(obj)  # the first use after opening migrates
    bpy.context.view_layer.update()
    empties = {e.name: e for e in api.handles_of(obj)}
    assert set(empties) == set(worlds)
    for name, empty in empties.items():
        assert np.abs(world(empty) - worlds[name]).max() <= 1e-7 * max(1.0, np.abs(worlds[name]).max()), name
        if name == wrist:
            assert empty.matrix_parent_inverse == Matrix.Identity(4)
            assert np.array_equal(np.array(empty.matrix_basis), keyed_basis)
        else:
            assert np.abs(np.array(empty.matrix_basis) - world(empty)).max() <= 1e-6, f"{name}: not migrated"
            assert handles.value_of(empty, "parenting") == handles.WORLD_PARENTING
    converted = {n: (np.array(e.matrix_parent_inverse), np.array(e.matrix_basis)) for n, e in empties.items()}
    binding.open_binding(obj)  # once: nothing left to do
    assert all(np.array_equal(np.array(e.matrix_parent_inverse), converted[n][0]) and
               np.array_equal(np.array(e.matrix_basis), converted[n][1]) for n, e in empties.items())
    api.deform(obj)
    assert np.abs(local(obj) - mesh_before).max() <= EXACT * size
    # Migrated, Ctrl+P keeps the hand where it is.
    hand, forearm = empties[hand], empties[forearm]
    hand_world = world(hand)
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_set(type='OBJECT') == {'FINISHED'}
    assert_still(obj, hand, hand_world, local(obj), "Ctrl+P after the migration")
    activate(obj)


def test_live_update_keeps_out_of_a_drag_whose_moves_evaluate_the_depsgraph(scene):
    """Live Update on, the forearm's empty dragged with the hand's parented to it: every move
    evaluates the depsgraph (the hand's world matrix), whose handler used to queue a live-update
    solve of the pose before the operator took it as the drag's; in a window its timer then ran
    between moves when it happened to fire first (a settled solve in the drag's warm start: the
    next moves continued from another iterate). A running drag's object is never queued."""
    from skin_detach_addon.ui import live_update
    obj, forearm, hand, parts = rigged(IMPORTS["OBJ import (rotation X 90)"])
    select_and_make_active(hand, forearm)
    assert bpy.ops.object.parent_set(type='OBJECT') == {'FINISHED'}
    bpy.context.scene.skin_detach.live_update = True
    bpy.context.view_layer.update()
    live_update.flush()
    live_update.remember(obj)
    view = TopView(world_size(obj) / 1000.0)
    centre = np.array(view.to_screen(forearm.matrix_world.to_translation()))
    session = DragSession(obj, forearm, view, tuple(centre))
    assert api.is_dragged(obj)
    for k in range(1, 4):
        mouse = tuple(centre + np.array((9.0, 6.0)) * k)
        session.event("MOUSEMOVE", "NOTHING", mouse)
        assert live_update.pending() == set()
        bpy.context.view_layer.update()               # the redraw, before the operator's remember
        assert live_update.pending() == set()
    assert session.event("RET", "PRESS", mouse) == FINISHED and not api.is_dragged(obj)
    bpy.context.view_layer.update()                   # after the drag, live update watches again
    assert live_update.pending() == {obj.name}
    live_update.flush()
