"""Issue 44: Build runs while the window answers, shows its progress, and Esc cancels it."""

import time


import bpy
import numpy as np

import gui
import rigs


def _big_mesh(ui, n=700):
    """A wavy n x n grid of quads (490,000 vertices at 700: a build of seconds here) made from
    arrays (Blender's UV sphere operator takes minutes at that size), active (the start-up cube
    stays: removing it before making the big mesh hung this Blender)."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    points = np.stack([u, v, 0.1 * np.sin(4 * u) * np.cos(3 * v)], axis=-1).reshape(-1, 3)
    ids = np.arange(n * n).reshape(n, n)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], axis=-1).reshape(-1, 4)
    mesh = bpy.data.meshes.new("Scan")
    mesh.vertices.add(points.shape[0])
    mesh.loops.add(quads.size)
    mesh.polygons.add(quads.shape[0])
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    mesh.loops.foreach_set("vertex_index", quads.astype(np.int32).ravel())
    mesh.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new("Scan", mesh)
    bpy.context.scene.collection.objects.link(obj)
    rigs.activate(ui, obj)
    rigs.undo_push(ui, "Scan")
    return obj


def _builds():
    return gui.addon().ui.operators.BUILDS


class _Beat:
    """A timer of the event loop: the times it ran (a frozen window runs none)."""

    def __init__(self):
        self.times, self.stages = [], []
        bpy.app.timers.register(self, first_interval=0.0)

    def __call__(self):
        self.times.append(time.monotonic())
        self.stages.append(next((job.stage for job in _builds().values()), ""))
        return 0.05

    def stop(self):
        if bpy.app.timers.is_registered(self):
            bpy.app.timers.unregister(self)

    def longest_wait(self, start, end):
        """(seconds, the stage before it) of the longest time between two beats in [start, end]."""
        beats = [(start, "")] + [(t, s) for t, s in zip(self.times, self.stages) if start <= t <= end] + [(end, "")]
        return max((b[0] - a[0], a[1]) for a, b in zip(beats, beats[1:]))


def test_build_shows_its_progress_the_view_zooms_meanwhile_and_esc_cancels(ui):
    yield from ui.setup()
    # The Build button is found on the start-up cube (hovering the panel is slow once the view
    # draws half a million vertices), then pressed on the big mesh.
    yield from ui.find_button("bpy.ops.skin_detach.build()")
    assert ui.found is not None, "no Build button in the panel"
    build = ui.found
    obj = _big_mesh(ui)
    sd = rigs.api()
    names = set(bpy.data.objects.keys())
    # Build pressed, then Esc while it runs: nothing changes.
    yield from ui.click(*build, wait=0.3)
    assert obj.name in _builds(), "Build is not running after its press (it finished at once, or never began)"
    yield from ui.hover_view()
    yield from ui.press('ESC', wait=0.5)
    assert obj.name not in _builds(), "Esc did not end the build"
    yield 1.0
    assert not sd.is_bound(obj) and set(bpy.data.objects.keys()) == names, "the cancelled build wrote something"
    yield from ui.reports()
    assert any("cancelled" in line and "nothing changed" in line for line in ui.last_reports), ui.last_reports[-3:]
    # Build again and let it finish; the view zooms while it runs, the panel shows how far it got.
    beat = _Beat()
    begun = time.monotonic()
    yield from ui.click(*build, wait=0.3)
    job = _builds().get(obj.name)
    assert job is not None, "Build is not running after its press"
    view = ui.area().spaces.active.region_3d
    distance = view.view_distance
    yield from ui.hover_view()
    for _ in range(3):
        yield from ui.press('WHEELUPMOUSE', wait=0.2)
    assert view.view_distance < distance, "the wheel did not zoom the view while Build ran"
    stages = set()
    while obj.name in _builds():
        stages.add(job.stage)
        assert time.monotonic() - begun < 150, "the build did not end"
        yield 0.1
    ended = time.monotonic()
    beat.stop()
    yield 0.5
    assert sd.is_bound(obj), "the build did not bind the mesh"
    assert len(stages) >= 2, f"the build showed one stage only: {stages}"
    wait, stage = beat.longest_wait(begun + 0.3, ended)
    assert wait < 0.5 * (ended - begun), \
        f"the window did not answer for {wait:.2f} s of the build's {ended - begun:.2f} s"
    print(f"GUI build: {ended - begun:.2f} s, longest wait of the event loop {wait:.2f} s (after {stage!r}), stages {sorted(stages)}")
    yield from ui.reports()
    assert any("vertices bound to a proxy" in line for line in ui.last_reports), ui.last_reports[-3:]
    # One undo step: Ctrl+Z gives the unbound mesh back.
    yield from ui.hover_view()
    yield from ui.press('Z', ctrl=True, wait=1.5)
    assert not sd.is_bound(bpy.data.objects["Scan"]), "Ctrl+Z did not undo the build in one step"
