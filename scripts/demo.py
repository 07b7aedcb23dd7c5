"""Headless core demo: bind the bundled armadillo to a 1,000-face proxy, drag the top of the
proxy, rebuild the detail and write it out.

    python scripts/demo.py [--size 300K] [--out out]

Until the dual-Laplacian solve lands, the proxy is deformed by a smooth bend of its upper part
(the handle region of the bend scenario), so the demo shows the skin carrying the detail.
"""

import argparse
import pathlib
import time

import numpy as np

from mesh_tools import ROOT, SIZES, armadillo

from skin_detach_addon.core import SkinDetachedSurface
from skin_detach_addon.core.obj_io import write_obj


def bend(proxy):
    """Rotate the proxy progressively about the x axis above its lower 10 %, up to 45 degrees."""
    y = proxy[:, 1]
    low, high = np.percentile(y, 10), y.max()
    t = np.clip((y - low) / (high - low), 0.0, 1.0)
    angle = np.radians(45.0) * t * t
    pivot = np.array([0.0, low, np.median(proxy[:, 2])])
    rel = proxy - pivot
    out = proxy.copy()
    out[:, 1] = pivot[1] + rel[:, 1] * np.cos(angle) - rel[:, 2] * np.sin(angle)
    out[:, 2] = pivot[2] + rel[:, 1] * np.sin(angle) + rel[:, 2] * np.cos(angle)
    return out


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

    target = bend(sds.proxy_vertices)
    deformed = np.empty_like(points)
    steps = 30
    times = []
    for k in range(1, steps + 1):
        frame = sds.proxy_vertices + (target - sds.proxy_vertices) * (k / steps)
        start = time.perf_counter()
        sds.reconstruct(frame, out=deformed)
        times.append(time.perf_counter() - start)
    print(f"drag: {steps} steps, rebuild {1000 * np.median(times):.1f} ms per step (median)")

    sds.save(out / "armadillo_skin.npz")
    write_obj(out / "armadillo_proxy.obj", target, sds.proxy_faces)
    write_obj(out / "armadillo_deformed.obj", deformed, triangles)
    print(f"wrote {out / 'armadillo_deformed.obj'}, {out / 'armadillo_proxy.obj'}, {out / 'armadillo_skin.npz'}")


if __name__ == "__main__":
    main()
