"""Dual-Laplacian proxy solve: speed, and quality end to end on the bend scenario.

    python scripts/benchmark_deform.py [--mesh armadillo] [--json PATH]

Speed: factor time and warm-started drag-step time for proxies of 1,000 and 5,000 faces.
Quality: build the skin (5,000-face proxy), constrain the proxy vertices that carry the
scenario's anchors and handle, solve, rebuild the detail, and compare it with the rest mesh
and with full-resolution ARAP (libigl, dev-only; skipped when it is not installed). Blender's
own stack and ARAP as measured for DESIGN.md are printed beside it.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench.arap import arap_reference
from bench.meshes import bundled
from bench.quality import dihedral_change, edge_distortion, enclosed_volume, is_closed
from bench.scenario import bend_scenario

from skin_detach_addon.core import DualLaplacian, SkinDetachedSurface

#: The add-on's drag tolerance (api.DRAG_TOL).
DRAG_TOL = 1e-8
DESIGN_ROWS = [
    ("Blender stack (Laplacian Deform proxy + Surface Deform), DESIGN.md", 0.081, 2.0, 4.3),
    ("full-resolution ARAP (libigl), DESIGN.md", 0.045, 1.86, 0.0),
]


def drag_speed(points, triangles, faces, method, steps=30):
    sds = SkinDetachedSurface.build(points, triangles, target_faces=faces)
    scenario = bend_scenario(points)
    ids, targets = scenario.proxy_constraints(sds)
    start = time.perf_counter()
    solver = DualLaplacian(sds.proxy_vertices, sds.proxy_faces, ids, method=method)
    factor = time.perf_counter() - start
    rest = sds.proxy_vertices[ids]
    previous, times, iterations = None, [], []
    for k in range(1, steps + 1):
        start = time.perf_counter()
        result = solver.solve(rest + (targets - rest) * (k / steps), initial=previous, tol=DRAG_TOL)
        times.append(time.perf_counter() - start)
        iterations.append(result.iterations)
        previous = result.vertices
    start = time.perf_counter()
    settled = solver.solve(targets, max_iter=500, tol=1e-12)
    settle = time.perf_counter() - start
    return {"proxy_faces": int(sds.proxy_faces.shape[0]), "method": method, "factor_ms": 1000 * factor,
            "settle_ms": 1000 * settle, "settle_iterations": settled.iterations,
            "step_ms_median": 1000 * float(np.median(times)), "iterations_median": float(np.median(iterations))}


def bend_quality(points, triangles, faces, preserve_volume, method, arap):
    scenario = bend_scenario(points)
    start = time.perf_counter()
    sds = SkinDetachedSurface.build(points, triangles, target_faces=faces)
    build = time.perf_counter() - start
    ids, targets = scenario.proxy_constraints(sds)
    solver = DualLaplacian(sds.proxy_vertices, sds.proxy_faces, ids, preserve_volume=preserve_volume, method=method)
    result = solver.solve(targets, max_iter=500, tol=1e-10)
    detail = sds.reconstruct(result.vertices, groups=scenario.proxy_groups(sds))
    diag = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    handle_error = np.linalg.norm(detail[scenario.handle_ids] - scenario.move(points[scenario.handle_ids]), axis=1)
    anchor_error = np.linalg.norm(detail[scenario.anchor_ids] - points[scenario.anchor_ids], axis=1)
    row = {
        "preserve_volume": preserve_volume, "method": method, "proxy_faces": int(sds.proxy_faces.shape[0]), "build_s": build,
        "iterations": result.iterations, "converged": result.converged,
        "edge_distortion": edge_distortion(points, detail, triangles),
        "dihedral_change_deg": dihedral_change(points, detail, triangles),
        "handle_error_pct_diag": 100 * float(handle_error.mean()) / diag,
        "anchor_error_pct_diag": 100 * float(anchor_error.mean()) / diag,
        "proxy_volume_change_pct": 100 * result.volume_change,
        "detail_volume_change_pct": (100 * (enclosed_volume(detail, triangles) / enclosed_volume(points, triangles) - 1)
                                     if is_closed(triangles) else float("nan")),
    }
    if arap is not None:
        row["rms_vs_arap_pct_diag"] = 100 * float(np.sqrt(np.mean(np.sum((detail - arap) ** 2, axis=1)))) / diag
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="armadillo")
    parser.add_argument("--faces", type=int, default=5000)
    parser.add_argument("--arap-iterations", type=int, default=10,
                        help="10 is the reference DESIGN.md measured Blender's stack against")
    parser.add_argument("--json")
    args = parser.parse_args()
    points, triangles = bundled(args.mesh)

    speed = [drag_speed(points, triangles, faces, method) for method in ("rotated", "paper") for faces in (1000, 5000)]
    print(f"## Dual-Laplacian proxy solve (bend scenario, 30 warm-started drag steps at tol {DRAG_TOL:g}; "
          f"settle from rest at tol 1e-12)\n")
    print("| method | proxy faces | factor ms | drag step ms (median) | iterations per step | settle ms | settle iterations |")
    print("|---|---|---|---|---|---|---|")
    for r in speed:
        print(f"| {r['method']} | {r['proxy_faces']} | {r['factor_ms']:.1f} | {r['step_ms_median']:.2f} "
              f"| {r['iterations_median']:.0f} | {r['settle_ms']:.0f} | {r['settle_iterations']} |")

    arap, arap_s = arap_reference(points, triangles, bend_scenario(points), args.arap_iterations)
    rows = [bend_quality(points, triangles, args.faces, flag, method, arap)
            for method in ("rotated", "paper") for flag in (True, False)]
    print(f"\n## Bend scenario on {args.mesh}.obj ({points.shape[0]:,} vertices), proxy target {args.faces} faces\n")
    print("| method | edge distortion | dihedral change | handle error | anchor error | volume change (detail) "
          "| RMS vs ARAP |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        name = f"Skin Detach, {r['method']}, volume {'kept' if r['preserve_volume'] else 'free'}"
        rms = f"{r['rms_vs_arap_pct_diag']:.2f} %" if "rms_vs_arap_pct_diag" in r else "n/a"
        print(f"| {name} | {r['edge_distortion']:.3f} | {r['dihedral_change_deg']:.2f} deg "
              f"| {r['handle_error_pct_diag']:.2e} % | {r['anchor_error_pct_diag']:.2e} % "
              f"| {r['detail_volume_change_pct']:+.2f} % | {rms} |")
    if arap is not None:
        print(f"| ARAP (libigl, {args.arap_iterations} iterations, this run, {arap_s:.1f} s) "
              f"| {edge_distortion(points, arap, triangles):.3f} | {dihedral_change(points, arap, triangles):.2f} deg "
              f"| - | - | {100 * (enclosed_volume(arap, triangles) / enclosed_volume(points, triangles) - 1):+.2f} % | 0 |")
    for name, edge, dihedral, rms in DESIGN_ROWS:
        print(f"| {name} | {edge:.3f} | {dihedral:.2f} deg | - | - | - | {rms:.1f} % |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"speed": speed, "quality": rows}, handle, indent=2)


if __name__ == "__main__":
    main()
