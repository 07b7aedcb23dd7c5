"""Small synthetic meshes for the tests: (vertices (n, 3), triangles (f, 3))."""

import numpy as np


def grid_solid(x_breaks, y_breaks, z_breaks, occupied):
    """Closed surface of the occupied cells of a rectilinear grid.

    ``occupied`` (X, Y, Z) bool over cells; returns outward-facing triangles over the grid
    nodes the surface uses.
    """
    occ = np.pad(occupied, 1)
    ny, nz = len(y_breaks), len(z_breaks)
    node = lambda i, j, k: (i * ny + j) * nz + k  # noqa: E731
    quads = []
    for axis in range(3):
        diff = np.diff(occ.astype(np.int8), axis=axis)
        for sign in (1, -1):
            cells = np.argwhere(diff == -sign)  # sign=1: occupied then empty -> faces +axis
            for c in cells:
                idx = list(c - 1)
                idx[axis] += 1  # node-plane index of the shared face
                a, b = (axis + 1) % 3, (axis + 2) % 3
                corners = []
                for da, db in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = list(idx)
                    p[a] += da
                    p[b] += db
                    corners.append(node(*p))
                quads.append(corners if sign == 1 else corners[::-1])
    quads = np.array(quads)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    used, tris = np.unique(tris, return_inverse=True)
    gx, gy, gz = np.meshgrid(x_breaks, y_breaks, z_breaks, indexing="ij")
    points = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)[used]
    return points, tris.reshape(-1, 3)


def closed_mouth(gap=0.01, bump=0.004, hinge=0.1):
    """Two thick jaws 1 x 0.15 x 0.3 whose facing surfaces are ``gap`` apart (1 % of the
    length), joined only by a hinge block at x < ``hinge``, with fine bumps on every surface
    that keep the gap constant. Returns (vertices, triangles, lower mask, upper mask)."""
    x = np.linspace(0.0, 1.0, 41)
    jaw = np.linspace(0.0, 0.15, 7)
    y = np.concatenate([-gap / 2 - jaw[::-1], gap / 2 + jaw])
    z = np.linspace(0.0, 0.3, 13)
    occupied = np.ones((40, 13, 12), dtype=bool)
    occupied[int(round(hinge * 40)):, 6, :] = False  # the gap row of cells, open beyond the hinge
    points, tris = grid_solid(x, y, z, occupied)
    points[:, 1] += bump * np.sin(40.0 * points[:, 0]) * np.sin(40.0 * points[:, 2])
    lower = points[:, 1] < 0.0
    upper = points[:, 1] > 0.0
    return points, tris, lower, upper


def box(size=(1.0, 1.0, 1.0), cells=(6, 6, 6), offset=(0.0, 0.0, 0.0)):
    """Closed box surface made of grid cells."""
    breaks = [np.linspace(0.0, s, c + 1) + o for s, c, o in zip(size, cells, offset)]
    points, tris = grid_solid(*breaks, np.ones(cells, dtype=bool))
    return points, tris


def plane(n=20, size=1.0):
    """Open square sheet (n x n quads, split in two triangles each) with gentle waves."""
    g = np.linspace(0.0, size, n + 1)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    z = 0.05 * size * np.sin(6.0 * gx / size) * np.cos(5.0 * gy / size)
    points = np.stack([gx.ravel(), gy.ravel(), z.ravel()], axis=1)
    ids = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
    return points, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def merge(*meshes):
    """Concatenate meshes into one with several components."""
    points, tris, offset = [], [], 0
    for p, t in meshes:
        points.append(p)
        tris.append(t + offset)
        offset += p.shape[0]
    return np.concatenate(points), np.concatenate(tris)


def random_rotation(seed):
    q = np.random.default_rng(seed).normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def cylinder(radius=0.5, length=8.0, around=16, along=32):
    """Closed round bar along z from 0 to ``length``: a tube with a fan cap at each end."""
    angle = 2 * np.pi * np.arange(around) / around
    z = np.linspace(0.0, length, along + 1)
    ring = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    points = np.concatenate([np.column_stack([np.tile(ring, (along + 1, 1)), np.repeat(z, around)]),
                             [[0.0, 0.0, 0.0], [0.0, 0.0, length]]])
    ids = np.arange((along + 1) * around).reshape(along + 1, around)
    a, b = ids[:-1], np.roll(ids[:-1], -1, axis=1)
    c, d = ids[1:], np.roll(ids[1:], -1, axis=1)
    side = np.concatenate([np.stack([a.ravel(), b.ravel(), d.ravel()], 1), np.stack([a.ravel(), d.ravel(), c.ravel()], 1)])
    low, high = points.shape[0] - 2, points.shape[0] - 1
    bottom = np.stack([np.full(around, low), np.roll(ids[0], -1), ids[0]], 1)
    top = np.stack([np.full(around, high), ids[-1], np.roll(ids[-1], -1)], 1)
    return points, np.concatenate([side, bottom, top])


def bend_constraints(points):
    """The bend scenario (bench.scenario) applied to ``points`` (n, 3) themselves: (constrained
    ids (c,), their targets (c, 3))."""
    from bench.scenario import bend_scenario
    scenario = bend_scenario(points)
    ids = np.concatenate([scenario.anchor_ids, scenario.handle_ids])
    return ids, np.concatenate([points[scenario.anchor_ids], scenario.move(points[scenario.handle_ids])])


def ribbon(length_cells, width=1e-4, rows=3):
    """Thin flat strip 1 long and ``width`` wide: a (length_cells + 1) x rows grid of float32-rounded
    points, two triangles per cell."""
    x, y = np.linspace(0.0, 1.0, length_cells + 1), np.linspace(0.0, width, rows)
    gx, gy = np.meshgrid(x, y, indexing="ij")
    points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1).astype(np.float32).astype(np.float64)
    index = np.arange(points.shape[0]).reshape(length_cells + 1, rows)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return points, np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def simple_subdivided(points, triangles, levels):
    """The triangles as Blender's Simple subdivision of ``levels`` (>= 1) leaves them, read back
    as triangles: each triangle into three quads (through its edge midpoints and centre), each
    quad into four at every further level, all flat; then each quad (a, b, c, d) split along its
    diagonal a-c. Returns (points (n', 3), triangles (f', 3)), f' = 6 * 4**(levels - 1) * f."""
    polygons = triangles
    for _ in range(levels):
        n, sides = points.shape[0], polygons.shape[1]
        edges = np.sort(np.stack([polygons, np.roll(polygons, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = n + inverse.ravel().reshape(-1, sides)  # mid[:, i]: the midpoint of side (i, i + 1)
        centre = n + unique.shape[0] + np.arange(polygons.shape[0])
        points = np.concatenate([points, points[unique].mean(axis=1), points[polygons].mean(axis=1)])
        # Corner i keeps the quad (corner, midpoint after it, centre, midpoint before it).
        polygons = np.concatenate([np.stack([polygons[:, i], mid[:, i], centre, mid[:, i - 1]], axis=1)
                                   for i in range(sides)])
    return points, np.concatenate([polygons[:, [0, 1, 2]], polygons[:, [0, 2, 3]]])


def bumpy_ball(cells=6, bumps=0.3, frequency=12.0, seed=0):
    """A closed ball of :func:`box` triangles pushed onto a sphere of radius 1 with waves of
    relative height ``bumps`` (about ``frequency`` / pi of them around)."""
    points, tris = box(cells=(cells, cells, cells))
    points = points - 0.5
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    k = np.random.default_rng(seed).normal(size=(2, 3)) * frequency
    radius = 1.0 + bumps * np.sin(points @ k[0]) * np.cos(points @ k[1])
    return points * radius[:, None], tris
