"""Issue 43, item 11: the id validators give the values as they are (a uint64 2**63 is not read
as a negative int64), the real bound ("[0, n)") or "non-negative" when no bound is known."""

import numpy as np
import pytest

from skin_detach_addon.core.errors import SkinDetachError
from skin_detach_addon.core.validation import as_ids, as_triangles, as_vertex_ids


def message(call):
    with pytest.raises(SkinDetachError) as caught:
        call()
    return str(caught.value)


def test_a_uint64_id_of_2_63_is_reported_as_it_is_and_refused():
    ids = np.array([3, 2**63], dtype=np.uint64)
    said = message(lambda: as_vertex_ids("vertex_ids", ids, 10))
    assert said == "vertex_ids: expected vertex ids in [0, 10), got values in [3, 9223372036854775808]"
    said = message(lambda: as_ids("ids", ids))                 # no bound: still does not fit an int64
    assert said == "ids: expected non-negative ids below 2**63, got values in [3, 9223372036854775808]"
    assert as_ids("ids", np.array([2**63 - 1], dtype=np.uint64))[0] == 2**63 - 1


def test_a_negative_id_names_the_real_bound_or_non_negative():
    ids = np.array([-3, 5], dtype=np.int32)
    assert message(lambda: as_ids("handle 'h'", ids, 482, "detail_ids")) == \
        "handle 'h': expected detail_ids in [0, 482), got values in [-3, 5]"
    assert message(lambda: as_ids("handle 'h'", ids, None, "detail_ids")) == \
        "handle 'h': expected non-negative detail_ids below 2**63, got values in [-3, 5]"
    assert "None" not in message(lambda: as_ids("x", ids))


def test_triangles_name_the_bound_as_a_half_open_range_and_the_values_as_they_are():
    faces = np.array([[0, 1, 2**63]], dtype=np.uint64)
    assert message(lambda: as_triangles("faces", faces, 3)) == \
        "faces: expected indices in [0, 3), got values in [0, 9223372036854775808]"


def test_good_ids_pass_unchanged_as_int64():
    out = as_vertex_ids("vertex_ids", np.array([[2, 0], [1, 1]], dtype=np.uint16), 3)
    assert out.dtype == np.int64 and out.tolist() == [2, 0, 1, 1]
    assert as_ids("ids", []).shape == (0,)
    with pytest.raises(SkinDetachError, match="at least one vertex id"):
        as_vertex_ids("vertex_ids", [], 3)
    with pytest.raises(SkinDetachError, match="integer vertex ids, got dtype float64"):
        as_vertex_ids("vertex_ids", [0.5], 3)
