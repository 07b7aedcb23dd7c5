"""Blender's own stack for the same job, as an artist would set it up (bpy module): a Decimate
copy of the detail as the proxy, Hook + Laplacian Deform on it, Surface Deform on the detail.

Arrays: ``points`` (n, 3), ``triangles`` (f, 3); the scenario is a :class:`bench.scenario.BendScenario`.
"""

import time

import numpy as np

from bench.meshes import blender_mesh


def evaluated_positions(obj):
    """(n, 3) float64 positions of ``obj`` with its modifiers evaluated."""
    import bpy
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    out = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3).astype(np.float64)


def masks(n, scenario):
    """(n,) boolean masks of the scenario's anchors and handle."""
    anchor, handle = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    anchor[scenario.anchor_ids] = True
    handle[scenario.handle_ids] = True
    return anchor, handle


def groups_for(obj, anchor_mask, handle_mask):
    """Vertex groups "held" (anchors and handle) and "hooked" (handle) on ``obj``; their names."""
    held = obj.vertex_groups.new(name="held")
    held.add(np.flatnonzero(anchor_mask | handle_mask).tolist(), 1.0, 'REPLACE')
    hooked = obj.vertex_groups.new(name="hooked")
    hooked.add(np.flatnonzero(handle_mask).tolist(), 1.0, 'REPLACE')
    return "held", "hooked"


def hook_and_laplacian(obj, scenario, groups):
    """Hook (on the handle group) + Laplacian Deform (anchors and handle held) on ``obj``,
    bound at rest; returns the hook empty, the bind seconds and the Laplacian modifier."""
    import bpy
    empty = bpy.data.objects.new(f"{obj.name}_hook", None)
    bpy.context.scene.collection.objects.link(empty)
    hook = obj.modifiers.new("hook", 'HOOK')
    hook.object, hook.vertex_group = empty, groups[1]
    laplacian = obj.modifiers.new("laplacian", 'LAPLACIANDEFORM')
    laplacian.vertex_group = groups[0]
    start = time.perf_counter()
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.laplaciandeform_bind(modifier=laplacian.name)
    bpy.context.view_layer.update()
    return empty, time.perf_counter() - start, laplacian


def move_hook(empty, scenario, steps):
    """Median ms of ``steps`` hook moves along the bend, each followed by the depsgraph update
    (the empty ends at the full pose)."""
    import bpy
    from mathutils import Matrix
    times = []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        empty.matrix_world = Matrix(scenario.motion(k / steps).tolist())
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    return 1000 * float(np.median(times))


def build_stack(points, triangles, scenario, proxy_faces):
    """The detail object with Surface Deform onto a Decimate copy (``proxy_faces`` triangles)
    carrying Hook + Laplacian Deform, in the current (empty) scene. Returns (figures dict: decimate_s,
    bind_s, proxy_faces, bound; the detail object; the hook empty)."""
    import bpy
    obj = blender_mesh("detail", points, triangles)
    proxy = blender_mesh("stack_proxy", points, triangles)
    groups = groups_for(proxy, *masks(points.shape[0], scenario))
    start = time.perf_counter()
    decimate = proxy.modifiers.new("decimate", 'DECIMATE')
    decimate.ratio = proxy_faces / triangles.shape[0]  # Decimate counts triangles
    with bpy.context.temp_override(object=proxy, active_object=proxy):
        bpy.ops.object.modifier_apply(modifier=decimate.name)
    decimate_s = time.perf_counter() - start
    empty, laplacian_bind_s, _ = hook_and_laplacian(proxy, scenario, groups)
    start = time.perf_counter()
    surface = obj.modifiers.new("surface", 'SURFACE_DEFORM')
    surface.target = proxy
    with bpy.context.temp_override(object=obj, active_object=obj):
        try:
            bpy.ops.object.surfacedeform_bind(modifier=surface.name)
        except RuntimeError:  # "Target contains invalid polygons" and the like
            pass
    bpy.context.view_layer.update()
    figures = {"decimate_s": decimate_s, "bind_s": laplacian_bind_s + time.perf_counter() - start,
               "proxy_faces": len(proxy.data.polygons), "bound": bool(surface.is_bound)}
    return figures, obj, empty


def stack_pose(points, triangles, scenario, proxy_faces):
    """(n, 3) detail positions of Blender's stack at the scenario's full pose, or None where
    Surface Deform does not bind; runs in a fresh empty scene."""
    import bpy
    from mathutils import Matrix
    bpy.ops.wm.read_homefile(use_empty=True)
    figures, obj, empty = build_stack(points, triangles, scenario, proxy_faces)
    if not figures["bound"]:
        return None
    empty.matrix_world = Matrix(scenario.motion(1.0).tolist())
    bpy.context.view_layer.update()
    return evaluated_positions(obj)
