"""Several mesh objects posed as one rig (issue 51, part 2): a character made of a body and
accessories as separate objects (ZBrush subtools, an FBX import's parts), some rotated and
scaled as imports leave them, built into ONE rig owned by the body."""

import math
import os

import numpy as np
import pytest

pytest.importorskip("bpy")
import bmesh  # noqa: E402
import bpy  # noqa: E402
from mathutils import Matrix  # noqa: E402

from blender_support import activate, save_and_reopen  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io, rig_members  # noqa: E402

TARGET_FACES = 300


def _world(obj):
    return np.array(obj.matrix_world, dtype=np.float64)


def world_positions(obj):
    """(n, 3) float64 the object's vertices in the world (its Basis)."""
    local = mesh_io.read_positions(obj.data).astype(np.float64)
    matrix = _world(obj)
    return local @ matrix[:3, :3].T + matrix[:3, 3]


def sphere(name, radius, location, segments=16, rings=8):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def character():
    """A body (a quad sphere imported as FBX leaves it: turned 90 degrees about X, its mesh 100
    times larger and the object scaled 0.01), two eyes half sunk into the head, a belt (a torus,
    its object turned 90 about X and scaled 0.5 with the mesh made to match: a ring around the
    middle), a boot (a box at the bottom, turned about Z), and an unrelated lamp. Returns
    (body, [eye_l, eye_r, belt, boot], lamp); the body is active and every part selected."""
    body = sphere("body", 100.0, (0, 0, 0), segments=24, rings=12)
    body.rotation_euler = (math.pi / 2, 0.0, 0.0)
    body.scale = (0.01, 0.01, 0.01)
    eye_l = sphere("eye_L", 0.15, (0.25, -0.75, 0.6))
    eye_r = sphere("eye_R", 0.15, (-0.25, -0.75, 0.6))
    bpy.ops.mesh.primitive_torus_add(major_segments=32, minor_segments=8, major_radius=1.0, minor_radius=0.08)
    belt = bpy.context.active_object
    belt.name = belt.data.name = "belt"
    belt.data.transform(Matrix.Rotation(-math.pi / 2, 4, 'X') @ Matrix.Scale(2.04, 4))
    belt.rotation_euler = (math.pi / 2, 0.0, 0.0)
    belt.scale = (0.5, 0.5, 0.5)
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0.0, 0.1, -1.05), rotation=(0.0, 0.0, 0.5))
    boot = bpy.context.active_object
    boot.name = boot.data.name = "boot"
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(4.0, 0.0, 0.0))
    lamp = bpy.context.active_object
    lamp.name = lamp.data.name = "lamp"
    bpy.context.view_layer.update()
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj is not lamp)
    bpy.context.view_layer.objects.active = body
    return body, [eye_l, eye_r, belt, boot], lamp


def world_diagonal(objects):
    points = np.concatenate([world_positions(o) for o in objects])
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def bits(objects):
    """Every object's positions and shape keys, bit for bit."""
    return [mesh_io.snapshot(o.data)[:2] for o in objects]


def same_bits(before, after):
    for (positions_a, keys_a), (positions_b, keys_b) in zip(before, after):
        assert positions_a.tobytes() == positions_b.tobytes()
        assert keys_a.keys() == keys_b.keys()
        for name in keys_a:
            assert keys_a[name].tobytes() == keys_b[name].tobytes()
    return True


def lowest_and_top(members):
    """{object: its vertex ids} of the lowest part (world z below -0.85: the body's bottom and the
    boot) and of the top (world z above 0.55: the body's head and the left eye)."""
    low = {o: np.flatnonzero(world_positions(o)[:, 2] < -0.85) for o in members}
    low = {o: ids for o, ids in low.items() if ids.size}
    top = {members[0]: np.flatnonzero(world_positions(members[0])[:, 2] > 0.55)}
    eye = next(o for o in members if o.name == "eye_L")
    top[eye] = np.arange(len(eye.data.vertices))
    return low, top


def rigged(scene):
    body, parts, lamp = character()
    stats = api.build([body] + parts, target_faces=TARGET_FACES)
    members = api.members(body)
    low, top = lowest_and_top(members)
    anchor = api.add_anchor(body, low)
    handle = api.add_handle(body, top)
    return body, members, lamp, stats, anchor, handle, low, top


def moved(handle):
    """Turn the handle 25 degrees about Y and move it up and sideways (world); returns the world motion."""
    start = np.array(handle.matrix_world, dtype=np.float64)
    pivot = start[:3, 3]
    motion = np.eye(4)
    motion[:3, :3] = np.array(Matrix.Rotation(math.radians(25.0), 3, 'Y'))
    motion[:3, 3] = pivot - motion[:3, :3] @ pivot + np.array([0.15, -0.05, 0.3])
    handle.matrix_world = Matrix((motion @ start).tolist())
    bpy.context.view_layer.update()
    return motion


def test_several_objects_build_one_rig_whose_handles_are_exact_in_every_object(scene):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    eye_l = bpy.data.objects["eye_L"]
    # One rig: the body owns it, the others sorted by name after it; one proxy in the file.
    assert [o.name for o in members] == ["body", "belt", "boot", "eye_L", "eye_R"]
    assert stats["objects"] == 5
    assert stats["detail_vertices"] == sum(len(o.data.vertices) for o in members)
    proxies = [o for o in bpy.data.objects if binding.PROXY_TAG in o]
    assert proxies == [api.proxy_of(body)]
    for obj in members:
        assert api.mesh_of(obj) == body and api.is_bound(obj) and api.members(obj) == members
    assert not api.is_bound(lamp)
    ranges = api.member_ranges(body)
    assert [ranges[o] for o in members] == [(int(a), int(b)) for a, b in zip(
        np.cumsum([0] + [len(o.data.vertices) for o in members])[:-1],
        np.cumsum([len(o.data.vertices) for o in members]))]
    # The combined rest is every object's vertices in the owner's space (independently: through the world).
    rest = api.rest_positions(body).astype(np.float64)
    to_owner = np.linalg.inv(_world(body))
    diagonal = world_diagonal(members)
    for obj in members:
        first, stop = ranges[obj]
        expected = world_positions(obj) @ to_owner[:3, :3].T + to_owner[:3, 3]
        assert np.abs(rest[first:stop] - expected).max() <= 1e-6 * diagonal / 0.01  # owner space is 100x the world

    lamp_before = bits([lamp]), np.array(lamp.matrix_world)
    rest_world = {o: world_positions(o) for o in members}
    motion = moved(handle)
    api.deform(body)
    for obj in members:  # every selected vertex where the handle's world motion puts it, in every object
        ids = top.get(obj)
        now = world_positions(obj)
        if ids is not None:
            expected = rest_world[obj][ids] @ motion[:3, :3].T + motion[:3, 3]
            assert np.abs(now[ids] - expected).max() <= 1e-5 * diagonal, obj.name
        ids = low.get(obj)
        if ids is not None:  # anchors still
            assert np.abs(now[ids] - rest_world[obj][ids]).max() <= 1e-5 * diagonal, obj.name
    assert np.abs(world_positions(eye_l) - rest_world[eye_l]).max() > 0.1  # it did move
    right = bpy.data.objects["eye_R"]
    assert np.isfinite(world_positions(right)).all()
    # Nothing else was touched.
    assert same_bits(lamp_before[0], bits([lamp])) and np.array_equal(lamp_before[1], np.array(lamp.matrix_world))

    # Reset puts each object's own rest back, bit for bit.
    api.reset(bpy.data.objects["belt"])  # any object of the rig stands for it
    for obj, (positions, _) in zip(members, [(rest_world[o], None) for o in members]):
        assert np.array_equal(world_positions(obj), positions), obj.name


def test_reset_writes_every_object_back_bit_for_bit(scene):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    before = bits(members)
    moved(handle)
    api.deform(body)
    assert not same_bits_quiet(before, bits(members))
    api.reset(body)
    assert same_bits(before, bits(members))


def same_bits_quiet(before, after):
    try:
        return same_bits(before, after)
    except AssertionError:
        return False


def joined_copy(members, owner):
    """The joined mesh independently made: every object's vertices mapped into the owner's space
    through the world matrices, in the rig's order, over each object's own loop triangles; an
    object of the owner's world matrix."""
    to_owner = np.linalg.solve(_world(owner), np.eye(4))
    points, faces, offset = [], [], 0
    for obj in members:
        relative = to_owner @ _world(obj)
        local = mesh_io.read_positions(obj.data).astype(np.float64)
        points.append((local @ relative[:3, :3].T + relative[:3, 3]).astype(np.float32) if obj is not owner
                      else mesh_io.read_positions(obj.data))
        obj.data.calc_loop_triangles()
        tris = np.empty(3 * len(obj.data.loop_triangles), dtype=np.int32)
        obj.data.loop_triangles.foreach_get("vertices", tris)
        faces.append(tris.reshape(-1, 3) + offset)
        offset += len(obj.data.vertices)
    points, faces = np.concatenate(points), np.concatenate(faces)
    mesh = bpy.data.meshes.new("joined")
    mesh.vertices.add(points.shape[0])
    mesh.loops.add(faces.size)
    mesh.polygons.add(faces.shape[0])
    mesh.vertices.foreach_set("co", points.ravel())
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update()
    joined = bpy.data.objects.new("joined", mesh)
    bpy.context.scene.collection.objects.link(joined)
    joined.matrix_world = owner.matrix_world.copy()
    bpy.context.view_layer.update()
    return joined


def test_each_object_is_its_slice_of_the_joined_mesh_posed_the_same_and_bakes_so(scene, tmp_path):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    joined = joined_copy(members, body)
    ranges = api.member_ranges(body)
    combined = lambda ids: np.concatenate([ids[o] + ranges[o][0] for o in members if o in ids])  # noqa: E731
    api.build(joined, target_faces=TARGET_FACES)
    api.add_anchor(joined, combined(low))
    joined_handle = api.add_handle(joined, combined(top))
    motion = moved(handle)
    joined_handle.matrix_world = Matrix((motion @ np.array(joined_handle.matrix_world)).tolist())
    bpy.context.view_layer.update()
    api.deform(body)
    api.deform(joined)
    diagonal = world_diagonal(members)
    whole = world_positions(joined)
    for obj in members:
        first, stop = ranges[obj]
        assert np.abs(world_positions(obj) - whole[first:stop]).max() <= 1e-6 * diagonal, obj.name

    # The bake of a frame gives the same per object: keys on each object, a file per object and frame.
    posed = {o: mesh_io.read_positions(o.data) for o in members}
    api.reset(body)
    bpy.context.view_layer.update()
    handle.matrix_world = Matrix((motion @ np.array(handle.matrix_world)).tolist())
    handle.keyframe_insert("location", frame=3)
    handle.keyframe_insert("rotation_euler", frame=3)
    records = api.bake(body, [3], into=api.SHAPE_KEYS)
    assert records[0]["output"] == ["skin_detach_0003"] * len(members)
    for obj in members:
        key = obj.data.shape_keys.key_blocks["skin_detach_0003"]
        values = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
        key.data.foreach_get("co", values)
        assert np.abs(values.reshape(-1, 3) - posed[obj]).max() <= 1e-6 * diagonal / 0.01, obj.name
    pattern = str(tmp_path / "char_####.obj")
    records = api.bake(body, [3], into=api.FILES, path=pattern)
    expected = [str(tmp_path / f"char_{o.name}_0003.obj") for o in members]
    assert records[0]["output"] == expected
    assert all(os.path.isfile(path) for path in expected)
    assert api.bake_file_path(pattern, 3, members[3]) == expected[3]
    assert sorted(os.listdir(tmp_path)) == sorted(os.path.basename(p) for p in expected)
    records = api.bake(body, [3], into=api.OBJECTS)
    for obj, name in zip(members, records[0]["output"]):
        baked = bpy.data.objects[name]
        assert name == f"{obj.name}_bake_0003"
        assert np.allclose(np.array(baked.matrix_world), np.array(obj.matrix_world), rtol=0.0, atol=1e-6)
        assert np.abs(mesh_io.read_positions(baked.data) - posed[obj]).max() <= 1e-6 * diagonal / 0.01, obj.name


def _delete(scene, obj):
    bpy.data.objects.remove(obj)


def _edit_topology(scene, obj):
    mesh = bmesh.new()
    mesh.from_mesh(obj.data)
    mesh.verts.ensure_lookup_table()
    bmesh.ops.delete(mesh, geom=[mesh.verts[0]], context='VERTS')
    mesh.to_mesh(obj.data)
    mesh.free()
    obj.data.update()


def _move(scene, obj):
    obj.location.x += 0.05


def _unlink(scene, obj):
    for collection in list(obj.users_collection):
        collection.objects.unlink(obj)


def _edit_mode(scene, obj):
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')


@pytest.mark.parametrize("change, words", [
    (_delete, ("deleted", "Rebuild")),
    (_edit_topology, ("topology", "Rebuild")),
    (_move, ("moved", "Rebuild")),
    (_unlink, ("unlinked", "Rebuild")),
    (_edit_mode, ("Edit Mode",)),
])
def test_a_member_changed_is_named_and_nothing_is_written(scene, change, words):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    belt = bpy.data.objects["belt"]
    others = [o for o in members if o is not belt]
    before = bits(others)
    proxy = bits([api.proxy_of(body)])
    moved(handle)
    change(scene, belt)
    bpy.context.view_layer.update()
    for step in (lambda: api.deform(body), lambda: api.reset(body),
                 lambda: api.bake(body, [1], into=api.SHAPE_KEYS)):
        with pytest.raises(api.SkinDetachError) as raised:
            step()
        message = str(raised.value)
        assert "'belt'" in message and all(word in message for word in words), message
        assert same_bits(before, bits(others))
        assert same_bits(proxy, bits([api.proxy_of(body)]))
        assert all(o.data.shape_keys is None for o in others)
    if change is _edit_mode:
        bpy.ops.object.mode_set(mode='OBJECT')
    api.build(body, target_faces=TARGET_FACES)  # Rebuild: the rig as it is now (a deleted or unlinked object left out)
    api.deform(body)
    expected = [o.name for o in members if o is not belt or change not in (_delete, _unlink)]
    assert [o.name for o in api.members(body)] == expected
    # The handles kept their vertices: each id followed its object's vertex to its new place.
    from skin_detach_addon.blender import handles
    ranges = api.member_ranges(body)
    ids = np.sort(np.concatenate([top[o] + ranges[o][0] for o in top]))
    assert np.array_equal(handles.detail_ids_of(handle), ids)


def test_a_renamed_member_still_works_and_a_member_active_stands_for_the_rig(scene):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    eye = bpy.data.objects["eye_L"]
    eye.name = "left eye"
    assert api.members(body)[3] == eye and rig_members.names(body)[3] == "left eye"
    before = world_positions(eye)
    moved(handle)
    activate(eye)  # the operators work whichever object of the rig is active
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert np.abs(world_positions(eye) - before).max() > 0.1
    activate(bpy.data.objects["boot"])
    assert bpy.ops.skin_detach.reset() == {'FINISHED'}
    assert np.array_equal(world_positions(eye), before)


def test_multi_object_edit_mode_selection_makes_one_handle_over_two_objects(scene):
    body, parts, lamp = character()
    bpy.context.scene.skin_detach.target_faces = TARGET_FACES
    assert bpy.ops.skin_detach.build() == {'FINISHED'}  # the body active, every part selected: one rig
    members = api.members(body)
    assert len(members) == 5 and api.figures(body)["build"]["detail_vertices"] == \
        sum(len(o.data.vertices) for o in members)
    low, top = lowest_and_top(members)
    eye = bpy.data.objects["eye_L"]
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (body, eye))
    bpy.context.view_layer.objects.active = eye  # an object of the rig other than the owner
    bpy.ops.object.mode_set(mode='EDIT')  # Blender's multi-object Edit Mode: both meshes
    assert body.mode == 'EDIT' and eye.mode == 'EDIT' and bpy.data.objects["belt"].mode == 'OBJECT'
    for obj in (body, eye):  # select as a click or box would, in each mesh being edited
        edited = bmesh.from_edit_mesh(obj.data)
        for face in edited.faces:
            face.select = False
        for edge in edited.edges:
            edge.select = False
        chosen = set(top[obj].tolist())
        for vertex in edited.verts:
            vertex.select = vertex.index in chosen
        bmesh.update_edit_mesh(obj.data)
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    assert body.mode == 'OBJECT' and eye.mode == 'OBJECT'
    handle = bpy.context.active_object
    ranges = api.member_ranges(body)
    from skin_detach_addon.blender import handles
    expected = np.sort(np.concatenate([top[o] + ranges[o][0] for o in (body, eye)]))
    assert np.array_equal(handles.detail_ids_of(handle), expected)
    # A group: the union of that group in every object that has it; none: refused naming it.
    for obj in (body, bpy.data.objects["boot"]):
        group = obj.vertex_groups.new(name="feet")
        group.add(low[obj].tolist(), 1.0, 'REPLACE')
    anchor = api.add_anchor(eye, group="feet")
    assert np.array_equal(handles.detail_ids_of(anchor),
                          np.sort(np.concatenate([low[o] + ranges[o][0] for o in low])))
    with pytest.raises(api.SkinDetachError, match="'nowhere'"):
        api.add_anchor(body, group="nowhere")


def test_the_rig_saves_reopens_and_poses_the_same(scene, tmp_path):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    motion = moved(handle)
    api.deform(body)
    posed = [mesh_io.read_positions(o.data) for o in members]
    api.reset(body)
    path = tmp_path / "character.blend"
    body, handle = save_and_reopen(path, "body")
    members = api.members(body)
    assert [o.name for o in members] == ["body", "belt", "boot", "eye_L", "eye_R"]
    handle.matrix_world = Matrix((motion @ np.array(handle.matrix_world)).tolist())
    bpy.context.view_layer.update()
    api.deform(body)
    for obj, before in zip(members, posed):
        assert np.array_equal(mesh_io.read_positions(obj.data), before), obj.name


def test_clear_removes_the_whole_rig_and_keeps_every_shape(scene):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    moved(handle)
    api.deform(body)
    before = bits(members)
    api.clear(bpy.data.objects["boot"])
    assert same_bits(before, bits(members))
    assert not any(binding.PROXY_TAG in o or api.is_handle(o) for o in bpy.data.objects)
    for obj in members:
        assert not api.is_bound(obj) and rig_members.MEMBER_TAG not in obj and binding.KEY not in obj


def test_build_refuses_a_member_of_another_rig_and_a_list_of_one_binds_it_alone(scene):
    body, parts, lamp = character()
    api.build([body, parts[0]], target_faces=TARGET_FACES)
    with pytest.raises(api.SkinDetachError, match="'eye_L'.*rig of 'body'"):
        api.build([lamp, parts[0]], target_faces=TARGET_FACES)
    with pytest.raises(api.SkinDetachError, match="'body'.*bound itself"):
        api.build([lamp, body], target_faces=TARGET_FACES)
    api.build([body], target_faces=TARGET_FACES)  # a list of one: the body alone
    assert api.members(body) == [body] and not api.is_bound(parts[0])


def test_a_drag_writes_every_object_and_its_cancel_restores_each_bit_for_bit(scene):
    from blender_support import TopView
    from skin_detach_addon.blender.drag_session import DragSession
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    belt = bpy.data.objects["belt"]  # a member with shape keys: kept as offsets from the Basis
    belt.shape_key_add(name="Basis")
    flex = belt.shape_key_add(name="flex")
    flex.data[0].co.z += 0.1
    before = bits(members)
    session = DragSession(body, handle, TopView(0.01), (100, 100))
    session.event("MOUSEMOVE", "NOTHING", (140, 120))
    assert not same_bits_quiet(before, bits(members))
    eye = bpy.data.objects["eye_L"]
    assert not same_bits_quiet(before[3:4], bits([eye]))
    assert session.event("RIGHTMOUSE", "PRESS", (140, 120)) == "CANCELLED"
    assert same_bits(before, bits(members))
    session = DragSession(body, handle, TopView(0.01), (100, 100))
    session.event("MOUSEMOVE", "NOTHING", (140, 120))
    assert session.event("LEFTMOUSE", "PRESS", (140, 120)) == "FINISHED"
    assert binding.holds_written(body)  # the confirm recorded what every object holds
    keys = {b.name: np.array([v.co[:] for v in b.data]) for b in belt.data.shape_keys.key_blocks}
    assert np.allclose(keys["flex"] - keys["Basis"], before[1][1]["flex"].reshape(-1, 3)
                       - before[1][1]["Basis"].reshape(-1, 3), atol=1e-6)


def test_the_build_button_with_several_meshes_selected_says_so_and_the_panel_lists_them(scene, capfd):
    body, parts, lamp = character()
    bpy.context.scene.skin_detach.target_faces = TARGET_FACES
    capfd.readouterr()
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    n = sum(len(o.data.vertices) for o in [body] + parts)
    out = capfd.readouterr().out
    assert f"Skin Detach: 5 objects, {n:,} vertices bound" in out, out
    from test_blender_rig import _draw_panel
    activate(parts[2])  # the belt: the panel shows its rig
    labels = [value for kind, value in _draw_panel() if kind == "label"]
    assert "Objects: 5" in labels
    assert [value.strip() for value in labels[labels.index("Objects: 5") + 1:][:5]] == \
        ["body (owner)", "belt", "boot", "eye_L", "eye_R"]
    # Build again with only the rig's owner selected: the whole rig is rebuilt (a Rebuild).
    activate(body)
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    assert len(api.members(body)) == 5


def test_show_stretch_paints_every_object_its_own_slice(scene):
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    moved(handle)
    api.deform(body)
    api.show_stretch(bpy.data.objects["eye_R"])
    stretch = api.stretch(body)
    ranges = api.member_ranges(body)
    for obj in members:
        assert mesh_io.stretch_shown(obj.data)
        first, stop = ranges[obj]
        assert np.array_equal(mesh_io.read_point_floats(obj.data, mesh_io.STRETCH), stretch[first:stop])
    assert stretch.max() > 0.0
    api.show_stretch(body, False)
    assert not any(mesh_io.stretch_shown(o.data) for o in members)


def test_build_with_a_new_mesh_selected_beside_an_object_of_a_rig_adds_it_to_that_rig(scene):
    body, parts, lamp = character()
    eye_l, eye_r, belt, boot = parts
    api.build([body, eye_l], target_faces=TARGET_FACES)
    handle = api.add_handle(body, {eye_l: np.arange(len(eye_l.data.vertices))})
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (eye_l, boot))
    bpy.context.view_layer.objects.active = eye_l  # an object of the rig active, a new mesh selected
    bpy.context.scene.skin_detach.target_faces = TARGET_FACES
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    assert api.members(body) == [body, boot, eye_l]
    ranges = api.member_ranges(body)
    from skin_detach_addon.blender import handles
    assert np.array_equal(handles.detail_ids_of(handle), np.arange(*ranges[eye_l]))  # it kept the eye's vertices
    with pytest.raises(api.SkinDetachError, match=r"obj\[1\]: expected a mesh object, got None"):
        api.build([body, None])
    with pytest.raises(api.SkinDetachError, match="one twice"):
        api.build([body, eye_l, eye_l])


def test_the_bake_command_line_bakes_every_object_of_a_rig_into_its_own_files(scene, tmp_path):
    from skin_detach_addon import bake_cli
    body, members, lamp, stats, anchor, handle, low, top = rigged(scene)
    handle.keyframe_insert("location", frame=1)
    handle.location.z += 0.2
    handle.keyframe_insert("location", frame=2)
    path = tmp_path / "character.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    names = [o.name for o in members]
    try:
        bake_cli.main(["--blend", str(path), "--object", "eye_R", "--frames", "1-2",
                       "--output", str(tmp_path / "out" / "c_####.obj")])
    except SystemExit as stop:
        assert stop.code in (0, None)
    assert sorted(os.listdir(tmp_path / "out")) == sorted(f"c_{name}_{frame:04d}.obj" for name in names
                                                          for frame in (1, 2))
    try:  # --verify (a farm job's last task) finds every object's file
        bake_cli.main(["--blend", str(path), "--frames", "1-2", "--verify", "--output",
                       str(tmp_path / "out" / "c_####.obj")])
    except SystemExit as stop:
        assert stop.code in (0, None)
    os.remove(tmp_path / "out" / "c_eye_L_0002.obj")
    with pytest.raises(SystemExit) as stop:
        bake_cli.main(["--blend", str(path), "--frames", "1-2", "--verify", "--output",
                       str(tmp_path / "out" / "c_####.obj")])
    assert stop.value.code == 1
