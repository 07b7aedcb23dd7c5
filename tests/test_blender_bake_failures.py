"""Issue 52, item 7 (headless bpy): a FILES bake that fails says what happened in the project's
own words: the output folder removed mid-bake is named (not Blender's RuntimeError about a hidden
partial file), and a failure at a later frame says which frames' files were written and kept (it
said "nothing was written")."""

import math
import os
import shutil

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import quad_sphere  # noqa: E402

from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.api import SkinDetachError  # noqa: E402


def keyed_rig():
    """A sphere rigged, its handle keyed to move over frames 1-4."""
    obj = quad_sphere()
    api.build(obj, target_faces=200)
    z = api.rest_positions(obj)[:, 2]
    api.add_anchor(obj, np.flatnonzero(z < -0.7), mirror="")
    handle = api.add_handle(obj, np.flatnonzero(z > 0.7), mirror="")
    for frame in range(1, 5):
        handle.location.x = 0.1 * frame
        handle.keyframe_insert("location", frame=frame)
    return obj, handle


def test_the_output_folder_removed_mid_bake_is_named(scene, tmp_path):
    obj, _ = keyed_rig()
    folder = tmp_path / "shots"
    folder.mkdir()

    def progress(done, total, record):
        if done == 2:
            shutil.rmtree(folder)

    with pytest.raises(SkinDetachError, match="is gone") as caught:
        api.bake(obj, "1-4", into=api.FILES, path=str(folder / "scan_####.obj"), progress=progress)
    message = str(caught.value)
    assert "partial" not in message and str(folder) in message
    assert "frames before it" in message  # frames 1 and 2 were written, then their folder went


def test_a_bake_that_fails_at_a_later_frame_names_the_files_it_kept(scene, tmp_path):
    obj, handle = keyed_rig()
    handle.animation_data_clear()
    name = handle.name

    def nan_at_frame_3(scene_, *args):  # a frame whose handle lands on NaN (a driver gone wrong)
        bpy.data.objects[name].location.x = math.nan if scene_.frame_current == 3 else 0.1 * scene_.frame_current

    bpy.app.handlers.frame_change_pre.append(nan_at_frame_3)
    try:
        with pytest.raises(SkinDetachError) as caught:
            api.bake(obj, "1-4", into=api.FILES, path=str(tmp_path / "scan_####.obj"))
    finally:
        bpy.app.handlers.frame_change_pre.remove(nan_at_frame_3)
    message = str(caught.value)
    assert message.startswith("frame 3:") and "1 to 2" in message and "kept" in message, message
    assert "(nothing was written)" not in message
    assert sorted(os.listdir(tmp_path)) == ["scan_0001.obj", "scan_0002.obj"]
