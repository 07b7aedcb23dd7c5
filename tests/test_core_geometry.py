"""Core: the prepared mesh's connectivity (component labels) on a mesh of many loose parts."""

import numpy as np

from skin_detach_addon.core import geometry


def test_component_labels_are_the_weak_components_numbered_by_first_vertex():
    rng = np.random.default_rng(3)
    # Seven strips of triangles, their vertex ids shuffled, a few faces dropped (open borders
    # walked one way only), and loose vertices at the end. The expected components come from the
    # construction (which strip a face was made in) joined by a plain union-find over the faces'
    # corners, not from the code's graph.
    strip = np.array([[i, i + 1, i + 2] if i % 2 == 0 else [i + 1, i, i + 2] for i in range(40)])
    k, u = 7, 42
    triangles = np.concatenate([strip + c * u for c in range(k)])
    triangles = rng.permutation(k * u)[triangles]
    triangles = triangles[rng.random(triangles.shape[0]) > 0.1]
    n = k * u + 3
    labels = geometry.component_labels(triangles, n)
    parent = list(range(n))

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b, c in triangles.tolist():
        for x, y in ((a, b), (b, c)):
            parent[root(x)] = root(y)
    roots = [root(v) for v in range(n)]
    same = np.equal.outer(roots, roots)
    assert np.array_equal(np.equal.outer(labels, labels), same)
    assert len(set(roots)) >= k + 3  # the premise: dropped faces split strips, loose vertices alone
    first = np.array([np.flatnonzero(labels == label)[0] for label in range(labels.max() + 1)])
    assert (np.diff(first) > 0).all()  # numbered in the order of their first vertex
