"""Meshes for tests, benchmarks and the demo: the bundled OBJ files, flat subdivision to reach
the paper's sizes, and a Blender mesh object from arrays.

Arrays: ``points`` (n, 3) float64 indexed by vertex id, ``triangles`` (f, 3) int64 vertex ids.
"""

import pathlib

import numpy as np

from skin_detach_addon.core.errors import SkinDetachError
from skin_detach_addon.core.geometry import unique_edges

ROOT = pathlib.Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
#: Meshes the project was not tuned on (bench/data/README.md says where each comes from).
UNSEEN = ROOT / "bench" / "data"


def read_obj(path):
    """(points (n, 3), triangles (f, 3)) of the Wavefront OBJ file at ``path`` (polygons fan-triangulated)."""
    vertices, triangles = [], []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if line.startswith("v "):
                vertices.append(line.split()[1:4])
            elif line.startswith("f "):
                ids = [int(token.split("/")[0]) for token in line.split()[1:]]
                triangles.extend((ids[0], ids[k], ids[k + 1]) for k in range(1, len(ids) - 1))
    if not vertices or not triangles:
        raise SkinDetachError(f"path: expected an OBJ file with vertices and faces, got none in {path!s}")
    points = np.array(vertices, dtype=np.float64)
    faces = np.array(triangles, dtype=np.int64)
    faces = np.where(faces < 0, faces + points.shape[0], faces - 1)
    return points, faces


def bundled(name):
    """(vertices (n, 3), triangles (f, 3)) of a mesh in tests/data."""
    return read_obj(DATA / f"{name}.obj")


def named(name):
    """(vertices (n, 3), triangles (f, 3)) of a mesh by name: bench/data's (stored as NPZ) or
    tests/data's (OBJ)."""
    if (UNSEEN / f"{name}.npz").exists():
        stored = np.load(UNSEEN / f"{name}.npz")
        return stored["vertices"].astype(np.float64), stored["triangles"].astype(np.int64)
    return bundled(name)


def split_edges(points, triangles, k):
    """Flat subdivision of every edge into ``k`` equal parts and every triangle into k * k similar
    ones (no sliver: the triangles keep their shapes): (n + e (k - 1) + f (k - 1)(k - 2) / 2
    points, k * k f triangles)."""
    edges, _ = unique_edges(triangles)
    n, e = points.shape[0], edges.shape[0]
    grid = [(i, j) for j in range(k + 1) for i in range(k + 1 - j)]
    local = {ij: index for index, ij in enumerate(grid)}
    inner = [(i, j) for i, j in grid if i >= 1 and j >= 1 and i + j <= k - 1]
    a, b, c = triangles.T
    ids = np.empty((triangles.shape[0], len(grid)), dtype=np.int64)
    ids[:, local[0, 0]], ids[:, local[k, 0]], ids[:, local[0, k]] = a, b, c
    keys = edges[:, 0] * n + edges[:, 1]

    def on_edge(start, stop, column_of):
        low, high = np.minimum(start, stop), np.maximum(start, stop)
        base = n + (k - 1) * np.searchsorted(keys, low * n + high)
        forward = start < stop
        for t in range(1, k):
            ids[:, column_of(t)] = base + np.where(forward, t - 1, k - 1 - t)

    on_edge(a, b, lambda t: local[t, 0])
    on_edge(b, c, lambda t: local[k - t, t])
    on_edge(c, a, lambda t: local[0, k - t])
    first_inner = n + (k - 1) * e
    for index, ij in enumerate(inner):
        ids[:, local[ij]] = first_inner + np.arange(triangles.shape[0]) * len(inner) + index
    t = np.arange(1, k)[:, None] / k
    on_edges = (points[edges[:, 0]][:, None] * (1 - t) + points[edges[:, 1]][:, None] * t).reshape(-1, 3)
    weights = np.array([(k - i - j, i, j) for i, j in inner], dtype=np.float64).reshape(-1, 3) / k
    inside = np.einsum("pc,fcx->fpx", weights, points[triangles]).reshape(-1, 3)
    template = [(local[i, j], local[i + 1, j], local[i, j + 1]) for i, j in grid if i + j <= k - 1]
    template += [(local[i + 1, j], local[i + 1, j + 1], local[i, j + 1]) for i, j in grid if i + j <= k - 2]
    faces = ids[:, np.array(template)].reshape(-1, 3)
    return np.concatenate([points, on_edges, inside]), faces


def subdivide(points, triangles, parts):
    """Flat subdivision: ``parts`` = 3 splits every triangle at its centroid (n + f vertices),
    4 at its edge midpoints (n + e), 6 at both (n + e + f), a square k * k >= 9 every edge into k
    parts (:func:`split_edges`). Positions stay on the input."""
    if parts >= 9 and round(parts ** 0.5) ** 2 == parts:
        return split_edges(points, triangles, round(parts ** 0.5))
    if parts == 3:
        centre = np.arange(triangles.shape[0]) + points.shape[0]
        a, b, c = triangles.T
        return (np.concatenate([points, points[triangles].mean(axis=1)]),
                np.concatenate([np.stack(f, axis=1) for f in ((a, b, centre), (b, c, centre), (c, a, centre))]))
    edges = unique_edges(triangles)[0]
    n = points.shape[0]
    sides = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    inverse = np.searchsorted(edges[:, 0] * n + edges[:, 1], sides[:, 0] * n + sides[:, 1])
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
        raise ValueError(f"parts: expected 3, 4, 6 or a square >= 9, got {parts}")
    return np.concatenate(new_points), np.concatenate([np.stack(f, axis=1) for f in faces])


SIZES = {
    "50K": (),
    "200K": (4,),
    "300K": (6,),
    "800K": (4, 4),
    "1.2M": (4, 6),
    "1.8M": (6, 6),
    "3.2M": (4, 4, 4),
    "10M": (196,),  # every edge of the 50K armadillo in 14 parts: 9.8M vertices, no sliver
}


def subdivided(name, parts):
    """A bundled mesh flat-subdivided by each of ``parts`` in turn (see :func:`subdivide`)."""
    points, triangles = bundled(name)
    for step in parts:
        points, triangles = subdivide(points, triangles, step)
    return points, triangles


def blender_mesh(name, points, triangles):
    """A new smooth-shaded mesh object from (n, 3) points and (f, 3) triangles, linked to the scene."""
    import bpy
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(points.shape[0])
    mesh.loops.add(triangles.size)
    mesh.polygons.add(triangles.shape[0])
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    mesh.loops.foreach_set("vertex_index", triangles.astype(np.int32).ravel())
    mesh.polygons.foreach_set("loop_start", np.arange(0, triangles.size, 3, dtype=np.int32))
    mesh.polygons.foreach_set("use_smooth", np.ones(triangles.shape[0], dtype=bool))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def armadillo(size):
    """armadillo.obj flat-subdivided to one of :data:`SIZES`."""
    return subdivided("armadillo", SIZES[size])
