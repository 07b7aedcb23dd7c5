"""The modal drag as an artist feels it, beside Blender's own stack on the same mesh.

    python scripts/benchmark_drag.py [--meshes armadillo,bunny,rocker-arm-40K] [--faces 1000,2000]
                                     [--moves 60] [--json PATH]

Per mesh (30-60K vertices; ``rocker-arm-40K`` is rocker-arm.obj flat-subdivided once) and proxy
size: the bend scenario's anchors (lowest 10 % of the longest axis) pinned, a handle on the
highest 10 %, and a DragSession that presses R and turns the handle 90 degrees about the view
axis (the view looks along the mesh's shortest axis) in ``--moves`` mouse moves, then confirms.
Figures: move ms (event + depsgraph update: median, p95, slowest), moves that stopped on the
budget before converging, confirm ms, and the release pop: the largest vertex jump between the
mesh after the last move and after the confirm, over the bounding-box diagonal. Blender's stack
(Decimate to the same face count + Hook + Laplacian Deform + Surface Deform) is stepped through
the same 90-degree turn in the same process: its step ms (median, p95), and our p95 over its.
"""

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

import bpy  # noqa: E402  (first: the bpy module makes mathutils importable)
from mathutils import Matrix  # noqa: E402

from bench import blender_stack  # noqa: E402
from bench.meshes import blender_mesh, bundled, subdivide  # noqa: E402
from bench.scenario import bend_scenario  # noqa: E402
from bench.views import AxisView  # noqa: E402

import skin_detach_addon  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import mesh_io  # noqa: E402

RADIUS_PX = 100.0


def mesh(name):
    if name.endswith("-40K"):
        return subdivide(*bundled(name[:-4]), 4)
    return bundled(name)


def percentile(values, q):
    return float(np.percentile(np.asarray(values), q))


def turn_matrix(axis, pivot, angle):
    """(4, 4) rotation by ``angle`` about ``axis`` (3,) through ``pivot`` (3,)."""
    turn = np.array(Matrix.Rotation(angle, 4, axis.tolist()))
    out = turn.copy()
    out[:3, 3] = pivot - turn[:3, :3] @ pivot
    return out


def our_drag(name, points, triangles, faces, moves):
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = blender_mesh(name, points, triangles)
    api.build(obj, target_faces=faces)
    scenario = bend_scenario(points)
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    axis = np.zeros(3)
    axis[int(np.argmin(np.ptp(points, axis=0)))] = 1.0
    view = AxisView(-axis, scale=float(np.linalg.norm(np.ptp(points, axis=0))) / 1000.0)
    centre = np.array(view.to_screen(handle.matrix_world.to_translation()))
    start = tuple(centre + (RADIUS_PX, 0.0))
    session = api.DragSession(obj, handle, view, start)
    session.event("R", "PRESS", start)
    times, unconverged = [], 0
    for k in range(1, moves + 1):
        angle = math.radians(90.0) * k / moves
        mouse = tuple(centre + RADIUS_PX * np.array((math.cos(angle), math.sin(angle))))
        begun = time.perf_counter()
        session.event("MOUSEMOVE", "NOTHING", mouse)
        bpy.context.view_layer.update()
        times.append(1000 * (time.perf_counter() - begun))
        unconverged += not session.last.converged
    shown = mesh_io.read_positions(obj.data).astype(np.float64)
    begun = time.perf_counter()
    session.event("LEFTMOUSE", "PRESS", mouse)
    bpy.context.view_layer.update()
    confirm_ms = 1000 * (time.perf_counter() - begun)
    written = mesh_io.read_positions(obj.data).astype(np.float64)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    pop = float(np.linalg.norm(written - shown, axis=1).max()) / diagonal
    proxy_faces = api.figures(obj)["build"]["proxy_faces"]
    return {"proxy_faces": proxy_faces, "move_ms_median": float(np.median(times)), "move_ms_p95": percentile(times, 95),
            "move_ms_max": float(np.max(times)), "unconverged_moves": int(unconverged), "confirm_ms": confirm_ms,
            "confirm_converged": bool(session.last.converged), "release_pop": pop}, axis, scenario


def stack_drag(points, triangles, faces, axis, scenario, moves):
    bpy.ops.wm.read_homefile(use_empty=True)
    figures, obj, empty = blender_stack.build_stack(points, triangles, scenario, faces)
    if not figures["bound"]:
        return None
    pivot = points[scenario.handle_ids].mean(axis=0)
    times = []
    for k in range(1, moves + 1):
        begun = time.perf_counter()
        empty.matrix_world = Matrix(turn_matrix(axis, pivot, math.radians(90.0) * k / moves).tolist())
        bpy.context.view_layer.update()
        times.append(1000 * (time.perf_counter() - begun))
    return {"step_ms_median": float(np.median(times)), "step_ms_p95": percentile(times, 95)}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", default="armadillo,bunny,rocker-arm-40K")
    parser.add_argument("--faces", default="1000,2000")
    parser.add_argument("--moves", type=int, default=60)
    parser.add_argument("--json")
    args = parser.parse_args()
    if not hasattr(bpy.types.Scene, "skin_detach"):
        skin_detach_addon.register()
    rows = []
    print(f"## Modal drag: R, 90 degrees about the view axis in {args.moves} moves, then confirm\n")
    print("| mesh | vertices | proxy faces | move ms median / p95 / max | unconverged moves | confirm ms "
          "| release pop (diag) | stack step ms median / p95 | our p95 / stack p95 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in args.meshes.split(",") if n]:
        points, triangles = mesh(name)
        for faces in [int(f) for f in args.faces.split(",") if f]:
            ours, axis, scenario = our_drag(name, points, triangles, faces, args.moves)
            stack = stack_drag(points, triangles, ours["proxy_faces"], axis, scenario, args.moves)
            row = dict(mesh=name, vertices=int(points.shape[0]), **ours, stack=stack)
            rows.append(row)
            ratio = f"{ours['move_ms_p95'] / stack['step_ms_p95']:.2f}" if stack else "-"
            stack_text = f"{stack['step_ms_median']:.1f} / {stack['step_ms_p95']:.1f}" if stack else "did not bind"
            print(f"| {name} | {row['vertices']:,} | {ours['proxy_faces']} | {ours['move_ms_median']:.1f} / "
                  f"{ours['move_ms_p95']:.1f} / {ours['move_ms_max']:.1f} | {ours['unconverged_moves']} | "
                  f"{ours['confirm_ms']:.0f} | {ours['release_pop']:.1e} | {stack_text} | {ratio} |", flush=True)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(rows, handle, indent=2)


if __name__ == "__main__":
    main()
