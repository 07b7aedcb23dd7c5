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


def subdivide(points, triangles, parts):
    """Flat subdivision: ``parts`` = 3 splits every triangle at its centroid (n + f vertices),
    4 at its edge midpoints (n + e), 6 at both (n + e + f). Positions stay on the input."""
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
        raise ValueError(f"parts: expected 3, 4 or 6, got {parts}")
    return np.concatenate(new_points), np.concatenate([np.stack(f, axis=1) for f in faces])


SIZES = {
    "50K": (),
    "200K": (4,),
    "300K": (6,),
    "800K": (4, 4),
    "1.2M": (4, 6),
    "1.8M": (6, 6),
    "3.2M": (4, 4, 4),
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
