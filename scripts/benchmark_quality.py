"""Deformation quality and solver trust, per mesh: the pose suite and the bend scenario.

    python scripts/benchmark_quality.py [--meshes armadillo,cow,spot,...] [--at-least 25000] [--poses 300]
                                        [--pose-meshes armadillo,spot,cow] [--faces 1000] [--json PATH]

Pose suite (bench/poses.py): random handle poses (axis random, up to 90 degrees, shift up to 10 %
of the diagonal), each solved warm (from the previous pose, as dragging does) and cold at
tol 1e-12: how many converged, how far warm and cold are apart, settle ms, and a handle turned
180 degrees in 15-degree steps and back. Bend scenario (DESIGN section 4) on every mesh at the
default proxy size, meshes flat-subdivided to at least ``--at-least`` vertices: edge distortion,
dihedral change, creases (interior edges whose dihedral angle changes by more than 30 degrees) and
the share of them on proxy seams (an endpoint bound to more than one proxy face, or the two to
different faces), handle error and detail volume change (bench/quality.py bend_quality, the row every benchmark
shares), first for the bend made as a script makes it ("add-on (api.deform)": api.build,
api.add_anchor, api.add_handle, the empty moved, api.deform, where the bpy module is there) with
its pivot offset (the handle empty's distance from its selected vertices' median point, world
space, over the diagonal) and api.stretch's mean and max, then for the default solver ("rotated": the
rebuild with the skin's weights diffused over the detail mesh, as every rebuild is), the same
solve rebuilt from the skin as bound (``seam_steps`` 0, what the product did before), and the
paper's iteration; beside Blender's own stack (Decimate
to our proxy's face count + Hook + Laplacian Deform + Surface Deform, where the bpy module is
there and Surface Deform binds) and full-resolution ARAP (libigl, 20 iterations, dev-only).
Totals over the meshes close the table.
"""

import argparse
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench import report
from bench.arap import arap_reference
from bench.meshes import named, subdivide
from bench.poses import pose_suite
from bench.quality import bend_quality
from bench.scenario import bend_scenario

from skin_detach_addon.core import DualLaplacian, SkinDetachedSurface
from skin_detach_addon.core.seam_weights import SEAM_STEPS
from skin_detach_addon.core.stretch import SkinStretch

MESHES = "armadillo,cow,spot,homer,alligator,cheburashka,horse,ogre,beetle-alt"


def mesh(name, at_least):
    """A mesh of tests/data or bench/data (the unseen ones), flat-subdivided (4 ways) until it has
    ``at_least`` vertices, positions rounded to float32 as Blender stores them."""
    points, triangles = named(name)
    while points.shape[0] < at_least:
        points, triangles = subdivide(points, triangles, 4)
    return points.astype(np.float32).astype(np.float64), triangles


def seam_vertices(surface):
    """(first face (u,), face count (u,)) of every welded detail vertex's associations."""
    skin = surface.skin
    u = skin.case.shape[0]
    first = np.full(u, -1)
    first[skin.vertex[::-1]] = skin.face[::-1]
    return first, np.bincount(skin.vertex, minlength=u)


def creases_on_seams(rest, detail, triangles, surface):
    """Share of the creased edges on a proxy seam: an endpoint bound to more than one proxy face,
    or the two bound to different faces (nan without creases)."""
    from bench.quality import CREASE_DEGREES, dihedral_angles, dihedral_changes
    _, pairs = dihedral_angles(rest, triangles)
    creased = pairs[dihedral_changes(rest, detail, triangles) > CREASE_DEGREES]
    if not creased.size:
        return float("nan")
    corners = np.sort(np.concatenate([triangles[creased[:, 0]], triangles[creased[:, 1]]], axis=1), axis=1)
    shared = corners[:, 1:][corners[:, 1:] == corners[:, :-1]].reshape(-1, 2)  # the edge's two vertices
    first, count = seam_vertices(surface)
    a, b = surface.weld[shared[:, 0]], surface.weld[shared[:, 1]]
    return float(np.mean((count[a] > 1) | (count[b] > 1) | (first[a] != first[b])))


def bend_rows(name, faces, at_least):
    points, triangles = mesh(name, at_least)
    scenario = bend_scenario(points)
    surface = SkinDetachedSurface.build(points, triangles, target_faces=faces)
    ids, targets = scenario.proxy_constraints(surface)
    rows = []
    scripted = through_api(name, points, triangles, scenario, faces)
    if scripted is not None:
        rows.append(quality_row(name, "add-on (api.deform)", points, scripted["detail"], triangles, scenario, surface,
                                converged=scripted["deform"]["converged"], settle_ms=scripted["deform"]["milliseconds"],
                                stretch_mean=float(scripted["stretch"].mean()),
                                stretch_max=float(scripted["stretch"].max()),
                                pivot_offset_diag=scripted["pivot"]))
    surface.attach_topology(triangles)
    rig = scenario.held_rig(surface)
    stretch = SkinStretch(surface)
    for method, steps in (("rotated", SEAM_STEPS), ("rotated, every corner held", SEAM_STEPS),
                          ("rotated, skin as bound", 0), ("paper", SEAM_STEPS)):
        surface.seam_steps = steps
        held = method == "rotated"
        solver = DualLaplacian(surface.proxy_vertices, surface.proxy_faces, rig["ids"] if held else ids,
                               method=method.split(",")[0], pulls=rig["pulls"] if held else ())
        start = time.perf_counter()
        result = solver.solve(rig["targets"] if held else targets, max_iter=500, tol=1e-12,
                              pull_motions=rig["motions"] if held else None)
        settle = time.perf_counter() - start
        layout = dict(groups=rig["groups"], held=rig["layout"].held) if held else \
            dict(groups=scenario.proxy_groups(surface))
        surface.reconstruct(result.vertices, **layout)  # the layout's first rebuild prepares its matrix
        start = time.perf_counter()
        detail = surface.reconstruct(result.vertices, **layout)
        rebuild = time.perf_counter() - start
        start = time.perf_counter()
        stretched = stretch(result.vertices)
        stretch_s = time.perf_counter() - start
        rows.append(quality_row(name, method, points, detail, triangles, scenario, surface,
                                converged=result.converged, settle_ms=1000 * settle,
                                stretch_mean=float(stretched.mean()), stretch_max=float(stretched.max()),
                                stretch_pct_of_step=100 * stretch_s / (settle + rebuild + stretch_s)))
    stack = blender_stack_pose(points, triangles, scenario, int(surface.proxy_faces.shape[0]))
    if stack is not None:
        rows.append(quality_row(name, "Blender stack", points, stack, triangles, scenario, surface))
    arap, _ = arap_reference(points, triangles, scenario, 20)
    if arap is not None:
        rows.append(quality_row(name, "ARAP (full resolution)", points, arap, triangles, scenario, surface))
    return rows


def blender_stack_pose(points, triangles, scenario, proxy_faces):
    """Blender's Decimate + Hook + Laplacian Deform + Surface Deform at the full pose, or None
    (no bpy module, or Surface Deform refuses the proxy)."""
    try:
        import bpy  # noqa: F401
    except ImportError:
        return None
    from bench.blender_stack import stack_pose
    return stack_pose(points, triangles, scenario, proxy_faces)


def quality_row(name, method, points, detail, triangles, scenario, surface, **extra):
    """bench/quality.py's bend row for one method, with the share of its creases on proxy seams."""
    return dict(mesh=name, method=method, vertices=int(points.shape[0]),
                **bend_quality(points, detail, triangles, scenario),
                creases_on_seams=creases_on_seams(points, detail, triangles, surface), **extra)


def through_api(name, points, triangles, scenario, faces):
    """The bend as a script does it on a Blender mesh of ``points``: api.build, api.add_anchor,
    api.add_handle, the empty moved by the scenario's motion, api.deform. A dict: ``pivot`` (the
    empty's distance from its selection's median point at rest, a fraction of the diagonal),
    ``detail`` (n, 3) the written positions, ``deform`` (api.deform's figures) and ``stretch``
    (n,) api.stretch; None without the bpy module."""
    try:
        import bpy
    except ImportError:
        return None
    from mathutils import Matrix

    from bench.meshes import blender_mesh
    from bench.quality import pivot_offset
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = blender_mesh(name, points, triangles)
    api.build(obj, target_faces=faces)
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    pivot = pivot_offset(obj, handle, scenario.handle_ids)
    handle.matrix_world = Matrix((scenario.motion() @ np.array(handle.matrix_world)).tolist())
    figures = api.deform(obj)
    return dict(pivot=pivot, detail=mesh_io.read_positions(obj.data).astype(np.float64), deform=figures,
                stretch=api.stretch(obj))


def totals(rows):
    """Per method: meshes, total creases and mean dihedral change over the meshes every method has."""
    meshes = set.intersection(*[{r["mesh"] for r in rows if r["method"] == m} for m in {r["method"] for r in rows}])
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        picked = [r for r in rows if r["method"] == method and r["mesh"] in meshes]
        out.append(dict(method=method, meshes=len(picked), creases=int(sum(r["creases"] for r in picked)),
                        dihedral_change_deg=float(np.mean([r["dihedral_change_deg"] for r in picked]))))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", default=MESHES)
    parser.add_argument("--pose-meshes", default="armadillo,spot,cow")
    parser.add_argument("--poses", type=int, default=300)
    parser.add_argument("--faces", type=int, default=1000)
    parser.add_argument("--at-least", type=int, default=25_000, help="flat-subdivide smaller meshes to this many vertices")
    parser.add_argument("--json")
    args = parser.parse_args()
    figures = {"poses": [], "bend": []}
    print(f"## Pose suite ({args.poses} random poses, tol 1e-12, proxy target {args.faces} faces)\n")
    print("| mesh | method | proxy faces | factor ms | warm / cold converged | warm-cold within 1e-5 diag "
          "| max warm-cold (diag) | settle ms (median) | 180 deg and back (diag) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in args.pose_meshes.split(",") if n]:
        points, triangles = named(name)
        surface = SkinDetachedSurface.build(points, triangles, target_faces=args.faces)
        for method in ("rotated", "paper"):
            row = dict(mesh=name, method=method, **pose_suite(surface, bend_scenario(points), count=args.poses,
                                                             method=method))
            figures["poses"].append(row)
            print(f"| {name} | {method} | {row['proxy_faces']} | {row['factor_ms']:.1f} | {row['warm_converged']} / "
                  f"{row['cold_converged']} of {row['poses']} | {100 * row['within_1e-5']:.1f} % | "
                  f"{row['max_warm_cold']:.1e} | {row['settle_ms_median']:.1f} | {row['turned_back_to_rest']:.1e} |",
                  flush=True)
    print(f"\n## Bend scenario, proxy target {args.faces} faces\n")
    print("| mesh | vertices | method | edge distortion | dihedral change deg | creases (> 30 deg) | on proxy seams "
          "| handle error % diag | volume change % | converged | settle ms | stretch mean / max | stretch % of a step "
          "| pivot offset (diag) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in args.meshes.split(",") if n]:
        for row in bend_rows(name, args.faces, args.at_least):
            figures["bend"].append(row)
            settle = f"{row['converged']} | {row['settle_ms']:.0f}" if "settle_ms" in row else "- | -"
            settle += (f" | {row['stretch_mean']:.3f} / {row['stretch_max']:.3f}" if "stretch_mean" in row else " | -")
            settle += f" | {row['stretch_pct_of_step']:.1f}" if "stretch_pct_of_step" in row else " | -"
            settle += f" | {row['pivot_offset_diag']:.1e}" if "pivot_offset_diag" in row else " | -"
            print(f"| {name} | {row['vertices']:,} | {row['method']} | {row['edge_distortion']:.3f} | "
                  f"{row['dihedral_change_deg']:.2f} | {row['creases']} | {100 * row['creases_on_seams']:.0f} % | "
                  f"{row['handle_error_pct_diag']:.2e} | {row['volume_change_pct']:+.2f} | {settle} |", flush=True)
    figures["totals"] = totals(figures["bend"])
    print("\n## Totals over the meshes\n\n| method | meshes | creases | mean dihedral change deg |\n|---|---|---|---|")
    for row in figures["totals"]:
        print(f"| {row['method']} | {row['meshes']} | {row['creases']} | {row['dihedral_change_deg']:.3f} |")
    if args.json:
        report.save(args.json, figures)


if __name__ == "__main__":
    main()
