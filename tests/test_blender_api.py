"""Headless bpy: the scripting API and baking (shape keys, objects, OBJ/PLY files)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import all_data, band, quad_sphere  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import baking, mesh_io  # noqa: E402
from skin_detach_addon.core.errors import SkinDetachError  # noqa: E402


def scripted_rig(target_faces=300):
    """Quad sphere bound through the API: anchor on the lowest 15 %, handle on the highest 15 %."""
    obj = quad_sphere()
    api.build(obj, target_faces=target_faces)
    api.add_anchor(obj, np.flatnonzero(band(obj, 0.0, 0.15)))
    handle = api.add_handle(obj, np.flatnonzero(band(obj, 0.85, 1.0)))
    return obj, handle


def animate(handle, frames_and_offsets):
    """Key the handle's location at rest + offset on each frame."""
    rest = handle.location.copy()
    for frame, offset in frames_and_offsets:
        handle.location = rest + type(rest)(offset)
        handle.keyframe_insert("location", frame=frame)


def test_api_rest_in_rest_out_and_translation_follows_the_handle(scene):
    obj, handle = scripted_rig()
    rest = mesh_io.read_positions(obj.data).copy()
    stats = api.deform(obj)
    assert stats["converged"] and set(stats) == {"milliseconds", "iterations", "converged", "volume_change", "preview"}
    assert stats["preview"] is False
    assert np.abs(mesh_io.read_positions(obj.data) - rest).max() < 1e-5
    handle.location.x += 0.3
    api.deform(handle)  # a handle means its mesh
    moved = mesh_io.read_positions(obj.data)
    top, base = band(obj, 0.9, 1.0), band(obj, 0.0, 0.1)
    assert np.allclose(moved[top, 0] - rest[top, 0], 0.3, atol=0.02)
    assert np.abs(moved[base] - rest[base]).max() < 1e-3
    api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)
    api.clear(obj)
    assert not api.is_bound(obj) and not [o for o in bpy.data.objects if o.type == 'EMPTY']


def test_api_refuses_bad_arguments_naming_them(scene):
    obj = quad_sphere()
    with pytest.raises(SkinDetachError, match="call build"):
        api.deform(obj)
    with pytest.raises(SkinDetachError, match="target_faces"):
        api.build(obj, target_faces="many")
    api.build(obj, target_faces=300)
    n = len(obj.data.vertices)
    with pytest.raises(SkinDetachError, match="vertex_ids"):
        api.add_handle(obj, [0, n])
    with pytest.raises(SkinDetachError, match="vertex_ids"):
        api.add_anchor(obj, [])
    with pytest.raises(SkinDetachError, match="at least one handle"):
        api.deform(obj)
    with pytest.raises(SkinDetachError, match="None"):
        api.build(None)
    with pytest.raises(SkinDetachError, match="into"):
        api.bake(obj, "1-2", into="VIDEO")


def test_frame_ranges_parse_and_refuse():
    assert baking.parse_frames("1-3,7, 2,9-10") == [1, 2, 3, 7, 9, 10]
    assert baking.check_frames(range(4, 6)) == [4, 5]
    assert baking.file_path("out/m_####.obj", 12) == "out/m_0012.obj"
    assert baking.file_path("out/m.ply", 3) == "out/m_0003.ply"
    for bad in ("5-1", "a-b", ""):
        with pytest.raises(SkinDetachError, match="frames"):
            baking.parse_frames(bad)
    with pytest.raises(SkinDetachError, match="frames"):
        baking.check_frames([1.5])


def test_bake_shape_keys_play_back_the_animation_and_rerun_is_idempotent(scene):
    obj, handle = scripted_rig()
    animate(handle, [(1, (0, 0, 0)), (3, (0.4, 0, 0.1))])
    before = mesh_io.snapshot(obj.data)
    scene.frame_set(2)
    records = api.bake(obj, "1-3")
    assert [r["frame"] for r in records] == [1, 2, 3] and all(r["converged"] for r in records)
    assert scene.frame_current == 2
    keys = obj.data.shape_keys.key_blocks
    assert [k.name for k in keys] == ["Basis", "skin_detach_0001", "skin_detach_0002", "skin_detach_0003"]
    assert np.array_equal(mesh_io.snapshot(obj.data)[0], before[0])  # the mesh itself is untouched

    def key(name):
        data = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
        keys[name].data.foreach_get("co", data)
        return data.reshape(-1, 3)

    assert np.abs(key("skin_detach_0001") - before[0].reshape(-1, 3)).max() < 1e-5  # frame 1 is at rest
    # Each key is what deform gives at its frame.
    scene.frame_set(3)
    keyed = key("skin_detach_0003").copy()
    for block in keys:
        block.value = 0.0
    obj.data.shape_keys.animation_data_clear()
    live = api.deform(obj)
    assert live["converged"]
    assert np.abs(mesh_io.read_positions(obj.data) - keyed).max() < 1e-5
    api.reset(obj)

    # Playback: the evaluated mesh at frame 3 is that key (the keys are keyed 0-1-0).
    api.bake(obj, [1, 2, 3])
    scene.frame_set(3)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    shown = np.empty(3 * len(evaluated.vertices), dtype=np.float32)
    evaluated.vertices.foreach_get("co", shown)
    assert np.abs(shown.reshape(-1, 3) - key("skin_detach_0003")).max() < 1e-5
    assert len(obj.data.shape_keys.key_blocks) == 4  # re-run replaced, did not add


def test_bake_objects_and_files_keep_uvs_and_vertex_order(scene, tmp_path):
    obj, handle = scripted_rig()
    animate(handle, [(1, (0, 0, 0)), (2, (0, 0.3, 0))])
    original = all_data(obj.data)
    records = api.bake(obj, "2", into=api.OBJECTS)
    baked = bpy.data.objects[records[0]["output"]]
    assert baked.name == "quads_bake_0002" and not api.is_bound(baked)
    for key, value in all_data(baked.data).items():
        assert np.array_equal(value, original[key]), key
    baked_positions = mesh_io.read_positions(baked.data).copy()
    assert np.abs(baked_positions - mesh_io.read_positions(obj.data)).max() > 0.1
    api.bake(obj, "2", into=api.OBJECTS)
    assert len(bpy.data.collections[baking.BAKE_COLLECTION].objects) == 1

    records = api.bake(obj, "1-2", into=api.FILES, path=str(tmp_path / "frames" / "sphere_##.obj"))
    assert [r["output"] for r in records] == [str(tmp_path / "frames" / f"sphere_0{f}.obj") for f in (1, 2)]
    lines = (tmp_path / "frames" / "sphere_02.obj").read_text().splitlines()
    vertices = np.array([[float(x) for x in line.split()[1:4]] for line in lines if line.startswith("v ")])
    assert sum(line.startswith("vt ") for line in lines) > 0
    # Blender's OBJ axes: file (x, y, z) = Blender (x, z, -y).
    assert np.abs(vertices[:, [0, 2, 1]] * [1, -1, 1] - baked_positions).max() < 1e-4
    ply = api.bake(obj, [2], into=api.FILES, path=str(tmp_path / "sphere.ply"))[0]["output"]
    header = open(ply, "rb").read(400).split(b"end_header")[0].decode()
    # PLY holds UVs per vertex, so Blender's exporter splits vertices along UV seams.
    assert int(header.split("element vertex ")[1].split()[0]) >= len(obj.data.vertices)
    assert "property float s" in header


def test_failed_bake_removes_what_it_added_and_leaves_the_mesh(scene, tmp_path):
    obj, handle = scripted_rig()
    animate(handle, [(1, (0, 0, 0)), (3, (0.4, 0, 0.1))])
    scene.frame_set(3)
    api.deform(obj)
    before = mesh_io.snapshot(obj.data)

    def interrupt(done, total, record):
        if done == 2:
            raise KeyboardInterrupt  # Ctrl-C in the middle of a bake

    for into, path in ((api.SHAPE_KEYS, None), (api.OBJECTS, None), (api.FILES, str(tmp_path / "m.obj"))):
        with pytest.raises(KeyboardInterrupt):
            api.bake(obj, "1-3", into=into, path=path, progress=interrupt)
        assert obj.data.shape_keys is None and baking.BAKE_COLLECTION not in bpy.data.collections or \
            not bpy.data.collections[baking.BAKE_COLLECTION].objects
        assert np.array_equal(mesh_io.snapshot(obj.data)[0], before[0]) and scene.frame_current == 3
    api.deform(obj)  # what Skin Detach wrote is still recognised as its own
    with pytest.raises(SkinDetachError, match="path"):
        api.bake(obj, "1", into=api.FILES, path=str(tmp_path / "mesh.stl"))
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(SkinDetachError, match="folder"):
        api.bake(obj, "1", into=api.FILES, path=str(blocker / "mesh.obj"))


def test_a_new_handle_has_a_current_world_matrix(scene):
    obj, handle = scripted_rig()
    centroid = mesh_io.read_positions(obj.data)[band(obj, 0.85, 1.0)].mean(axis=0)
    assert np.linalg.norm(np.array(handle.matrix_world.translation) - centroid) < 0.1
