"""Scale: the paper's Table 1, Blender's own stack side by side at 300K, and the modal drag up to
3.2M vertices, each timing the add-on's own code paths (api.build; api.add_anchor and
api.add_handle, which prepare their layout through api.prepare; Deformation.step as the drag
steps; api.DragSession as the modal operator drives it), printed as Markdown tables.

    python scripts/benchmark_scale.py [--parts table1,side,large,files] [--table1 bunny,armadillo,bunny-418K]
                                      [--side 50K,300K] [--large 800K,1.2M,1.8M,3.2M] [--steps 30]
                                      [--files 1.2M,1.2M-quads] [--preview-above N] [--quick] [--json PATH]

Every mesh runs in its own process (bpy module), so each peak memory figure is that run's own.
``--quick`` is the CI run: the 50K armadillo once in every part, few steps.

Table 1: bundled meshes flat-subdivided towards the paper's sizes, proxies of the paper's
vertex counts (about twice as many faces). Build is api.build, then the bend's anchor and handle
are added (each add prepares its layout: the factored solver, the rebuild); a drag step is
Deformation.step as the modal drag steps (warm start from the last solve, the drag's tolerance
and budget, write-back and the depsgraph update).

Side by side: the bend scenario (DESIGN section 4) on the armadillo. Set-up: api.build and the
anchor and handle added (their layout prepared) against Decimate to the same face count +
Laplacian Deform and Surface Deform bind. Per frame: a drag step against moving
the hook of Hook + Laplacian Deform on the Decimate proxy + Surface Deform on the detail (and,
at 50K only, Laplacian Deform on the whole detail mesh). Both as ratios ours / theirs. Quality of
the final pose (bench/quality.py bend_quality): edge distortion, dihedral change, creases,
handle error, volume change, RMS against libigl ARAP (10 iterations, where libigl is installed,
at 50K). The last, settled step (a confirm's write: mesh, proxy, stretch attribute) is timed
with the share the stretch attribute takes (``mesh_io.write_stretch``, which waits for the stretch
made beside the positions' write, and writes it: the
stretch is shown, api.show_stretch, so that every confirm writes it, as it does for an artist
who shows it; hidden, a confirm writes none).

Large: the modal drag as DragSession drives it with a fake top view: api.build seconds, its
stages and the peak memory it adds (the Blender mesh itself not counted), the seconds adding the
anchor and handle (Add Anchor, Add Handle: each prepares its layout, so the drag does not),
median ms per mouse move with Blender's depsgraph update, and every confirm's seconds: the first
drag, a second drag of the same handle, and a drag after a second handle is added (Add Handle
timed; the first confirm of that layout), each with the stretch attribute's share.

Files: the bound file against the plain one for a mesh of triangles and one of quads of about the
same size (``--parts files`` runs it alone): the armadillo flat-subdivided (a size of the large
part) or split into quads by Blender's Simple subdivision ("300K-quads", "1.2M-quads",
"4.8M-quads": one, two or three levels, as an artist's quad mesh is), rotated and scaled as an
OBJ import leaves it; api.build, the bend's anchor and handle added, the handle moved by a tenth
of the mesh's width and api.deform; then bench/file_figures.py (the .blend's size against the
same posed mesh saved without its rig).

Every part runs the add-on as an artist has it: registered (bench/addon.py; its handlers
installed), unregistered at the end; the JSON's meta says ``registered``, so does every row.
"""

import argparse
import contextlib
import json
import os
import pathlib
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
from bench.file_figures import file_figures
from bench.meshes import SIZES, blender_mesh, subdivided
from bench.quality import bend_quality
from bench.scale_tables import tables

#: name -> (bundled mesh, flat subdivisions, proxy faces, paper row: model, vertices, proxy vertices, FPS, precompute)
TABLE1 = {
    "bunny": ("bunny", (6,), 1000, ("Detail bunny", "278K", 500, 92, "44 min")),
    "armadillo": ("armadillo", (6,), 2000, ("Armadillo", "332K", 1000, 75, "52 min")),
    "bunny-418K": ("bunny", (3, 4), 10000, ("Max-Planck head", "398K", 5000, 34, "64 min")),
    "armadillo-50K": ("armadillo", (), 1000, ("(CI size)", "-", "-", "-", "-")),
}
ARAP_ITERATIONS = 10


def peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def median_ms(times):
    return 1000 * statistics.median(times)


def fresh_scene():
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    return bpy


@contextlib.contextmanager
def stretch_timer():
    """Time the stretch attribute inside whatever runs in the block: yields a dict whose
    "stretch_s" sums the seconds spent in ``mesh_io.write_stretch`` (``Deformation._write`` calls
    it while the stretch is shown: it waits for the stretch and its colours, made on a pool
    thread while the positions are written, and writes them), the product's own function wrapped."""
    from skin_detach_addon.blender import mesh_io
    spent = {"stretch_s": 0.0}
    original = mesh_io.write_stretch

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            spent["stretch_s"] += time.perf_counter() - start

    mesh_io.write_stretch = timed
    try:
        yield spent
    finally:
        mesh_io.write_stretch = original


def bind_bend(obj, target_faces, preview_above=None):
    """Build ``obj`` through the API (``preview_above``: api.build's, None for the add-on's
    Preview Above) and add the bend scenario's anchor and handle, each add preparing its layout
    (api.prepare), and shows its stretch (untimed: every confirm then writes it). Returns (figures: ``build_s``, ``build_peak_mb_added`` (what the build adds to
    the peak memory), ``handles_s`` (the anchor and the handle added), ``stats`` (api.build's);
    scenario; handle empty)."""
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    from bench.scenario import bend_scenario

    before = peak_mb()
    start = time.perf_counter()
    stats = api.build(obj, target_faces=target_faces,
                      preview_above=api.PREVIEW_ABOVE if preview_above is None else preview_above)
    figures = {"build_s": time.perf_counter() - start, "build_peak_mb_added": peak_mb() - before, "stats": stats}
    scenario = bend_scenario(mesh_io.read_positions(obj.data).astype(np.float64))
    start = time.perf_counter()
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    figures["handles_s"] = time.perf_counter() - start
    api.show_stretch(obj)
    return figures, scenario, handle


def blender_drag(obj, handle, scenario, steps):
    """Median ms of ``steps`` handle moves along the bend, each solved, written back and
    evaluated (the modal drag's path: the binding opened once, every step follows the last one
    within the drag's budget), then the last pose settled and written as a confirm writes it:
    (median step ms, settle dict: seconds, stretch seconds)."""
    import bpy
    from mathutils import Matrix

    from skin_detach_addon.blender.deformation import Deformation
    from skin_detach_addon.core.proxy_solve.proxy_solves import DRAG_BUDGET_UNITS, DRAG_TOL
    deformation = Deformation(obj)
    rest_world = np.array(handle.matrix_world)
    times = []
    for k in range(1, steps + 1):
        handle.matrix_world = Matrix((scenario.motion(k / steps) @ rest_world).tolist())
        start = time.perf_counter()
        bpy.context.view_layer.update()
        deformation.step(DRAG_TOL, mark=False, follow=True, budget=DRAG_BUDGET_UNITS)
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    with stretch_timer() as spent:
        start = time.perf_counter()
        deformation.step(follow=True)
        settle = time.perf_counter() - start
    return median_ms(times), {"settle_s": settle, "stretch_s": spent["stretch_s"],
                              "stretch_pct": 100 * spent["stretch_s"] / settle}


def table1_row(name, steps):
    from skin_detach_addon.blender import binding
    mesh, parts, faces, paper = TABLE1[name]
    points, triangles = subdivided(mesh, parts)
    fresh_scene()
    baseline = peak_mb()
    obj = blender_mesh(name, points, triangles)
    bound, scenario, handle = bind_bend(obj, faces)
    surface = binding.open_binding(obj).surface
    step_ms, _ = blender_drag(obj, handle, scenario, steps)
    return {"name": name, "vertices": int(points.shape[0]), "proxy_vertices": int(surface.proxy_vertices.shape[0]),
            "proxy_faces": int(surface.proxy_faces.shape[0]), "build_s": bound["build_s"],
            "handles_s": bound["handles_s"], "blender_steps_per_s": 1000 / step_ms, "peak_mb": peak_mb(),
            "peak_mb_over_blender": peak_mb() - baseline, "paper": list(paper)}


def side_row(size, steps):
    import bpy  # noqa: F401  (first: the bpy module makes mathutils importable)

    from skin_detach_addon.blender import binding, mesh_io
    points, triangles = subdivided("armadillo", SIZES[size])
    target = 1000
    # Skin Detach
    fresh_scene()
    obj = blender_mesh("armadillo", points, triangles)
    bound, scenario, handle = bind_bend(obj, target)
    setup = bound["build_s"] + bound["handles_s"]
    proxy_faces = int(binding.open_binding(obj).surface.proxy_faces.shape[0])
    ours_ms, settle = blender_drag(obj, handle, scenario, steps)
    arap = arap_reference(points, triangles, scenario, ARAP_ITERATIONS)[0] if size == "50K" else None
    ours_q = bend_quality(points, mesh_io.read_positions(obj.data).astype(np.float64), triangles, scenario, arap)

    # Blender's stack: Decimate copy + Hook + Laplacian Deform, Surface Deform on the detail
    fresh_scene()
    stack, obj, empty = blender_stack.build_stack(points, triangles, scenario, proxy_faces)
    if stack["bound"]:
        stack["frame_ms"] = blender_stack.move_hook(empty, scenario, steps)
        stack["quality"] = bend_quality(points, blender_stack.evaluated_positions(obj), triangles, scenario, arap)
    row = {"size": size, "vertices": int(points.shape[0]), "steps": steps,
           "skin_detach": {"build_s": bound["build_s"], "handles_s": bound["handles_s"], "setup_s": setup,
                           "proxy_faces": proxy_faces, "step_ms": ours_ms, "quality": ours_q, "settle": settle},
           "blender_stack": stack}
    if stack["bound"]:
        row["ratios"] = {"setup": setup / (stack["decimate_s"] + stack["bind_s"]),
                         "step": ours_ms / stack["frame_ms"]}

    if size == "50K":  # the conventional single-resolution route: Laplacian Deform on the detail itself
        fresh_scene()
        whole = blender_mesh("armadillo", points, triangles)
        groups = blender_stack.groups_for(whole, *blender_stack.masks(points.shape[0], scenario))
        empty, bind_s, laplacian = blender_stack.hook_and_laplacian(whole, scenario, groups)
        single = {"bind_s": bind_s, "bound": bool(laplacian.is_bind)}
        if laplacian.is_bind:
            single["frame_ms"] = blender_stack.move_hook(empty, scenario, steps)
            single["quality"] = bend_quality(points, blender_stack.evaluated_positions(whole), triangles, scenario,
                                             arap)
        row["laplacian_whole_detail"] = single
    return row


def modal_drag(session, steps):
    """Drive a new DragSession through ``steps`` mouse moves and a confirm, each followed by
    Blender's depsgraph update: (move seconds (steps,), confirm s, stretch s, seconds waited
    before the confirm for the layout's background preparation)."""
    import bpy

    from skin_detach_addon import api
    times = []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        session.event("MOUSEMOVE", "NOTHING", (10 * k, 5 * k))
        bpy.context.view_layer.update()
        times.append(time.perf_counter() - start)
    # An artist's drag lasts longer than these moves: what a background thread still makes for
    # the layout (a large mesh's own rebuild, see api.preparing) is waited for first, and timed.
    start = time.perf_counter()
    api.finish_preparing(session.obj)
    waited = time.perf_counter() - start
    with stretch_timer() as spent:
        start = time.perf_counter()
        session.event("RET", "PRESS", (10 * steps, 5 * steps))
        bpy.context.view_layer.update()
        confirm = time.perf_counter() - start
    return times, confirm, spent["stretch_s"], waited


def large_row(spec, steps):
    """The modal drag at scale, as DragSession drives it (fake top view): build seconds, stages
    and the peak memory it adds (the Blender mesh itself not counted), the seconds until its
    background job (the full-detail free rebuild,
    :data:`~skin_detach_addon.core.detached_surface.surface.BACKGROUND_ABOVE`) is done,
    Add Anchor's and Add Handle's seconds (each prepares its layout; the background job
    runs beside them), then, once the background job is done, three drags (first drag; the same
    handle again; a second handle's first drag), each with the seconds adding its handle, its
    first and median move ms, the moves' 95th percentile and its confirm's seconds with the
    stretch attribute's share, and api.deform's seconds after a script moves the handle. ``spec``
    is a size, or "size@N" to give meshes above N vertices a preview (default: the add-on's
    Preview Above)."""
    import bpy

    from bench.scenario import bend_scenario
    from bench.views import TopView
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
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
    build_s = time.perf_counter() - start
    build_peak = peak_mb() - before
    scenario = bend_scenario(mesh_io.read_positions(obj.data).astype(np.float64))
    timed = time.perf_counter()
    api.add_anchor(obj, scenario.anchor_ids)
    anchor_s = time.perf_counter() - timed
    timed = time.perf_counter()
    handle = api.add_handle(obj, scenario.handle_ids)
    handle_s = time.perf_counter() - timed
    api.finish_preparing(obj)
    ready_s = time.perf_counter() - start
    api.show_stretch(obj)
    coordinate = points[:, np.argmax(points.max(axis=0) - points.min(axis=0))]
    low, high = coordinate.min(), coordinate.max()
    middle = np.flatnonzero(np.abs(coordinate - (low + high) / 2) <= 0.05 * (high - low))  # a band about the middle
    after_build = peak_mb()
    view = TopView(0.002)
    drags = []
    for name, empty in (("first drag", handle), ("same handle again", handle), ("second handle", None)):
        added = anchor_s + handle_s if name == "first drag" else None
        if empty is None:
            timed = time.perf_counter()
            empty = api.add_handle(obj, middle)
            added = time.perf_counter() - timed
        bpy.context.view_layer.update()  # what came before is evaluated, as a window's redraw does before a drag
        moves, confirm, stretch, waited = modal_drag(api.DragSession(obj, empty, view, (0, 0), preview_above=preview_above),
                                             steps)
        drags.append({"drag": name, "handles_s": added, "first_move_ms": 1000 * moves[0],
                      "move_ms": median_ms(moves), "move_p95_ms": 1000 * float(np.percentile(moves, 95)),
                      "confirm_s": confirm, "stretch_s": stretch, "stretch_pct": 100 * stretch / confirm,
                      "waited_s": waited})
    empty.location.x += 0.01 * float(high - low)
    timed = time.perf_counter()
    api.deform(obj)
    deform_s = time.perf_counter() - timed
    return {"size": size, "vertices": int(points.shape[0]), "build_s": build_s, "ready_s": ready_s,
            "build_peak_mb_added": build_peak, "preview_vertices": stats.get("preview_vertices", 0),
            "proxy_faces": stats["proxy_faces"], "build_stages_s": stats["seconds"], "anchor_s": anchor_s,
            "handle_s": handle_s, "drags": drags, "deform_s": deform_s,
            "drag_peak_mb_added": peak_mb() - after_build, "peak_mb": peak_mb(),
            "files": file_figures(obj)}  # last: it opens files (bench/file_figures.py)


#: Quad meshes of the files part: name -> levels of Simple subdivision of the 50K armadillo.
QUADS = {"300K-quads": 1, "1.2M-quads": 2, "4.8M-quads": 3}


def files_row(spec, steps):
    """The file figures (bench/file_figures.py) of the armadillo bound and posed by the bend, as
    triangles (``spec`` a size of :data:`bench.meshes.SIZES`) or quads (``spec`` in :data:`QUADS`);
    ``steps`` is not used."""
    import bpy

    from bench.scenario import bend_scenario
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    fresh_scene()
    if spec in QUADS:
        obj = blender_mesh("armadillo", *subdivided("armadillo", ()))
        modifier = obj.modifiers.new("simple", 'SUBSURF')
        modifier.subdivision_type, modifier.levels = 'SIMPLE', QUADS[spec]
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.modifier_apply(modifier=modifier.name)
    else:
        obj = blender_mesh("armadillo", *subdivided("armadillo", SIZES[spec]))
    obj.rotation_euler, obj.scale = (np.pi / 2, 0.0, 0.0), (0.5, 0.5, 0.5)  # as an OBJ import leaves it
    bpy.context.view_layer.update()
    stats = api.build(obj, target_faces=1000)
    points = mesh_io.read_positions(obj.data)
    scenario = bend_scenario(points.astype(np.float64))
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    handle.location.x += 0.1 * float(np.ptp(points[:, 0]))
    api.deform(obj)
    sizes = np.empty(len(obj.data.polygons), dtype=np.int32)
    obj.data.polygons.foreach_get("loop_total", sizes)
    return {"size": spec, "faces": "quads" if (sizes == 4).all() else "triangles", "vertices": int(points.shape[0]),
            "preview_vertices": int(stats.get("preview_vertices", 0)), "files": file_figures(obj)}


def run_one(spec, steps):
    part, name = spec.split(":", 1)
    return {"table1": table1_row, "side": side_row, "large": large_row, "files": files_row}[part](name, steps)


def in_subprocess(spec, steps):
    env = dict(os.environ)
    env.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="skin_detach_bench_"))
    done = subprocess.run([sys.executable, __file__, "--one", spec, "--steps", str(steps)], capture_output=True,
                          text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"benchmark {spec} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    from bench import report
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parts", default="table1,side,large,files")
    parser.add_argument("--large", default="800K,1.2M,1.8M,3.2M")
    parser.add_argument("--table1", default="bunny,armadillo,bunny-418K")
    parser.add_argument("--side", default="50K,300K")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--files", default="1.2M,1.2M-quads", help="files part: sizes of triangle meshes and of "
                        f"quad meshes ({', '.join(QUADS)})")
    parser.add_argument("--preview-above", type=int, help="large part: meshes above this many vertices get a "
                        "preview (default: the add-on's Preview Above)")
    parser.add_argument("--quick", action="store_true", help="CI run: the 50K armadillo once per part, 5 steps")
    parser.add_argument("--json", help="also write every figure to this file (with bench/report.py's metadata)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        # The add-on as an artist has it: registered, its handlers installed (bench/addon.py).
        from bench.addon import finish, register
        registered = register()
        print(json.dumps(dict(run_one(args.one, args.steps), registered=registered)))
        finish()
        return
    if args.quick:
        args.table1, args.side, args.large, args.steps, args.files = "armadillo-50K", "50K", "50K", 5, "300K-quads"
        args.preview_above = 10_000 if args.preview_above is None else args.preview_above  # the preview path too
    parts = [p for p in args.parts.split(",") if p]
    unknown = set(parts) - {"table1", "side", "large", "files"}
    if unknown:
        parser.error(f"--parts: expected table1, side, large, files, got {', '.join(sorted(unknown))}")
    for name in [n for n in args.files.split(",") if n] if "files" in parts else []:
        if name not in QUADS and name not in SIZES:
            parser.error(f"--files: expected sizes from {', '.join(SIZES)} or {', '.join(QUADS)}, got {name!r}")
    figures = {}
    for name in [n for n in args.table1.split(",") if n] if "table1" in parts else []:
        if name not in TABLE1:
            parser.error(f"--table1: expected names from {', '.join(TABLE1)}, got {name!r}")
    above = "" if args.preview_above is None else f"@{args.preview_above}"
    for part, names in (("table1", args.table1), ("side", args.side), ("large", args.large), ("files", args.files)):
        if part in parts:
            figures[part] = [in_subprocess(f"{part}:{name}{above if part == 'large' else ''}", args.steps)
                             for name in names.split(",") if name]
            print(tables({part: figures[part]}), end="", flush=True)
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        report.save(args.json, figures, registered=all(row["registered"] for rows in figures.values() for row in rows))


if __name__ == "__main__":
    main()
