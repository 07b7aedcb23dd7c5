"""Headless bpy: build, handles, apply, reset, clear, persistence and refusals."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, band, import_spot, rig, save_and_reopen, select_vertices  # noqa: E402

from skin_detach_addon.blender import binding, binding_figures, handles, mesh_io, skin_rig  # noqa: E402
from skin_detach_addon.core.proxy_solve import proxy_solves  # noqa: E402
from skin_detach_addon.core import packed_arrays  # noqa: E402


def test_build_makes_a_wire_proxy_in_its_own_collection_and_rebuild_replaces_it(scene):
    obj = import_spot()
    scene.skin_detach.target_faces = 400
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    proxy = binding.proxy_of(obj)
    assert proxy.name == "spot_proxy" and proxy.parent == obj
    assert proxy.display_type == 'WIRE' and proxy.hide_render
    assert [c.name for c in proxy.users_collection] == [skin_rig.RIG_COLLECTION]
    assert np.allclose(np.array(proxy.matrix_world), np.array(obj.matrix_world))
    assert 300 <= len(proxy.data.polygons) <= 400
    stats = binding_figures.stats_of(obj)
    assert stats["detail_vertices"] == len(obj.data.vertices)

    select_vertices(obj, band(obj, 0.8, 1.0, axis=1))
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    activate(proxy)
    proxy.data.vertices.foreach_set("select", np.arange(len(proxy.data.vertices)) < 5)
    assert bpy.ops.skin_detach.add_anchor() == {'FINISHED'}
    activate(obj)
    scene.skin_detach.target_faces = 200
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    proxies = [o for o in bpy.data.objects if skin_rig.PROXY_TAG in o]
    assert len(proxies) == 1 and len(proxies[0].data.polygons) < 300  # the normal test may stop above 200
    assert len(bpy.data.meshes) == 2
    kept = handles.handles_of(obj)
    # The handle made from detail vertices follows to the new proxy; the proxy-made anchor cannot.
    assert [handles.kind_of(e) for e in kept] == [handles.HANDLE]
    assert kept[0].parent == proxies[0]
    assert handles.proxy_ids_of(kept[0]).max() < len(proxies[0].data.vertices)


def test_build_operator_takes_its_own_parameters_with_the_panel_values_as_defaults(scene):
    obj = import_spot()
    scene.skin_detach.target_faces = 1000
    scene.skin_detach.normal_test = False
    assert bpy.ops.skin_detach.build(target_faces=200) == {'FINISHED'}
    assert len(binding.proxy_of(obj).data.polygons) == 200  # no normal test: exactly the target
    assert scene.skin_detach.target_faces == 1000            # the panel's value stays
    assert bpy.ops.skin_detach.build() == {'FINISHED'}
    assert 980 <= len(binding.proxy_of(obj).data.polygons) <= 1000  # the target, less the slivers' merges
    assert bpy.ops.skin_detach.build(target_faces=300, normal_test=True) == {'FINISHED'}
    assert 300 <= len(binding.proxy_of(obj).data.polygons) < 400


def test_binding_is_stored_without_int64_or_pickles(scene):
    obj = import_spot()
    rig(obj, axis=1)
    props = obj[binding.KEY]
    for key, value in list(props.items()) + list(binding.arrays_of(obj).items()):
        if hasattr(value, "typecode"):
            assert value.typecode in "ifd", key
        elif isinstance(value, bytes) and packed_arrays.is_packed(value):  # packed (lossless, zlib)
            assert binding.stored_array(value, key).dtype.kind in "if", key
        elif isinstance(value, bytes):                         # a small narrow integer array, its type beside it
            assert props[key + binding.TYPE_SUFFIX] in ("int8", "int16"), key
        elif key == binding.DIGESTS:                            # a group of digests (strings)
            assert all(isinstance(digest, str) for digest in value.values()), key
        else:
            assert isinstance(value, (int, str, float)) or key in ("proxy", "settings", binding.STORE), key
    assert props["schema_version"] == 3 and not set(binding.WHOLE_SKIN_KEYS) & set(props.keys())


def test_the_bindings_arrays_live_on_a_text_datablock_that_goes_with_the_binding(scene):
    """The record on the object keeps no array (Blender copies an object's ID properties into its
    evaluated copy on every update): its arrays are on a text datablock it points at, which
    Clear removes with it."""
    import bpy
    obj = import_spot()
    rig(obj, axis=1)
    side = obj[binding.KEY][binding.STORE]
    assert side.name.startswith(binding.STORE_PREFIX) and side.users == 1
    assert max((len(value) for value in obj[binding.KEY].values() if hasattr(value, "typecode")), default=0) <= 16
    assert binding.arrays_of(obj)["rest"] is not None
    name = side.name
    skin_rig.clear(obj)
    assert name not in bpy.data.texts


def test_add_handle_leaves_edit_mode_and_uses_the_edit_selection(scene):
    obj = import_spot()
    rig(obj, axis=1)
    assert handles.is_handle(bpy.context.active_object)  # a new handle is active, ready to drag
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='DESELECT')
    bpy.ops.object.mode_set(mode='OBJECT')
    picked = np.zeros(len(obj.data.vertices), dtype=bool)
    picked[:20] = True
    select_vertices(obj, picked)
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.skin_detach.add_handle() == {'FINISHED'}
    assert obj.mode == 'OBJECT'
    empty = handles.handles_of(obj)[-1]
    assert np.array_equal(handles.detail_ids_of(empty), np.arange(20))


def test_apply_moves_the_handle_rigidly_keeps_anchors_and_reset_is_exact(scene):
    obj = import_spot()
    rest = mesh_io.read_positions(obj.data)
    handle = rig(obj, axis=1)
    top, bottom = band(obj, 0.85, 1.0, axis=1), band(obj, 0.0, 0.15, axis=1)
    handle.location = handle.location + type(handle.location)((0.2, 0.05, -0.1))  # in the world, as any child object
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    moved = mesh_io.read_positions(obj.data)
    shift = np.linalg.solve(np.array(obj.matrix_world)[:3, :3], (0.2, 0.05, -0.1))  # spot is turned X 90 (OBJ import)
    assert np.allclose(moved[top] - rest[top], shift, atol=1e-5)
    assert np.abs(moved[bottom] - rest[bottom]).max() <= 1e-5
    assert np.abs(moved - rest).max() > 0.1
    # The proxy shows the deformed proxy.
    assert not np.array_equal(mesh_io.read_positions(binding.proxy_of(obj).data),
                              binding.open_binding(obj).surface.proxy_vertices.astype(np.float32))
    assert bpy.ops.skin_detach.reset() == {'FINISHED'}
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)
    bpy.context.view_layer.update()
    assert np.allclose(np.array(handle.matrix_world),  # back on its rest frame, in the world
                       np.array(obj.matrix_world) @ handles.rest_local_of(handle), atol=1e-6)


def test_thousands_of_applies_do_not_drift(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    start = handle.location.copy()
    handle.location.x += 0.1
    bpy.ops.skin_detach.apply()
    first = mesh_io.read_positions(obj.data)
    for k in range(200):
        handle.location.x = start.x + 0.1 + 0.05 * np.sin(k)
        bpy.ops.skin_detach.apply()
    handle.location.x = start.x + 0.1
    bpy.ops.skin_detach.apply()
    assert np.abs(mesh_io.read_positions(obj.data) - first).max() <= 1e-5


def test_clear_removes_proxy_handles_binding_and_collection(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.2
    bpy.ops.skin_detach.apply()
    shape = mesh_io.read_positions(obj.data)
    assert bpy.ops.skin_detach.clear() == {'FINISHED'}
    assert binding.KEY not in obj
    assert [o.name for o in bpy.data.objects] == [obj.name]
    assert skin_rig.RIG_COLLECTION not in bpy.data.collections
    assert np.array_equal(mesh_io.read_positions(obj.data), shape)


def test_save_reload_then_apply_without_rebuilding(scene, tmp_path):
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.15
    bpy.ops.skin_detach.apply()
    expected = mesh_io.read_positions(obj.data)
    bpy.ops.skin_detach.reset()
    obj, handle = save_and_reopen(tmp_path / "bound.blend")
    activate(handle)
    handle.location.x += 0.15
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert np.abs(mesh_io.read_positions(obj.data) - expected).max() <= 1e-5


def _refused(operator, match):
    with pytest.raises(RuntimeError, match=match):
        operator()


def test_bad_input_is_reported_and_changes_nothing(scene):
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    activate(camera)
    assert not bpy.ops.skin_detach.build.poll()

    empty_mesh = bpy.data.objects.new("empty_mesh", bpy.data.meshes.new("empty_mesh"))
    scene.collection.objects.link(empty_mesh)
    activate(empty_mesh)
    _refused(bpy.ops.skin_detach.build, "expected vertices and faces")
    assert binding.KEY not in empty_mesh

    obj = import_spot()
    positions = mesh_io.read_positions(obj.data)
    broken = positions.copy()
    broken[7] = np.nan
    obj.data.attributes["position"].data.foreach_set("vector", broken.ravel())
    _refused(bpy.ops.skin_detach.build, "NaN")
    assert binding.KEY not in obj and len(bpy.data.objects) == 3


def test_no_handles_is_refused(scene):
    obj = import_spot()
    scene.skin_detach.target_faces = 300
    bpy.ops.skin_detach.build()
    rest = mesh_io.read_positions(obj.data)
    _refused(bpy.ops.skin_detach.apply, "at least one handle")
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)


def test_edited_positions_or_topology_are_refused_and_nothing_is_written(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.1
    # Positions edited outside Skin Detach (as a sculpt stroke would).
    edited = mesh_io.read_positions(obj.data)
    edited[0] += 0.01
    obj.data.attributes["position"].data.foreach_set("vector", edited.ravel())
    _refused(bpy.ops.skin_detach.apply, "edited since")
    assert np.array_equal(mesh_io.read_positions(obj.data), edited)

    # Topology edited after binding.
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='DESELECT')
    bpy.ops.object.mode_set(mode='OBJECT')
    select_vertices(obj, np.arange(len(obj.data.vertices)) == 3)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.delete(type='VERT')
    bpy.ops.object.mode_set(mode='OBJECT')
    before = mesh_io.read_positions(obj.data)
    activate(obj)
    _refused(bpy.ops.skin_detach.apply, "edited after binding")
    assert np.array_equal(mesh_io.read_positions(obj.data), before)


def test_a_skin_detach_write_keeps_the_topology_fingerprint_and_a_later_edge_rotation_still_drops_it(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.1
    bpy.ops.skin_detach.apply()
    bpy.context.view_layer.update()  # Blender reports the write as a geometry update
    pointer = obj.data.as_pointer()
    assert pointer in mesh_io._FINGERPRINTS  # positions only: the corners are not read again
    # Topology edited with the same counts (one edge rotated), after the write's update.
    activate(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_mode(type='EDGE')
    bpy.ops.mesh.select_all(action='DESELECT')
    bpy.ops.object.mode_set(mode='OBJECT')
    counts = (len(obj.data.vertices), len(obj.data.polygons), len(obj.data.loops))
    mesh = obj.data
    first, second = mesh.polygons[0].vertices[0], mesh.polygons[0].vertices[1]
    for edge in mesh.edges:
        edge.select = set(edge.vertices) == {first, second}
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.edge_rotate(use_ccw=False)
    bpy.ops.object.mode_set(mode='OBJECT')
    assert (len(obj.data.vertices), len(obj.data.polygons), len(obj.data.loops)) == counts
    activate(obj)
    _refused(bpy.ops.skin_detach.apply, "edited after binding")


def test_deleted_proxy_is_refused(scene):
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.1
    rest = mesh_io.read_positions(obj.data)
    proxy = binding.proxy_of(obj)
    proxy.hide_select = False  # the panel's Select Proxy: an unselectable proxy cannot be deleted by the operator
    activate(proxy)
    bpy.ops.object.delete()
    activate(obj)
    _refused(bpy.ops.skin_detach.apply, "proxy object, it was deleted")
    assert np.array_equal(mesh_io.read_positions(obj.data), rest)


class _Layout:
    """Stands in for a UI layout: records what a panel draws."""

    def __init__(self, lines):
        self.lines = lines

    def box(self):
        return self

    def row(self, align=False):
        return self

    def label(self, text="", icon='NONE'):
        self.lines.append(("label", text))

    def prop(self, data, name, **options):
        assert hasattr(data, name), name
        self.lines.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **options):
        assert hasattr(data, name) and hasattr(search_data, search_name), (name, search_name)
        self.lines.append(("prop", name))

    def operator(self, idname, text="", icon='NONE', depress=False, **options):
        group, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, group), name), idname
        self.lines.append(("operator", idname))
        return type("Properties", (), {})()


def _draw_panel():
    from skin_detach_addon.ui.panel import VIEW3D_PT_skin_detach
    lines = []
    VIEW3D_PT_skin_detach.draw(type("Panel", (), {"layout": _Layout(lines)})(), bpy.context)
    return lines


def test_panel_draws_build_handles_deform_and_figures(scene):
    obj = import_spot()
    assert ("label", "spot: not bound") in _draw_panel()
    handle = rig(obj, axis=1)
    activate(obj)
    lines = _draw_panel()
    operators = [value for kind, value in lines if kind == "operator"]
    for idname in ("skin_detach.build", "skin_detach.add_handle", "skin_detach.add_anchor", "skin_detach.drag",
                   "skin_detach.apply", "skin_detach.reset", "skin_detach.clear"):
        assert idname in operators
    assert operators.count("skin_detach.select_handle") == 2 and operators.count("skin_detach.remove_handle") == 2
    assert ("prop", "live_update") in lines and ("prop", "target_faces") in lines
    assert any(kind == "label" and value.startswith("Detail: 2,930 vertices") for kind, value in lines)
    assert ("label", "Last step: -") in lines
    activate(handle)
    bpy.ops.skin_detach.apply()
    lines = _draw_panel()
    assert any(kind == "label" and value.startswith("Last step: ") and value.endswith(" ms") for kind, value in lines)
    assert any(kind == "label" and value.strip().endswith(" iterations") for kind, value in lines)
    assert not any("did not converge" in value for kind, value in lines if kind == "label")


def test_a_solve_that_did_not_converge_is_reported_by_apply_and_the_panel(scene, monkeypatch, capfd):
    obj = import_spot()
    handle = rig(obj, axis=1)
    monkeypatch.setattr(proxy_solves, "MAX_ITERATIONS", 1)
    handle.location.x += 0.3
    activate(handle)
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert "the solve did not converge" in capfd.readouterr().out
    activate(obj)
    assert ("label", "The last solve did not converge") in _draw_panel()
    monkeypatch.setattr(proxy_solves, "MAX_ITERATIONS", 300)
    activate(handle)
    assert bpy.ops.skin_detach.apply() == {'FINISHED'}
    assert "did not converge" not in capfd.readouterr().out
