"""Artist workflow (headless bpy): symmetry, handles from vertex groups, scale in the drag, the
panel's figures."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.api import SkinDetachError  # noqa: E402
from skin_detach_addon.blender import handle_symmetry, handles  # noqa: E402


def monkey():
    """Suzanne (symmetric across local X, loose eyes), triangulated, as the active object."""
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    modifier = obj.modifiers.new("tri", 'TRIANGULATE')
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    activate(obj)
    return obj


def bound_monkey(mirror_x=False):
    """Suzanne bound to a 300-face proxy, its mesh X toggle as given: (obj, rest (n, 3), size)."""
    obj = monkey()
    obj.data.use_mirror_x = mirror_x
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    return obj, rest, float(np.ptp(rest, axis=0).max())


def positions(obj):
    out = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
    obj.data.vertices.foreach_get("co", out)
    return out.reshape(-1, 3).astype(np.float64)


def test_a_mirrored_rig_moves_twins_mirrored_and_keeps_a_symmetric_mesh_symmetric(scene):
    obj = monkey()
    obj.rotation_euler = (0.3, 0.0, 0.7)  # world transforms do not matter: symmetry is local
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    ear = np.flatnonzero(rest[:, 0] < -1.0)                  # the left ear
    chin = np.flatnonzero(rest[:, 2] < -0.6)                  # symmetric itself
    grip = api.add_handle(obj, ear, mirror="X")
    api.add_anchor(obj, chin, mirror="X")
    made = api.handles_of(obj)
    assert len(made) == 3 and sum(api.handle_kind(e) == api.HANDLE for e in made) == 2
    grip.location.z += 0.3
    grip.location.x -= 0.2
    grip.rotation_euler.y = 0.4
    api.deform(obj)
    twin = [e for e in made if api.handle_kind(e) == api.HANDLE and e != grip][0]
    assert twin.matrix_basis != twin.matrix_basis.Identity(4)  # the twin followed
    now = positions(obj)
    mapping = np.full(len(rest), -1)
    from skin_detach_addon.core.detached_surface.symmetry import mirror_map
    mapping = mirror_map(rest, 0)
    matched = mapping >= 0
    image = now[mapping[matched]] * [-1.0, 1.0, 1.0]
    size = float(np.ptp(rest, axis=0).max())
    assert matched.mean() > 0.95
    assert np.abs(now[matched] - image).max() <= 1e-6 * size
    assert np.abs(now - rest).max() > 0.1  # it did move
    # Moving the twin instead drives the first one, mirrored.
    twin.location.z -= 0.5
    api.deform(obj)
    assert grip.location.z < handles.rest_local_of(grip)[2, 3]  # moved down from its rest (the pivot)
    now = positions(obj)
    assert np.abs(now[matched] - now[mapping[matched]] * [-1.0, 1.0, 1.0]).max() <= 1e-6 * size


def test_mirror_on_a_mesh_that_is_not_symmetric_is_refused(scene):
    from blender_support import import_spot
    obj = import_spot()  # spot is symmetric across X: nudge a few vertices off
    nudged = positions(obj)
    nudged[:40, 0] += 0.02
    obj.data.vertices.foreach_set("co", nudged.astype(np.float32).ravel())
    obj.data.update()
    api.build(obj, target_faces=300)
    with pytest.raises(SkinDetachError, match="symmetric across X.* 40 of 40"):
        api.add_handle(obj, np.arange(40), mirror="X")
    with pytest.raises(SkinDetachError, match="mirror"):
        api.add_handle(obj, np.arange(40), mirror="W")
    assert api.handles_of(obj) == []


def test_handles_and_anchors_from_vertex_groups(scene):
    obj = monkey()
    rest = positions(obj)
    jaw = obj.vertex_groups.new(name="jaw")
    jaw_ids = np.flatnonzero(rest[:, 2] < -0.5)
    jaw.add(jaw_ids.tolist(), 0.8, 'REPLACE')
    jaw.add([0], 0.0, 'REPLACE')  # weight zero: not a member
    api.build(obj, target_faces=300)
    handle = api.add_handle(obj, group="jaw")
    assert api.handle_vertex_count(handle) > 0
    from skin_detach_addon.blender import handles
    assert handles.group_of(handle) == "jaw"
    assert set(handles.detail_ids_of(handle)) == set(jaw_ids) - {0}
    with pytest.raises(SkinDetachError, match="vertex group"):
        api.add_anchor(obj, group="base")
    with pytest.raises(SkinDetachError, match="exactly one"):
        api.add_anchor(obj, [1, 2], group="jaw")


def test_drag_scales_about_the_handle_centre_freely_or_along_an_axis(scene):
    from blender_support import TopView, import_spot, rig
    from skin_detach_addon.blender.drag_session import DragSession
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = positions(obj)
    view = TopView(0.01)
    centre = np.array(view.to_screen(handle.matrix_world.to_translation()))
    start = np.array(handle.matrix_world)
    session = DragSession(obj, handle, view, tuple(centre + (10, 0)))
    session.event("S", "PRESS", tuple(centre + (10, 0)))
    session.event("MOUSEMOVE", "NOTHING", tuple(centre + (0, 15)))  # 1.5 times as far from the centre
    scaled = np.array(handle.matrix_world)
    assert np.allclose(scaled[:3, :3], 1.5 * start[:3, :3], atol=1e-6)
    assert np.allclose(scaled[:3, 3], start[:3, 3], atol=1e-6)   # about the handle's own centre
    assert session.header.startswith("Skin Detach scale") and "S scale" in session.header
    session.event("Z", "PRESS", tuple(centre + (0, 15)))           # keep 1.5, now along world Z only
    session.event("MOUSEMOVE", "NOTHING", tuple(centre + (0, 30)))  # twice again along Z
    both = np.array(handle.matrix_world)
    assert np.allclose(both[:3, :3], np.diag([1.5, 1.5, 3.0]) @ start[:3, :3], atol=1e-6)
    session.event("RET", "PRESS", tuple(centre + (0, 30)))
    assert np.abs(positions(obj) - rest).max() > 0.01
    assert np.isfinite(positions(obj)).all()


def test_the_panel_tells_conflicts_groups_the_target_and_the_add_operators_mirror(scene):
    from test_blender_rig import _draw_panel
    obj = monkey()
    group = obj.vertex_groups.new(name="brow")
    rest = positions(obj)
    group.add(np.flatnonzero(rest[:, 2] > 0.5).tolist(), 1.0, 'REPLACE')
    scene.skin_detach.target_faces = 120  # the normal test stops above such a small target
    activate(obj)
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    older = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.3))
    newer = api.add_handle(obj, group="brow")
    conflicts = api.handle_conflicts(obj)
    assert conflicts and conflicts[0]["loser"] == older.name and conflicts[0]["winner"] == newer.name
    activate(obj)
    text = " ".join(value for kind, value in _draw_panel() if kind == "label")  # long labels are wrapped
    assert f"with {newer.name}, which wins there" in text
    assert ("the normal test stopped above it" in text) == \
        (not api.figures(obj)["build"]["target_reached"])
    # The add operators: a group and the panel's mirror setting.
    scene.skin_detach.mirror = 'X'
    activate(obj)
    count = len(api.handles_of(obj))
    assert bpy.ops.skin_detach.add_anchor(group="brow") == {'FINISHED'}
    assert len(api.handles_of(obj)) == count + 1  # brow is its own mirror image: one symmetric anchor
    activate(obj)
    obj.data.vertices.foreach_set("select", rest[:, 0] < -1.0)
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    assert len(api.handles_of(obj)) == count + 3  # the ear and its twin


def test_numbers_typed_in_the_drag_set_exact_moves_angles_and_factors(scene):
    from blender_support import TopView, import_spot, rig
    from skin_detach_addon.blender.drag_session import FINISHED, DragSession
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = np.array(handle.matrix_world)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("MOUSEMOVE", "NOTHING", (40, 0))          # the mouse moves it 0.4 along X first
    session.event("Y", "PRESS", (40, 0))
    for key in ("MINUS", "ZERO", "PERIOD", "TWO", "FIVE"):   # then exactly -0.25 along Y
        session.event(key, "PRESS", (40, 0))
    session.event("MOUSEMOVE", "NOTHING", (90, 70))          # ignored while a number is typed
    moved = np.array(handle.matrix_world)
    assert np.allclose(moved[:3, 3] - start[:3, 3], (0.4, -0.25, 0.0), atol=1e-9)
    assert "-0.25 typed" in session.header
    session.event("BACK_SPACE", "PRESS", (90, 70))           # -0.2
    moved_back = np.array(handle.matrix_world)
    assert np.allclose(moved_back[:3, 3] - start[:3, 3], (0.4, -0.2, 0.0), atol=1e-9)
    session.event("R", "PRESS", (90, 70))                    # the move is kept, the number cleared
    assert session.typed == "" and np.allclose(np.array(handle.matrix_world), moved_back, atol=1e-9)
    for key in ("MINUS", "TWO", "FIVE"):                     # -25 degrees about Y (the right hand)
        session.event(key, "PRESS", (90, 70))
    turned = np.array(handle.matrix_world)
    c, s = np.cos(np.radians(-25)), np.sin(np.radians(-25))
    assert np.allclose(turned[:3, :3], np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ start[:3, :3], atol=1e-9)
    assert np.allclose(turned[:3, 3], moved_back[:3, 3], atol=1e-9)
    assert session.event("RET", "PRESS", (90, 70)) == FINISHED
    assert np.isfinite(positions(obj)).all()


def test_a_shift_d_copy_of_a_handle_is_newer_and_is_no_twin(scene):
    obj = monkey()
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    grip = api.add_handle(obj, np.flatnonzero(rest[:, 0] < -1.0), mirror="X")
    twin = handle_symmetry.twin_of(grip)
    assert twin is not None and handle_symmetry.twin_of(twin) == grip
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    grip.select_set(True)
    bpy.context.view_layer.objects.active = grip
    bpy.ops.object.duplicate()
    copy = bpy.context.active_object
    assert copy != grip and api.is_handle(copy)
    assert api.handles_of(obj)[-1] == copy                  # the newest: it wins on shared vertices
    conflicts = api.handle_conflicts(obj)
    assert any(c["loser"] == grip.name for c in conflicts)
    assert handle_symmetry.twin_of(copy) is None and handle_symmetry.twin_of(grip) == twin


def test_a_mirror_twin_deleted_in_the_viewport_is_gone(scene):
    obj = monkey()
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6))
    grip = api.add_handle(obj, np.flatnonzero(rest[:, 0] < -1.0), mirror="X")
    twin = handle_symmetry.twin_of(grip)
    twin_name = twin.name
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    twin.select_set(True)
    bpy.ops.object.delete()
    assert twin_name not in [e.name for e in api.handles_of(obj)]
    assert handle_symmetry.twin_of(grip) is None
    assert all(twin_name not in (c["winner"], c["loser"]) for c in api.handle_conflicts(obj))
    grip.location.z += 0.3
    api.deform(obj)
    moved = positions(obj)
    right = np.flatnonzero(rest[:, 0] > 1.0)                 # where the twin was: not carried up 0.3
    assert np.abs(moved[right, 2] - rest[right, 2]).max() < 0.1


def test_typed_numbers_stay_in_budget_and_an_absurd_one_is_refused_as_a_keystroke(scene):
    import time
    from blender_support import TopView, import_spot, rig
    from skin_detach_addon.blender.drag_session import FINISHED, RUNNING, DragSession
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = np.array(handle.matrix_world)
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("X", "PRESS", (0, 0))
    times = []
    for key in ("ZERO", "PERIOD", "EIGHT"):                  # 0.8 along X: a far jump from rest
        begun = time.perf_counter()
        assert session.event(key, "PRESS", (0, 0)) == RUNNING
        times.append(time.perf_counter() - begun)
    assert max(times) < 0.5                                   # a settle from far away took seconds
    assert session.event("RET", "PRESS", (0, 0)) == FINISHED
    assert np.isfinite(positions(obj)).all() and session.last.converged
    assert np.abs(np.array(handle.matrix_world)[:3, 3] - start[:3, 3]).max() > 0.7
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    session.event("X", "PRESS", (0, 0))
    session.event("ONE", "PRESS", (0, 0))
    for _ in range(60):                                       # 1 and ever more zeros: soon too far to be finite
        assert session.event("ZERO", "PRESS", (0, 0)) == RUNNING
    assert "refused" in session.header and len(session.typed) < 61
    assert np.isfinite(np.array(handle.matrix_world)).all() and np.isfinite(positions(obj)).all()


def _mirror_error(points, axis=0, rest=None):
    """Largest distance of a vertex from its mirror twin's image (twins found on ``rest``, else on
    ``points`` themselves)."""
    from skin_detach_addon.core.detached_surface.symmetry import mirror_map
    mapping = mirror_map(points if rest is None else rest, axis)
    matched = np.flatnonzero(mapping >= 0)
    image = points[mapping[matched]].copy()
    image[:, axis] *= -1.0
    return float(np.abs(points[matched] - image).max())


@pytest.mark.parametrize("setting", ["mesh symmetry", "mirror flags"])
def test_mesh_x_symmetry_makes_twins_and_keeps_a_rig_without_mirror_flags_symmetric(scene, setting):
    from skin_detach_addon.blender import handles
    obj = monkey()
    obj.data.use_mirror_x = setting == "mesh symmetry"
    mirror = None if setting == "mesh symmetry" else "X"
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    size = float(np.ptp(rest, axis=0).max())
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6), mirror=mirror)     # the chin: its own mirror image
    ear = api.add_handle(obj, np.flatnonzero(rest[:, 0] < -1.0), mirror=mirror)  # a twin across X
    assert handle_symmetry.twin_of(ear) is not None
    top = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.75), mirror=mirror)  # self-symmetric
    ear.location.z += 0.2
    top.location.x += 0.5                                     # across the plane: cannot stay symmetric
    top.location.z += 0.1
    api.deform(obj)
    moved = positions(obj)
    assert _mirror_error(moved, rest=rest) <= 1e-6 * size
    motion = handles.local_motion(obj, top)                  # put back on a symmetric motion: no X move
    assert abs(motion[0, 3]) <= 1e-9 and np.allclose(motion[:3, :3], np.eye(3), atol=1e-9)
    assert abs(motion[2, 3] - 0.1) <= 1e-6
    proxy = api.proxy_of(obj)
    ids = handles.proxy_ids_of(top)
    proxy_points = np.array([proxy.data.vertices[i].co for i in ids])
    from skin_detach_addon.blender import binding
    targets = binding.open_binding(obj).surface.proxy_vertices[ids] @ motion[:3, :3].T + motion[:3, 3]
    assert np.abs(proxy_points - targets).max() <= 1e-5 * size  # the handle is exact where it is shown


@pytest.mark.parametrize("scale", [0.5, 2.0, -1.0])
def test_s_on_a_self_symmetric_handle_keeps_the_scale_about_its_centre(scene, scale):
    from skin_detach_addon.blender import binding, handles
    obj, rest, size = bound_monkey(mirror_x=True)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6))
    top = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.75))  # its own mirror image
    assert handle_symmetry.twin_of(top) is None
    centre = np.array(handles.rest_local_of(top))[:3, 3]
    top.scale = (scale, scale, scale)                         # S about the handle's centre, as the drag does
    api.deform(obj)
    motion = handles.local_motion(obj, top)
    centre[0] = 0.0                                           # its proxy vertices' centre, put on the plane
    expected = np.eye(4)
    expected[:3, :3] *= scale
    expected[:3, 3] = (1.0 - scale) * centre
    assert np.allclose(motion, expected, atol=1e-6 * size)    # not a translation of the cap to the origin
    moved = positions(obj)
    assert _mirror_error(moved, rest=rest) <= 1e-6 * size
    ids = handles.proxy_ids_of(top)
    proxy = api.proxy_of(obj)
    proxy_points = np.array([proxy.data.vertices[i].co for i in ids])
    targets = binding.open_binding(obj).surface.proxy_vertices[ids] * scale + (1.0 - scale) * centre
    assert np.abs(proxy_points - targets).max() <= 1e-5 * size
    cap = np.flatnonzero(rest[:, 2] > 0.85)                   # the mesh follows the proxy: the cap is scaled
    assert np.abs(moved[cap] - (rest[cap] * scale + (1.0 - scale) * centre)).max() <= 0.05 * size


def _raised_with(obj, grip, rest):
    """Raise ``grip`` 0.3 and deform: (the mean rise of its mesh vertices, of its proxy vertices)."""
    from skin_detach_addon.blender import binding, handles
    grip.location.z += 0.3
    api.deform(obj)
    detail = handles.detail_ids_of(grip)
    proxy = api.proxy_of(obj)
    ids = handles.proxy_ids_of(grip)
    proxy_rest = binding.open_binding(obj).surface.proxy_vertices[ids]
    proxy_now = np.array([proxy.data.vertices[i].co for i in ids])
    return float((positions(obj)[detail, 2] - rest[detail, 2]).mean()), float((proxy_now[:, 2] - proxy_rest[:, 2]).mean())


@pytest.mark.parametrize("change", ["delete the twin", "copy the twin", "toggle off"])
def test_mesh_and_proxy_agree_whatever_happens_to_the_twins(scene, change):
    obj, rest, _ = bound_monkey(mirror_x=True)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6))
    grip = api.add_handle(obj, np.flatnonzero(rest[:, 0] < -1.0))
    twin = handle_symmetry.twin_of(grip)
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    if change == "delete the twin":
        twin.select_set(True)
        bpy.ops.object.delete()
    elif change == "copy the twin":
        twin.select_set(True)
        bpy.context.view_layer.objects.active = twin
        bpy.ops.object.duplicate()                            # the copy is nobody's twin
    else:
        obj.data.use_mirror_x = False                         # the twins stay twins
    mesh_rise, proxy_rise = _raised_with(obj, grip, rest)
    assert abs(proxy_rise - 0.3) <= 1e-3
    assert abs(mesh_rise - proxy_rise) <= 0.02, (mesh_rise, proxy_rise)  # it was 0.158 against 0.300
    if change == "toggle off":                               # still a symmetric rig: exactly symmetric
        assert _mirror_error(positions(obj), rest=rest) <= 1e-6 * float(np.ptp(rest, axis=0).max())


def test_two_mirror_toggles_are_refused_with_a_message_and_one_axis_given_is_taken(scene):
    obj = monkey()
    obj.data.use_mirror_x = obj.data.use_mirror_y = True
    api.build(obj, target_faces=300)
    rest = api.rest_positions(obj).astype(np.float64)
    ear = np.flatnonzero(rest[:, 0] < -1.0)
    with pytest.raises(SkinDetachError, match="X and Y"):
        api.add_handle(obj, ear)
    assert api.handles_of(obj) == []
    grip = api.add_handle(obj, ear, mirror="X")
    assert handle_symmetry.twin_of(grip) is not None


@pytest.mark.parametrize("toggle", [False, True])
def test_a_constraint_that_is_its_own_mirror_image_keeps_the_rig_symmetric_toggle_or_not(scene, toggle):
    obj, rest, size = bound_monkey(mirror_x=toggle)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6), mirror="")       # its own mirror image, no flag
    ear = api.add_handle(obj, np.flatnonzero(rest[:, 0] < -1.0), mirror="X")  # and its twin
    ear.location.z += 0.2
    ear.rotation_euler.y = 0.3
    api.deform(obj)
    assert _mirror_error(positions(obj), rest=rest) <= 1e-6 * size                      # it was 1.7 % of the size


def test_a_rig_symmetric_by_chance_stays_exact_while_it_moves_symmetrically_and_is_never_snapped(scene):
    obj, rest, size = bound_monkey()                          # no toggle, no mirror flags
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6), mirror="")
    top = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.75), mirror="")
    top.location.z += 0.2                                     # a symmetric move: the result is exactly symmetric
    api.deform(obj)
    assert _mirror_error(positions(obj), rest=rest) <= 1e-6 * size
    before = float(top.location.x)
    top.location.x += 0.3                                     # sideways: nobody asked for symmetry, so it goes
    api.deform(obj)
    assert abs(top.location.x - (before + 0.3)) <= 1e-6     # not snapped back onto a symmetric motion
    assert _mirror_error(positions(obj), rest=rest) > 1e-2 * size


def test_apply_and_interactive_updates_write_the_detail_of_the_diffused_skin(scene):
    from bench.quality import dihedral_change
    from blender_support import import_spot, rig
    from skin_detach_addon.blender import binding
    obj = import_spot()
    handle = rig(obj, axis=1)
    rest = api.rest_positions(obj).astype(np.float64)
    triangles = np.array([p.vertices[:] for p in obj.data.polygons])
    handle.rotation_euler.x = 1.2
    handle.location.z += 0.3
    api.deform(obj)                                           # Apply: from rest
    applied = positions(obj)
    proxy = api.proxy_of(obj)
    solved = np.array([v.co[:] for v in proxy.data.vertices])
    api.deform(obj, follow=True)                              # an interactive update of the same pose
    followed = positions(obj)
    assert np.abs(np.array([v.co[:] for v in proxy.data.vertices]) - solved).max() <= 1e-5  # the same solve
    assert np.abs(applied - followed).max() <= 1e-4            # one rebuild: what a drag shows is what Apply writes
    surface = binding.open_binding(obj).surface
    steps = surface.seam_steps
    try:
        surface.seam_steps = 0                                # the skin as bound bends the detail more
        as_bound = surface.reconstruct(solved.astype(np.float64))
    finally:
        surface.seam_steps = steps
    assert dihedral_change(rest, applied, triangles) < dihedral_change(rest, as_bound, triangles)
    assert np.abs(api.rest_positions(obj) - rest).max() == 0.0
