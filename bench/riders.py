"""Loose parts on a body, as artists' sculpts have them, and how well they follow it.

Arrays: ``points`` (n, 3) float64 indexed by vertex id, ``triangles`` (f, 3) int64. A *part* is a
named (k,) array of vertex ids of one loose piece.

The parts are placed on the body from its own shape, so any mesh gets them: an *eye* (a small UV
sphere half sunk into the surface at the top of the longest axis), a *plate* (a sphere flattened
to a third, lying on the surface at the middle of the body, on the side the middle axis points
to), a *bracelet* (a thin torus around the forearm of the limb :func:`bench.rigs.limb` finds, a
little wider than its cross-section) and a *far* prop (a small cube standing apart at 20 % of the diagonal past
the body's box: it must not move).

Figures (:func:`follow_figures`): where the surface under a part carried it is the part's rest
moved, vertex by vertex, by the mean motion of the ``NEAREST`` body vertices nearest it at rest;
``offset`` is the mean distance of the part's vertices from there over the body's diagonal
(``offset_max`` the largest), ``displaced`` the largest distance of a part's vertex from its rest
(a part that rides on nothing must stay: 0); ``stretch`` the part's own edge distortion (mean | |e'| / |e| - 1 |
over its edges) and ``surface_stretch`` the same over the body's edges at those nearest vertices.
"""

import numpy as np
from scipy.spatial import cKDTree

from bench.rigs import limb

#: The parts :func:`body_parts` places, in the benchmark's order.
KINDS = ("eye", "plate", "bracelet", "far")
#: The header of the benchmark's table (:func:`table_lines`).
TABLE_HEAD = ("| mesh | set-up | part | bend: off where carried, mean / max (diag) | drag: the same | "
              "own stretch / surface's under it | handle / anchor error (diag) | build s / move ms / confirm ms |\n"
              "|---|---|---|---|---|---|---|---|")
#: Body vertices whose mean motion carries a part's vertex.
NEAREST = 8


def uv_sphere(center, radius, segments=16, rings=8, squash=(1.0, 1.0, 1.0), frame=None):
    """(points (v, 3), triangles (t, 3)) of a closed UV sphere, scaled per axis by ``squash`` in
    ``frame`` (3, 3) columns (identity if None)."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    local = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]]) * np.asarray(squash)
    frame = np.eye(3) if frame is None else np.asarray(frame)
    points = np.asarray(center) + radius * local @ frame.T
    faces = []
    last = 1 + (rings - 1) * segments
    for j in range(segments):
        a, b = 1 + j, 1 + (j + 1) % segments
        faces.append((0, a, b))
        faces.append((last, last - segments + (j + 1) % segments, last - segments + j))
    for i in range(rings - 2):
        for j in range(segments):
            a = 1 + i * segments + j
            b = 1 + i * segments + (j + 1) % segments
            faces += [(a, a + segments, b), (b, a + segments, b + segments)]
    return points, np.array(faces, dtype=np.int64)


def torus(center, axis, major, minor, around=32, tube=8):
    """(points, triangles) of a closed torus about ``axis`` (3,) through ``center``."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    a = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    b = np.linspace(0.0, 2.0 * np.pi, tube, endpoint=False)
    aa, bb = np.meshgrid(a, b, indexing="ij")
    radial = np.cos(aa)[..., None] * u + np.sin(aa)[..., None] * v
    points = (np.asarray(center) + (major + minor * np.cos(bb))[..., None] * radial
              + (minor * np.sin(bb))[..., None] * axis).reshape(-1, 3)
    faces = []
    for i in range(around):
        for j in range(tube):
            p, q = i * tube + j, ((i + 1) % around) * tube + j
            r, s = ((i + 1) % around) * tube + (j + 1) % tube, i * tube + (j + 1) % tube
            faces += [(p, q, r), (p, r, s)]
    return points, np.array(faces, dtype=np.int64)


def cube(center, size):
    """(points, triangles) of a closed axis-aligned cube."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], dtype=np.int64)
    return np.asarray(center) + size * corners, faces


def _normals(points, triangles):
    cross = np.cross(points[triangles[:, 1]] - points[triangles[:, 0]], points[triangles[:, 2]] - points[triangles[:, 0]])
    normals = np.zeros_like(points)
    for corner in range(3):
        np.add.at(normals, triangles[:, corner], cross)
    return normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-300)[:, None]


def body_parts(points, triangles, kinds=("eye", "plate", "bracelet", "far")):
    """Loose parts placed on the body ``points``, ``triangles``: a dict kind -> (points, triangles)."""
    low, high = points.min(axis=0), points.max(axis=0)
    extent = high - low
    diag = float(np.linalg.norm(extent))
    order = np.argsort(extent)
    longest, middle = order[2], order[1]
    normals = _normals(points, triangles)
    parts = {}
    if "eye" in kinds:  # the surface vertex nearest the top of the longest axis, facing along the middle axis
        top = points[:, longest] >= low[longest] + 0.85 * extent[longest]
        pick = np.flatnonzero(top)[np.argmax(points[top, middle])]
        parts["eye"] = uv_sphere(points[pick], 0.02 * diag)
    if "plate" in kinds:  # lying on the surface half-way up, on the side the middle axis points to
        band = np.abs(points[:, longest] - (low[longest] + 0.55 * extent[longest])) <= 0.05 * extent[longest]
        pick = np.flatnonzero(band)[np.argmax(points[band, middle])]
        n = normals[pick]
        t = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        t /= np.linalg.norm(t)
        frame = np.stack([t, np.cross(n, t), n], axis=1)
        radius = 0.04 * diag
        parts["plate"] = uv_sphere(points[pick] + n * radius * 0.32, radius, squash=(1.0, 1.0, 0.3), frame=frame)
    if "bracelet" in kinds:  # around the middle of the limb's forearm band, a little wider than it
        bands = limb(points, triangles)
        axis = points[bands["hand"]].mean(axis=0) - points[bands["upper arm"]].mean(axis=0)
        axis /= np.linalg.norm(axis)
        centre = points[bands["forearm"]].mean(axis=0)
        offsets = points[bands["forearm"]] - centre
        along = offsets @ axis
        thin = np.abs(along) <= 0.01 * diag
        radial = np.linalg.norm(offsets[thin] - np.outer(along[thin], axis), axis=1)
        # Hugging the arm: a little wider than most of the cross-section (a band slice catches
        # stray vertices of a hand or a body far out, which the largest radius would follow).
        parts["bracelet"] = torus(centre, axis, 1.05 * np.percentile(radial, 90) + 0.004 * diag, 0.006 * diag)
    if "far" in kinds:
        parts["far"] = cube(high + 0.2 * diag * np.ones(3) / np.sqrt(3.0), 0.04 * diag)
    return parts


def joined(body, parts):
    """(points, triangles, ranges) of the body and its parts in one mesh; ``ranges`` maps "body" and
    each part's kind to its (k,) vertex ids."""
    points, triangles = [body[0]], [body[1]]
    ranges = {"body": np.arange(body[0].shape[0])}
    offset = body[0].shape[0]
    for kind, (p, t) in parts.items():
        points.append(p)
        triangles.append(t + offset)
        ranges[kind] = np.arange(offset, offset + p.shape[0])
        offset += p.shape[0]
    return np.concatenate(points), np.concatenate(triangles), ranges


def _edge_stretch(rest, deformed, edges):
    length = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
    moved = np.linalg.norm(deformed[edges[:, 0]] - deformed[edges[:, 1]], axis=1)
    keep = length > 0
    return float(np.abs(moved[keep] / length[keep] - 1.0).mean()) if keep.any() else 0.0


def _edges(triangles):
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


def follow_figures(rest, deformed, triangles, ranges, body="body"):
    """Per part kind of ``ranges`` (but the body): dict of ``offset``, ``offset_max`` (over the
    body's diagonal), ``moved`` (how far the surface carried it, mean over the diagonal),
    ``stretch`` and ``surface_stretch`` (see the module's docstring)."""
    body_ids = ranges[body]
    diag = float(np.linalg.norm(rest[body_ids].max(axis=0) - rest[body_ids].min(axis=0)))
    tree = cKDTree(rest[body_ids])
    edges = _edges(triangles)
    out = {}
    for kind, ids in ranges.items():
        if kind == body:
            continue
        near = body_ids[tree.query(rest[ids], k=NEAREST)[1]]
        carried = rest[ids] + (deformed[near] - rest[near]).mean(axis=1)
        offset = np.linalg.norm(deformed[ids] - carried, axis=1) / diag
        mine = edges[np.isin(edges[:, 0], ids) & np.isin(edges[:, 1], ids)]
        under = np.unique(near)
        surface = edges[np.isin(edges[:, 0], under) & np.isin(edges[:, 1], body_ids)]
        out[kind] = dict(offset=float(offset.mean()), offset_max=float(offset.max()),
                         displaced=float(np.linalg.norm(deformed[ids] - rest[ids], axis=1).max() / diag),
                         moved=float(np.linalg.norm(carried - rest[ids], axis=1).mean() / diag),
                         stretch=_edge_stretch(rest, deformed, mine),
                         surface_stretch=_edge_stretch(rest, deformed, surface))
    return out


def table_lines(row):
    """Markdown lines of a row of scripts/benchmark_riders.py: one per part (:data:`TABLE_HEAD`)."""
    if row.get("unbound"):
        return [f"| {row['mesh']} | {row['setup']} | - | Surface Deform did not bind | | | | |"]
    out = []
    for kind in KINDS:
        bend = row["bend"][kind]
        drag = row["drag"][kind] if "drag" in row else None
        if kind == "far":  # rides on nothing: how far it moved from its rest
            bent, dragged = f"stays: moved {bend['displaced']:.1e}", \
                f"stays: moved {drag['displaced']:.1e}" if drag else "-"
        else:
            bent = f"{bend['offset']:.2e} / {bend['offset_max']:.2e}"
            dragged = f"{drag['offset']:.2e} / {drag['offset_max']:.2e}" if drag else "-"
        timing = (f"{row['build_s']:.2f} / {row['move_ms_median']:.1f} / {row['confirm_ms']:.0f}" if "build_s" in row
                  else f"{row['set_up_s']:.2f} / {row['step_ms']:.1f} / -")
        out.append(f"| {row['mesh']} | {row['setup']} | {kind} | {bent} | "
                   f"{dragged} | {bend['stretch']:.4f} / {bend['surface_stretch']:.4f} | "
                   f"{row['handle_error']:.1e} / {row['anchor_error']:.1e} | {timing} |")
    return out
