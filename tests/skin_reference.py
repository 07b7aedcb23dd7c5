"""Exhaustive, loop-per-vertex reference of the skin rules in skin_detach_addon.core.detached_surface.skin.

Every proxy face is tested for every vertex with textbook cross-product barycentrics, and
the candidate restriction is applied as a predicate on each face. With ``paper=True`` the
restriction is off (all faces, no normal agreement; case 2 uses the globally nearest proxy
vertex): the paper's own rules, which mis-attach across a closed mouth.
"""

import numpy as np

from skin_detach_addon.core.detached_surface.skin import CONTAIN_EPS, DISTANCE_EPS, Skin


def _project_all(point, p0, p1, p2):
    """Cross-product barycentrics, distances, unit normals and |cross| of ``point`` over every face."""
    n = np.cross(p1 - p0, p2 - p0)
    area2 = np.einsum("ij,ij->i", n, n)
    unit = n / np.sqrt(area2)[:, None]
    distance = np.einsum("ij,ij->i", point - p0, unit)
    drop = point - distance[:, None] * unit
    b1 = np.einsum("ij,ij->i", np.cross(p2 - p1, drop - p1), n) / area2
    b2 = np.einsum("ij,ij->i", np.cross(p0 - p2, drop - p2), n) / area2
    return np.stack([b1, b2, 1.0 - b1 - b2], axis=1), distance, unit, np.sqrt(area2)


def reference_skin(points, normals, carrier, proxy_points, proxy_faces, paper=False):
    m = proxy_points.shape[0]
    tolerance = DISTANCE_EPS * np.linalg.norm(proxy_points.max(axis=0) - proxy_points.min(axis=0))
    faces_of = [set() for _ in range(m)]
    for f, tri in enumerate(proxy_faces):
        for v in tri:
            faces_of[v].add(f)
    neighbours = [set(proxy_faces[list(faces_of[v])].ravel()) - {v} for v in range(m)]
    corners = [proxy_points[proxy_faces[:, k]] for k in range(3)]
    rows = []
    case = np.zeros(points.shape[0], dtype=np.int8)
    for v, point in enumerate(points):
        normal = normals[v]
        p = carrier[v]
        all_bary, all_distance, all_unit, all_cross = _project_all(point, *corners)
        projections = list(zip(all_bary, all_distance, all_unit, all_cross))

        def containing(candidates):
            hits = []
            for f in candidates:
                bary, distance, unit, _ = projections[f]
                agree = paper or not normal.any() or unit @ normal > 0
                if (bary >= -CONTAIN_EPS).all() and agree:
                    hits.append(f)
            if not hits:
                return []
            d_min = min(abs(projections[f][1]) for f in hits)
            return [f for f in hits if abs(projections[f][1]) <= 2 * d_min + tolerance]

        chosen = []
        if p >= 0:
            if paper:
                chosen = containing(range(len(proxy_faces)))
            else:
                tier1 = faces_of[p]
                tier2 = set().union(*(faces_of[q] for q in neighbours[p])) - tier1
                chosen = containing(sorted(tier1)) or containing(sorted(tier2))
        if chosen:
            case[v] = 1 if len(chosen) == 1 else 3
        else:
            if p < 0 or paper:
                pool = range(m)
            else:
                pool = sorted(neighbours[p] | {p})
            q = min(pool, key=lambda c: (np.sum((point - proxy_points[c]) ** 2), c))
            around = sorted(faces_of[q])
            if p >= 0 and not paper and normal.any():
                agreeing = [f for f in around if projections[f][2] @ normal > 0]
                around = agreeing or around
            chosen = around
            case[v] = 2 if p >= 0 else 4
        for f in chosen:
            bary, distance, _, cross_len = projections[f]
            rows.append((v, f, bary, distance / np.sqrt(cross_len), cross_len))
    vertex = np.array([r[0] for r in rows])
    area = np.array([r[4] for r in rows])
    weight = area / np.bincount(vertex, weights=area)[vertex]
    return Skin(vertex=vertex, face=np.array([r[1] for r in rows]), bary=np.array([r[2] for r in rows]),
                height=np.array([r[3] for r in rows]), weight=weight, case=case)
