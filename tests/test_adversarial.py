"""Adversarial cases (headless bpy, small meshes): each is refused with SkinDetachError and leaves
every mesh in the file bit-identical, or works and writes only finite, documented results."""

import re
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, import_spot, rig  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.api import SkinDetachError  # noqa: E402
from skin_detach_addon.blender import baking, binding, handles  # noqa: E402
from skin_detach_addon.core import packed_arrays  # noqa: E402


def meshes():
    """Every mesh's positions and shape keys in the file, by name."""
    out = {}
    for mesh in bpy.data.meshes:
        data = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", data)  # also readable while the mesh is in Edit Mode
        out[mesh.name] = data
    return out


def refused(call, match):
    """``call()`` raises SkinDetachError matching ``match`` and no mesh changed."""
    before = meshes()
    with pytest.raises(SkinDetachError, match=match):
        call()
    after = meshes()
    assert before.keys() == after.keys()
    for name in before:
        assert np.array_equal(before[name], after[name]), name


@pytest.fixture
def rigged(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    return obj, handle


def reload_binding():
    """Forget the runtime cache, as after loading a file."""
    binding._CACHE.clear()


def test_a_handle_moved_absurdly_far_writes_nothing(rigged):
    obj, handle = rigged
    handle.location.x = 1e39
    refused(lambda: api.deform(obj), "handle .*expected a transform that keeps its vertices finite")
    handle.location.x = 0.2
    assert api.deform(obj)["converged"]
    assert np.isfinite(meshes()[obj.data.name]).all()


@pytest.mark.parametrize("field, value, expected", [
    ("proxy_vertices", np.nan, "proxy_vertices"), ("proxy_vertices", 1e300, "proxy_vertices"),
    ("carrier", 10_000, "carrier: expected proxy vertex ids in [-1, "), ("carrier", -2, "carrier: expected proxy"),
    ("carrier", "inflates", "carrier: expected packed data that inflates"),
    ("carrier", "truncated", "carrier: expected packed bytes of the length their header gives"), ("carrier", b"\x01", "carrier: expected packed bytes")])
def test_crafted_stored_arrays_are_refused(rigged, field, value, expected):
    obj, handle = rigged
    group = binding.arrays_of(obj) if field in binding.arrays_of(obj) else obj[binding.KEY]
    stored = group[field]
    if value == "inflates":                                    # a byte of the packed zlib stream changed
        stored = bytearray(stored)
        stored[-3] ^= 0xFF
        stored = bytes(stored)
    elif value == "truncated":
        stored = stored[:-10]
    elif packed_arrays.is_packed(stored) and not isinstance(value, bytes):
        values = binding.stored_array(stored, field).reshape(-1, 3 if field == "proxy_vertices" else 1).copy()
        values[0] = value
        stored = packed_arrays.pack(values)
    elif isinstance(stored, bytes) and not isinstance(value, bytes):
        carrier = np.frombuffer(stored, dtype=obj[binding.KEY]["carrier_type"]).copy()
        carrier[0] = value
        stored = carrier.tobytes()
    elif hasattr(stored, "typecode"):
        stored = np.array(stored)
        stored[0] = value
    else:
        stored = value
    del group[field]
    group[field] = stored
    reload_binding()
    handle.location.x += 0.1
    refused(lambda: api.deform(obj), "binding of 'spot'.*" + re.escape(expected))
    refused(lambda: api.reset(obj), "binding of 'spot'.*" + re.escape(expected))


def test_crafted_rest_and_data_of_the_wrong_kind_are_refused(rigged):
    obj, _ = rigged
    rest = binding.stored_array(binding.arrays_of(obj)["rest"], "rest").copy()  # packed: stored back whole
    rest[5] = np.nan
    del binding.arrays_of(obj)["rest"]
    binding.arrays_of(obj)["rest"] = rest
    reload_binding()
    refused(lambda: api.reset(obj), "finite stored rest")
    del binding.arrays_of(obj)["rest"]
    binding.arrays_of(obj)["rest"] = rest[:30]
    reload_binding()
    refused(lambda: api.reset(obj), "stored rest positions")
    obj[binding.KEY]["stats"] = "{not json"
    binding.arrays_of(obj)["proxy_faces"] = np.array([1, 2], dtype=np.int32)
    reload_binding()
    refused(lambda: api.deform(obj), "binding of 'spot'")
    assert api.figures(obj)["build"] == {}  # the panel's figures still read


def test_a_proxy_in_edit_mode_stops_the_step_before_any_write(rigged):
    obj, handle = rigged
    proxy = api.proxy_of(obj)
    activate(proxy)
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        handle.location.x += 0.2
        refused(lambda: api.deform(obj), "proxy .*Edit Mode")
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
    assert api.deform(obj)["converged"]  # nothing stale: the next deform works


def test_a_linked_duplicate_in_edit_mode_stops_the_step(rigged):
    obj, handle = rigged
    twin = bpy.data.objects.new("twin", obj.data)
    bpy.context.scene.collection.objects.link(twin)
    activate(twin)
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        handle.location.x += 0.2
        refused(lambda: api.deform(obj), "Edit Mode")
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')


def test_a_proxy_pointer_to_another_mesh_is_refused(rigged):
    obj, handle = rigged
    other = bpy.data.objects.new("other", api.proxy_of(obj).data.copy())
    bpy.context.scene.collection.objects.link(other)
    obj[binding.KEY]["proxy"] = other
    handle.location.x += 0.2
    refused(lambda: api.deform(obj), "expected its own proxy")
    refused(lambda: api.reset(obj), "expected its own proxy")


def test_apply_scale_after_binding_is_refused_by_reset(rigged):
    obj, handle = rigged
    activate(obj)
    obj.scale = (2.0, 2.0, 2.0)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    refused(lambda: api.reset(obj), "Apply Scale/Rotation")
    refused(lambda: api.deform(obj), "edited since")
    api.build(obj)  # rebinding takes the applied shape
    assert api.deform(obj)["converged"]


def test_a_copy_of_a_bound_object_is_refused_until_rebuilt(rigged):
    obj, handle = rigged
    activate(obj)
    bpy.ops.object.duplicate()
    copy = bpy.context.active_object
    assert copy is not obj and binding.KEY in copy
    refused(lambda: api.deform(copy), "belongs to 'spot'")
    refused(lambda: api.add_handle(copy, [0, 1, 2]), "belongs to 'spot'")
    api.build(copy)
    assert api.proxy_of(copy) is not api.proxy_of(obj)
    assert api.deform(obj)["converged"]


def test_object_scale_zero_is_refused(rigged):
    obj, handle = rigged
    obj.scale = (0.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    refused(lambda: api.deform(obj), "invertible transform")


def test_crafted_handle_ids_and_kinds_are_refused(rigged):
    obj, handle = rigged
    tag = handle[handles.TAG]
    ids = np.array(tag["proxy_ids"])
    del tag["proxy_ids"]
    tag["proxy_ids"] = np.r_[ids, -1].astype(np.int32)
    refused(lambda: api.deform(obj), "proxy_ids in")
    del tag["proxy_ids"]
    tag["proxy_ids"] = ids.astype(np.float64) + 0.5
    refused(lambda: api.deform(obj), "integer proxy_ids")
    del tag["proxy_ids"]
    tag["proxy_ids"] = ids
    tag["kind"] = "MAGNET"
    refused(lambda: api.deform(obj), "expected kind")


def test_the_newest_handle_wins_on_shared_vertices(scene):
    obj = import_spot()
    api.build(obj, target_faces=300)
    top = np.flatnonzero(api.rest_positions(obj)[:, 1] > 0.3)
    made = [api.add_handle(obj, top) for _ in range(10)]
    assert [e.name for e in made][-2:] == ["spot_handle_9", "spot_handle_10"]
    assert api.handles_of(obj)[-1] == made[-1]
    made[-1].location.x += 0.3   # the newest handle moves, the older ones stay
    api.add_anchor(obj, np.flatnonzero(api.rest_positions(obj)[:, 1] < -0.3))
    api.deform(obj)
    moved = meshes()[obj.data.name].reshape(-1, 3)[top] - api.rest_positions(obj)[top]
    assert np.allclose(moved[:, 0], 0.3, atol=1e-4)


def test_frames_parse_in_linear_time_and_absurd_ranges_are_refused():
    assert baking.parse_frames("1-30000")[-1] == 30000
    with pytest.raises(SkinDetachError, match="at most"):
        baking.parse_frames("1-1000000")
    with pytest.raises(SkinDetachError, match="at most"):
        baking.parse_frames(",".join(["1-90000"] * 20))
    assert baking.file_path("out/#_take_##.obj", 7) == "out/#_take_07.obj"  # the last run only


def test_library_linked_objects_are_refused(scene, tmp_path):
    obj = import_spot()
    library = tmp_path / "library.blend"
    bpy.data.libraries.write(str(library), {obj})
    bpy.ops.wm.read_homefile(use_empty=True)
    with bpy.data.libraries.load(str(library), link=True) as (source, target):
        target.objects = ["spot"]
    linked = target.objects[0]
    bpy.context.scene.collection.objects.link(linked)
    refused(lambda: api.build(linked), "linked from")


def test_an_unlinked_mesh_held_by_its_rig_is_refused(rigged):
    obj, handle = rigged
    for collection in list(obj.users_collection):
        collection.objects.unlink(obj)
    handle.location.x += 0.2
    refused(lambda: api.deform(obj), "unlinked from every scene")


def test_bake_script_refuses_to_overwrite_its_source_and_resolves_handles(rigged, tmp_path):
    obj, handle = rigged
    source = tmp_path / "rig.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(source))
    script = [sys.executable, "scripts/bake.py", "--blend", str(source)]
    run = subprocess.run(script + ["--output", str(source), "--into", "shape-keys"], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 1 and "overwrite the source" in run.stderr
    run = subprocess.run(script + ["--object", handle.name, "--frames", "1", "--output",
                                   str(tmp_path / "o_####.obj")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert f"({len(obj.data.vertices):,} vertices)" in run.stdout and "belongs to 'spot'" in run.stdout
    run = subprocess.run(script + ["--frames", "1-99999999", "--output", str(tmp_path / "p_####.obj")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1 and "at most" in run.stderr and not list(tmp_path.glob("p_*.obj"))


def test_a_binding_that_is_not_a_group_is_refused_and_the_panel_still_draws(rigged):
    from test_blender_rig import _draw_panel
    obj, handle = rigged
    handle[handles.TAG]["kind"] = 7
    activate(obj)
    lines = _draw_panel()
    assert any(kind == "operator" and value == "skin_detach.remove_handle" for kind, value in lines)
    obj[binding.KEY] = 5
    reload_binding()
    refused(lambda: api.deform(obj), "binding group")
    refused(lambda: api.reset(obj), "binding group")
    assert any(kind == "label" and value.startswith("Detail:") for kind, value in _draw_panel())
    with pytest.raises(RuntimeError, match="binding group"):  # headless, an ERROR report raises
        bpy.ops.skin_detach.apply()


def sliver_icosphere():
    """Icosphere (float32) with a zero-area sliver on each edge: a face (a, b, m), m the midpoint
    of the edge ab (its own vertex), as the active object."""
    import bmesh
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3)
    obj = bpy.context.active_object
    mesh = bmesh.new()
    mesh.from_mesh(obj.data)
    for edge in list(mesh.edges):
        a, b = edge.verts
        mesh.faces.new((a, b, mesh.verts.new((a.co + b.co) / 2)))
    mesh.to_mesh(obj.data)
    mesh.free()
    obj.data.update()
    activate(obj)
    return obj


def test_sliver_faces_build_finite_coefficients_and_deform_at_rest_writes_the_rest(scene):
    obj = sliver_icosphere()
    api.build(obj, target_faces=100, preview_above=None)
    rest = meshes()[obj.data.name].reshape(-1, 3)
    api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.7))
    api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.7))
    skin = binding.open_binding(obj).surface.skin
    for name in ("bary", "height", "weight"):
        assert np.isfinite(getattr(skin, name)).all(), name
    api.deform(obj)
    out = meshes()[obj.data.name].reshape(-1, 3)
    assert np.isfinite(out).all()
    assert np.abs(out - rest).max() <= 1e-5


def test_a_non_finite_array_is_never_written(rigged):
    obj, _ = rigged
    from skin_detach_addon.blender import mesh_io
    bad = meshes()[obj.data.name].reshape(-1, 3).copy()
    bad[7, 1] = np.nan
    refused(lambda: mesh_io.write_positions(obj.data, bad), "expected finite vertex positions, got 1 vertices")


@pytest.mark.parametrize("damage", [{"seconds": 5}, {"detail_vertices": "many"}, {"detail_vertices": None},
                                    {"proxy_faces": -3, "seconds": {"total": "slow"}}, {"target_reached": "no"}])
def test_the_panel_draws_over_damaged_stored_figures(rigged, damage):
    import json
    from test_blender_rig import _draw_panel
    obj, _ = rigged
    stats = json.loads(str(obj[binding.KEY]["stats"]))
    stats.update(damage)
    obj[binding.KEY]["stats"] = json.dumps(stats)
    activate(obj)
    lines = _draw_panel()
    assert any(kind == "label" and value.startswith("Detail:") for kind, value in lines)
    assert any(kind == "label" and value.startswith("Build:") for kind, value in lines)


@pytest.mark.parametrize("where", ["detail", "preview"])
def test_a_rebuild_gone_non_finite_writes_nothing_mesh_proxy_or_preview(rigged, monkeypatch, where):
    # Each array of a step is checked once, before any write (the writes are told so): a NaN in
    # the detail or the preview must still stop the step with nothing written.
    obj, handle = rigged
    record = binding.open_binding(obj)
    name = "rebuild" if where == "detail" else "rebuild_preview"
    if where == "preview":
        api.build(obj, target_faces=300, preview_above=1000)
        record = binding.open_binding(obj)
    original = getattr(type(record), name)

    def poisoned(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        out[3] = np.nan
        return out
    monkeypatch.setattr(type(record), name, poisoned)
    handle.location.x += 0.3
    refused(lambda: api.deform(obj, preview=where == "preview"), "finite")
