"""Issue 52, item 5 (headless bpy): a script that deforms a rig and then reorders the mesh's
vertices with bmesh (the counts the same) before the scene is evaluated: Blender reports the two
in one geometry update, which the kept fingerprint took for Skin Detach's own write. The next step
and Reset must see the new order: a refusal naming the topology, and nothing written (Reset wrote
the rest in the old order onto the reordered mesh: a unit sphere's longest edge 0.16 -> 2.00)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import bmesh  # noqa: E402

from blender_support import quad_sphere  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.api import SkinDetachError  # noqa: E402
from skin_detach_addon.blender import mesh_io  # noqa: E402


def longest_edge(mesh):
    edges = np.empty(2 * len(mesh.edges), dtype=np.int32)
    mesh.edges.foreach_get("vertices", edges)
    edges = edges.reshape(-1, 2)
    positions = mesh_io.read_positions(mesh)
    return float(np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1).max())


@pytest.mark.parametrize("step", ["deform", "reset"])
def test_vertices_reordered_after_a_deform_are_refused_as_a_topology_edit(scene, step):
    obj = quad_sphere()
    api.build(obj, target_faces=200)
    z = api.rest_positions(obj)[:, 2]
    api.add_anchor(obj, np.flatnonzero(z < -0.7), mirror="")
    handle = api.add_handle(obj, np.flatnonzero(z > 0.7), mirror="")
    handle.location.x += 0.3
    bpy.context.view_layer.update()
    api.deform(obj)
    # bmesh: reverse the vertex order (same counts), written back before any evaluation.
    work = bmesh.new()
    work.from_mesh(obj.data)
    work.verts.ensure_lookup_table()
    for index, vertex in enumerate(work.verts):
        vertex.index = len(work.verts) - 1 - index
    work.verts.sort()
    work.to_mesh(obj.data)
    work.free()
    bpy.context.view_layer.update()  # one geometry update: the write's and the reorder's
    edge = longest_edge(obj.data)
    before = mesh_io.read_positions(obj.data).copy()
    with pytest.raises(SkinDetachError, match="topology"):
        api.deform(obj) if step == "deform" else api.reset(obj)
    assert np.array_equal(mesh_io.read_positions(obj.data), before)  # nothing written
    assert longest_edge(obj.data) == edge
