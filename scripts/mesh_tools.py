"""Helpers for scripts: bundled meshes and flat subdivision to reach the paper's sizes."""

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from skin_detach_addon.core.obj_io import read_obj  # noqa: E402

DATA = ROOT / "tests" / "data"


def bundled(name):
    """(vertices (n, 3), triangles (f, 3)) of a mesh in tests/data."""
    return read_obj(DATA / f"{name}.obj")


def subdivide(points, triangles, parts):
    """Flat subdivision: ``parts`` = 4 splits every triangle at its edge midpoints (n + e
    vertices), 6 also adds its centroid (n + e + f vertices). Positions stay on the input."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = inverse.reshape(3, -1).T + points.shape[0]
    a, b, c = triangles.T
    ab, bc, ca = mid.T
    new_points = [points, (points[edges[:, 0]] + points[edges[:, 1]]) / 2]
    if parts == 4:
        faces = [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    elif parts == 6:
        centre = np.arange(triangles.shape[0]) + points.shape[0] + edges.shape[0]
        new_points.append(points[triangles].mean(axis=1))
        faces = [(a, ab, centre), (ab, b, centre), (b, bc, centre), (bc, c, centre), (c, ca, centre), (ca, a, centre)]
    else:
        raise ValueError(f"parts: expected 4 or 6, got {parts}")
    return np.concatenate(new_points), np.concatenate([np.stack(f, axis=1) for f in faces])


SIZES = {
    "50K": (),
    "200K": (4,),
    "300K": (6,),
    "800K": (4, 4),
    "1.2M": (4, 6),
}


def armadillo(size):
    """armadillo.obj flat-subdivided to one of :data:`SIZES`."""
    points, triangles = bundled("armadillo")
    for parts in SIZES[size]:
        points, triangles = subdivide(points, triangles, parts)
    return points, triangles
