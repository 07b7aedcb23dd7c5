"""Minimal Wavefront OBJ reading and writing for tests, scripts and batch output.

``read_obj`` returns vertices (n, 3) float64 and triangles (f, 3) int64 (polygons fan-
triangulated); ``write_obj`` writes vertices, polygons and optional per-corner UVs.
"""

import numpy as np

from .errors import SkinDetachError


def read_obj(path):
    """(vertices (n, 3), triangles (f, 3)) of the OBJ file at ``path``."""
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


def write_obj(path, vertices, polygons, uvs=None):
    """Write ``vertices`` (n, 3) and ``polygons`` (a list of index sequences, or a (f, c) array).

    ``uvs``, if given, is (sum of corner counts, 2): one UV per polygon corner, in order.
    """
    lines = ["# written by Skin Detach"]
    lines.extend(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(vertices, dtype=np.float64))
    if uvs is not None:
        lines.extend(f"vt {u:.9g} {v:.9g}" for u, v in np.asarray(uvs, dtype=np.float64))
    corner = 1
    for poly in polygons:
        if uvs is None:
            lines.append("f " + " ".join(str(int(i) + 1) for i in poly))
        else:
            lines.append("f " + " ".join(f"{int(i) + 1}/{corner + k}" for k, i in enumerate(poly)))
            corner += len(poly)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
