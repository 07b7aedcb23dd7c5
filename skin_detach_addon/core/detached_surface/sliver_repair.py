"""The proxy without slivers: needles and caps the quadric collapses leave, repaired on the proxy.

Arrays: proxy points (m, 3) float64 indexed by proxy vertex, triangles (k, 3) int64 (consistently
oriented) indexed by proxy face; ``remap`` (m,) int64 maps every vertex before the repair to its
vertex after.

Quadric collapses place vertices well but keep the connectivity they happened to collapse into:
where any placement costs nothing (a flat or evenly curved stretch, a subdivided mesh's flat
triangles) needles (an angle near 0) and caps (an angle near 180 degrees) are left, which a
wireframe draws as spikes and over which the skin binds badly. A face is a sliver when its least
angle is under :data:`SLIVER_DEGREES` or its largest over :data:`CAP_DEGREES`. Three local
operations take slivers out, each made only where it raises the least angle of the faces it
remakes and keeps the surface where it was (within :data:`MOVED` of the edge it works on):

1. flip: the shared edge of a sliver and its neighbour replaced by the quad's other diagonal,
   where the two faces are nearly coplanar (normals within :data:`FLAT_DEGREES`) or the quad's two
   triangulations lie within :data:`THIN` of the edge's length of each other (a cap's apex on its
   long edge, whatever the fold beside it), the new edge not an edge already and no face turned;
2. collapse: a cap's apex merged into the nearer end of its long edge (which keeps a crease's
   line where it was), a needle's short edge merged into one of its ends, where the merge keeps
   the mesh manifold (the link condition) and turns no face over;
3. relaxation: a sliver's vertex moved in its tangent plane towards its one-ring's centre, where
   its faces lie within :data:`RELAX_FLAT_DEGREES` of its normal (not on a crease or a tip).

What is maximised is the least angle of the faces each operation remakes; it never falls, so the
mesh's least angle never falls either. Each operation repeats until a pass over the slivers
changes nothing (at most :data:`PASSES` passes). Flips and relaxation leave faces with a corner on
the border as they are: the skin binds detail beyond an open border over the faces around the
border's vertices, extended, and fans remade there fold that detail when the proxy bends (the flat
alligator's bend: 44 -> 213 creases with them, 0 without; its border's caps collapsed). Only
slivers and their neighbours change, so a proxy without slivers comes back as it went in.
"""

import numpy as np

from ..geometry import bbox_diagonal, cross_rows, face_cross, unique_edges, unit_rows, vertex_faces

#: A face whose least angle is under this is a sliver (degrees).
SLIVER_DEGREES = 10.0
#: A face whose largest angle is over this is a cap: its apex lies nearly on its longest edge.
CAP_DEGREES = 170.0
#: Two faces are coplanar enough to flip their shared edge when their normals are this close.
FLAT_DEGREES = 12.0
#: Or, where they are not, when the two triangulations of their quad lie this close (a fraction of
#: the shared edge's length).
THIN = 0.02
#: A collapse moves the surface by this fraction of the merged edge's length at most.
MOVED = 0.05
#: Vertices this close (a fraction of the proxy's bounding-box diagonal) are one point: merged
#: wherever the mesh stays manifold.
COINCIDENT = 1e-6
#: A flip raises the least angle of its two faces by more than this (degrees).
GAIN_DEGREES = 0.5
#: A vertex is relaxed only where its faces' normals lie within this of its own (degrees).
RELAX_FLAT_DEGREES = 25.0
#: Passes of each operation at most.
PASSES = 20


def face_angles(points, triangles):
    """(k, 3) the angle in degrees at each corner of the faces ``triangles`` (k, 3) over ``points``."""
    corners = points[triangles]
    out = np.empty(triangles.shape, dtype=np.float64)
    for corner in range(3):
        u = corners[:, (corner + 1) % 3] - corners[:, corner]
        v = corners[:, (corner + 2) % 3] - corners[:, corner]
        lengths = np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)
        cosine = np.einsum("ij,ij->i", u, v) / np.where(lengths > 0.0, lengths, 1.0)
        out[:, corner] = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return out


def is_sliver(angles):
    """(k,) bool: faces whose corner ``angles`` (k, 3) (degrees) make them a needle or a cap."""
    return (angles.min(axis=1) < SLIVER_DEGREES) | (angles.max(axis=1) > CAP_DEGREES)


def repair_slivers(points, triangles):
    """(points (m', 3), triangles (k', 3), remap (m,) the vertex each of ``points`` is now) of the
    proxy ``points`` (m, 3), ``triangles`` (k, 3) repaired: flips, then collapses, then
    relaxation, then flips again (see the module). The inputs are not changed."""
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    border = _border_vertices(triangles, points.shape[0])
    faces = flip_slivers(points, triangles, border)
    merged_points, faces, remap = collapse_slivers(points, faces)
    border = _border_vertices(faces, merged_points.shape[0])
    relaxed = relax_slivers(merged_points, faces, border)
    faces = flip_slivers(relaxed, faces, border)
    return relaxed, faces, remap


def _length(vector):
    """The length of a 3-vector (numpy's own arithmetic: BLAS's dot product rounds per CPU, and the
    build is the same bit for bit on every machine)."""
    return float(np.sqrt(vector[0] * vector[0] + vector[1] * vector[1] + vector[2] * vector[2]))


def _dots(rows, vector):
    """(r,) the dot products of ``rows`` (r, 3) with ``vector`` (3,), in numpy's own arithmetic."""
    return rows[:, 0] * vector[0] + rows[:, 1] * vector[1] + rows[:, 2] * vector[2]


def _border_vertices(triangles, m):
    """(m,) bool: vertices on an edge only one face has."""
    edges, counts = unique_edges(triangles)
    border = np.zeros(m, dtype=bool)
    border[edges[counts == 1].ravel()] = True
    return border


def _interior_pairs(faces, m):
    """Every edge two faces share, once: (a, b, c, d, first, second) (e,) each, ``first`` the face
    with the half-edge a -> b and third corner c, ``second`` the face with b -> a and third d."""
    k = faces.shape[0]
    start = faces.ravel()
    end = faces[:, [1, 2, 0]].ravel()
    third = faces[:, [2, 0, 1]].ravel()
    owner = np.repeat(np.arange(k), 3)
    keys = start * m + end
    order = np.argsort(keys, kind="stable")
    found = np.searchsorted(keys[order], end * m + start)
    found = np.minimum(found, keys.size - 1)
    back = order[found]
    paired = (keys[back] == end * m + start) & (start < end)
    half, other = np.flatnonzero(paired), back[paired]
    return start[half], end[half], third[half], third[other], owner[half], owner[other]


def flip_slivers(points, triangles, border):
    """(k, 3) ``triangles`` with the shared edges of slivers flipped where that raises the least
    angle of the pair by more than :data:`GAIN_DEGREES` (operation 1 of the module), worst pair
    first, a face at most once a pass, until a pass flips nothing. ``border`` (m,) bool: faces
    with a border corner stay. Vertices, their count and order do not change."""
    faces = np.array(triangles, dtype=np.int64, copy=True)
    m = points.shape[0]
    flat = np.cos(np.radians(FLAT_DEGREES))
    for _ in range(PASSES):
        angles = face_angles(points, faces)
        least, sliver = angles.min(axis=1), is_sliver(angles)
        a, b, c, d, first, second = _interior_pairs(faces, m)
        keep = (sliver[first] | sliver[second]) & (c != d) & ~(border[a] | border[b] | border[c] | border[d])
        a, b, c, d, first, second = (x[keep] for x in (a, b, c, d, first, second))
        worst = np.minimum(least[first], least[second])
        # Where the quad a-d-b-c lies: nearly one plane, or its two triangulations close together
        # (three times the tetrahedron's volume over the larger face's area, against the edge).
        old_first, old_second = face_cross(points, faces[first]), face_cross(points, faces[second])
        (unit_first, area_first), (unit_second, area_second) = unit_rows(old_first), unit_rows(old_second)
        volume = np.abs(np.einsum("ij,ij->i", cross_rows(points[b] - points[a], points[c] - points[a]),
                                  points[d] - points[a])) / 6.0
        larger = np.maximum(area_first, area_second) / 2.0
        thickness = np.divide(3.0 * volume, larger, out=np.full(larger.shape, np.inf), where=larger > 0.0)
        planar = np.einsum("ij,ij->i", unit_first, unit_second) >= flat
        thin = thickness <= THIN * np.linalg.norm(points[a] - points[b], axis=1)
        # The new faces a-d-c and d-b-c: none turned against the pair's area-weighted normal (a cap's
        # own normal says little about where the surface faces), and a higher least angle.
        new_first, new_second = np.stack([a, d, c], axis=1), np.stack([d, b, c], axis=1)
        facing = old_first + old_second
        unit_new_first, length_first = unit_rows(face_cross(points, new_first))
        unit_new_second, length_second = unit_rows(face_cross(points, new_second))
        upright = ((np.einsum("ij,ij->i", unit_new_first, facing) > 0.0) & (length_first > 0.0)
                   & (np.einsum("ij,ij->i", unit_new_second, facing) > 0.0) & (length_second > 0.0))
        better = np.minimum(face_angles(points, new_first).min(axis=1),
                            face_angles(points, new_second).min(axis=1)) > worst + GAIN_DEGREES
        ok = np.flatnonzero((area_first > 0.0) & (area_second > 0.0) & (planar | thin) & upright & better)
        ok = ok[np.argsort(worst[ok], kind="stable")]
        edges = set((np.minimum(faces, faces[:, [1, 2, 0]]) * m + np.maximum(faces, faces[:, [1, 2, 0]])).ravel().tolist())
        touched = np.zeros(faces.shape[0], dtype=bool)
        flipped = 0
        for pair in ok.tolist():
            f, g = first[pair], second[pair]
            new_edge = min(c[pair], d[pair]) * m + max(c[pair], d[pair])
            if touched[f] or touched[g] or new_edge in edges:
                continue
            faces[f], faces[g] = new_first[pair], new_second[pair]
            touched[f] = touched[g] = True
            edges.discard(min(a[pair], b[pair]) * m + max(a[pair], b[pair]))
            edges.add(new_edge)
            flipped += 1
        if not flipped:
            break
    return faces


def collapse_slivers(points, triangles):
    """Slivers collapsed (operation 2 of the module), worst first, until a pass merges nothing:
    (points (m', 3) the vertices kept, in their order, triangles (k', 3), remap (m,) the vertex
    each earlier one is now)."""
    points = np.asarray(points, dtype=np.float64)
    faces = np.array(triangles, dtype=np.int64, copy=True)
    m = points.shape[0]
    target = np.arange(m)  # vertex -> the vertex it was merged into (itself if none)
    alive = np.ones(faces.shape[0], dtype=bool)
    around = [set() for _ in range(m)]  # vertex -> its live faces
    for index, face in enumerate(faces.tolist()):
        for vertex in face:
            around[vertex].add(index)
    coincident = COINCIDENT * bbox_diagonal(points) if m else 0.0
    for _ in range(PASSES):
        live = np.flatnonzero(alive)
        angles = face_angles(points, faces[live])
        sliver = is_sliver(angles)
        slivers = live[sliver]
        order = np.argsort(angles[sliver].min(axis=1), kind="stable")
        merged = 0
        for sliver in slivers[order].tolist():
            if not alive[sliver]:
                continue
            own = face_angles(points, faces[sliver][None])[0]
            if not is_sliver(own[None])[0]:
                continue
            for apex, into in _merges(points, faces[sliver].tolist(), own):
                if not _collapsible(points, faces, around, apex, into, own.min(), coincident):
                    continue
                for index in list(around[apex]):
                    face = faces[index]
                    if (face == into).any():  # the two faces across the edge go
                        alive[index] = False
                        for vertex in face.tolist():
                            around[vertex].discard(index)
                    else:
                        face[face == apex] = into
                        around[into].add(index)
                around[apex] = set()
                target[target == apex] = into
                merged += 1
                break
        if not merged:
            break
    kept = np.unique(target)
    rank = np.full(m, -1, dtype=np.int64)
    rank[kept] = np.arange(kept.size)
    return np.ascontiguousarray(points[kept]), rank[faces[alive]], rank[target]


def _merges(points, face, angles):
    """(apex, into) pairs that would take the sliver ``face`` (3 vertex ids) with corner ``angles``
    (3,) out, the shorter merged edge first: a cap's apex into either end of its long edge, else
    either end of the needle's short edge into the other."""
    if angles.max() > CAP_DEGREES:
        corner = int(np.argmax(angles))
        pairs = [(face[corner], face[(corner + k) % 3]) for k in (1, 2)]
    else:
        corner = int(np.argmin(angles))
        ends = (face[(corner + 1) % 3], face[(corner + 2) % 3])
        pairs = [ends, ends[::-1]]
    pairs.sort(key=lambda pair: _length(points[pair[1]] - points[pair[0]]))
    return pairs


def _collapsible(points, faces, around, apex, into, least, coincident):
    """Whether merging ``apex`` into ``into`` keeps the live faces (``around``: vertex -> its live
    face ids) manifold (their edge has two faces, the two vertices share no neighbour but the
    two across it), turns none over, leaves every remade face's least angle above ``least`` and
    moves the surface by at most :data:`MOVED` of the merged edge's length (the apex's distance
    from its remade faces' planes). Two vertices within ``coincident`` of each other merge where
    the mesh stays manifold: no face moves."""
    with_apex = faces[sorted(around[apex])]
    with_into = faces[sorted(around[into])]
    shared = (with_apex == into).any(axis=1)
    if shared.sum() != 2:
        return False
    across = set(with_apex[shared].ravel().tolist()) - {apex, into}
    if (set(with_apex.ravel().tolist()) - {apex}) & (set(with_into.ravel().tolist()) - {into}) != across:
        return False
    others = with_apex[~shared]
    if not others.shape[0]:
        return False
    if _length(points[apex] - points[into]) <= coincident:
        return True
    remade = np.where(others == apex, into, others)
    before, after = face_cross(points, others), face_cross(points, remade)
    if not (np.einsum("ij,ij->i", before, after) > 0.0).all():
        return False
    if face_angles(points, remade).min() <= least:
        return False
    normals = after / np.linalg.norm(after, axis=1)[:, None]
    away = np.abs(np.einsum("ij,ij->i", points[apex] - points[remade[:, 0]], normals))
    return bool(away.max() <= MOVED * _length(points[apex] - points[into]))


def relax_slivers(points, triangles, border):
    """(m, 3) ``points`` with the slivers' vertices relaxed (operation 3 of the module): each moved
    by the whole, half or a quarter of its tangential step to its one-ring's centre, the first
    that raises the least angle of its faces and turns none of them over; sweeps until none
    moves. ``border`` (m,) bool: border vertices stay. The input is not changed."""
    points = np.array(points, dtype=np.float64, copy=True)
    faces = np.asarray(triangles, dtype=np.int64)
    indptr, around = vertex_faces(faces, points.shape[0])
    flat = np.cos(np.radians(RELAX_FLAT_DEGREES))
    for _ in range(PASSES):
        chosen = np.unique(faces[is_sliver(face_angles(points, faces))])
        moved = 0
        for vertex in chosen[~border[chosen]].tolist():
            own = faces[around[indptr[vertex]:indptr[vertex + 1]]]
            areas = face_cross(points, own)
            normal, sizes = areas.sum(axis=0), np.linalg.norm(areas, axis=1)
            length = _length(normal)
            if length == 0.0 or (sizes == 0.0).any() or (_dots(areas, normal) / (sizes * length) < flat).any():
                continue
            normal /= length
            step = points[own[own != vertex]].mean(axis=0) - points[vertex]
            step -= _dots(step[None], normal)[0] * normal
            before = face_angles(points, own).min()
            old = points[vertex].copy()
            for share in (1.0, 0.5, 0.25):
                points[vertex] = old + share * step
                if (np.einsum("ij,ij->i", face_cross(points, own), areas) > 0.0).all() and face_angles(points, own).min() > before:
                    moved += 1
                    break
                points[vertex] = old
        if not moved:
            break
    return points
