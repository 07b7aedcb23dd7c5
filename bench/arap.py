"""Full-resolution as-rigid-as-possible reference (libigl, a dev-only dependency) for the
quality figures: the detail mesh itself deformed under the scenario's constraints."""

import time

import numpy as np


def arap_reference(points, triangles, scenario, iterations, motion=None):
    """(n, 3) ARAP solution of ``points`` (n, 3), ``triangles`` (f, 3) with the scenario's anchors
    at rest and its handle moved (by ``motion``, (r, 3) -> (r, 3), default ``scenario.move``),
    after ``iterations`` local-global iterations, and the seconds it took; (None, None) without
    libigl or when it refuses the mesh."""
    try:
        import igl
    except ImportError:
        return None, None
    move = scenario.move if motion is None else motion
    fixed = np.concatenate([scenario.anchor_ids, scenario.handle_ids]).astype(np.int32)
    targets = np.concatenate([points[scenario.anchor_ids], move(points[scenario.handle_ids])])
    data = igl.ARAPData()
    data.max_iter = iterations
    start = time.perf_counter()
    try:
        igl.arap_precomputation(points, triangles.astype(np.int64), 3, fixed, data)
        result = igl.arap_solve(targets, data, points.copy())
    except RuntimeError:  # libigl refuses some meshes (e.g. unreferenced vertices)
        return None, None
    return result, time.perf_counter() - start
