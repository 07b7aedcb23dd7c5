"""Issue 44 (a .blend that does not double): a surface kept as its proxy, carrier, fingerprint and
figures is made again from the detail mesh bit for bit, and a damaged compact record is refused
naming the field."""

import numpy as np
import pytest

from shapes import merge, plane
from test_core_skin import messy_mesh

from skin_detach_addon.core.detached_surface.compact_surface import compact_arrays, narrowest, surface_from_compact
from skin_detach_addon.core.errors import SkinDetachError
from skin_detach_addon.core.detached_surface.surface import SkinDetachedSurface

SKIN = ("vertex", "face", "bary", "height", "weight", "case")


def messy_with_loose_part():
    """The messy box (a duplicate, repeated and zero-area faces, an unused vertex) beside a tiny
    loose sheet, in float32 as Blender gives them: (points, triangles)."""
    points, tris, *_ = messy_mesh()
    sheet, sheet_tris = plane(4, size=0.05)
    points, tris = merge((points, tris), (sheet + [3.0, 0.0, 0.0], sheet_tris))
    return points.astype(np.float32), tris.astype(np.int32)


def same_surface(made, built):
    for name in SKIN:
        assert np.array_equal(getattr(made.skin, name), getattr(built.skin, name)), name
    for name in ("proxy_vertices", "proxy_faces", "weld", "carrier"):
        assert np.array_equal(getattr(made, name), getattr(built, name)), name
    assert made.fingerprint == built.fingerprint and made.stats == built.stats


@pytest.mark.parametrize("preview", [None, 3000])
def test_a_surface_made_from_its_compact_arrays_rebuilds_bit_for_bit(bundled, preview):
    if preview is None:
        points, tris = messy_with_loose_part()
        built = SkinDetachedSurface.build(points, tris, target_faces=60)
        assert built.stats["welded_duplicates"] and built.stats["dropped_faces"] and built.stats["components"] >= 2
    else:
        points, tris = bundled("armadillo")
        points, tris = points.astype(np.float32), tris.astype(np.int32)
        built = SkinDetachedSurface.build(points, tris, target_faces=300, preview_vertices=preview)
        assert built.preview is not None
    arrays = compact_arrays(built)
    assert arrays["carrier"].itemsize <= 2 and arrays["carrier"].shape == built.carrier.shape
    made = surface_from_compact(arrays, points, tris)
    same_surface(made, built)
    rng = np.random.default_rng(4)
    moved = built.proxy_vertices + rng.normal(scale=0.02, size=built.proxy_vertices.shape)
    groups = np.full(built.proxy_vertices.shape[0], -1)
    groups[:5] = 0
    for layout in ({}, {"groups": groups}, {"groups": groups, "held": [(0, np.arange(10))]}):
        for out in (None, np.empty((points.shape[0], 3), dtype=np.float32)):
            a = built.reconstruct(moved, out=None if out is None else out.copy(), **layout)
            b = made.reconstruct(moved, out=None if out is None else out.copy(), **layout)
            assert np.array_equal(a, b)


def test_the_carrier_takes_the_narrowest_signed_type_of_its_range():
    assert narrowest([-1, 5], -1, 126).dtype == np.int8
    assert narrowest([-1, 5], -1, 127).dtype == np.int8
    assert narrowest([-1, 5], -1, 128).dtype == np.int16
    assert narrowest([-1, 5], -1, 40_000).dtype == np.int32
    with pytest.raises(SkinDetachError, match="within int32"):
        narrowest([0], -1, 2**31)


@pytest.mark.parametrize("damage, expected", [
    ({"format_tag": np.array("other")}, "expected format_tag"),
    ({"format_version": np.array(7)}, "expected compact format version 1, got 7"),
    ({"carrier": None}, "expected arrays ['carrier'], they are missing"),
    ({"carrier": np.array([0.5])}, "carrier: expected a flat array of signed integers"),
    ({"carrier": "big"}, "carrier: expected proxy vertex ids in [-1, "),
    ({"carrier": "short"}, "carrier: expected ("),
    ({"proxy_faces": np.array([0, 1, 99999], dtype=np.int32)}, "proxy_faces"),
    ({"proxy_vertices": np.array([np.nan, 0.0, 0.0])}, "proxy_vertices"),
    ({"proxy_vertices": "far"}, "proxy_vertices: expected points within 10 diagonals"),
    ({"stats": np.array("{not json")}, "malformed data"),
    ({"stats": np.array("[1]")}, "build figures as a JSON object"),
    ({"fingerprint": np.array("0")}, "expected the detail topology it was built from"),
])
def test_a_damaged_compact_record_is_refused_naming_the_field(damage, expected):
    points, tris = messy_with_loose_part()
    built = SkinDetachedSurface.build(points, tris, target_faces=60)
    arrays = compact_arrays(built)
    for key, value in damage.items():
        if value is None:
            del arrays[key]
        elif isinstance(value, str) and value == "big":
            arrays[key] = arrays[key].copy()
            arrays[key][3] = built.proxy_vertices.shape[0]
        elif isinstance(value, str) and value == "far":
            arrays[key] = arrays[key].copy()
            arrays[key][2, 1] = 1e300
        elif isinstance(value, str) and value == "short":
            arrays[key] = arrays[key][:-1]
        else:
            arrays[key] = value
    with pytest.raises(SkinDetachError) as caught:
        surface_from_compact(arrays, points, tris, source="binding of 'box'")
    assert expected in str(caught.value) and "binding of 'box'" in str(caught.value), str(caught.value)


def test_content_digests_are_of_the_values_not_of_how_they_are_stored():
    from skin_detach_addon.core.detached_surface.compact_surface import check_digests, content_digests
    carrier = np.array([3, -1, 7, 0])
    stored = content_digests({"carrier": carrier.astype(np.int16), "tag": "skin", "rest": np.ones((2, 3), np.float32)})
    # The same values read back in another integer or float width, a 0-d string, a flat array: the
    # same digests.
    assert content_digests({"carrier": carrier.astype(np.int32), "tag": np.array("skin"),
                            "rest": np.ones(6, np.float64)}) == stored
    check_digests({"carrier": carrier.astype(np.int8), "tag": "skin", "rest": np.ones(6, np.float32)}, stored, "b")
    for changed, key in (({"carrier": np.array([3, -1, 7, 1])}, "carrier"), ({"tag": "skim"}, "tag"),
                         ({"rest": np.full(6, 1.0 + 2.0 ** -23, np.float32)}, "rest"), ({"carrier": carrier[:3]}, "carrier")):
        arrays = {"carrier": carrier, "tag": "skin", "rest": np.ones(6, np.float32), **changed}
        with pytest.raises(SkinDetachError, match=rf"^b {key}: expected the values the build stored"):
            check_digests(arrays, stored, "b")
    with pytest.raises(SkinDetachError, match="b rest: expected the stored values the build wrote, it is missing"):
        check_digests({"carrier": carrier, "tag": "skin"}, stored, "b")


def preview_cases(bundled):
    """(points, triangles, built surface with a preview): the armadillo, and the riders' character
    (a body with parts riding on it: its preview has riders)."""
    from test_core_riders import character
    points, tris = bundled("armadillo")
    points, tris = points.astype(np.float32), tris.astype(np.int32)
    yield points, tris, SkinDetachedSurface.build(points, tris, target_faces=300, preview_vertices=3000)
    points, tris, _ = character()
    yield points, tris, SkinDetachedSurface.build(points, tris, target_faces=300, preview_vertices=1500)


def test_a_preview_made_from_its_compact_arrays_rebinds_bit_for_bit(bundled):
    """Issue 52 item 4: the preview is stored as its points, triangles, carrier, representatives
    and riders, its skin bound again on opening: the same skin, the same rebuilds."""
    from skin_detach_addon.core.detached_surface.compact_surface import compact_preview_arrays, preview_from_compact
    riders = 0
    for points, tris, built in preview_cases(bundled):
        preview = built.preview
        assert preview is not None
        arrays = compact_preview_arrays(preview)
        assert not {f"skin_{name}" for name in SKIN} & arrays.keys() and "weld" not in arrays
        made = preview_from_compact(arrays, built.proxy_vertices, built.proxy_faces, "preview of 'spot'")
        same_surface(made.surface, preview.surface)
        assert np.array_equal(made.points, preview.points) and np.array_equal(made.triangles, preview.triangles)
        assert np.array_equal(made.representatives, preview.representatives)
        riders += preview.surface.riders is not None
        rng = np.random.default_rng(7)
        moved = built.proxy_vertices + rng.normal(scale=0.02, size=built.proxy_vertices.shape)
        groups = np.full(built.proxy_vertices.shape[0], -1)
        groups[:5] = 0
        for layout in ({}, {"groups": groups}):
            assert np.array_equal(preview.surface.reconstruct(moved, **layout), made.surface.reconstruct(moved, **layout))
    assert riders  # one case has riders: they come back too


def test_a_damaged_compact_preview_is_refused_naming_the_field(bundled):
    from skin_detach_addon.core.detached_surface.compact_surface import compact_preview_arrays, preview_from_compact
    points, tris, built = next(preview_cases(bundled))
    arrays = compact_preview_arrays(built.preview)
    m = built.proxy_vertices.shape[0]
    for key, value, expected in [("carrier", np.full(arrays["carrier"].shape, m, dtype=np.int32), "carrier: expected"),
                                 ("carrier", arrays["carrier"][:-1], "carrier: expected"),
                                 ("triangles", arrays["triangles"][:-1], "expected preview triangles matching"),
                                 ("points", np.full_like(arrays["points"], np.nan), "points"),
                                 ("format_version", np.array(9), "expected compact format version 1, got 9")]:
        with pytest.raises(SkinDetachError, match=r"^preview of 'spot'.*" + expected):
            preview_from_compact({**arrays, key: value}, built.proxy_vertices, built.proxy_faces, "preview of 'spot'")
    with pytest.raises(SkinDetachError, match=r"preview of 'spot': expected arrays \['carrier'\], they are missing"):
        preview_from_compact({k: v for k, v in arrays.items() if k != "carrier"}, built.proxy_vertices,
                             built.proxy_faces, "preview of 'spot'")
