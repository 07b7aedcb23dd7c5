"""Headless bpy: the one background mechanism (issue 52, item 9). Opening another file cancels the
closed file's preparation (the new file's starts at once, nothing of the closed file is kept),
unregistering does not wait for it, and the stretch shared between threads is made once."""

import threading
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import import_spot, quad_sphere  # noqa: E402

import skin_detach_addon  # noqa: E402
from skin_detach_addon import api  # noqa: E402
from skin_detach_addon.blender import binding  # noqa: E402
from skin_detach_addon.core import threads  # noqa: E402
from skin_detach_addon.ui import idle_preparation  # noqa: E402


def _saved(path, make):
    """Save a file holding one bound mesh made by ``make``; returns its name."""
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = make()
    api.build(obj, target_faces=200)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return obj.name


def _slow_opening(monkeypatch, name, ended):
    """Make the opening of the mesh ``name`` last 60 s (its progress checked every millisecond,
    as the real one's stages report), recording in ``ended`` when it stopped."""
    make = binding.Opening.make

    def slow(self, *args):
        if self.name == name:
            try:
                report = self._report(0.0, 1.0)
                for k in range(60_000):
                    report(k / 60_000, "slow on purpose")
                    time.sleep(0.001)
            finally:
                ended.append(time.perf_counter())
        return make(self, *args)

    monkeypatch.setattr(binding.Opening, "make", slow)


def _opening_under_way(path, name):
    """Open ``path`` and start its preparation; returns the background job of ``name``'s opening."""
    bpy.ops.wm.open_mainfile(filepath=str(path))
    assert idle_preparation.queued() == [name]
    assert idle_preparation.prepare_next() == idle_preparation.POLL
    opening = binding._PENDING[binding.binding_id(bpy.data.objects[name])]
    time.sleep(0.1)
    assert not opening.done()
    return opening


def test_opening_another_file_cancels_the_closed_files_preparation(scene, tmp_path, monkeypatch, capsys):
    old_name = _saved(tmp_path / "old.blend", import_spot)
    new_name = _saved(tmp_path / "new.blend", lambda: quad_sphere("new"))
    ended = []
    _slow_opening(monkeypatch, old_name, ended)
    old = _opening_under_way(tmp_path / "old.blend", old_name)
    old_id = old.binding_id
    begun = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "new.blend"))
    assert old._job.wait(1.0), "the closed file's opening went on"
    assert ended[0] - begun < 1.0 and old.cancelled
    assert not binding._PENDING and not binding._CACHE  # nothing kept of the closed file
    assert idle_preparation.queued() == [new_name]
    started = time.perf_counter()
    while idle_preparation.prepare_next() is not None:
        time.sleep(0.005)
        assert time.perf_counter() - started < 60
    obj = bpy.data.objects[new_name]
    assert binding.cached(obj) is not None and set(binding._CACHE) == {binding.binding_id(obj)} != {old_id}
    assert new_name not in idle_preparation.FAILED and "not prepared" not in capsys.readouterr().out
    assert binding.open_binding(obj) is binding.cached(obj)  # made in the background: taken as it is


def test_unregister_returns_quickly_while_a_file_is_being_prepared(scene, tmp_path, monkeypatch):
    name = _saved(tmp_path / "rig.blend", import_spot)
    ended = []
    _slow_opening(monkeypatch, name, ended)
    opening = _opening_under_way(tmp_path / "rig.blend", name)
    begun = time.perf_counter()
    skin_detach_addon.unregister()
    try:
        assert time.perf_counter() - begun < 1.0 and opening.done() and opening.cancelled
    finally:
        skin_detach_addon.register()
    monkeypatch.undo()
    obj = bpy.data.objects[name]
    assert binding.open_binding(obj).surface.n_detail == len(obj.data.vertices)  # the cancelled opening made anew


def test_the_stretch_asked_for_by_two_threads_at_once_is_made_once(scene, monkeypatch):
    obj = import_spot()
    api.build(obj, target_faces=200)
    record = binding.open_binding(obj)
    record._stretch = None
    made = []

    class SlowStretch:
        def __init__(self, surface):
            made.append(surface)
            time.sleep(0.2)  # both threads ask meanwhile

        def __call__(self, proxy_vertices):
            return np.zeros(record.surface.n_detail, dtype=np.float32)

    monkeypatch.setattr(binding, "SkinStretch", SlowStretch)
    barrier = threading.Barrier(2)
    got = []

    def ask():
        barrier.wait()
        got.append(record._skin_stretch())

    workers = [threading.Thread(target=ask) for _ in range(2)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(10)
    assert len(made) == 1 and len(got) == 2 and got[0] is got[1] is record._skin_stretch()


@pytest.mark.parametrize("change", ["clear", "delete", "rebuild"])
def test_a_mesh_cleared_deleted_or_built_again_during_its_preparation_stops_it_quietly(scene, tmp_path, monkeypatch,
                                                                                      capsys, change):
    """Issue 52 item 8: Clear Skin during a preparation had the preparation report "press Build
    first"; a mesh deleted or edited meanwhile left its half-made binding in memory."""
    name = _saved(tmp_path / "rig.blend", import_spot)
    ended = []
    _slow_opening(monkeypatch, name, ended)
    opening = _opening_under_way(tmp_path / "rig.blend", name)
    obj = bpy.data.objects[name]
    if change == "clear":
        api.clear(obj)
    elif change == "delete":
        bpy.data.objects.remove(obj)
    else:
        api.build(obj, target_faces=150)
    begun = time.perf_counter()
    assert idle_preparation.prepare_next() is None  # done: nothing left to prepare
    assert opening._job.wait(1.0) and ended[0] - begun < 1.0, "the opening went on"
    assert name not in idle_preparation.FAILED and "not prepared" not in capsys.readouterr().out
    assert opening.binding_id not in binding._PENDING and opening.binding_id not in binding._CACHE
    if change == "rebuild":
        assert set(binding._CACHE) == {binding.binding_id(bpy.data.objects[name])}
