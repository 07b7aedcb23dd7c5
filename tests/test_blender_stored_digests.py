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
from skin_detach_addon.core import packed_arrays  # noqa: E402


def reopen(path, name):
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    binding._CACHE.clear()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    return bpy.data.objects[name]


def stored(obj):
    return binding.arrays_of(obj), obj[binding.KEY]


def get(obj, key):
    """The values stored under ``key`` (unpacked, or viewed in their narrow type)."""
    arrays, record = stored(obj)
    narrow = {key + binding.TYPE_SUFFIX: record[key + binding.TYPE_SUFFIX]} if key + binding.TYPE_SUFFIX in record else {}
    return np.array(binding._unpacked({key: arrays[key], **narrow}, key)[key])


def put(obj, key, values):
    """Store ``values`` under ``key`` as the old value was stored (packed, narrow bytes or an array)."""
    arrays, record = stored(obj)
    old = arrays[key]
    del arrays[key]  # a bytes value assigned over one is cut at its first zero byte
    if packed_arrays.is_packed(old):
        arrays[key] = binding._packed(values)
    elif key + binding.TYPE_SUFFIX in record:
        arrays[key] = values.astype(binding.NARROW_TYPES[record[key + binding.TYPE_SUFFIX]]).tobytes()
    else:
        arrays[key] = values.astype(np.array(old).dtype).ravel()


def carrier_to_minus_one(obj):
    put(obj, "carrier", np.full(get(obj, "carrier").shape, -1))


def faces_flipped(obj):
    put(obj, "proxy_faces", get(obj, "proxy_faces").reshape(-1, 3)[:, ::-1].copy())


def vertex_moved(obj):
    points = get(obj, "proxy_vertices").reshape(-1, 3)
    points[0] += 0.05 * np.ptp(points, axis=0).max()
    put(obj, "proxy_vertices", points)


def face_dropped(obj):
    put(obj, "proxy_faces", get(obj, "proxy_faces")[3:])


def rest_nudged(obj):
    rest = get(obj, "rest").astype(np.float32).reshape(-1, 3)
    rest[7] += np.float32(1e-3)
    put(obj, "rest", rest)


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
    local = get(obj, rig_members.LOCAL_REST).astype(np.float32).reshape(-1, 3)
    local[-1] += np.float32(0.01)
    put(obj, rig_members.LOCAL_REST, local)
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
