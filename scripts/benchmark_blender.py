"""Drag speed inside Blender (bpy module), against Blender's own stack in the same run.

    python scripts/benchmark_blender.py [--levels 1] [--target 1000] [--steps 30] [--json PATH]

The detail mesh is armadillo.obj after ``--levels`` of Subdivision Surface (1: ~300K
vertices). Skin Detach: Build, an anchor on the lowest 10 % of the longest axis, a handle on
the highest 10 %, then a drag session fed ``--steps`` mouse moves; one step is solve + rebuild
+ write-back + depsgraph update. Blender's stack for the same job: a Decimate copy of the
detail with ``--target`` faces, a Hook on the handle vertices and Laplacian Deform (anchors and
handle as its group) on it, Surface Deform on the detail bound to it; one frame is moving the
hook empty and the depsgraph update that evaluates all of it.
"""

import argparse
import json
import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="skin_detach_bench_"))

import numpy as np  # noqa: E402

from mesh_tools import DATA, ROOT  # noqa: E402

import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402

sys.path.insert(0, str(ROOT))
import skin_detach_addon  # noqa: E402
from skin_detach_addon.blender import handles, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import DragSession  # noqa: E402


class ScreenPlane:
    """Orthographic view looking down -Z, one pixel = ``scale`` world units (no window here)."""

    direction = Vector((0.0, 0.0, -1.0))

    def __init__(self, scale):
        self.scale = scale

    def to_world(self, mouse, depth_point):
        return Vector((mouse[0] * self.scale, mouse[1] * self.scale, depth_point[2]))

    def to_screen(self, point):
        return Vector((point[0] / self.scale, point[1] / self.scale))


def activate(obj):
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def detail_mesh(levels):
    bpy.ops.wm.obj_import(filepath=str(DATA / "armadillo.obj"))
    obj = bpy.context.selected_objects[0]
    activate(obj)
    if levels:
        modifier = obj.modifiers.new("subsurf", 'SUBSURF')
        modifier.levels = levels
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    return obj


def bands(obj, fraction=0.10):
    positions = mesh_io.read_positions(obj.data)
    world = np.array(obj.matrix_world)
    positions = positions @ world[:3, :3].T + world[:3, 3]
    extent = positions.max(axis=0) - positions.min(axis=0)
    longest = int(np.argmax(extent))
    low, high = positions[:, longest].min(), positions[:, longest].max()
    span = high - low
    return (positions[:, longest] <= low + fraction * span), (positions[:, longest] >= high - fraction * span), \
        float(np.linalg.norm(extent))


def skin_detach(obj, target, steps):
    bpy.context.scene.skin_detach.target_faces = target
    start = time.perf_counter()
    bpy.ops.skin_detach.build()
    build = time.perf_counter() - start
    anchors, handle_mask, diagonal = bands(obj)
    obj.data.vertices.foreach_set("select", anchors)
    bpy.ops.skin_detach.add_anchor()
    obj.data.vertices.foreach_set("select", handle_mask)
    bpy.ops.skin_detach.add_handle()
    handle = [e for e in handles.handles_of(obj) if e[handles.TAG]["kind"] == handles.HANDLE][0]
    bpy.context.view_layer.update()
    session = DragSession(obj, handle, ScreenPlane(diagonal / 1000.0), (0, 0))
    times = []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        session.event("MOUSEMOVE", "NOTHING", (5 * k, 3 * k))
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    session.confirm()
    return {"build_s": build, "step_ms_median": 1000 * statistics.median(times),
            "solve_rebuild_write_ms_median": statistics.median(session.step_ms),
            "proxy_faces": len(session.deformation.proxy.data.polygons)}


def blender_stack(obj, target, steps):
    anchors, handle_mask, diagonal = bands(obj)
    start = time.perf_counter()
    proxy = obj.copy()
    proxy.data = obj.data.copy()
    proxy.name = "stack_proxy"
    bpy.context.scene.collection.objects.link(proxy)
    group = proxy.vertex_groups.new(name="held")
    group.add(np.flatnonzero(anchors | handle_mask).tolist(), 1.0, 'REPLACE')
    hooked = proxy.vertex_groups.new(name="hooked")
    hooked.add(np.flatnonzero(handle_mask).tolist(), 1.0, 'REPLACE')
    decimate = proxy.modifiers.new("decimate", 'DECIMATE')
    triangles = np.empty(len(obj.data.polygons), dtype=np.int32)
    obj.data.polygons.foreach_get("loop_total", triangles)
    decimate.ratio = target / float((triangles - 2).sum())  # Decimate counts triangles
    activate(proxy)
    bpy.ops.object.modifier_apply(modifier=decimate.name)
    decimate_s = time.perf_counter() - start

    empty = bpy.data.objects.new("stack_hook", None)
    bpy.context.scene.collection.objects.link(empty)
    hook = proxy.modifiers.new("hook", 'HOOK')
    hook.object = empty
    hook.vertex_group = "hooked"
    laplacian = proxy.modifiers.new("laplacian", 'LAPLACIANDEFORM')
    laplacian.vertex_group = "held"
    with bpy.context.temp_override(object=proxy, active_object=proxy):
        bpy.ops.object.laplaciandeform_bind(modifier=laplacian.name)
    start = time.perf_counter()
    bpy.context.view_layer.update()
    surface = obj.modifiers.new("surface", 'SURFACE_DEFORM')
    surface.target = proxy
    with bpy.context.temp_override(object=obj, active_object=obj):
        bpy.ops.object.surfacedeform_bind(modifier=surface.name)
    bpy.context.view_layer.update()
    bind_s = time.perf_counter() - start
    if not surface.is_bound:
        return {"decimate_s": decimate_s, "error": "Surface Deform did not bind (invalid target polygons)"}
    times = []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        empty.location = Vector((5 * k, 3 * k, 0.0)) * (diagonal / 1000.0)
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    moved = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    evaluated = len(moved.data.vertices)
    return {"decimate_s": decimate_s, "bind_s": bind_s, "frame_ms_median": 1000 * statistics.median(times),
            "proxy_faces": len(proxy.data.polygons), "evaluated_vertices": evaluated}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--levels", type=int, default=1)
    parser.add_argument("--target", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--json")
    args = parser.parse_args()
    skin_detach_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = detail_mesh(args.levels)
    vertices = len(obj.data.vertices)
    ours = skin_detach(obj, args.target, args.steps)

    bpy.ops.wm.read_homefile(use_empty=True)
    obj = detail_mesh(args.levels)
    stack = blender_stack(obj, args.target, args.steps)

    print(f"## Drag inside Blender: armadillo.obj + {args.levels} level(s) of Subdivision Surface "
          f"({vertices:,} vertices), proxy target {args.target} faces, {args.steps} steps\n")
    print("| method | set-up | per step / frame (median) |")
    print("|---|---|---|")
    print(f"| Skin Detach (solve + rebuild + write-back + depsgraph update) | build {ours['build_s']:.1f} s "
          f"({ours['proxy_faces']} proxy faces) | {ours['step_ms_median']:.1f} ms "
          f"(of which solve + rebuild + write {ours['solve_rebuild_write_ms_median']:.1f} ms) |")
    if "error" in stack:
        print(f"| Blender stack | Decimate {stack['decimate_s']:.1f} s | {stack['error']} |")
    else:
        print(f"| Blender stack (Hook + Laplacian Deform on Decimate proxy, Surface Deform on detail) | "
              f"Decimate {stack['decimate_s']:.1f} s + binds {stack['bind_s']:.1f} s ({stack['proxy_faces']} faces) | "
              f"{stack['frame_ms_median']:.1f} ms |")
        print(f"\nratio Blender stack / Skin Detach per step: {stack['frame_ms_median'] / ours['step_ms_median']:.2f}x")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump({"vertices": vertices, "skin_detach": ours, "blender_stack": stack}, handle, indent=2)


if __name__ == "__main__":
    main()
