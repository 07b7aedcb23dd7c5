"""The build is a function of the mesh and the settings: the same vertices and faces give the same
proxy and skin, bit for bit, in one process and in another (another hash seed, another thread
count, other block sizes), whatever order the faces are stored in and whichever corner each
starts at (Blender numbers the faces of a new UV sphere differently on every call)."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from shapes import plane
from skin_detach_addon.core import SkinDetachedSurface, geometry, threads
from skin_detach_addon.core.detached_surface import clustering, prepared_mesh, reconstruction, skin

ROOT = pathlib.Path(__file__).resolve().parent.parent


def uv_sphere(segments=32, rings=16):
    """Blender's UV sphere (radius 1, poles on z), triangulated: quads split along one diagonal."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.repeat(np.cos(theta)[:, None], segments, axis=1)], axis=2).reshape(-1, 3)
    points = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]])
    bottom = points.shape[0] - 1
    s = np.arange(segments)
    s1 = (s + 1) % segments
    faces = [np.stack([np.zeros(segments, dtype=np.int64), 1 + s, 1 + s1], axis=1)]
    for r in range(rings - 2):
        a, b = 1 + r * segments, 1 + (r + 1) * segments
        faces += [np.stack([a + s, b + s, b + s1], axis=1), np.stack([a + s, b + s1, a + s1], axis=1)]
    last = 1 + (rings - 2) * segments
    faces.append(np.stack([np.full(segments, bottom), last + s1, last + s], axis=1))
    return points, np.concatenate(faces)


# (name, mesh, build arguments): the sphere, a regular grid (ties everywhere), a scan
# through the clustered copy (the preview path), a scan at the default proxy size.
CASES = {
    "sphere": (lambda bundled: uv_sphere(), {"target_faces": 200}),
    "plane": (lambda bundled: plane(24), {"target_faces": 150}),
    "spot_preview": (lambda bundled: bundled("spot"), {"target_faces": 300, "preview_vertices": 700}),
    "plane_preview": (lambda bundled: plane(40), {"target_faces": 150, "preview_vertices": 300}),
    "armadillo": (lambda bundled: bundled("armadillo"), {}),
}


def arrays_of(surface):
    """Every array a build makes: the stored ones, the preview's, and a rebuild from a moved proxy."""
    out = {key: np.asarray(value) for key, value in surface.to_arrays().items() if key != "stats"}
    if surface.preview is not None:
        out.update({f"preview_{key}": np.asarray(value) for key, value in surface.preview.to_arrays().items()
                    if key != "stats"})
    motion = np.sin(np.arange(surface.proxy_vertices.size, dtype=np.float64)).reshape(-1, 3)
    out["rebuilt"] = surface.reconstruct(surface.proxy_vertices + 0.01 * motion)
    return out


def assert_identical(first, second, skip=()):
    assert sorted(first) == sorted(second)
    for key in first:
        if key in skip:
            continue
        a, b = first[key], second[key]
        assert a.dtype == b.dtype and a.shape == b.shape, key
        assert a.tobytes() == b.tobytes(), f"{key} differs"


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks small enough that a small mesh runs on several threads (:data:`~.threads.WORKERS` set
    by the test), the pool made again for that count and put back afterwards."""
    monkeypatch.setattr(skin, "CHUNK", 300)
    monkeypatch.setattr(geometry, "FACE_BLOCK", 500)
    monkeypatch.setattr(clustering, "EDGE_BLOCK", 700)
    monkeypatch.setattr(threads, "PARALLEL_MIN_ROWS", 100)
    monkeypatch.setattr(reconstruction, "BLOCK_ROWS", 150)
    threads.shutdown()
    yield monkeypatch
    threads.shutdown()


@pytest.mark.parametrize("case", sorted(CASES))
def test_two_builds_in_one_process_are_identical(bundled, case):
    make, options = CASES[case]
    points, tris = make(bundled)
    first = arrays_of(SkinDetachedSurface.build(points, tris, **options))
    assert_identical(first, arrays_of(SkinDetachedSurface.build(points, tris, **options)))


@pytest.mark.parametrize("case", ["sphere", "plane", "spot_preview", "plane_preview"])
def test_face_order_and_first_corner_do_not_change_the_build(bundled, case):
    """The same faces stored in another order, each starting at another corner (orientation kept),
    give the same build; only the fingerprint differs (the digest of the face list as given)."""
    make, options = CASES[case]
    points, tris = make(bundled)
    rng = np.random.default_rng(7)
    shuffled = tris[rng.permutation(tris.shape[0])]
    turn = rng.integers(0, 3, shuffled.shape[0])[:, None]
    shuffled = np.take_along_axis(shuffled, (turn + np.arange(3)) % 3, axis=1)
    first = arrays_of(SkinDetachedSurface.build(points, tris, **options))
    second = arrays_of(SkinDetachedSurface.build(points, shuffled, **options))
    assert_identical(first, second, skip=("fingerprint",))
    assert first["fingerprint"] != second["fingerprint"]


@pytest.mark.parametrize("workers", [1, 3])
def test_thread_count_and_block_sizes_do_not_change_the_build(bundled, small_blocks, workers):
    make, options = CASES["spot_preview"]
    points, tris = make(bundled)
    small_blocks.setattr(threads, "WORKERS", 1)
    alone = arrays_of(SkinDetachedSurface.build(points, tris, **options))
    threads.shutdown()
    small_blocks.setattr(threads, "WORKERS", workers)
    assert_identical(alone, arrays_of(SkinDetachedSurface.build(points, tris, **options)))


CHILD = """
import json, sys
import numpy as np
sys.path[:0] = [{root!r}, {tests!r}]
from test_core_determinism import CASES, arrays_of
from bench.meshes import bundled
from skin_detach_addon.core import SkinDetachedSurface, threads
threads.WORKERS = {workers}
out = {{}}
for case in {cases!r}:
    make, options = CASES[case]
    points, tris = make(bundled)
    for key, value in arrays_of(SkinDetachedSurface.build(points, tris, **options)).items():
        out[case + "/" + key] = value
np.savez({path!r}, **out)
print(json.dumps({{"workers": threads.WORKERS}}))
"""


#: An older CPU of the same platform, as far as one machine can pretend: numpy without its AVX
#: loops (its sorts break ties by the vector width) and OpenBLAS's kernel without fused
#: multiply-adds (Prescott).
OLDER_CPU = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 X86_V3 AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL "
                                         "AVX512_SPR AVX2 FMA3 F16C AVX",  # numpy 2.4+ names, then older ones
             "OPENBLAS_CORETYPE": "Prescott"}


@pytest.mark.parametrize("machine", ["this", "older"])
def test_a_build_in_another_process_is_identical(bundled, tmp_path, machine):
    """Another interpreter, another hash seed (set and dict order), another thread count, and
    (``older``) other vector instructions."""
    cases = sorted(CASES)
    path = tmp_path / "child.npz"
    workers = 1 if threads.WORKERS > 1 else 2
    code = CHILD.format(root=str(ROOT), tests=str(ROOT / "tests"), workers=workers, cases=cases, path=str(path))
    env = dict(os.environ, PYTHONHASHSEED="12345", **(OLDER_CPU if machine == "older" else {}))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout.strip().splitlines()[-1]) == {"workers": workers}
    with np.load(path, allow_pickle=False) as data:
        child = {key: data[key] for key in data.files}
    for case in cases:
        make, options = CASES[case]
        points, tris = make(bundled)
        here = arrays_of(SkinDetachedSurface.build(points, tris, **options))
        assert_identical(here, {key: child[f"{case}/{key}"] for key in here})


def test_a_grid_cell_seeds_its_lowest_vertex_among_the_equally_near():
    """The clustering's seed of a cell is the vertex nearest its centre, the lowest id among equally
    near ones (a regular grid has four): the same on every machine."""
    grid = np.stack(np.meshgrid(np.arange(200.0), np.arange(200.0), [0.0], indexing="ij"), axis=-1).reshape(-1, 3)
    components = np.zeros(grid.shape[0], dtype=np.int64)
    for size in (4.0, 5.0):
        cells = np.floor(grid / size).astype(np.int64)
        offset = grid / size - cells - 0.5
        key = cells[:, 0] * 1000 + cells[:, 1]
        order = np.lexsort((np.arange(grid.shape[0]), np.einsum("ij,ij->i", offset, offset), key))
        first = np.ones(order.size, dtype=bool)
        first[1:] = key[order[1:]] != key[order[:-1]]
        assert np.array_equal(clustering._seeds(grid, components, size), order[first])


def test_normal_test_decides_signs_near_zero_in_numpy_order():
    """The normal test counts detail normals facing away (a non-positive dot with the face normal);
    dots near zero, whose BLAS rounding differs per CPU, are decided by numpy's own arithmetic in
    a fixed order (here: face normals perpendicular to bin directions, up to rounding)."""
    from skin_detach_addon.core.detached_surface.checked_collapse import CUBE_BINS, _CollapseState, cube_directions
    from skin_detach_addon.core.geometry import cross_rows, unit_rows
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    rng = np.random.default_rng(3)
    hist = rng.integers(0, 50, (4, CUBE_BINS)).astype(np.float64)
    state = _CollapseState(points, tris, np.zeros((4, 10)), hist, np.zeros(4, dtype=np.int64))
    directions = cube_directions()
    normals = unit_rows(cross_rows(directions[rng.integers(0, CUBE_BINS, 400)], rng.standard_normal((400, 3))))[0]
    corners = rng.integers(-1, 4, (400, 3))
    merged = hist[0] + hist[1]
    away = (directions[:, None, 0] * normals[:, 0] + directions[:, None, 1] * normals[:, 1]
            + directions[:, None, 2] * normals[:, 2]) <= 0.0
    rows = np.where(corners < 0, -1, corners)
    per_corner = np.where(rows[..., None] < 0, merged, hist[np.maximum(rows, 0)])  # (400, 3, bins)
    expected = np.einsum("fcb,bf->f", per_corner, away.astype(np.float64))
    assert np.array_equal(state._violations(normals, corners, merged), expected)


@pytest.mark.parametrize("n", [12, 5000, 1_664_510, 1_664_511, 3_000_000, 100_000_000])
def test_canonical_faces_are_the_same_faces_in_one_order(n):
    """Keys in one group (up to 1,664,510 vertices), in two, in six and in 216,920 (the int64
    sort of the group numbers): each output row is an input row turned to start at its smallest
    id, the rows are sorted, repeated faces are neighbours, and the input's order and first
    corners do not show."""
    assert (n + prepared_mesh.key_span(n) - 1) // prepared_mesh.key_span(n) == {
        12: 1, 5000: 1, 1_664_510: 1, 1_664_511: 2, 3_000_000: 6, 100_000_000: 216_920}[n]
    rng = np.random.default_rng(n)
    faces = np.stack([rng.choice(np.arange(max(n - 40, 0), n) if k % 2 else n, 3, replace=False) for k in range(600)])
    faces = np.concatenate([faces, faces[:40, ::-1], faces[40:60]])  # flipped and repeated copies
    out = prepared_mesh.canonical_faces(faces, n)
    turned = []
    for row in faces.tolist():
        k = row.index(min(row))
        turned.append(tuple(row[k:] + row[:k]))
    assert sorted(turned) == sorted(map(tuple, out.tolist()))
    lo, hi = np.minimum(out[:, 1], out[:, 2]), np.maximum(out[:, 1], out[:, 2])
    assert (np.diff(np.lexsort(((out[:, 1] > out[:, 2]), hi, lo, out[:, 0]))) == 1).all()
    shuffled = faces[rng.permutation(faces.shape[0])]
    shuffled = np.take_along_axis(shuffled, (rng.integers(0, 3, shuffled.shape[0])[:, None] + np.arange(3)) % 3, axis=1)
    assert np.array_equal(prepared_mesh.canonical_faces(shuffled, n), out)
    firsts = prepared_mesh._first_of_repeats(out)
    assert firsts.size == np.unique(np.sort(faces, axis=1), axis=0).shape[0]


def test_points_whose_hashes_repeat_but_not_their_coordinates_are_not_welded():
    """weld_map groups rows by a 64-bit hash and compares them in full: two points of one hash
    (made here by solving the hash for the first coordinate's bits) stay apart, the map is the
    identity; an exact duplicate among them is welded."""
    rng = np.random.default_rng(7)
    points = rng.random((50, 3))
    half = np.uint64(32)
    mixed = points.view(np.uint64) ^ (points.view(np.uint64) >> half)  # weld_map's own folding
    c1, c2 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F)
    inverse = np.uint64(pow(int(c1), -1, 2**64))
    other = mixed[0].copy()
    with np.errstate(over="ignore"):
        for y in rng.random(100):
            other[1] = np.float64(y).view(np.uint64) ^ (np.float64(y).view(np.uint64) >> half)
            other[0] = ((mixed[0, 0] * c1) ^ (mixed[0, 1] * c2) ^ (other[1] * c2)) * inverse
            other ^= other >> half  # the folding undone (it is its own inverse)
            if np.isfinite(other.view(np.float64)).all():
                break
    colliding = np.concatenate([points, other.view(np.float64)[None]])
    weld, first = prepared_mesh.weld_map(colliding)
    assert np.array_equal(weld, np.arange(51)) and np.array_equal(first, np.arange(51))
    weld, first = prepared_mesh.weld_map(np.concatenate([colliding, points[3:4]]))
    assert np.array_equal(weld, np.r_[np.arange(51), 3]) and np.array_equal(first, np.arange(51))
