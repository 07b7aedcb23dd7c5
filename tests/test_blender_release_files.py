"""Headless bpy: files bound by earlier releases open, drag and bake in this one.

tests/data/schema2_rig.blend was bound, rigged and posed by release 0.1.0 (binding schema 2, written
by tests/data/make_schema2_rig.py with bpy 4.2 so every Blender the manifest claims reads it): a
box of 12x12x12 cells and a loose sheet, a preview, an anchor on the box's bottom, a handle on its
top raised and turned (keyed at frames 1 and 3), the mesh deformed at frame 1, Show Stretch on.
Each later release adds its own file here when it changes the stored format (schema 1's is in
tests/test_blender_compact_binding.py)."""

import pathlib
import shutil

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import TopView  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import FINISHED, RUNNING, DragSession  # noqa: E402

DATA = pathlib.Path(__file__).parent / "data"


def opened(tmp_path, name="schema2_rig.blend"):
    path = tmp_path / name
    shutil.copy(DATA / name, path)
    binding._CACHE.clear()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects["box"]
    kinds = {api.handle_kind(e): e for e in api.handles_of(obj)}
    return obj, kinds[api.HANDLE], path


def diagonal(obj):
    points = mesh_io.read_positions(obj.data)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def test_the_0_1_0_file_opens_with_its_rig_and_its_saved_pose_is_what_its_handles_give(scene, tmp_path):
    obj, handle, _ = opened(tmp_path)
    record = obj[binding.KEY]
    assert record["schema_version"] == 2
    assert sorted(api.handle_kind(e) for e in api.handles_of(obj)) == sorted([api.ANCHOR, api.HANDLE])
    assert binding.open_binding(obj).preview is not None and api.stretch_shown(obj)
    saved = mesh_io.read_positions(obj.data).copy()
    assert api.deform(obj)["converged"]                       # solved from rest with the saved handles
    assert np.abs(mesh_io.read_positions(obj.data) - saved).max() <= 1e-5 * diagonal(obj)
    api.reset(obj)                                            # the rest stored in the file comes back
    rest = mesh_io.read_positions(obj.data)
    assert np.abs(rest - saved).max() > 0.05                  # the saved pose was a pose


def test_the_0_1_0_file_drags_confirms_saves_and_reopens(scene, tmp_path):
    obj, handle, path = opened(tmp_path)
    before = mesh_io.read_positions(obj.data).copy()
    session = DragSession(obj, handle, TopView(0.01), (0, 0))
    assert session.event("MOUSEMOVE", "NOTHING", (20, 10)) == RUNNING
    assert session.event("RET", "PRESS", (20, 10)) == FINISHED
    after = mesh_io.read_positions(obj.data)
    assert np.isfinite(after).all() and np.abs(after - before).max() > 0.05
    bpy.ops.wm.save_mainfile()                                # saved by this release, opened again
    binding._CACHE.clear()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects["box"]
    assert np.array_equal(mesh_io.read_positions(obj.data), after)
    assert api.deform(obj)["converged"]


def test_the_0_1_0_file_bakes_its_keyed_handle(scene, tmp_path):
    obj, _, _ = opened(tmp_path)
    shown = mesh_io.read_positions(obj.data).copy()
    frames = api.bake(obj, "1-3", into=api.OBJECTS)
    assert [f["frame"] for f in frames] == [1, 2, 3] and all(f["converged"] for f in frames)
    first, last = (mesh_io.read_positions(bpy.data.objects[f["output"]].data) for f in (frames[0], frames[-1]))
    assert np.abs(first - shown).max() <= 1e-5 * diagonal(obj)   # frame 1: the saved pose
    assert np.abs(last - first).max() > 0.05                     # frame 3: the handle keyed at rest
    assert np.array_equal(mesh_io.read_positions(obj.data), shown)  # the mesh as it was
