"""Issue 52, item 3: keys pressed while Build runs were dropped with nothing said (Ctrl+S, Tab,
Ctrl+Z, X). Ctrl+S saves the file while the build goes on; Tab and X are not taken, and a warning
says so; the build still ends and binds the mesh."""

import os
import tempfile
import time

import bpy

import gui
import rigs
import test_build_progress


def test_ctrl_s_saves_during_a_build_and_other_keys_say_they_wait(ui):
    yield from ui.setup()
    yield from ui.find_button("bpy.ops.skin_detach.build()")
    assert ui.found is not None, "no Build button in the panel"
    build = ui.found
    obj = test_build_progress._big_mesh(ui)
    path = os.path.join(tempfile.mkdtemp(), "scan.blend")
    with rigs.override(ui):
        bpy.ops.wm.save_as_mainfile(filepath=path)
    saved = os.path.getmtime(path)
    yield 1.1  # a save now shows as a later modification time
    sd = rigs.api()
    yield from ui.click(*build, wait=0.3)
    builds = gui.addon().ui.operators.BUILDS
    assert obj.name in builds, "Build is not running after its press"
    yield from ui.hover_view()
    yield from ui.press('S', ctrl=True, wait=1.5)
    assert obj.name in builds, "the build ended before the keys could be tried (make the mesh larger)"
    assert os.path.getmtime(path) > saved, "Ctrl+S during the build did not save the file"
    yield from ui.press('TAB', wait=0.5)
    assert obj.mode == 'OBJECT', "Tab entered Edit Mode on the mesh being built"
    yield from ui.press('X', wait=0.5)
    begun = time.monotonic()
    while obj.name in builds:
        assert time.monotonic() - begun < 150, "the build did not end"
        yield 0.2
    yield 0.5
    assert sd.is_bound(obj), "the build did not bind the mesh"
    yield from ui.reports()
    said = [line for line in ui.last_reports if "not taken until the build ends" in line]
    assert any("Tab" in line for line in said) and any("X" in line for line in said), ui.last_reports[-5:]
