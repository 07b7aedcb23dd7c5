"""Headless bpy: the same mesh rigs the same way every time (issue 36: a 32x16 UV sphere at 200
faces, the cap z > 0.8 as a handle, gave another proxy and another empty on every build).
Blender numbers the faces of a new UV sphere differently on every call, so two spheres made in a
row are the same mesh stored in two orders."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, handles, mesh_io  # noqa: E402


def sphere_rig(name):
    """A new 32x16 UV sphere built at 200 faces, its cap z > 0.8 a handle: (object, handle)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    obj = bpy.context.active_object
    obj.name = name
    api.build(obj, target_faces=200)
    handle = api.add_handle(obj, np.flatnonzero(mesh_io.read_positions(obj.data)[:, 2] > 0.8), mirror="")
    return obj, handle


def rig_arrays(obj, handle):
    """Every array of a rig: the binding's (its fingerprint aside: the digest of the face list as
    stored), the proxy object's mesh, the handle's transform, rest frame and held proxy vertices."""
    surface = binding.open_binding(obj).surface
    out = {key: np.asarray(value) for key, value in surface.to_arrays().items() if key not in ("stats", "fingerprint")}
    proxy = binding.proxy_of(obj)
    out["proxy_mesh_positions"] = mesh_io.read_positions(proxy.data)
    out["proxy_mesh_triangles"] = mesh_io.read_triangles(proxy.data)
    bpy.context.view_layer.update()  # matrix_world follows a new matrix_basis only then
    out["empty_matrix_basis"] = np.array(handle.matrix_basis)
    out["empty_matrix_world"] = np.array(handle.matrix_world)
    # A copy: rest_local_of views the empty's ID property, which a Rebuild replaces.
    out["empty_rest_local"] = handles.rest_local_of(handle).copy()
    out["empty_proxy_ids"] = handles.proxy_ids_of(handle)
    return {key: np.array(value, copy=True) for key, value in out.items()}


def assert_identical(first, second):
    assert sorted(first) == sorted(second)
    for key in first:
        assert first[key].tobytes() == second[key].tobytes(), f"{key} differs"


def test_two_spheres_and_a_rebuild_rig_identically(scene):
    first, first_handle = sphere_rig("first")
    second, second_handle = sphere_rig("second")
    reference = rig_arrays(first, first_handle)
    assert_identical(reference, rig_arrays(second, second_handle))

    for obj in (first, second):  # the same pull gives the same shape, bit for bit
        [handle] = api.handles_of(obj)
        handle.location.z += 0.3
        handle.rotation_euler.x = 0.4
        api.deform(obj)
    assert mesh_io.read_positions(first.data).tobytes() == mesh_io.read_positions(second.data).tobytes()

    api.reset(first)  # an artist's Rebuild: the same proxy and skin, the handle back at rest where it was
    api.build(first, target_faces=200)
    [handle] = api.handles_of(first)
    assert_identical(reference, rig_arrays(first, handle))
