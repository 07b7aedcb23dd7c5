"""Headless bpy: a build in parts (api.start_build, BuildJob.run on a thread, api.finish_build),
as the Build button drives it while the window answers (issue 44)."""

import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import import_spot, rig  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.blender.preview_stand_in import preview_of  # noqa: E402


def _world(obj):
    """Everything a build may change: the objects, the mesh's positions, the binding's id."""
    return (sorted(o.name for o in bpy.data.objects), mesh_io.read_positions(obj.data).copy(),
            binding.binding_id(obj), sorted(o.name for o in bpy.data.meshes))


def _same(before, after):
    return before[0] == after[0] and np.array_equal(before[1], after[1]) and before[2:] == after[2:]


def _run_on_thread(job, timeout=120):
    job.start()
    assert job.wait(timeout), "the build did not end"


def test_a_build_on_its_thread_binds_exactly_as_build_does(scene):
    obj = import_spot()
    twin = obj.copy()
    twin.data = obj.data.copy()
    scene.collection.objects.link(twin)
    before = _world(obj)
    job = api.start_build(obj, target_faces=300)
    assert _same(before, _world(obj)) and not api.is_bound(obj)  # reading writes nothing
    stages = []
    job.start()
    while not job.done:  # the main thread is free meanwhile: it watches the progress
        stages.append((job.fraction, job.stage))
        time.sleep(0.001)
    assert job.error is None and not api.is_bound(obj)  # nothing is written off the main thread
    stats = api.finish_build(job)
    assert (job.fraction, job.stage) == (1.0, "writing the binding")
    assert all(b[0] >= a[0] for a, b in zip(stages, stages[1:]))
    expected = api.build(twin, target_faces=300)
    assert stats["proxy_faces"] == expected["proxy_faces"] and stats["case1"] == expected["case1"]
    assert np.array_equal(mesh_io.read_positions(api.proxy_of(obj).data),
                          mesh_io.read_positions(api.proxy_of(twin).data))
    assert np.array_equal(api.rest_positions(obj), api.rest_positions(twin))


def test_a_build_runs_beside_a_main_thread_that_keeps_answering(scene):
    """The window's event loop stands for the main thread here: while the core builds on its
    thread, the main thread is never kept waiting long (numpy and scipy let it run)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128)  # 32K vertices
    obj = bpy.context.active_object
    job = api.start_build(obj, target_faces=500)
    job.start()
    begun = last = time.perf_counter()
    gaps = []
    while not job.done:
        time.sleep(0.002)
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    total = time.perf_counter() - begun
    assert job.error is None and total > 0.2, f"the build took {total:.2f} s: too short to tell"
    assert max(gaps) < 0.5 * total, f"the main thread waited {max(gaps):.3f} s of {total:.2f} s"
    api.finish_build(job)
    assert api.is_bound(obj)


@pytest.mark.parametrize("when", ["before", "during", "after"])
def test_a_cancelled_rebuild_writes_nothing(scene, when):
    obj = import_spot()
    handle = rig(obj)
    handle.location.x += 0.2
    api.deform(obj)
    before = _world(obj)
    matrices = {e.name: np.array(e.matrix_world) for e in api.handles_of(obj)}
    job = api.start_build(obj, target_faces=200)
    if when == "before":
        job.cancel()
        with pytest.raises(api.BuildCancelled):
            job.run()
    elif when == "during":
        with pytest.raises(api.BuildCancelled):
            job.run(lambda fraction, stage: job.cancel() if stage == "simplifying" else None)
        assert job.stage == "simplifying"
    else:
        _run_on_thread(job)
        job.cancel()
    with pytest.raises(api.BuildCancelled):
        api.finish_build(job)
    assert _same(before, _world(obj))
    assert {e.name: np.array(e.matrix_world) for e in api.handles_of(obj)}.keys() == matrices.keys()
    assert all(np.array_equal(np.array(e.matrix_world), matrices[e.name]) for e in api.handles_of(obj))


@pytest.mark.parametrize("change", ["moved", "edit mode", "deleted", "topology"])
def test_a_mesh_changed_during_the_build_is_not_written(scene, change):
    obj = import_spot()
    name = obj.name
    job = api.start_build(obj, target_faces=300)
    _run_on_thread(job)
    if change == "moved":
        positions = mesh_io.read_positions(obj.data)
        positions[0, 0] += 0.1
        mesh_io.write_positions(obj.data, positions)
    elif change == "edit mode":
        bpy.ops.object.mode_set(mode='EDIT')
    elif change == "deleted":
        bpy.data.objects.remove(obj)
    else:
        bpy.ops.object.mode_set(mode='EDIT')
        bpy.ops.mesh.select_all(action='SELECT')
        bpy.ops.mesh.subdivide()
        bpy.ops.object.mode_set(mode='OBJECT')
    names = sorted(o.name for o in bpy.data.objects)
    with pytest.raises(api.SkinDetachError, match="nothing was written"):
        api.finish_build(job)
    assert sorted(o.name for o in bpy.data.objects) == names
    if change != "deleted":
        assert not api.is_bound(bpy.data.objects[name])


def test_a_core_error_on_the_thread_is_raised_by_finish_build_writing_nothing(scene):
    obj = import_spot()
    job = api.start_build(obj, target_faces=300)
    job.positions = job.positions[:10]  # a core build that refuses its input (triangles out of range)
    _run_on_thread(job)
    assert isinstance(job.error, api.SkinDetachError)
    with pytest.raises(api.SkinDetachError):
        api.finish_build(job)
    assert not api.is_bound(obj)


def test_start_build_where_the_preview_stands_in_writes_nothing_until_finish(scene):
    scene.skin_detach.preview_above = 1000
    obj = import_spot()
    handle = rig(obj, axis=1)
    handle.location.x += 0.3
    api.deform(obj, preview=True)
    assert api.preview_stands_in(obj)
    before = _world(obj)
    job = api.start_build(obj, target_faces=300, preview_above=1000)
    assert _same(before, _world(obj)) and api.preview_stands_in(obj)
    _run_on_thread(job)
    assert _same(before, _world(obj)) and api.preview_stands_in(obj)
    api.finish_build(job)
    assert not api.preview_stands_in(obj) and preview_of(obj) is not None
    moved = mesh_io.read_positions(obj.data)
    assert np.abs(moved - before[1]).max() > 0.01  # the pose the preview showed, now the mesh's and its rest
    assert np.array_equal(api.rest_positions(obj), moved)
