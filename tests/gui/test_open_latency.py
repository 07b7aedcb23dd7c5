"""Issue 44: a rigged file of 3 million vertices opens, and while its binding is made again and its
layout prepared (on a background thread) the window answers every event within 100 ms; the panel
shows the progress; then a handle is dragged. The mesh is drawn as its bounds (Object Properties >
Viewport Display), so the time measured is the add-on's and not software drawing's."""

import os
import subprocess
import tempfile
import time

import bpy
import numpy as np

import gui
import rigs

#: The longest an event may wait while the file is prepared (issue 44's goal).
LATENCY_S = 0.1
#: Seconds between two events of the stream.
EVERY_S = 0.03

MAKE = """
import numpy as np
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
bpy.ops.mesh.primitive_uv_sphere_add(segments=2448, ring_count=1224)
obj = bpy.context.active_object
obj.name = 'Scan'
obj.display_type = 'BOUNDS'
api.build(obj, target_faces=1000)
rest = api.rest_positions(obj)
api.add_anchor(obj, np.flatnonzero(rest[:, 2] < -0.6), mirror='')
handle = api.add_handle(obj, np.flatnonzero(rest[:, 2] > 0.6), mirror='')
for other in bpy.context.view_layer.objects:
    other.select_set(False)
handle.select_set(True)
bpy.context.view_layer.objects.active = handle
bpy.ops.wm.save_as_mainfile(filepath=PATH)
print('MADE', len(obj.data.vertices))
"""


class EventClock(bpy.types.Operator):
    """Notes when each mouse move reaches the window's handlers (passes every event on)."""
    bl_idname = "wm.skin_detach_test_event_clock"
    bl_label = "Event Clock"
    seen = {}
    running = False

    def invoke(self, context, event):
        context.window_manager.modal_handler_add(self)
        EventClock.running = True
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type == 'MOUSEMOVE':
            EventClock.seen.setdefault((event.mouse_x, event.mouse_y), time.perf_counter())
        if not EventClock.running:
            return {'FINISHED', 'PASS_THROUGH'}
        return {'PASS_THROUGH'}


def make_file(path):
    """The rigged 3M-vertex file, made by this Blender in the background (the same extension)."""
    prefix = (f"import bpy, sys; sys.path.insert(0, {os.path.dirname(gui.__file__)!r}); import gui; "
              f"api = gui.addon().api; PATH = {path!r}\n")
    done = subprocess.run([bpy.app.binary_path, "--background", "--python-exit-code", "1", "--python-expr",
                           prefix + MAKE], capture_output=True, text=True, timeout=150)
    assert "MADE" in done.stdout, f"the rigged file was not made: {(done.stdout + done.stderr)[-800:]}"


def test_a_3m_file_opens_and_is_prepared_without_a_wait(ui):
    yield from ui.setup()
    path = os.path.join(tempfile.mkdtemp(), "scan.blend")
    started = time.perf_counter()
    make_file(path)
    print(f"open_latency: file made in {time.perf_counter() - started:.1f} s")
    package = gui.addon()
    idle = package.ui.idle_preparation
    with bpy.context.temp_override(window=ui.window):
        opened = time.perf_counter()
        bpy.ops.wm.open_mainfile(filepath=path)
    print(f"open_latency: opened in {time.perf_counter() - opened:.1f} s")
    yield 0.0
    assert idle.queued() == ["Scan"] or idle._current is not None, "the opened file was not queued"
    bpy.utils.register_class(EventClock)
    try:
        with bpy.context.temp_override(window=ui.window, area=ui.area(), region=ui.view):
            bpy.ops.wm.skin_detach_test_event_clock('INVOKE_DEFAULT')
        x0, y = ui.view.x + 20, ui.view.y + 20
        sent, gaps, shown, last = {}, [], set(), None
        began = time.perf_counter()
        k = 0
        while idle.queued() or idle._current is not None or k < 10:
            assert time.perf_counter() - began < 120, "still preparing after 120 s"
            now = time.perf_counter()
            if last is not None:
                gaps.append(now - last - EVERY_S)
            last = now
            point = (x0 + k % 400, y + k // 400)
            sent[point] = time.perf_counter()
            ui.event('MOUSEMOVE', 'NOTHING', *point)
            text = idle.progress_of("Scan")
            if text:
                shown.add(text)
            k += 1
            yield EVERY_S
        prepared = time.perf_counter() - began
        yield 0.3
    finally:
        EventClock.running = False
        yield from ui.move(ui.view.x + 30, ui.view.y + 30)
        bpy.utils.unregister_class(EventClock)
    waits = [EventClock.seen[p] - t for p, t in sent.items() if p in EventClock.seen]
    print(f"open_latency: prepared {prepared:.1f} s after opening; {len(sent)} events, {len(waits)} handled, "
          f"longest wait {1000 * max(waits):.0f} ms, median {1000 * float(np.median(waits)):.0f} ms; longest "
          f"extra gap between the stream's ticks {1000 * max(gaps):.0f} ms; shown {sorted(shown)[:3]}")
    assert "Scan" not in idle.FAILED, idle.FAILED
    assert len(waits) >= 0.9 * len(sent), f"only {len(waits)} of {len(sent)} events reached the window's handlers"
    assert max(waits) <= LATENCY_S, f"an event waited {1000 * max(waits):.0f} ms while the file was prepared"
    assert max(gaps) <= LATENCY_S, f"the main thread was held {1000 * max(gaps):.0f} ms while the file was prepared"
    if prepared > 2.0:
        assert any(text.startswith("Preparing Scan: ") for text in shown), "the panel never showed the progress"
    obj = bpy.data.objects["Scan"]
    before = rigs.positions(obj).copy()
    yield from rigs.drag(ui, 60, 0)
    after = rigs.positions(obj)
    assert np.abs(after - before).max() > 1e-3, "the drag did not move the mesh"
