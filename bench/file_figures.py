"""The file figures of a bound, rigged mesh (issue 44, a .blend that does not double): the save,
the .blend's size, its open (the least of three), the seconds until it is prepared after opening (the binding made
again and the handles' layout prepared on the background thread, polled as the add-on's timer
polls it) and the longest the main thread was held meanwhile; then the same mesh saved and opened
without a binding (plain: the rig's objects and the record removed). It opens files: call it
last, nothing of the scene before it is valid after it.

    file_figures(obj) -> dict
"""

import pathlib
import tempfile
import time

#: Seconds between two polls of the preparation (the add-on's timer polls every 50 ms).
POLL = 0.05
#: Each file is opened this many times; the least is kept.
OPENS = 3


def _saved(bpy, path):
    start = time.perf_counter()
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return time.perf_counter() - start, path.stat().st_size / 1e6


def _opened(bpy, path):
    """The least of :data:`OPENS` opens of ``path`` (one open on a busy machine says little); the
    file is left open."""
    from skin_detach_addon.blender import binding
    seconds = []
    for _ in range(OPENS):
        bpy.ops.wm.read_homefile(use_empty=True)
        binding._CACHE.clear()
        start = time.perf_counter()
        bpy.ops.wm.open_mainfile(filepath=str(path))
        seconds.append(time.perf_counter() - start)
    return min(seconds)


def _prepared(bpy, api):
    """(seconds until every bound mesh is prepared, the longest main-thread poll in ms)."""
    start, longest = time.perf_counter(), 0.0
    for obj in api.bound_objects(bpy.data.objects):
        began = time.perf_counter()
        preparation = api.prepare_in_background(obj)
        longest = max(longest, time.perf_counter() - began)
        while True:
            began = time.perf_counter()
            done = preparation.poll()
            longest = max(longest, time.perf_counter() - began)
            if done:
                break
            time.sleep(POLL)
    return time.perf_counter() - start, 1000 * longest


def file_figures(obj):
    """Figures of saving and opening the bound mesh object ``obj``'s file, and of the same mesh
    without a binding (see the module): save_s, blend_mb, open_s, prepared_s (after the open),
    main_thread_max_ms, plain_mb, plain_open_s, and the ratios size_x and open_x."""
    import bpy
    from skin_detach_addon import api

    name = obj.name
    if api.stretch_shown(obj):  # its attributes are the mesh's own data, not the binding's: neither file has them
        api.show_stretch(obj, False)
    folder = pathlib.Path(tempfile.mkdtemp(prefix="skin_detach_files_"))
    bound_path, plain_path = folder / "bound.blend", folder / "plain.blend"
    save_s, blend_mb = _saved(bpy, bound_path)
    open_s = _opened(bpy, bound_path)
    prepared_s, longest_ms = _prepared(bpy, api)
    obj = bpy.data.objects[name]
    api.clear(obj)  # the proxy, the preview, the handles and the record go
    _saved(bpy, plain_path)
    plain_mb = plain_path.stat().st_size / 1e6
    plain_open_s = _opened(bpy, plain_path)
    for path in (bound_path, plain_path):
        path.unlink()
    folder.rmdir()
    return {"save_s": save_s, "blend_mb": blend_mb, "open_s": open_s, "prepared_s": prepared_s,
            "main_thread_max_ms": longest_ms, "plain_mb": plain_mb, "plain_open_s": plain_open_s,
            "size_x": blend_mb / plain_mb, "open_x": open_s / plain_open_s}
