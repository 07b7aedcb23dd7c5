"""Issue 51 with issue 53's drag: a rig of several objects above Preview Above gets ONE preview that
stands in for every object while a drag moves (each object hidden, none written); the confirm
writes every object in full detail and shows them again, each where api.deform puts it; a
cancel shows them again as they were."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_blender_several_objects import (bits, character, lowest_and_top, same_bits, same_bits_quiet,  # noqa: E402
                                          world_diagonal)

from bench.views import TopView  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import mesh_io  # noqa: E402
from skin_detach_addon.blender.drag_session import CANCELLED, FINISHED, DragSession  # noqa: E402
from skin_detach_addon.blender.preview_stand_in import preview_of  # noqa: E402


def rig_with_a_preview(scene):
    body, parts, _ = character()
    api.build([body] + parts, target_faces=300, preview_above=500)
    members = api.members(body)
    low, top = lowest_and_top(members)
    api.add_anchor(body, low)
    handle = api.add_handle(body, top)
    return body, members, handle


def drag(body, handle, finish):
    session = DragSession(body, handle, TopView(scale=0.01), (100.0, 100.0), preview_above=500)
    for k in range(1, 6):
        session.event("MOUSEMOVE", "NOTHING", (100.0 + 8 * k, 100.0 + 3 * k))
        bpy.context.view_layer.update()
    return session


@pytest.mark.parametrize("finish", ["RET", "ESC"])
def test_one_preview_stands_in_for_every_object_and_the_confirm_writes_them_all(scene, finish):
    body, members, handle = rig_with_a_preview(scene)
    preview = preview_of(body)
    assert preview is not None  # the premise: above Preview Above, the rig has its preview
    assert len(preview.data.vertices) < sum(len(m.data.vertices) for m in members)
    before = bits(members)
    session = drag(body, handle, finish)
    assert all(m.hide_get() for m in members) and not preview.hide_viewport  # the preview stands in for all
    assert same_bits(before, bits(members))  # moves write the preview only
    state = session.event(finish, "PRESS", (140.0, 115.0))
    bpy.context.view_layer.update()
    assert state == (FINISHED if finish == "RET" else CANCELLED)
    assert not any(m.hide_get() for m in members) and preview.hide_viewport
    if finish == "ESC":
        assert same_bits(before, bits(members))
        return
    dragged = [mesh_io.read_positions(m.data).copy() for m in members]
    api.deform(body)  # the same handles solved from rest: the drag's settled confirm lands there too
    diagonal = world_diagonal(members)
    for member, shown in zip(members, dragged):
        assert np.abs(mesh_io.read_positions(member.data) - shown).max() <= 1e-3 * diagonal / min(
            member.scale), member.name
    assert max(np.abs(d - b[0].reshape(-1, 3)).max() for d, b in zip(dragged, before)) > 0  # they moved


def test_a_save_during_a_previewing_drag_writes_every_object_and_the_cancel_puts_them_back(scene, tmp_path):
    body, members, handle = rig_with_a_preview(scene)
    before = bits(members)
    session = drag(body, handle, "ESC")
    api.before_save()  # a save during the drag (Blender's save_pre) writes the pose shown into every object
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "during.blend"))
    assert not same_bits_quiet(before, bits(members))  # the objects hold the pose shown now
    session.event("ESC", "PRESS", (140.0, 115.0))
    assert same_bits(before, bits(members))

