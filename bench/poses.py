"""The pose suite: random handle poses on a proxy, each solved warm (from the previous pose,
as dragging does) and cold (from rest), and a handle turned 180 degrees and back.

Poses: the bend scenario's anchors pinned, its handle moved by a random rigid motion about the
handle's centroid (random axis, angle up to ``max_degrees``, shift up to ``max_shift`` of the
bounding-box diagonal), drawn from a seeded generator so every run sees the same poses.
"""

import time

import numpy as np

from skin_detach_addon.core import DualLaplacian


def rotation(axis, angle):
    """(3, 3) rotation by ``angle`` radians about the unit ``axis`` (3,)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def random_poses(count, diagonal, seed=0, max_degrees=90.0, max_shift=0.10):
    """``count`` (rotation (3, 3), shift (3,)) pairs."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = np.radians(rng.uniform(0.0, max_degrees))
        direction = rng.normal(size=3)
        shift = direction / np.linalg.norm(direction) * rng.uniform(0.0, max_shift) * diagonal
        out.append((rotation(axis, angle), shift))
    return out


def pose_suite(surface, scenario, count=300, tol=1e-12, max_iter=500, seed=0, **solver_options):
    """Figures of the pose suite on ``surface`` (a SkinDetachedSurface) with ``scenario``'s
    anchors and handle: converged counts, warm-vs-cold distances over the diagonal, settle ms,
    and the distance to rest after 180 degrees and back."""
    rest = surface.proxy_vertices
    diagonal = float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))
    handle = surface.proxy_vertices_for(scenario.handle_ids)
    anchors = np.setdiff1d(surface.proxy_vertices_for(scenario.anchor_ids), handle)
    ids = np.concatenate([anchors, handle])
    pivot = rest[handle].mean(axis=0)
    start = time.perf_counter()
    solver = DualLaplacian(rest, surface.proxy_faces, ids, **solver_options)
    factor_ms = 1000 * (time.perf_counter() - start)

    def targets(turn, shift):
        return np.concatenate([rest[anchors], (rest[handle] - pivot) @ turn.T + pivot + shift])

    warm_converged = cold_converged = 0
    distances, settle_ms, previous = [], [], None
    for turn, shift in random_poses(count, diagonal, seed):
        goal = targets(turn, shift)
        start = time.perf_counter()
        warm = solver.solve(goal, initial=previous, max_iter=max_iter, tol=tol)
        settle_ms.append(1000 * (time.perf_counter() - start))
        cold = solver.solve(goal, max_iter=max_iter, tol=tol)
        warm_converged += warm.converged
        cold_converged += cold.converged
        distances.append(float(np.abs(warm.vertices - cold.vertices).max()) / diagonal)
        previous = warm.vertices
    distances = np.array(distances)
    axis = np.cross(*np.linalg.svd(rest[handle] - pivot)[2][:2])
    previous = None
    for angle in np.radians(np.r_[np.arange(15.0, 181.0, 15.0), np.arange(165.0, -1.0, -15.0)]):
        previous = solver.solve(targets(rotation(axis / np.linalg.norm(axis), angle), np.zeros(3)),
                                initial=previous, max_iter=max_iter, tol=tol).vertices
    back = float(np.abs(previous - rest).max()) / diagonal
    return {"poses": count, "proxy_faces": int(surface.proxy_faces.shape[0]), "factor_ms": factor_ms,
            "warm_converged": int(warm_converged), "cold_converged": int(cold_converged),
            "within_1e-5": float(np.mean(distances <= 1e-5)), "max_warm_cold": float(distances.max()),
            "settle_ms_median": float(np.median(settle_ms)), "turned_back_to_rest": back}
