"""The proxy's sliver repair: slivers out, the least angle never falling, the surface kept, the
border and sliver-free proxies left alone, rigid motion and scale, and the build's use of it."""

import numpy as np
import pytest

from shapes import plane, random_rotation
from skin_detach_addon.core import SkinDetachedSurface
from skin_detach_addon.core.geometry import unique_edges
from skin_detach_addon.core.detached_surface import surface as surface_module
from skin_detach_addon.core.detached_surface.sliver_repair import (CAP_DEGREES, SLIVER_DEGREES, face_angles,
                                                                   flip_slivers, is_sliver, no_repair,
                                                                   relax_slivers,
                                                                   repair_slivers)


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
    assert unrepaired.stats["proxy_slivers"] > 3 * max(built.stats["proxy_slivers"], 1)
    assert built.stats["proxy_least_angle"] > unrepaired.stats["proxy_least_angle"]
    assert built.stats["proxy_slivers"] == int(is_sliver(face_angles(built.proxy_vertices, built.proxy_faces)).sum())
