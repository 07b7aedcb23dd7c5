"""Headless demo in Blender (bpy module): bind the bundled armadillo, subdivided to ~300K
vertices, to a 1,000-face proxy, pin its base, drag a handle on its top, and write the result.

    python scripts/demo.py [--size 300K] [--target 1000] [--steps 30] [--out out] [--width 1800]

The drag is the bend scenario of DESIGN section 4 (lowest 10 % pinned, highest 10 % turned
45 degrees and shifted by a quarter of the height) in ``--steps`` scripted moves of the handle
empty, each solved and written back into the mesh as in an interactive drag. Writes
``out/demo.blend`` (the rig, deformed), ``out/armadillo_deformed_####.obj`` (through the bake API),
``out/demo.png`` (original, proxy and result side by side) and ``out/demo_figures.json``, and
prints the figures.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench.meshes import ROOT, SIZES, armadillo, blender_mesh
from bench.render import colour_object, render_row

import bpy
from mathutils import Matrix

from skin_detach_addon import api
from bench.scenario import bend_scenario


def drag(obj, handle, scenario, steps):
    """Move the handle empty along the bend in ``steps`` moves, solving after each; ms per step."""
    rest_world = np.array(handle.matrix_world)
    times = []
    for k in range(1, steps + 1):
        handle.matrix_world = Matrix((scenario.motion(k / steps) @ rest_world).tolist())
        start = time.perf_counter()
        api.deform(obj, tol=api.DRAG_TOL, follow=True)  # a drag follows its path
        times.append(1000 * (time.perf_counter() - start))
    settle = api.deform(obj)  # the result to keep, solved to the settle tolerance
    return times, settle


def render(obj, rest, proxy, path, labels, pixels=1800):
    """Original (rest), proxy and result side by side (bench.render.render_row)."""
    scene = bpy.context.scene
    extent = float(np.ptp(rest, axis=0).max())
    original = bpy.data.objects.new("original", obj.data.copy())
    original.data.vertices.foreach_set("co", rest.astype(np.float32).ravel())
    original.data.update()
    cage = bpy.data.objects.new("proxy_view", proxy.data.copy())
    wire = bpy.data.objects.new("proxy_wire", cage.data.copy())  # its own mesh: its own colour
    result = bpy.data.objects.new("result", obj.data.copy())
    for item in (original, cage, wire, result):
        scene.collection.objects.link(item)
        item.matrix_world = obj.matrix_world.copy()
    wire.modifiers.new("wire", 'WIREFRAME').thickness = 0.004 * extent
    for item, colour in ((original, (0.72, 0.72, 0.72, 1)), (cage, (0.95, 0.62, 0.3, 1)),
                         (wire, (0.15, 0.1, 0.05, 1)), (result, (0.45, 0.65, 0.9, 1))):
        colour_object(item, colour)
    obj.hide_render = True
    return render_row([[original], [cage, wire], [result]], labels, path, pixels)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", default="300K", choices=list(SIZES))
    parser.add_argument("--target", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--out", default=str(ROOT / "out"))
    parser.add_argument("--width", type=int, default=1800, help="picture width in pixels")
    args = parser.parse_args()
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)

    bpy.ops.wm.read_homefile(use_empty=True)
    points, triangles = armadillo(args.size)
    points = points[:, [0, 2, 1]] * [1, -1, 1]  # OBJ's Y-up to Blender's Z-up
    obj = blender_mesh("armadillo", points, triangles)
    print(f"detail mesh: armadillo.obj subdivided to {points.shape[0]:,} vertices, {triangles.shape[0]:,} triangles")
    start = time.perf_counter()
    stats = api.build(obj, target_faces=args.target)
    build_s = time.perf_counter() - start
    print(f"build: {build_s:.2f} s (core {stats['seconds']['total']:.2f} s) -> proxy of "
          f"{stats['proxy_vertices']:,} vertices / {stats['proxy_faces']:,} faces, least angle "
          f"{stats['proxy_least_angle']:.1f} degrees, {stats['proxy_slivers']} faces under 10 or over 170")

    scenario = bend_scenario(points)
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    times, settle = drag(obj, handle, scenario, args.steps)
    median = float(np.median(times))
    print(f"drag: {args.steps} steps, median {median:.1f} ms per step in Blender (solve + rebuild + write-back), "
          f"{1000 / median:.0f} steps per second; settled in {settle['iterations']} iterations "
          f"({'converged' if settle['converged'] else 'stopped: the iteration cycles'}), "
          f"proxy volume change {100 * settle['volume_change']:+.3f} %")

    bpy.ops.wm.save_as_mainfile(filepath=str(out / "demo.blend"), copy=True)
    obj_file = api.bake(obj, [bpy.context.scene.frame_current], into=api.FILES,
                        path=str(out / "armadillo_deformed_####.obj"))[0]["output"]
    rest = api.rest_positions(obj).astype(np.float64)
    start = time.perf_counter()
    engine = render(obj, rest, api.proxy_of(obj), out / "demo.png", [
        f"original: {points.shape[0]:,} vertices", f"proxy: {stats['proxy_faces']:,} faces",
        f"result: {median:.0f} ms per drag step"], args.width)
    print(f"render: {engine}, {time.perf_counter() - start:.1f} s")
    figures = {"detail_vertices": int(points.shape[0]), "proxy_faces": int(stats["proxy_faces"]),
               "build_seconds": build_s, "drag_step_ms_median": median, "drag_steps": args.steps,
               "settle_iterations": settle["iterations"], "settle_converged": settle["converged"],
               "proxy_volume_change": settle["volume_change"], "proxy_least_angle": stats["proxy_least_angle"],
               "proxy_slivers": stats["proxy_slivers"]}
    (out / "demo_figures.json").write_text(json.dumps(figures, indent=2))
    print(f"wrote {out / 'demo.blend'}, {obj_file}, {out / 'demo.png'}, {out / 'demo_figures.json'}")


if __name__ == "__main__":
    main()
