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
   long edge), the new edge not an edge already, no face turned, and the fold across the new
   edge no sharper than across the old one (:data:`FOLD_SLACK`): creases in a bend come from the
   skin's seams over proxy folds, and a flip that turns a fold across the proxy's crease line
   moves a seam there (a thin rod's bend, radius 0.1: 705 creases with such flips, 168 without,
   239 with no repair). A flip may leave both faces slivers, their least angle higher (a cap
   beside a fair face made two needles: caps bind worse);
2. collapse: a cap's apex merged into the nearer end of its long edge (which keeps a crease's
   line where it was), a needle's short edge merged into one of its ends, where the merge keeps
   the mesh manifold (the link condition), turns no face over and leaves fewer slivers among the
   faces it remakes than the apex had. A merge takes two faces away: merges stop where the proxy
   would keep fewer than :data:`KEEP_FACES` of the build's target (a thin rod lost 5 % of its faces and a flat sheet 28 % when they did not),
   and at most :data:`TRIES` are tried per merge allowed; vertices at one point (within
   :data:`COINCIDENT` of the diagonal: their faces have no area) merge whatever the count;
3. relaxation: a sliver's vertex moved in its tangent plane towards its one-ring's centre, where
   its faces lie within :data:`RELAX_FLAT_DEGREES` of its normal (not on a crease or a tip) and
   no more of its faces are slivers after; a pass moves every such vertex that is the worst on
   each of its faces at once (no two share a face).

What is maximised is the least angle of the faces each operation remakes; it never falls, so the
mesh's least angle never falls either. Each operation repeats until a pass changes nothing, at most
:data:`PASSES` passes, and within a budget of :data:`WORK` face-angle rows evaluated per proxy face
(the operations' :data:`SHARES` of it in turn; a pass under way finishes): the work grows with the
proxy, never with how stubborn its slivers are (a thin rod of radius 0.02 took 23,784 face_angles
calls and 9.5 s before the budget and the one-pass relaxation). Flips and relaxation leave faces
with a corner on the border as they are: the skin binds detail beyond an open border over the
faces around the border's vertices, extended, and fans remade there fold that detail when the
proxy bends (the flat alligator's bend: 44 -> 213 creases with them, 0 without; its border's caps
collapsed). Only slivers and their neighbours change, so a proxy without slivers comes back as it
went in.
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
#: A flip leaves the cosine of the fold across its edge (between the two faces' normals) at most
#: this much under the old one's.
FOLD_SLACK = 1e-4
#: A flip raises the least angle of its two faces by more than this (degrees).
GAIN_DEGREES = 0.5
#: A vertex is relaxed only where its faces' normals lie within this of its own (degrees).
RELAX_FLAT_DEGREES = 25.0
#: Passes of each operation at most.
PASSES = 20
#: Merges stop where the proxy would keep fewer than this share of the build's target faces (each
#: takes two faces away); vertices at one point still merge.
KEEP_FACES = 0.95
#: The collapses try at most this many merges per merge the floor allows (vertices at one point
#: aside).
TRIES = 4
#: The repair evaluates at most this many face-angle rows per proxy face (and a pass's worth more).
WORK = 40
#: The shares of the budget the operations may reach in turn (flips, collapses, relaxation, flips);
#: what one leaves goes to the next.
SHARES = (0.3, 0.3, 0.2, 0.2)


def face_angles(points, triangles):
    """(k, 3) the angle in degrees at each corner of the faces ``triangles`` (k, 3) over ``points``."""
    corners = points[triangles]
    edges = corners[:, [1, 2, 0]] - corners  # edge i runs from corner i to corner i + 1
    before = edges[:, [2, 0, 1]]  # the edge into corner i
    lengths = np.sqrt((edges * edges).sum(axis=2))
    lengths = lengths * lengths[:, [2, 0, 1]]
    cosine = -(edges * before).sum(axis=2) / np.where(lengths > 0.0, lengths, 1.0)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def is_sliver(angles):
    """(k,) bool: faces whose corner ``angles`` (k, 3) (degrees) make them a needle or a cap."""
    return (angles.min(axis=1) < SLIVER_DEGREES) | (angles.max(axis=1) > CAP_DEGREES)


def repair_slivers(points, triangles, target=None):
    """(points (m', 3), triangles (k', 3), remap (m,) the vertex each of ``points`` is now, figures)
    of the proxy ``points`` (m, 3), ``triangles`` (k, 3) repaired: flips, then collapses, then
    relaxation, then flips again (see the module). ``target`` (the build's target faces): merges
    stop at :data:`KEEP_FACES` of it (None: no floor). ``figures`` (a dict, the build's stats):
    ``sliver_flips``, ``sliver_merges`` (vertices at one point among them: ``sliver_coincident``),
    ``sliver_moves``, ``sliver_passes``, ``sliver_angle_rows`` (face-angle rows evaluated, at most
    :data:`WORK` per face and a pass's worth more), ``proxy_short_of_target`` (why the proxy has
    under 95 % of ``target`` faces, or ""). The inputs are not changed."""
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    work = _Work(WORK * max(triangles.shape[0], 1))
    floor = 0 if target is None else int(np.ceil(KEEP_FACES * target))
    border = _border_vertices(triangles, points.shape[0])
    work.limit = SHARES[0] * work.budget
    faces, flips = flip_slivers(points, triangles, border, work)
    work.limit = sum(SHARES[:2]) * work.budget
    merged_points, faces, remap, merges, coincident = collapse_slivers(points, faces, floor, work)
    border = _border_vertices(faces, merged_points.shape[0])
    work.limit = sum(SHARES[:3]) * work.budget
    relaxed, moves = relax_slivers(merged_points, faces, border, work)
    work.limit = work.budget
    faces, more = flip_slivers(relaxed, faces, border, work)
    short = ""
    if target is not None and faces.shape[0] < 0.95 * target:
        reasons = []
        if triangles.shape[0] < 0.95 * target:
            reasons.append(f"the simplifier stopped at {triangles.shape[0]} faces")
        if coincident:
            reasons.append(f"{coincident} pairs of proxy vertices at one point merged ({2 * coincident} faces "
                           "without area)")
        short = "; ".join(reasons) or f"slivers merged ({merges} merges)"
    figures = dict(sliver_flips=flips + more, sliver_merges=merges, sliver_coincident=coincident,
                   sliver_moves=moves, sliver_passes=work.passes, sliver_angle_rows=work.rows,
                   proxy_short_of_target=short)
    return relaxed, faces, remap, figures


def no_repair(points, triangles, target=None):
    """:func:`repair_slivers`'s answer for the proxy left as it is (the benchmark's and the tests'
    build without the repair): ``points``, ``triangles``, the identity remap, zero figures."""
    points = np.asarray(points, dtype=np.float64)
    figures = dict(sliver_flips=0, sliver_merges=0, sliver_coincident=0, sliver_moves=0, sliver_passes=0,
                   sliver_angle_rows=0, proxy_short_of_target="")
    return points, np.asarray(triangles, dtype=np.int64), np.arange(points.shape[0]), figures


class _Work:
    """The repair's work: face-angle rows evaluated and passes made, against a budget of rows
    (``limit``: the rows the operation under way may reach, its share of the budget and what the
    ones before left); every operation stops its passes once it reaches its limit."""

    def __init__(self, budget):
        self.budget, self.limit, self.rows, self.passes = budget, budget, 0, 0

    def angles(self, points, triangles):
        self.rows += triangles.shape[0]
        return face_angles(points, triangles)

    def next_pass(self):
        """Whether another pass may start (counts it)."""
        if self.rows >= self.limit:
            return False
        self.passes += 1
        return True


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


def flip_slivers(points, triangles, border, work=None):
    """((k, 3) ``triangles`` with the shared edges of slivers flipped, flips made) for ``points``
    (m, 3): where a flip raises the least angle of the pair by more than :data:`GAIN_DEGREES`
    (operation 1 of the module), worst pair first, a face at
    most once a pass, until a pass flips nothing, :data:`PASSES` passes or ``work`` (a _Work) is
    spent. ``border`` (m,) bool: faces with a border corner stay. Vertices do not change."""
    work = _Work(np.inf) if work is None else work
    faces = np.array(triangles, dtype=np.int64, copy=True)
    m = points.shape[0]
    flat = np.cos(np.radians(FLAT_DEGREES))
    total = 0
    for _ in range(PASSES):
        if not work.next_pass():
            break
        angles = work.angles(points, faces)
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
        # A higher least angle, even where both new faces stay slivers: a cap beside a fair face
        # made two needles binds better (fandisk's bend: 227 creases where such flips were refused,
        # 132 with them).
        better = np.minimum(work.angles(points, new_first).min(axis=1),
                            work.angles(points, new_second).min(axis=1)) > worst + GAIN_DEGREES
        # The fold across the new edge no sharper than across the old one (FOLD_SLACK: flat pairs
        # stay flippable): a flip that turns the pair's fold across a crease line seams the skin.
        fold = (np.einsum("ij,ij->i", unit_new_first, unit_new_second)
                >= np.einsum("ij,ij->i", unit_first, unit_second) - FOLD_SLACK)
        ok = np.flatnonzero((area_first > 0.0) & (area_second > 0.0) & (planar | thin) & upright & better & fold)
        ok = ok[np.argsort(worst[ok], kind="stable")]
        ends = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        new_keys = np.minimum(c[ok], d[ok]) * m + np.maximum(c[ok], d[ok])
        exists = np.isin(new_keys, ends[:, 0] * m + ends[:, 1]).tolist()
        old_keys = (np.minimum(a[ok], b[ok]) * m + np.maximum(a[ok], b[ok])).tolist()
        touched = np.zeros(faces.shape[0], dtype=bool)
        added, removed = set(), set()
        flipped = 0
        for pair, new_edge, there, old_edge in zip(ok.tolist(), new_keys.tolist(), exists, old_keys):
            f, g = first[pair], second[pair]
            if touched[f] or touched[g] or new_edge in added or (there and new_edge not in removed):
                continue
            faces[f], faces[g] = new_first[pair], new_second[pair]
            touched[f] = touched[g] = True
            removed.add(old_edge)
            added.add(new_edge)
            flipped += 1
        total += flipped
        if not flipped:
            break
    return faces, total


def collapse_slivers(points, triangles, floor=0, work=None):
    """Slivers collapsed (operation 2 of the module), worst first, until a pass merges nothing,
    :data:`PASSES` passes or ``work`` (a _Work) is spent: (points (m', 3) the vertices kept, in
    their order, triangles (k', 3), remap (m,) the vertex each earlier one is now, merges made,
    of them merges of vertices at one point). ``points`` (m, 3), ``triangles`` (k, 3). A merge
    takes two faces away: none is made that would leave fewer than ``floor`` faces, and at most
    :data:`TRIES` merges are tried per merge the floor allows; vertices within
    :data:`COINCIDENT` of the diagonal of each other (faces without area) still merge."""
    work = _Work(np.inf) if work is None else work
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
    left, merges, at_one_point = faces.shape[0], 0, 0
    tries = TRIES * max((left - floor) // 2, 0)
    for _ in range(PASSES):
        if not work.next_pass():
            break
        live = np.flatnonzero(alive)
        angles = work.angles(points, faces[live])
        sliver = is_sliver(angles)
        slivers = live[sliver][np.argsort(angles[sliver].min(axis=1), kind="stable")]
        corners = points[faces[slivers]]
        edges = corners[:, [1, 2, 0]] - corners
        at_point = (np.sqrt((edges * edges).sum(axis=2)).min(axis=1) <= coincident).tolist()
        merged = 0
        for sliver, close in zip(slivers.tolist(), at_point):
            if not alive[sliver] or ((left - 2 < floor or tries <= 0) and not close):
                continue  # under the floor, or the tries spent, only vertices at one point still merge
            if work.rows >= work.limit:
                break
            own = work.angles(points, faces[sliver][None])[0]
            if not is_sliver(own[None])[0]:
                continue
            for apex, into in _merges(points, faces[sliver].tolist(), own):
                one_point = _length(points[apex] - points[into]) <= coincident
                if not one_point and (left - 2 < floor or tries <= 0):
                    continue
                tries -= not one_point
                if not _collapsible(points, faces, around, apex, into, own.min(), coincident, work):
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
                at_one_point += one_point
                left -= 2
                break
        merges += merged
        if not merged:
            break
    kept = np.unique(target)
    rank = np.full(m, -1, dtype=np.int64)
    rank[kept] = np.arange(kept.size)
    return np.ascontiguousarray(points[kept]), rank[faces[alive]], rank[target], merges, at_one_point


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


def _collapsible(points, faces, around, apex, into, least, coincident, work):
    """Whether merging ``apex`` into ``into`` keeps the live faces (``around``: vertex -> its live
    face ids) manifold (their edge has two faces, the two vertices share no neighbour but the
    two across it), turns none over, leaves every remade face's least angle above ``least`` and
    fewer slivers than the apex's faces had, and moves the surface by at most :data:`MOVED` of the merged edge's length (the apex's distance
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
    remade_angles = work.angles(points, remade)
    if remade_angles.min() <= least:
        return False
    if is_sliver(remade_angles).sum() >= is_sliver(work.angles(points, with_apex)).sum():
        return False  # fewer slivers than the apex's faces had, the two going among them
    normals = after / np.linalg.norm(after, axis=1)[:, None]
    away = np.abs(np.einsum("ij,ij->i", points[apex] - points[remade[:, 0]], normals))
    return bool(away.max() <= MOVED * _length(points[apex] - points[into]))


def relax_slivers(points, triangles, border, work=None):
    """((m, 3) ``points`` with the slivers' vertices relaxed, moves made) (operation 3 of the
    module): each pass takes the slivers' vertices whose faces lie within
    :data:`RELAX_FLAT_DEGREES` of its normal, those with the worst face among their neighbours'
    (no two share a face, so each is judged on its own faces), and moves each by the whole, half
    or a quarter of its tangential step to its one-ring's centre, the first that raises the least
    angle of its faces, leaves no more slivers among them and turns none over; passes until one
    moves nothing, :data:`PASSES` passes or ``work`` (a _Work) is spent. ``triangles`` (k, 3),
    ``border`` (m,) bool: border vertices stay. The input is not changed."""
    work = _Work(np.inf) if work is None else work
    points = np.array(points, dtype=np.float64, copy=True)
    faces = np.asarray(triangles, dtype=np.int64)
    m = points.shape[0]
    indptr, around = vertex_faces(faces, m)
    owner = np.repeat(np.arange(m), np.diff(indptr))  # the vertex of each (vertex, face) incidence
    flat = np.cos(np.radians(RELAX_FLAT_DEGREES))
    total = 0
    for _ in range(PASSES):
        if not work.next_pass():
            break
        angles = work.angles(points, faces)
        least, sliver = angles.min(axis=1), is_sliver(angles)
        candidate = np.zeros(m, dtype=bool)
        candidate[faces[sliver].ravel()] = True
        candidate &= ~border
        # Flat enough: every face's normal within RELAX_FLAT_DEGREES of the area-weighted normal.
        areas = face_cross(points, faces)[around]
        normal = np.stack([np.bincount(owner, areas[:, axis], minlength=m) for axis in range(3)], axis=1)
        sizes, lengths = np.sqrt((areas * areas).sum(axis=1)), np.sqrt((normal * normal).sum(axis=1))
        cosine = (areas * normal[owner]).sum(axis=1) / np.where(sizes * lengths[owner] > 0.0, sizes * lengths[owner], 1.0)
        steep = np.bincount(owner, (cosine < flat) | (sizes == 0.0), minlength=m) > 0
        candidate &= ~steep & (lengths > 0.0)
        worst = np.full(m, np.inf)
        np.minimum.at(worst, owner, least[around])
        chosen = _worst_on_their_faces(candidate, worst, faces, owner, around)
        if not chosen.any():
            break
        rows = np.flatnonzero(chosen[owner])  # incidences of the chosen vertices, grouped by vertex
        vertex, own = owner[rows], faces[around[rows]]
        starts = np.flatnonzero(np.r_[True, vertex[1:] != vertex[:-1]])
        movers = vertex[starts]
        unit = normal[movers] / lengths[movers][:, None]
        others = points[own].sum(axis=1) - points[vertex]  # the face's two other corners
        count = np.bincount(vertex, minlength=m)[movers]
        centre = np.stack([np.bincount(vertex, others[:, axis], minlength=m)[movers] for axis in range(3)],
                          axis=1) / (2.0 * count[:, None])
        step = centre - points[movers]
        step -= (step * unit).sum(axis=1)[:, None] * unit
        before = np.minimum.reduceat(least[around[rows]], starts)
        slivers = np.add.reduceat(sliver[around[rows]].astype(np.int64), starts)
        old = points[movers].copy()
        waiting = np.ones(movers.size, dtype=bool)
        for share in (1.0, 0.5, 0.25):
            points[movers[waiting]] = old[waiting] + share * step[waiting]
            after = work.angles(points, own)
            upright = (face_cross(points, own) * areas[rows]).sum(axis=1) > 0.0
            good = ((np.minimum.reduceat(after.min(axis=1), starts) > before)
                    & (np.add.reduceat(is_sliver(after).astype(np.int64), starts) <= slivers)
                    & (np.minimum.reduceat(upright.astype(np.int64), starts) > 0))
            waiting &= ~good
            points[movers[waiting]] = old[waiting]
            if not waiting.any():
                break
        moved = int(movers.size - waiting.sum())
        total += moved
        if not moved:
            break
    return points, total


def _worst_on_their_faces(candidate, worst, faces, owner, around):
    """(m,) bool: the ``candidate`` (m,) bool vertices whose key is the lowest among the candidates
    on each of their faces (key: the rank by ``worst`` (m,), ties by vertex id), so no two chosen
    share a face and the worst candidate is always chosen. ``faces`` (k, 3); ``owner`` and
    ``around`` (3k,): each (vertex, face) incidence's vertex and face (geometry.vertex_faces)."""
    m = candidate.shape[0]
    ids = np.flatnonzero(candidate)
    key = np.full(m, ids.size, dtype=np.int64)
    key[ids[np.argsort(worst[ids], kind="stable")]] = np.arange(ids.size)
    lowest = key[faces].min(axis=1)
    return candidate & (np.bincount(owner, lowest[around] != key[owner], minlength=m) == 0)
