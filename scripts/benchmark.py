"""The benchmark suite in one command: the paper's Table 1, Blender's own tools side by side on
the bend scenario, and scale, printed as Markdown tables.

    python scripts/benchmark.py [--parts table1,side,scale] [--table1 bunny,armadillo,bunny-418K]
                                [--side 50K,300K] [--scale 1.2M,1.8M] [--large 800K,3.2M] [--steps 30]
                                [--preview-above N]
                                [--quick] [--json PATH]

Every mesh runs in its own process (bpy module), so each peak memory figure is that run's own.
``--quick`` is the CI run: the 50K armadillo once in every part, few steps.

Table 1: bundled meshes flat-subdivided towards the paper's sizes, proxies of the paper's
vertex counts (about twice as many faces). Build is the add-on's Build in Blender; a core drag
step is the proxy solve (tolerance of a drag) + rebuild; a Blender drag step adds the write-back
into the mesh and the depsgraph update, as in the modal drag; a handle-set change is the new
factorisation and first solve when the constrained vertices change.

Side by side: the bend scenario (DESIGN section 4) on the armadillo. Set-up: Build against
Decimate to the same face count + Surface Deform bind. Per frame: a drag step against moving
the hook of Hook + Laplacian Deform on the Decimate proxy + Surface Deform on the detail (and,
at 50K only, Laplacian Deform on the whole detail mesh). Quality of the final pose: edge
distortion, dihedral change, handle error, volume change, RMS against libigl ARAP (10
iterations, where libigl is installed, at 50K). Ratios are ours / theirs.

Scale: core build, drag step and peak memory at 1.2M and 1.8M vertices (the armadillo
flat-subdivided twice; 1.8M stands in for the 2M row).

Large: the modal drag at 800K and 3.2M vertices as DragSession drives it with a fake view
(build seconds and the peak memory it adds, ms per mouse move with Blender's depsgraph update,
confirm seconds).
"""

import argparse
import json
import pathlib
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench import blender_stack
from bench.arap import arap_reference
from bench.meshes import SIZES, blender_mesh, subdivided

#: name -> (bundled mesh, flat subdivisions, proxy faces, paper row: model, vertices, proxy vertices, FPS, precompute)
TABLE1 = {
    "bunny": ("bunny", (6,), 1000, ("Detail bunny", "278K", 500, 92, "44 min")),
    "armadillo": ("armadillo", (6,), 2000, ("Armadillo", "332K", 1000, 75, "52 min")),
    "bunny-418K": ("bunny", (3, 4), 10000, ("Max-Planck head", "398K", 5000, 34, "64 min")),
    "armadillo-50K": ("armadillo", (), 1000, ("(CI size)", "-", "-", "-", "-")),
}
PAPER_ELEPHANT = ("Elephant", "157K", 700, 86, "21 min")
DRAG_TOL = 1e-8  # the add-on's api.DRAG_TOL (core rows run without bpy, so it is repeated here)
ARAP_ITERATIONS = 10


def peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def median_ms(times):
    return 1000 * statistics.median(times)


def fresh_scene():
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy


def bind_bend(obj, target_faces):
    """Build ``obj`` through the API and add the bend scenario's anchor and handle; returns
    (build seconds, scenario, handle empty)."""
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    from bench.scenario import bend_scenario

    start = time.perf_counter()
    api.build(obj, target_faces=target_faces)
    build = time.perf_counter() - start
    scenario = bend_scenario(mesh_io.read_positions(obj.data).astype(np.float64))
    api.add_anchor(obj, scenario.anchor_ids)
    return build, scenario, api.add_handle(obj, scenario.handle_ids)


def core_drag(surface, scenario, steps):
    """Median ms of ``steps`` warm-started proxy solves (drag tolerance) + float32 rebuilds."""
    from skin_detach_addon.core import DualLaplacian
    ids, targets = scenario.proxy_constraints(surface)
    solver = DualLaplacian(surface.proxy_vertices, surface.proxy_faces, ids)
    rest = surface.proxy_vertices[ids]
    out = np.empty((surface.n_detail, 3), dtype=np.float32)
    previous, times = None, []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        result = solver.solve(rest + (targets - rest) * (k / steps), initial=previous, tol=DRAG_TOL)
        surface.reconstruct(result.vertices, out=out)
        times.append(time.perf_counter() - start)
        previous = result.vertices
    return median_ms(times)


def blender_drag(obj, handle, scenario, steps):
    """Median ms of ``steps`` handle moves along the bend, each solved, written back and
    evaluated (the modal drag's path: the binding opened once, every step follows the last one
    within the drag's budget); the last pose is settled as the confirm does."""
    import bpy
    from mathutils import Matrix

    from skin_detach_addon.blender.deformation import DRAG_BUDGET_MS, Deformation
    deformation = Deformation(obj)
    rest_world = np.array(handle.matrix_world)
    times = []
    for k in range(1, steps + 1):
        handle.matrix_world = Matrix((scenario.motion(k / steps) @ rest_world).tolist())
        start = time.perf_counter()
        bpy.context.view_layer.update()
        deformation.step(DRAG_TOL, mark=False, follow=True, budget_ms=DRAG_BUDGET_MS)
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    deformation.step(follow=True)
    return median_ms(times)


def handle_set_change_s(surface, scenario):
    """Seconds to factor and solve once for a new set of constrained vertices (a wider handle)."""
    from skin_detach_addon.core import DualLaplacian
    ids, targets = scenario.proxy_constraints(surface)
    wider = np.unique(np.concatenate([ids, surface.proxy_faces[np.isin(surface.proxy_faces, ids).any(axis=1)].ravel()]))
    start = time.perf_counter()
    solver = DualLaplacian(surface.proxy_vertices, surface.proxy_faces, wider)
    moved = surface.proxy_vertices[wider].copy()
    held = np.isin(wider, ids)
    order = np.argsort(ids)  # ids come anchors first, then the handle
    moved[held] = targets[order][np.searchsorted(ids[order], wider[held])]
    solver.solve(moved, tol=DRAG_TOL)
    return time.perf_counter() - start


def table1_row(name, steps):
    from skin_detach_addon.blender import binding
    mesh, parts, faces, paper = TABLE1[name]
    points, triangles = subdivided(mesh, parts)
    fresh_scene()
    baseline = peak_mb()
    obj = blender_mesh(name, points, triangles)
    build, scenario, handle = bind_bend(obj, faces)
    surface = binding.open_binding(obj).surface
    core_ms = core_drag(surface, scenario, steps)
    blender_ms = blender_drag(obj, handle, scenario, steps)
    return {"name": name, "vertices": int(points.shape[0]), "proxy_vertices": int(surface.proxy_vertices.shape[0]),
            "proxy_faces": int(surface.proxy_faces.shape[0]), "build_s": build,
            "core_steps_per_s": 1000 / core_ms, "blender_steps_per_s": 1000 / blender_ms,
            "handle_set_change_s": handle_set_change_s(surface, scenario), "peak_mb": peak_mb(),
            "peak_mb_over_blender": peak_mb() - baseline, "paper": list(paper)}


def quality(rest, deformed, triangles, scenario, arap):
    from bench.quality import dihedral_change, edge_distortion, enclosed_volume, is_closed
    diag = float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))
    handle = np.linalg.norm(deformed[scenario.handle_ids] - scenario.move(rest[scenario.handle_ids]), axis=1)
    row = {"edge_distortion": edge_distortion(rest, deformed, triangles),
           "dihedral_change_deg": dihedral_change(rest, deformed, triangles),
           "handle_error_pct_diag": 100 * float(handle.mean()) / diag,
           "volume_change_pct": (100 * (enclosed_volume(deformed, triangles) / enclosed_volume(rest, triangles) - 1)
                                 if is_closed(triangles) else float("nan"))}
    if arap is not None:
        row["rms_vs_arap_pct_diag"] = 100 * float(np.sqrt(np.mean(np.sum((deformed - arap) ** 2, axis=1)))) / diag
    return row


def side_row(size, steps):
    import bpy  # noqa: F401  (first: the bpy module makes mathutils importable)

    from skin_detach_addon.blender import binding, mesh_io
    points, triangles = subdivided("armadillo", SIZES[size])
    target = 1000
    # Skin Detach
    fresh_scene()
    obj = blender_mesh("armadillo", points, triangles)
    build, scenario, handle = bind_bend(obj, target)
    proxy_faces = int(binding.open_binding(obj).surface.proxy_faces.shape[0])
    ours_ms = blender_drag(obj, handle, scenario, steps)
    arap = arap_reference(points, triangles, scenario, ARAP_ITERATIONS)[0] if size == "50K" else None
    ours_q = quality(points, mesh_io.read_positions(obj.data).astype(np.float64), triangles, scenario, arap)

    # Blender's stack: Decimate copy + Hook + Laplacian Deform, Surface Deform on the detail
    fresh_scene()
    stack, obj, empty = blender_stack.build_stack(points, triangles, scenario, proxy_faces)
    if stack["bound"]:
        stack["frame_ms"] = blender_stack.move_hook(empty, scenario, steps)
        stack["quality"] = quality(points, blender_stack.evaluated_positions(obj), triangles, scenario, arap)
    row = {"size": size, "vertices": int(points.shape[0]), "steps": steps,
           "skin_detach": {"build_s": build, "proxy_faces": proxy_faces, "step_ms": ours_ms, "quality": ours_q},
           "blender_stack": stack}

    if size == "50K":  # the conventional single-resolution route: Laplacian Deform on the detail itself
        fresh_scene()
        whole = blender_mesh("armadillo", points, triangles)
        groups = blender_stack.groups_for(whole, *blender_stack.masks(points.shape[0], scenario))
        empty, bind_s, laplacian = blender_stack.hook_and_laplacian(whole, scenario, groups)
        single = {"bind_s": bind_s, "bound": bool(laplacian.is_bind)}
        if laplacian.is_bind:
            single["frame_ms"] = blender_stack.move_hook(empty, scenario, steps)
            single["quality"] = quality(points, blender_stack.evaluated_positions(whole), triangles, scenario, arap)
        row["laplacian_whole_detail"] = single
    return row


def scale_row(size, steps):
    from skin_detach_addon.core import SkinDetachedSurface
    from bench.scenario import bend_scenario
    points, triangles = subdivided("armadillo", SIZES[size])
    baseline = peak_mb()
    start = time.perf_counter()
    surface = SkinDetachedSurface.build(points, triangles, target_faces=1000)
    build = time.perf_counter() - start
    step = core_drag(surface, bend_scenario(points), steps)
    return {"size": size, "vertices": int(points.shape[0]), "build_s": build, "step_ms": step,
            "peak_mb": peak_mb(), "peak_mb_over_input": peak_mb() - baseline,
            "build_s_per_million": build / (points.shape[0] / 1e6), "step_ms_per_million": step / (points.shape[0] / 1e6)}


def large_row(spec, steps):
    """The modal drag at scale, as DragSession drives it (fake top view): build seconds and the
    peak memory it adds (the Blender mesh itself not counted), median ms per mouse move (solve,
    rebuild, write-back and Blender's depsgraph update), the confirm's seconds and the peak memory
    the drag adds. ``spec`` is a size, or "size@N" to give meshes above N vertices a preview
    (default: the add-on's Preview Above)."""
    import bpy

    from bench.scenario import bend_scenario
    from bench.views import TopView
    from skin_detach_addon import api
    size, _, above = spec.partition("@")
    preview_above = int(above) if above else api.PREVIEW_ABOVE
    points, triangles = subdivided("armadillo", SIZES[size])
    fresh_scene()
    obj = blender_mesh("armadillo", points, triangles)
    del triangles
    bpy.context.view_layer.update()
    before = peak_mb()
    start = time.perf_counter()
    stats = api.build(obj, target_faces=1000, preview_above=preview_above)
    build = time.perf_counter() - start
    build_peak = peak_mb() - before
    scenario = bend_scenario(points)
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    after_build = peak_mb()
    session = api.DragSession(obj, handle, TopView(0.002), (0, 0), preview_above=preview_above)
    times = []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        session.event("MOUSEMOVE", "NOTHING", (10 * k, 5 * k))
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    start = time.perf_counter()
    session.event("RET", "PRESS", (10 * steps, 5 * steps))
    bpy.context.view_layer.update()
    confirm = time.perf_counter() - start
    return {"size": size, "vertices": int(points.shape[0]), "build_s": build, "build_peak_mb_added": build_peak,
            "preview_vertices": stats.get("preview_vertices", 0), "proxy_faces": stats["proxy_faces"],
            "build_stages_s": stats["seconds"], "move_ms": median_ms(times), "confirm_s": confirm,
            "drag_peak_mb_added": peak_mb() - after_build, "peak_mb": peak_mb()}


def run_one(spec, steps):
    part, name = spec.split(":", 1)
    return {"table1": table1_row, "side": side_row, "scale": scale_row, "large": large_row}[part](name, steps)


def in_subprocess(spec, steps):
    env = dict(os.environ)
    env.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="skin_detach_bench_"))
    done = subprocess.run([sys.executable, __file__, "--one", spec, "--steps", str(steps)], capture_output=True,
                          text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"benchmark {spec} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def fmt(value, digits=2):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return f"{value:,.{digits}f}" if isinstance(value, float) else f"{value:,}" if isinstance(value, int) else str(value)


def print_table1(rows):
    print("## Table 1 of the paper, reproduced\n")
    print("| model (ours) | vertices | proxy vertices / faces | build s | core steps/s | Blender steps/s "
          "| handle-set change s | peak MB | paper model | paper vertices | paper proxy vertices | paper FPS "
          "| paper precompute |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        p = r["paper"]
        print(f"| {r['name']} | {r['vertices']:,} | {r['proxy_vertices']:,} / {r['proxy_faces']:,} | {r['build_s']:.2f} "
              f"| {r['core_steps_per_s']:.0f} | {r['blender_steps_per_s']:.0f} | {r['handle_set_change_s']:.3f} "
              f"| {r['peak_mb']:.0f} | {p[0]} | {p[1]} | {p[2]} | {p[3]} | {p[4]} |")
    e = PAPER_ELEPHANT
    print(f"| (no elephant bundled) | | | | | | | | {e[0]} | {e[1]} | {e[2]} | {e[3]} | {e[4]} |")


def print_side(rows):
    for r in rows:
        ours, stack = r["skin_detach"], r["blender_stack"]
        print(f"\n## Side by side, bend scenario, armadillo {r['vertices']:,} vertices, {r['steps']} steps\n")
        print("| method | set-up s | per step / frame ms | edge distortion | dihedral deg | handle error % diag "
              "| volume change % | RMS vs ARAP % diag |")
        print("|---|---|---|---|---|---|---|---|")
        rows_out = [("Skin Detach (Build; drag step with write-back)", ours["build_s"], ours["step_ms"], ours["quality"])]
        if stack.get("bound"):
            rows_out.append((f"Blender: Decimate ({stack['proxy_faces']} faces) + Hook + Laplacian Deform + "
                             f"Surface Deform", stack["decimate_s"] + stack["bind_s"], stack["frame_ms"],
                             stack["quality"]))
        single = r.get("laplacian_whole_detail")
        if single and single.get("bound"):
            rows_out.append(("Blender: Hook + Laplacian Deform on the whole detail", single["bind_s"],
                             single["frame_ms"], single["quality"]))
        for name, setup, ms, q in rows_out:
            print(f"| {name} | {setup:.2f} | {ms:.1f} | {q['edge_distortion']:.3f} | {q['dihedral_change_deg']:.2f} "
                  f"| {q['handle_error_pct_diag']:.2f} | {fmt(q['volume_change_pct'])} "
                  f"| {fmt(q.get('rms_vs_arap_pct_diag'))} |")
        if stack.get("bound"):
            print(f"\nratios ours / Blender stack: set-up {ours['build_s'] / (stack['decimate_s'] + stack['bind_s']):.2f}, "
                  f"per step {ours['step_ms'] / stack['frame_ms']:.2f}")
        else:
            print("\nBlender stack: Surface Deform did not bind")
        if single and single.get("bound"):
            print(f"ratio ours / Laplacian Deform on the detail per step: {ours['step_ms'] / single['frame_ms']:.2f}")


def print_scale(rows):
    print("\n## Scale (core: build, drag step = proxy solve + float32 rebuild, peak memory)\n")
    print("| vertices | build s | build s per million | step ms | step ms per million | peak MB |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['vertices']:,} | {r['build_s']:.2f} | {r['build_s_per_million']:.2f} | {r['step_ms']:.1f} "
              f"| {r['step_ms_per_million']:.1f} | {r['peak_mb']:.0f} |")


def print_large(rows):
    print("\n## The modal drag at scale (DragSession + depsgraph update per mouse move, 1,000-face proxy target)\n")
    print("| vertices | proxy faces | preview vertices | build s | build adds MB to peak | move ms (median) "
          "| confirm s | drag adds MB to peak | peak MB |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['vertices']:,} | {r['proxy_faces']:,} | {r['preview_vertices']:,} | {r['build_s']:.2f} "
              f"| {r['build_peak_mb_added']:.0f} | {r['move_ms']:.1f} | {r['confirm_s']:.2f} "
              f"| {r['drag_peak_mb_added']:.0f} | {r['peak_mb']:.0f} |")
    for r in rows:
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["build_stages_s"].items())
        print(f"\n{r['vertices']:,} vertices, core build stages (s): {stages}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parts", default="table1,side,scale,large")
    parser.add_argument("--large", default="800K,3.2M")
    parser.add_argument("--table1", default="bunny,armadillo,bunny-418K")
    parser.add_argument("--side", default="50K,300K")
    parser.add_argument("--scale", default="1.2M,1.8M")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--preview-above", type=int, help="large part: meshes above this many vertices get a "
                        "preview (default: the add-on's Preview Above)")
    parser.add_argument("--quick", action="store_true", help="CI run: the 50K armadillo once per part, 5 steps")
    parser.add_argument("--json", help="also write every figure to this file")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.steps)))
        return
    if args.quick:
        args.table1, args.side, args.scale, args.large, args.steps = "armadillo-50K", "50K", "50K", "50K", 5
        args.preview_above = 10_000 if args.preview_above is None else args.preview_above  # the preview path too
    parts = [p for p in args.parts.split(",") if p]
    figures = {"machine": {"cores": os.cpu_count(), "python": sys.version.split()[0]}}
    for name in [n for n in args.table1.split(",") if n] if "table1" in parts else []:
        if name not in TABLE1:
            parser.error(f"--table1: expected names from {', '.join(TABLE1)}, got {name!r}")
    if "table1" in parts:
        figures["table1"] = [in_subprocess(f"table1:{n}", args.steps) for n in args.table1.split(",") if n]
        print_table1(figures["table1"])
    if "side" in parts:
        figures["side"] = [in_subprocess(f"side:{s}", args.steps) for s in args.side.split(",") if s]
        print_side(figures["side"])
    if "scale" in parts:
        figures["scale"] = [in_subprocess(f"scale:{s}", args.steps) for s in args.scale.split(",") if s]
        print_scale(figures["scale"])
    if "large" in parts:
        above = "" if args.preview_above is None else f"@{args.preview_above}"
        figures["large"] = [in_subprocess(f"large:{s}{above}", args.steps) for s in args.large.split(",") if s]
        print_large(figures["large"])
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump(figures, handle, indent=2)


if __name__ == "__main__":
    main()
