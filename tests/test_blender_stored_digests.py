"""Issue 52 item 8 (headless bpy): a stored binding changed outside Skin Detach into data that is
still well-formed (a carrier set to -1, proxy faces flipped, a proxy vertex moved, a proxy face
dropped, the rest nudged) passes every check of shapes and ranges and deformed the mesh 0.3-2 % of
the diagonal wrong; it is refused on opening, naming the changed key, and nothing is written.
The rig is a limb of quads and ngons with a loose bracelet, rotated and scaled as an OBJ import
leaves it; the files of earlier versions (no digests) still open."""

import shutil

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import DATA, imported_limb  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.api import SkinDetachError  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402


def reopen(path, name):
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    binding._CACHE.clear()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.data.objects[name]


def stored(obj):
    return binding.arrays_of(obj), obj[binding.KEY]


def carrier_to_minus_one(obj):
    arrays, record = stored(obj)
    kind = binding.NARROW_TYPES[record["carrier_type"]] if "carrier_type" in record else np.int32
    packed = arrays["carrier"]
    values = np.full(len(packed) // np.dtype(kind).itemsize if isinstance(packed, bytes) else len(packed), -1, kind)
    arrays["carrier"] = values.tobytes() if isinstance(packed, bytes) else values.astype(np.int32)


def faces_flipped(obj):
    arrays, _ = stored(obj)
    faces = np.array(arrays["proxy_faces"]).reshape(-1, 3)
    arrays["proxy_faces"] = faces[:, ::-1].astype(np.int32).ravel()


def vertex_moved(obj):
    arrays, _ = stored(obj)
    points = np.array(arrays["proxy_vertices"]).reshape(-1, 3)
    points[0] += 0.05 * np.ptp(points, axis=0).max()
    arrays["proxy_vertices"] = points.ravel()


def face_dropped(obj):
    arrays, _ = stored(obj)
    arrays["proxy_faces"] = np.array(arrays["proxy_faces"])[3:].astype(np.int32)


def rest_nudged(obj):
    arrays, _ = stored(obj)
    rest = np.array(arrays["rest"], dtype=np.float32)
    rest[7] += np.float32(1e-3)
    arrays["rest"] = rest


@pytest.mark.parametrize("change, key", [(carrier_to_minus_one, "carrier"), (faces_flipped, "proxy_faces"),
                                         (vertex_moved, "proxy_vertices"), (face_dropped, "proxy_faces"),
                                         (rest_nudged, "rest")])
def test_a_binding_changed_outside_the_add_on_is_refused_naming_what_changed(scene, tmp_path, change, key):
    obj, _ = imported_limb(scale=(0.02, 0.02, 0.02))
    api.build(obj, target_faces=120)
    rest = api.rest_positions(obj).copy()
    obj = reopen(tmp_path / "limb.blend", "limb")
    assert binding.open_binding(obj) is not None  # as stored: opens
    binding._CACHE.clear()
    change(obj)
    before = mesh_io.read_positions(obj.data).copy()
    with pytest.raises(SkinDetachError, match=rf"binding of 'limb' {key}: expected the values the build stored"):
        binding.open_binding(obj)
    with pytest.raises(SkinDetachError, match=key):
        api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), before)  # nothing written
    api.build(obj, target_faces=120)  # Rebuild binds it again, from the mesh as it is (at rest)
    assert np.array_equal(api.rest_positions(obj), rest)


def test_a_rig_of_several_objects_opens_with_its_digests_and_refuses_a_changed_member_rest(scene, tmp_path):
    from skin_detach_addon.blender import rig_members
    obj, _ = imported_limb()
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.2, location=(0.0, 0.0, 3.0))
    eye = bpy.context.active_object
    api.build([obj, eye], target_faces=120)
    obj = reopen(tmp_path / "several.blend", "limb")
    assert binding.open_binding(obj) is not None
    binding._CACHE.clear()
    arrays, _ = stored(obj)
    local = np.array(arrays[rig_members.LOCAL_REST], dtype=np.float32)
    local[-1] += np.float32(0.01)
    arrays[rig_members.LOCAL_REST] = local
    with pytest.raises(SkinDetachError, match=rig_members.LOCAL_REST):
        binding.open_binding(obj)


def test_a_file_of_an_earlier_version_without_digests_still_opens(scene, tmp_path):
    path = tmp_path / "schema2.blend"
    shutil.copy(DATA / "schema2_rig.blend", path)
    binding._CACHE.clear()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = next(o for o in bpy.data.objects if binding.has_binding(o))
    assert binding.DIGESTS not in obj[binding.KEY]
    assert binding.open_binding(obj).surface.n_detail == len(obj.data.vertices)
