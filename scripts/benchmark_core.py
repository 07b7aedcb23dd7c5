"""Core skin benchmark: build time, rebuild time and peak memory at the paper's sizes.

    python scripts/benchmark_core.py [--sizes 300K 1.2M] [--repeat 30] [--json PATH]

Each size runs in its own process so that its peak memory is its own. The library's own
simplification time (fast-simplification to the same face count) is measured in the same
process, so the build can be read against what the library alone costs on this machine.
"""

import argparse
import json
import pathlib
import resource
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench.meshes import SIZES, armadillo, bundled
from bench.scenario import bend_scenario
from skin_detach_addon.core.seam_weights import SEAM_STEPS

PAPER_PRECOMPUTE = "52 min (332K-vertex armadillo, 1,000 faces, 2008 PC)"


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def measure(size, repeat, target):
    import fast_simplification

    from skin_detach_addon.core import SkinDetachedSurface

    points, triangles = armadillo(size)
    before = peak_rss_mb()
    start = time.perf_counter()
    sds = SkinDetachedSurface.build(points, triangles, target_faces=target)
    build = time.perf_counter() - start
    after_build = peak_rss_mb()
    rebuild = {}
    for steps in (sds.seam_steps, 0):  # the diffused skin (every rebuild), then the skin as bound
        sds.seam_steps = steps
        for dtype in (np.float64, np.float32):
            out = np.empty(points.shape, dtype=dtype)
            proxy = sds.proxy_vertices.copy()
            sds.reconstruct(proxy, out=out)
            times = []
            for k in range(repeat):
                proxy[:, 2] += 1e-4
                t = time.perf_counter()
                sds.reconstruct(proxy, out=out)
                times.append(time.perf_counter() - t)
            rebuild[f"{steps}_{np.dtype(dtype).name}"] = 1000 * float(np.median(times))
        rebuild[f"{steps}_nnz_per_vertex"] = sds._rebuild_for(None).nnz / points.shape[0]
        if steps:
            groups = bend_scenario(points).proxy_groups(sds)
            t = time.perf_counter()
            sds.reconstruct(sds.proxy_vertices, groups=groups)
            rebuild["group_layout_s"] = time.perf_counter() - t
    start = time.perf_counter()
    fast_simplification.simplify(points, triangles.astype(np.int32), target_count=target)
    library = time.perf_counter() - start
    return {
        "size": size, "vertices": int(points.shape[0]), "faces": int(triangles.shape[0]),
        "proxy_faces": sds.stats["proxy_faces"], "build_s": build, "build_parts_s": sds.stats["seconds"],
        "library_simplify_s": library, "rebuild_ms_median": rebuild[f"{SEAM_STEPS}_float64"], "rebuild": rebuild,
        "build_peak_mb_over_input": after_build - before, "process_peak_mb": after_build,
    }


def normal_test_figures(target):
    from skin_detach_addon.core import SkinDetachedSurface

    points, triangles = bundled("armadillo")
    rows = {}
    for flag in (True, False):
        stats = SkinDetachedSurface.build(points, triangles, target_faces=target, normal_test=flag).stats
        rows["on" if flag else "off"] = {k: stats[k] for k in (
            "proxy_faces", "normal_disagree_ring", "normal_disagree_bound", "normal_test_refused",
            "case1", "case2", "case3")}
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["300K", "1.2M"], choices=list(SIZES))
    parser.add_argument("--repeat", type=int, default=30)
    parser.add_argument("--target", type=int, default=1000)
    parser.add_argument("--json", help="also write the figures to this file")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args.repeat, args.target)))
        return

    rows = []
    for size in args.sizes:
        done = subprocess.run([sys.executable, __file__, "--one", size, "--repeat", str(args.repeat),
                               "--target", str(args.target)], capture_output=True, text=True, check=True)
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
    normals = normal_test_figures(args.target)

    print(f"## Core skin, armadillo.obj flat-subdivided, proxy target {args.target} faces\n")
    print("| size | vertices | build s | of which library simplify s (alone) | normal test s | skin s "
          "| rebuild ms (median) | build peak MB | paper precompute |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        parts = r["build_parts_s"]
        print(f"| {r['size']} | {r['vertices']:,} | {r['build_s']:.2f} | {parts['simplify']:.2f} "
              f"({r['library_simplify_s']:.2f}) | {parts['normal_test']:.2f} | {parts['skin']:.2f} "
              f"| {r['rebuild_ms_median']:.1f} | {r['build_peak_mb_over_input']:.0f} | {PAPER_PRECOMPUTE} |")
    print(f"\n## Rebuild, ms (median of {args.repeat}): the skin diffused over the detail ({SEAM_STEPS} steps, every "
          f"rebuild) against the skin as bound (seam_steps 0)\n")
    print("| size | diffused float64 / float32 | as bound float64 / float32 | ratio (float32) | entries per vertex "
          "diffused / as bound | first rebuild with a handle layout s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        b = r["rebuild"]
        print(f"| {r['size']} | {b[f'{SEAM_STEPS}_float64']:.1f} / {b[f'{SEAM_STEPS}_float32']:.1f} | "
              f"{b['0_float64']:.1f} / {b['0_float32']:.1f} | {b[f'{SEAM_STEPS}_float32'] / b['0_float32']:.2f} | "
              f"{b[f'{SEAM_STEPS}_nnz_per_vertex']:.2f} / {b['0_nnz_per_vertex']:.2f} | {b['group_layout_s']:.2f} |")
    print("\n## 1-ring normal test, armadillo.obj (50K vertices)\n")
    print("| normal test | proxy faces | vertices disagreeing with a face around their proxy vertex "
          "| with a bound face | refused collapses | case 1 / 2 / 3 |")
    print("|---|---|---|---|---|---|")
    for key, r in normals.items():
        print(f"| {key} | {r['proxy_faces']} | {100 * r['normal_disagree_ring']:.2f} % "
              f"| {100 * r['normal_disagree_bound']:.2f} % | {r['normal_test_refused']} "
              f"| {r['case1']} / {r['case2']} / {r['case3']} |")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"sizes": rows, "normal_test": normals}, handle, indent=2)


if __name__ == "__main__":
    main()
