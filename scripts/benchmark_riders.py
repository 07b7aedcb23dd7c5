"""Riders and several objects: loose parts on a body follow it (issue 51), beside Blender's stack.

    python scripts/benchmark_riders.py [--meshes armadillo,cow,homer,spot] [--faces 1000] [--moves 20]
                                       [--at-least 25000] [--several 300K] [--json PATH]

Per mesh (flat-subdivided to at least 25,000 vertices), the parts of bench/riders.py are placed on
the body: an eye half sunk at the top, a plate lying on the middle, a bracelet round the limb's
forearm and a prop standing apart. Two set-ups of the same parts: joined into the body's mesh
(loose parts of one mesh) and, when the add-on builds several objects into one rig, as separate
objects. Each is rigged as the bend scenario (bench/scenario.py) rigs the body: the body's lowest
10 % anchored, its highest 10 % a handle (the parts are not selected), then posed two ways: the
bend (the handle's empty moved to the full pose, api.deform) and a drag (api.DragSession, as the
modal operator runs it: the mouse moves the handle by the bend's shift in ``--moves`` steps, then
Enter).

``--several``: a character of the armadillo at that size with two eyes, a plate and a bracelet
as separate objects, built as one rig and as the same meshes joined (the build's time against the
joined mesh's, goal 1.2x at most), a drag's moves (goal: 16 ms median) and how far the objects
end from the joined mesh's pose.

Figures per part and pose (bench/riders.py's follow_figures): how far the part ends from where
the surface under it carried it (its vertices moved by the mean motion of the 8 nearest body
vertices; mean and max over its vertices, over the body's diagonal), its own edge distortion
against that of the body's edges under it; per rig: the handle's and anchors' errors (over the
diagonal), the build seconds, a drag move's median ms and the confirm's ms. Blender's stack: the
body decimated to the same face count carrying Hook + Laplacian Deform, and Surface Deform on the
body and on each part (as separate objects) bound to it, in the same run: the same figures at the
bend, its bind and step times.

The add-on runs as an artist has it: registered (bench/addon.py; its handlers installed),
unregistered at the end; the JSON's meta says ``registered``.
"""

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the repository root: bench, the add-on

from bench import report  # noqa: E402
from bench.meshes import blender_mesh, named, split_edges  # noqa: E402
from bench.riders import KINDS, TABLE_HEAD, body_parts, follow_figures, joined, table_lines  # noqa: E402
from bench.scenario import bend_scenario  # noqa: E402

MESHES = "armadillo,cow,homer,spot"


def body(name, at_least=25_000):
    points, triangles = named(name)
    while points.shape[0] < at_least:
        points, triangles = split_edges(points, triangles, 2)
    return points.astype(np.float32).astype(np.float64), triangles


def several_objects_supported():
    from skin_detach_addon import api
    return hasattr(api, "members")


def ours(name, points, triangles, ranges, scenario, faces, moves, separate):
    """The add-on's figures: dict with ``bend`` and ``drag`` per-part figures, handle/anchor errors,
    build seconds, move ms median and confirm ms."""
    import bpy
    from mathutils import Matrix

    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    bpy.ops.wm.read_homefile(use_empty=True)
    if separate:
        objects = [blender_mesh(kind, points[ids], _local(triangles, ids)) for kind, ids in ranges.items()]
        start = time.perf_counter()
        api.build(objects, target_faces=faces)
        build_s = time.perf_counter() - start
        owner = objects[0]

        def read():
            out = np.empty_like(points)
            for obj, ids in zip(objects, ranges.values()):
                out[ids] = mesh_io.read_positions(obj.data)
            return out
        first = api.member_ranges(owner)[owner][0]  # the body's combined ids (the owner comes first)
        anchor_ids, handle_ids = scenario.anchor_ids + first, scenario.handle_ids + first
    else:
        owner = blender_mesh(name, points, triangles)
        start = time.perf_counter()
        api.build(owner, target_faces=faces)
        build_s = time.perf_counter() - start

        def read():
            return mesh_io.read_positions(owner.data).astype(np.float64)
        anchor_ids, handle_ids = scenario.anchor_ids, scenario.handle_ids
    stats = api.figures(owner)["build"]
    api.add_anchor(owner, anchor_ids)
    handle = api.add_handle(owner, handle_ids)
    rest_world = np.array(handle.matrix_world)
    handle.matrix_world = Matrix((scenario.motion() @ rest_world).tolist())
    api.deform(owner)
    bent = read()
    out = {"build_s": build_s, "parts": stats.get("parts", 1), "riders": stats.get("riders", 0),
           "bend": follow_figures(points, bent, triangles, ranges), **_held(points, bent, scenario)}
    api.reset(owner)
    handle.matrix_world = Matrix(rest_world.tolist())
    bpy.context.view_layer.update()
    times, out["confirm_ms"] = drag_by_shift(owner, handle, scenario, points, moves)
    dragged = read()
    out["drag"] = follow_figures(points, dragged, triangles, ranges)
    out["move_ms_median"] = float(np.median(times))
    moved = np.array(handle.matrix_world) @ np.linalg.inv(rest_world)
    expected = points[scenario.handle_ids] @ moved[:3, :3].T + moved[:3, 3]
    out["drag_handle_error"] = float(np.abs(dragged[scenario.handle_ids] - expected).max()
                                     / np.linalg.norm(np.ptp(points, axis=0)))
    return out


def drag_by_shift(owner, handle, scenario, points, moves):
    """A drag as the modal operator runs it (api.DragSession): the mouse moves ``handle`` by the
    scenario's shift in ``moves`` steps, seen along the shortest axis of ``points``, then Enter.
    Returns (each move's ms, the confirm's ms)."""
    import bpy

    from bench.views import AxisView
    from skin_detach_addon import api
    extent = np.ptp(points, axis=0)
    view = AxisView(-np.eye(3)[int(np.argmin(extent))], scale=float(np.linalg.norm(extent)) / 1000.0)
    origin = handle.matrix_world.to_translation()
    centre = np.array(view.to_screen(origin))
    target = np.array(view.to_screen(origin + type(origin)(scenario.shift.tolist())))
    session = api.DragSession(owner, handle, view, tuple(centre))
    times, mouse = [], tuple(centre)
    for k in range(1, moves + 1):
        mouse = tuple(centre + (target - centre) * k / moves)
        start = time.perf_counter()
        session.event("MOUSEMOVE", "NOTHING", mouse)
        bpy.context.view_layer.update()
        times.append(1000 * (time.perf_counter() - start))
    start = time.perf_counter()
    session.event("RET", "PRESS", mouse)
    bpy.context.view_layer.update()
    return times, 1000 * (time.perf_counter() - start)


def _local(triangles, ids):
    """The faces of ``triangles`` among vertices ``ids`` (consecutive), renumbered from 0."""
    inside = (triangles >= ids[0]) & (triangles <= ids[-1])
    return triangles[inside.all(axis=1)] - ids[0]


def _held(points, deformed, scenario):
    diag = float(np.linalg.norm(np.ptp(points, axis=0)))
    handle = np.abs(deformed[scenario.handle_ids] - scenario.move(points[scenario.handle_ids])).max() / diag
    anchor = np.abs(deformed[scenario.anchor_ids] - points[scenario.anchor_ids]).max() / diag
    return {"handle_error": float(handle), "anchor_error": float(anchor)}


def stack(points, triangles, ranges, scenario, faces):
    """Blender's stack: the body decimated to ``faces`` with Hook + Laplacian Deform, Surface
    Deform on the body and on each part (separate objects) bound to it; the bend's figures."""
    import bpy
    from mathutils import Matrix

    from bench.blender_stack import evaluated_positions, groups_for, hook_and_laplacian, masks
    bpy.ops.wm.read_homefile(use_empty=True)
    body_ids = ranges["body"]
    body_points, body_triangles = points[body_ids], _local(triangles, body_ids)
    proxy = blender_mesh("stack_proxy", body_points, body_triangles)
    groups = groups_for(proxy, *masks(body_ids.size, scenario))
    start = time.perf_counter()
    decimate = proxy.modifiers.new("decimate", 'DECIMATE')
    decimate.ratio = faces / body_triangles.shape[0]
    with bpy.context.temp_override(object=proxy, active_object=proxy):
        bpy.ops.object.modifier_apply(modifier=decimate.name)
    empty, _, _ = hook_and_laplacian(proxy, scenario, groups)
    objects = {}
    for kind, ids in ranges.items():
        obj = blender_mesh(f"stack_{kind}", points[ids], _local(triangles, ids))
        modifier = obj.modifiers.new("surface", 'SURFACE_DEFORM')
        modifier.target = proxy
        with bpy.context.temp_override(object=obj, active_object=obj):
            try:
                bpy.ops.object.surfacedeform_bind(modifier=modifier.name)
            except RuntimeError:
                pass
        objects[kind] = (obj, modifier)
    bpy.context.view_layer.update()
    set_up_s = time.perf_counter() - start
    if not all(modifier.is_bound for _, modifier in objects.values()):
        return None
    start = time.perf_counter()
    empty.matrix_world = Matrix(scenario.motion(1.0).tolist())
    bpy.context.view_layer.update()
    deformed = np.empty_like(points)
    for kind, ids in ranges.items():
        deformed[ids] = evaluated_positions(objects[kind][0])
    step_ms = 1000 * (time.perf_counter() - start)
    return {"set_up_s": set_up_s, "step_ms": step_ms, "bend": follow_figures(points, deformed, triangles, ranges),
            **_held(points, deformed, scenario)}


def rows_for(name, faces, moves, at_least=25_000):
    body_points, body_triangles = body(name, at_least)
    points, triangles, ranges = joined((body_points, body_triangles), body_parts(body_points, body_triangles, KINDS))
    scenario = bend_scenario(body_points)
    rows = [dict(mesh=name, setup="one mesh", vertices=int(points.shape[0]),
                 **ours(name, points, triangles, ranges, scenario, faces, moves, separate=False))]
    if several_objects_supported():
        rows.append(dict(mesh=name, setup="separate objects", vertices=int(points.shape[0]),
                         **ours(name, points, triangles, ranges, scenario, faces, moves, separate=True)))
    blender = stack(points, triangles, ranges, scenario, faces)
    rows.append(dict(mesh=name, setup="Blender stack", vertices=int(points.shape[0]),
                     **(blender if blender is not None else {"unbound": True})))
    return rows


def several_objects(size, faces, moves):
    """A character of the armadillo at ``size`` (bench.meshes.SIZES) and four accessories as separate
    objects (two eyes, a plate, a bracelet: bench/riders.py's, the second eye mirrored across the
    middle axis), built as one rig and as the same meshes joined; the bend's anchor and handle; a
    drag of ``moves`` mouse moves. Dict: vertices, build seconds of each and their ratio, the
    drag's move median and p95 ms and its confirm ms (the rig of several objects), and the largest
    difference between the objects' bent positions and the joined mesh's (over the diagonal)."""
    import bpy
    from mathutils import Matrix

    from bench.meshes import armadillo
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    body_points, body_triangles = armadillo(size)
    parts = body_parts(body_points, body_triangles, ("eye", "plate", "bracelet"))
    extent = np.ptp(body_points, axis=0)
    middle = int(np.argsort(extent)[1])
    mirrored = parts["eye"][0].copy()
    centre = body_points[:, middle].mean()
    mirrored[:, middle] = 2 * centre - mirrored[:, middle]
    parts["eye2"] = (mirrored, parts["eye"][1][:, ::-1])
    # Joined in the rig's order (the owner, then the others by name), so both builds see one mesh.
    parts = dict(sorted(parts.items()))
    points, triangles, ranges = joined((body_points, body_triangles), parts)
    scenario = bend_scenario(body_points)
    diag = float(np.linalg.norm(np.ptp(points, axis=0)))
    out = {"size": size, "vertices": int(points.shape[0]), "objects": len(ranges)}
    bent = {}
    for setup in ("joined", "separate"):
        bpy.ops.wm.read_homefile(use_empty=True)
        if setup == "joined":
            objects = [blender_mesh("character", points, triangles)]
        else:  # named so that the rig's order (the owner, then by name) is the joined mesh's
            objects = [blender_mesh(f"{k}_{kind}", points[ids], _local(triangles, ids))
                       for k, (kind, ids) in enumerate(ranges.items())]
        start = time.perf_counter()
        api.build(objects if setup == "separate" else objects[0], target_faces=faces)
        out[f"build_{setup}_s"] = time.perf_counter() - start
        owner = objects[0]
        api.add_anchor(owner, scenario.anchor_ids)
        handle = api.add_handle(owner, scenario.handle_ids)
        rest_world = np.array(handle.matrix_world)
        handle.matrix_world = Matrix((scenario.motion() @ rest_world).tolist())
        api.deform(owner)
        positions = np.empty_like(points)
        for obj, ids in zip(objects, ranges.values()) if setup == "separate" else [(owner, np.arange(points.shape[0]))]:
            positions[ids] = mesh_io.read_positions(obj.data)
        bent[setup] = positions
        if setup == "separate":
            api.reset(owner)
            handle.matrix_world = Matrix(rest_world.tolist())
            bpy.context.view_layer.update()
            times, confirm_ms = drag_by_shift(owner, handle, scenario, points, moves)
            out.update(confirm_ms=confirm_ms, move_ms_median=float(np.median(times)),
                       move_ms_p95=float(np.percentile(times, 95)))
    out["build_ratio"] = out["build_separate_s"] / out["build_joined_s"]
    out["separate_vs_joined_diag"] = float(np.abs(bent["separate"] - bent["joined"]).max() / diag)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", default=MESHES)
    parser.add_argument("--faces", type=int, default=1000)
    parser.add_argument("--moves", type=int, default=20)
    parser.add_argument("--at-least", type=int, default=25_000, help="flat-subdivide smaller bodies to this many vertices")
    parser.add_argument("--several", default="300K", help="the character of several objects: the armadillo's "
                        "size (bench.meshes.SIZES; '' for none)")
    parser.add_argument("--json")
    args = parser.parse_args()
    from bench.addon import finish, register
    registered = register()  # the add-on as an artist has it (bench/addon.py)
    print("## Riders and several objects\n")
    print(TABLE_HEAD)
    rows = []
    for name in [n for n in args.meshes.split(",") if n]:
        for row in rows_for(name, args.faces, args.moves, args.at_least):
            rows.append(row)
            print("\n".join(table_lines(row)), flush=True)
    figures = {"riders": rows}
    if args.several and several_objects_supported():
        print("\n## A character of several objects\n")
        print("| body size | vertices | objects | build joined s | build as objects s | ratio (goal <= 1.2) | "
              "move ms median / p95 (goal <= 16 median) | confirm ms | objects against the joined mesh (diag) |")
        print("|---|---|---|---|---|---|---|---|---|")
        row = several_objects(args.several, args.faces, args.moves)
        figures["several"] = row
        print(f"| {row['size']} | {row['vertices']:,} | {row['objects']} | {row['build_joined_s']:.2f} | "
              f"{row['build_separate_s']:.2f} | {row['build_ratio']:.2f} | {row['move_ms_median']:.1f} / "
              f"{row['move_ms_p95']:.1f} | {row['confirm_ms']:.0f} | {row['separate_vs_joined_diag']:.1e} |", flush=True)
    if args.json:
        report.save(args.json, figures, registered=registered)
    finish()


if __name__ == "__main__":
    main()
