"""Headless core demo: bind the bundled armadillo to a 1,000-face proxy, drag the top of the
proxy, rebuild the detail and write it out.

    python scripts/demo.py [--size 300K] [--out out]

The drag is the bend scenario: the lowest 10 % of the model pinned, the highest 10 % turned
45 degrees and shifted sideways by a quarter of its height, in 30 warm-started steps of the
dual-Laplacian proxy solve, each followed by the rebuild of the detail.
"""

import argparse
import pathlib
import time

import numpy as np

from mesh_tools import ROOT, SIZES, armadillo

from skin_detach_addon.core import DualLaplacian, SkinDetachedSurface
from skin_detach_addon.core.bend_scenario import bend_scenario
from skin_detach_addon.core.obj_io import write_obj


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", default="300K", choices=list(SIZES))
    parser.add_argument("--target", type=int, default=1000)
    parser.add_argument("--out", default=str(ROOT / "out"))
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    points, triangles = armadillo(args.size)
    print(f"detail mesh: armadillo.obj subdivided to {points.shape[0]:,} vertices, {triangles.shape[0]:,} triangles")
    sds = SkinDetachedSurface.build(points, triangles, target_faces=args.target)
    s = sds.stats
    print(f"build: {s['seconds']['total']:.2f} s -> proxy of {s['proxy_vertices']} vertices / {s['proxy_faces']} faces; "
          f"case 1/2/3: {s['case1']:,} / {s['case2']:,} / {s['case3']:,}; {s['associations']:,} associations")
    rest_error = np.abs(sds.reconstruct(sds.proxy_vertices) - points).max()
    print(f"rest round trip: max error {rest_error:.2e}")

    ids, targets = bend_scenario(points).proxy_constraints(sds)
    start = time.perf_counter()
    solver = DualLaplacian(sds.proxy_vertices, sds.proxy_faces, ids)
    print(f"handles: {ids.size} constrained proxy vertices, factored in {1000 * (time.perf_counter() - start):.0f} ms")
    rest = sds.proxy_vertices[ids]
    deformed = np.empty_like(points)
    steps, solve_times, rebuild_times, proxy = 30, [], [], None
    for k in range(1, steps + 1):
        start = time.perf_counter()
        result = solver.solve(rest + (targets - rest) * (k / steps), initial=proxy)
        proxy = result.vertices
        solve_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        sds.reconstruct(proxy, out=deformed)
        rebuild_times.append(time.perf_counter() - start)
    print(f"drag: {steps} steps, proxy solve {1000 * np.median(solve_times):.1f} ms + rebuild "
          f"{1000 * np.median(rebuild_times):.1f} ms per step (median); proxy volume change "
          f"{100 * result.volume_change:+.3f} %")

    sds.save(out / "armadillo_skin.npz")
    write_obj(out / "armadillo_proxy.obj", proxy, sds.proxy_faces)
    write_obj(out / "armadillo_deformed.obj", deformed, triangles)
    print(f"wrote {out / 'armadillo_deformed.obj'}, {out / 'armadillo_proxy.obj'}, {out / 'armadillo_skin.npz'}")


if __name__ == "__main__":
    main()
