"""The tension map's values (core/detached_surface/stretch.py), from their definition: a face's
stretch is the mean over its edges of | |e'| / |e| - 1 |, a detail vertex's the rest-area-weighted
mean of its faces'. Uniform scales give known values whatever the mesh; a one-axis stretch is
checked edge by edge from the proxy's own coordinates."""

import numpy as np
import pytest

from shapes import box, merge, random_rotation
from skin_detach_addon.core import SkinDetachedSurface
from skin_detach_addon.core.detached_surface.stretch import SkinStretch


@pytest.fixture(scope="module")
def surface():
    """A box and a separate plate, quads split in two, as the build makes them."""
    points, triangles = merge(box(size=(1.0, 2.0, 0.5), cells=(6, 10, 4)),
                              box(size=(0.8, 0.8, 0.1), cells=(5, 5, 2), offset=(2.0, 0.0, 0.0)))
    return SkinDetachedSurface.build(points, triangles, target_faces=200)


@pytest.mark.parametrize("factor, expected", [(2.0, 1.0), (0.5, 0.5), (1.25, 0.25)])
def test_a_uniform_scale_stretches_every_face_and_vertex_by_the_scale_less_one(surface, factor, expected):
    stretch = SkinStretch(surface)
    proxy = surface.proxy_vertices * factor
    # The proxy is measured as Blender stores it (float32): relative rounding of 1e-7 per coordinate.
    assert np.abs(stretch.face_stretch(proxy) - expected).max() <= 1e-5
    assert np.abs(stretch(proxy) - expected).max() <= 2e-5  # float32 weights summing to one


def test_rest_and_a_rigid_motion_do_not_stretch(surface):
    stretch = SkinStretch(surface)
    assert not stretch(surface.proxy_vertices).any()
    moved = surface.proxy_vertices @ random_rotation(7).T + [3.0, -1.0, 0.5]
    assert np.abs(stretch(moved)).max() <= 1e-5


def test_a_stretch_along_x_is_each_faces_mean_relative_edge_change(surface):
    stretch = SkinStretch(surface)
    rest = surface.proxy_vertices
    pulled = rest * [1.5, 1.0, 1.0]
    faces = surface.proxy_faces
    expected = np.zeros(faces.shape[0])
    for a, b in ((0, 1), (1, 2), (2, 0)):
        before = np.linalg.norm(rest[faces[:, a]] - rest[faces[:, b]], axis=1)
        after = np.linalg.norm(pulled[faces[:, a]] - pulled[faces[:, b]], axis=1)
        expected += np.abs(after / before - 1.0) / 3.0
    assert np.abs(stretch.face_stretch(pulled) - expected).max() <= 1e-5
    assert expected.max() > 0.3 and expected.min() < 0.2  # faces across x stretch, along y less
