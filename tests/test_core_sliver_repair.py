"""The proxy's sliver repair: slivers out, the least angle never falling, the surface kept, the
border and sliver-free proxies left alone, rigid motion and scale, the build's use of it, and its
limits (issue 52): faces kept near the target, work bounded, on thin rods and a flat sheet."""

import numpy as np
import pytest

from shapes import cylinder, plane, random_rotation
from skin_detach_addon.core import SkinDetachedSurface
from skin_detach_addon.core.geometry import unique_edges, vertex_faces
from skin_detach_addon.core.detached_surface import surface as surface_module
from skin_detach_addon.core.detached_surface.sliver_repair import (CAP_DEGREES, KEEP_FACES, PASSES, SLIVER_DEGREES,
                                                                   WORK, collapse_slivers, face_angles,
                                                                   flip_slivers, is_sliver, no_repair,
                                                                   relax_slivers, repair_slivers,
                                                                   _worst_on_their_faces)


def octahedron_sphere(levels=2):
    """(points (n, 3), triangles (k, 3)): an octahedron split ``levels`` times, on the unit sphere."""
    points = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    faces = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    points = [np.array(p, dtype=float) for p in points]
    for _ in range(levels):
        middle, out = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in middle:
                p = points[a] + points[b]
                points.append(p / np.linalg.norm(p))
                middle[key] = len(points) - 1
            return middle[key]
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            out += [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        faces = out
    return np.array(points), np.array(faces, dtype=np.int64)


def with_slivers(points, triangles, vertices, toward, share=0.97):
    """``points`` with each of ``vertices`` moved ``share`` of the way to the midpoint of the
    edge ``toward`` gives (a pair of vertex ids each): caps at the moved vertex, needles beside."""
    points = points.copy()
    for vertex, (a, b) in zip(vertices, toward):
        middle = (points[a] + points[b]) / 2
        points[vertex] += share * (middle - points[vertex])
    return points


def flat_with_slivers():
    """A 12 x 12 flat grid (z = 0) with three interior vertices pushed onto edges: caps and needles."""
    points, triangles = plane(n=12)
    points[:, 2] = 0.0
    n = 13
    ids = lambda i, j: i * n + j  # noqa: E731
    moved = [ids(3, 3), ids(6, 8), ids(9, 4)]
    toward = [(ids(3, 4), ids(4, 4)), (ids(6, 9), ids(7, 9)), (ids(9, 5), ids(10, 5))]
    return with_slivers(points, triangles, moved, toward), triangles, moved


def closed_with_slivers():
    points, triangles = octahedron_sphere(3)
    edges, _ = unique_edges(triangles)
    neighbours = {v: set() for v in range(points.shape[0])}
    for a, b in edges.tolist():
        neighbours[a].add(b)
        neighbours[b].add(a)
    moved, toward = [], []
    for vertex in (40, 90, 200):
        a = min(neighbours[vertex])
        b = min(neighbours[vertex] & neighbours[a])
        moved.append(vertex)
        toward.append((a, b))
    return with_slivers(points, triangles, moved, toward), triangles


def least_angle(points, triangles):
    return float(face_angles(points, triangles).min())


def signed_volume(points, triangles):
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def test_the_fixtures_have_slivers():
    for points, triangles in (flat_with_slivers()[:2], closed_with_slivers()):
        assert is_sliver(face_angles(points, triangles)).sum() >= 3


def test_a_flat_proxy_loses_its_slivers_and_stays_where_it_was():
    points, triangles, _ = flat_with_slivers()
    new_points, new_triangles, _, _ = repair_slivers(points, triangles)
    angles = face_angles(new_points, new_triangles)
    assert not is_sliver(angles).any()
    assert angles.min() > least_angle(points, triangles)
    assert np.all(new_points[:, 2] == 0.0)  # in the plane
    area = lambda p, t: 0.5 * np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])[:, 2]  # noqa: E731
    assert np.all(area(new_points, new_triangles) > 0)  # no face turned over
    assert area(new_points, new_triangles).sum() == pytest.approx(area(points, triangles).sum(), rel=1e-12)


def test_a_closed_proxy_stays_closed_with_its_volume():
    points, triangles = closed_with_slivers()
    new_points, new_triangles, _, _ = repair_slivers(points, triangles)
    assert is_sliver(face_angles(new_points, new_triangles)).sum() == 0
    assert least_angle(new_points, new_triangles) > least_angle(points, triangles)
    _, counts = unique_edges(new_triangles)
    assert np.all(counts == 2)
    euler = lambda p, t: p.shape[0] - unique_edges(t)[0].shape[0] + t.shape[0]  # noqa: E731
    assert euler(new_points, new_triangles) == euler(points, triangles) == 2
    assert signed_volume(new_points, new_triangles) == pytest.approx(signed_volume(points, triangles), rel=0.01)
    assert np.linalg.norm(new_points, axis=1).max() <= 1.0 + 1e-12  # on or inside the sphere


def test_a_proxy_without_slivers_comes_back_as_it_went_in():
    points, triangles = octahedron_sphere(3)
    assert not is_sliver(face_angles(points, triangles)).any()
    new_points, new_triangles, remap, _ = repair_slivers(points, triangles)
    assert np.array_equal(new_triangles, triangles) and np.array_equal(new_points, points)
    assert np.array_equal(remap, np.arange(points.shape[0]))


def test_flips_and_moves_leave_the_border_fans():
    """A border vertex pushed next to an inner edge: flips remake no face with a border corner and
    relaxation moves no border vertex (the skin extends detail beyond an open border over the
    border's fans); the repair as a whole still raises the least angle."""
    points, triangles = plane(n=8)
    points[:, 2] = 0.0
    border_vertex, next_on_border, inner = 3, 4, 9 + 4  # row 0 is the border; (1, 4) is inside
    points = with_slivers(points, triangles, [border_vertex], [(next_on_border, inner)])
    assert is_sliver(face_angles(points, triangles)).any()
    edges, counts = unique_edges(triangles)
    border = np.zeros(points.shape[0], dtype=bool)
    border[edges[counts == 1].ravel()] = True
    flipped, _ = flip_slivers(points, triangles, border)
    on_border = border[triangles].any(axis=1)
    assert np.array_equal(flipped[on_border], triangles[on_border])
    relaxed, _ = relax_slivers(points, triangles, border)
    assert np.array_equal(relaxed[border], points[border])
    new_points, new_triangles, _, _ = repair_slivers(points, triangles)
    assert least_angle(new_points, new_triangles) > least_angle(points, triangles)
    everywhere, _ = flip_slivers(points, triangles, np.zeros_like(border))
    assert not np.array_equal(everywhere[on_border], triangles[on_border])  # the fixture has a border flip to refuse


def test_rigid_motion_and_scale_give_the_same_repair():
    points, triangles = closed_with_slivers()
    new_points, new_triangles, remap, _ = repair_slivers(points, triangles)
    rotation = random_rotation(3)
    moved_points, moved_triangles, moved_remap, _ = repair_slivers(2.5 * points @ rotation.T + [4.0, -1.0, 7.0], triangles)
    assert np.array_equal(moved_triangles, new_triangles) and np.array_equal(moved_remap, remap)
    assert np.allclose(moved_points, 2.5 * new_points @ rotation.T + [4.0, -1.0, 7.0], atol=1e-12)


def test_caps_and_needles_are_told_apart():
    angles = np.array([[60.0, 60.0, 60.0], [5.0, 85.0, 90.0], [4.0, 4.0, 172.0], [SLIVER_DEGREES, 80.0, 90.0]])
    assert is_sliver(angles).tolist() == [False, True, True, False]
    assert CAP_DEGREES > 90.0


def test_the_build_repairs_its_proxy_and_rebuilds_its_rest(bundled, monkeypatch):
    points, triangles = bundled("fandisk")
    built = SkinDetachedSurface.build(points, triangles, target_faces=600)
    assert np.abs(built.reconstruct(built.proxy_vertices) - points).max() < 1e-9 * np.ptp(points, axis=0).max() * 1e3
    monkeypatch.setattr(surface_module, "repair_slivers", no_repair)
    unrepaired = SkinDetachedSurface.build(points, triangles, target_faces=600)
    # 118 -> 42: flips that would sharpen a fold across fandisk's creases are left (39 with them).
    assert unrepaired.stats["proxy_slivers"] > 2.5 * max(built.stats["proxy_slivers"], 1)
    assert built.stats["proxy_least_angle"] > unrepaired.stats["proxy_least_angle"]
    assert built.stats["proxy_slivers"] == int(is_sliver(face_angles(built.proxy_vertices, built.proxy_faces)).sum())


def build_on_and_off(monkeypatch, points, triangles, target):
    """(the build with the repair, the same build without it)."""
    built = SkinDetachedSurface.build(points, triangles, target_faces=target)
    with monkeypatch.context() as patch:
        patch.setattr(surface_module, "repair_slivers", no_repair)
        unrepaired = SkinDetachedSurface.build(points, triangles, target_faces=target)
    return built, unrepaired


def assert_within_limits(built, unrepaired, target):
    """Faces at least 95 % of the target (or the stat says why), the least angle and the slivers no
    worse than without the repair, the work within its budget."""
    stats, before = built.stats, unrepaired.stats
    assert stats["proxy_faces"] >= 0.95 * target or stats["proxy_short_of_target"]
    assert stats["proxy_faces"] >= min(int(np.ceil(KEEP_FACES * target)), before["proxy_faces"])  # merges stop there
    assert stats["proxy_least_angle"] >= before["proxy_least_angle"]
    assert stats["proxy_slivers"] <= before["proxy_slivers"]
    # Work: WORK face-angle rows per face of the proxy it was given, and at most one pass's worth
    # over (a relaxation pass evaluates every face and three times the faces it moves: 10 per face).
    assert 0 < stats["sliver_angle_rows"] <= (WORK + 10) * before["proxy_faces"]
    assert stats["sliver_passes"] <= 4 * PASSES


@pytest.mark.parametrize("radius", [0.02, 0.1])
def test_a_thin_rod_keeps_its_faces_and_the_work_stays_bounded(monkeypatch, radius):
    """The reviewer's rod (issue 52: radius 0.02, length 4, 4,826 vertices; 23,784 face_angles
    calls and 507 of 954 faces slivers): a proxy whose faces are long needles whatever is done
    (its 1,000 faces on 0.5 of area, four vertices around)."""
    points, triangles = cylinder(radius=radius, length=4.0, around=24, along=200)
    assert points.shape[0] == 4826
    built, unrepaired = build_on_and_off(monkeypatch, points, triangles, 1000)
    assert_within_limits(built, unrepaired, 1000)


@pytest.mark.parametrize("target", [50, 300])
def test_a_flat_sheet_keeps_its_faces_flat_and_near_the_target(monkeypatch, target):
    """A flat 60 x 60 sheet (issue 52: 36 of 50 and 270 of 300 faces): the repair's merges stop at
    the floor and every move stays in the plane."""
    points, triangles = plane(n=60)
    points[:, 2] = 0.0
    built, unrepaired = build_on_and_off(monkeypatch, points, triangles, target)
    assert_within_limits(built, unrepaired, target)
    assert unrepaired.stats["proxy_slivers"] > built.stats["proxy_slivers"]  # there was something to repair
    assert np.all(built.proxy_vertices[:, 2] == 0.0)
    proxy = built.proxy_vertices[built.proxy_faces]
    normal_z = np.cross(proxy[:, 1] - proxy[:, 0], proxy[:, 2] - proxy[:, 0])[:, 2]
    assert np.all(normal_z > 0) or np.all(normal_z < 0)  # no face turned over


def test_merges_stop_at_the_floor_but_vertices_at_one_point_still_merge():
    points, triangles, _ = flat_with_slivers()
    k = triangles.shape[0]
    _, free, _, merges, _ = collapse_slivers(points, triangles)
    assert merges >= 1 and free.shape[0] == k - 2 * merges  # the fixture has merges to make
    _, kept, _, merges, _ = collapse_slivers(points, triangles, floor=k - 1)
    assert merges == 0 and np.array_equal(kept, triangles)
    _, kept, _, merges, _ = collapse_slivers(points, triangles, floor=k - 2)
    assert merges == 1 and kept.shape[0] == k - 2
    _, _, _, figures = repair_slivers(points, triangles, target=k)
    assert figures["sliver_merges"] <= (k - int(np.ceil(KEEP_FACES * k))) // 2
    # A vertex on top of its neighbour: its faces have no area, and it merges under the floor too.
    edges, counts = unique_edges(triangles)
    inner = edges[counts == 2]
    a, b = inner[len(inner) // 2]
    on_top = points.copy()
    on_top[a] = points[b] + 1e-9
    _, merged, remap, merges, at_one_point = collapse_slivers(on_top, triangles, floor=k)
    assert merges == at_one_point == 1 and merged.shape[0] == k - 2 and remap[a] == remap[b]


def test_a_flip_leaves_the_fold_across_its_edge_no_sharper():
    """A needle (3.5 degrees) and its neighbour, folded 13 degrees across their edge: the other
    diagonal would raise the least angle to 4.2 but fold the pair 16.8 degrees (the skin seams
    where the proxy folds), so the edge stays; laid flat, the same pair flips."""
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.04, 0.058, -0.008], [0.062, -0.549, 0.212]])
    pair, flipped_pair = np.array([[0, 1, 2], [1, 0, 3]]), np.array([[0, 3, 2], [3, 1, 2]])
    free = np.zeros(4, dtype=bool)

    def fold(p, faces):
        n = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
        n /= np.linalg.norm(n, axis=1)[:, None]
        return np.degrees(np.arccos(np.clip(n[0] @ n[1], -1.0, 1.0)))
    assert fold(points, flipped_pair) > fold(points, pair) + 3.0
    assert least_angle(points, flipped_pair) > least_angle(points, pair) + 0.5
    faces, flips = flip_slivers(points, pair, free)
    assert flips == 0 and np.array_equal(faces, pair)
    flat = points.copy()
    flat[:, 2] = 0.0
    faces, flips = flip_slivers(flat, pair, free)
    assert flips == 1 and {tuple(sorted(f)) for f in faces.tolist()} == {(0, 2, 3), (1, 2, 3)}


def test_a_cap_beside_a_fair_face_is_flipped_into_two_needles():
    """A cap (173 degrees) beside a fair face (least angle 10.7): the other diagonal leaves both
    faces slivers, but needles (least angle 2.3 -> 9.4 degrees, no cap): the flip is made (caps
    bind worse: fandisk's bend had 227 creases where such flips were refused, 132 with them)."""
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.352, 0.027, 0.0], [-0.496, -0.283, 0.0]])
    pair, flipped_pair = np.array([[0, 1, 2], [1, 0, 3]]), np.array([[0, 3, 2], [3, 1, 2]])
    assert is_sliver(face_angles(points, pair)).sum() == 1 and is_sliver(face_angles(points, flipped_pair)).sum() == 2
    assert face_angles(points, pair).max() > CAP_DEGREES > face_angles(points, flipped_pair).max()
    assert least_angle(points, flipped_pair) > least_angle(points, pair) + 0.5
    faces, flips = flip_slivers(points, pair, np.zeros(4, dtype=bool))
    assert flips == 1 and {tuple(sorted(f)) for f in faces.tolist()} == {(0, 2, 3), (1, 2, 3)}


def test_relaxation_moves_no_two_vertices_of_one_face_at_once():
    """A pass moves only candidates that are the worst candidate on each of their faces: each is
    judged on its own faces with its neighbours where they were (two on a face would each be
    judged with the other still in place, and both moves together may lower the face)."""
    points, triangles = plane(n=8)
    m = points.shape[0]
    indptr, around = vertex_faces(triangles, m)
    owner = np.repeat(np.arange(m), np.diff(indptr))
    rng = np.random.default_rng(5)
    for _ in range(5):
        candidate = rng.random(m) < 0.6
        worst = rng.random(m).round(1)  # ties too
        chosen = _worst_on_their_faces(candidate, worst, triangles, owner, around)
        assert not (chosen & ~candidate).any()
        assert chosen[triangles].sum(axis=1).max() == 1  # no face with two chosen corners
        ids = np.flatnonzero(candidate)
        assert chosen[ids[np.argmin(worst[ids])]]  # the worst candidate goes first
        # Every candidate left out shares a face with a chosen one or a worse candidate.
        for vertex in np.flatnonzero(candidate & ~chosen).tolist():
            ring = np.unique(triangles[around[indptr[vertex]:indptr[vertex + 1]]])
            others = ring[(ring != vertex) & candidate[ring]]
            assert (worst[others] <= worst[vertex]).any()
