"""After a file is opened, every bound mesh is prepared in the background, one mesh at a time
(:func:`skin_detach_addon.api.prepare_in_background`): its skin bound again from the stored
carrier, its rebuilds and its handle layout prepared (seconds at millions of vertices), on a
background thread, while the window answers events; a timer polls it on the main thread, which
alone reads and writes Blender data, and the panel shows "Preparing <mesh>: NN %" once it has
taken longer than a second. A step the artist asks for meanwhile waits for what is under way. A
load handler only queues; the timer starts the work after the file is up and drawn. Opening
another file cancels what is under way (:func:`skin_detach_addon.api.before_load`): the new file's
meshes are prepared at once.
"""

import traceback

import bpy
from bpy.app.handlers import persistent

from .. import api
from ..api import SkinDetachError

#: Names of the bound meshes still to prepare (in order).
_queue = []
#: The preparation under way (:class:`skin_detach_addon.blender.background.Preparation`), or None.
_current = None
#: Why a bound mesh could not be prepared, by name (the panel shows it; a mesh prepared later,
#: or the next file loaded, clears it).
FAILED = {}
#: Seconds after a load before the first mesh is prepared (the window draws the file first).
FIRST_DELAY = 0.2
#: Seconds between two polls of the preparation under way.
POLL = 0.05
#: A preparation is shown in the panel once it has taken this many seconds.
SHOWN_AFTER = 1.0
_shown = [None]


def prepare_next():
    """Advance the preparation under way, or start the next queued mesh's (the timer's body; tests
    call it directly); returns the interval to the next call, or None when nothing is left. A mesh
    that cannot be prepared is reported once (console and :data:`FAILED`) and skipped: whatever it
    raises, the timer goes on to the next (Blender never calls again a timer that raised)."""
    global _current
    while _current is not None or _queue:
        if _current is None:
            name = _queue.pop(0)
            obj = bpy.data.objects.get(name)
            try:
                if obj is None or not api.is_bound(obj) or api.mesh_of(obj) != obj:
                    continue
                _current = api.prepare_in_background(obj, bpy.context.scene.skin_detach.preserve_volume)
            except Exception as exc:  # noqa: BLE001 (reported, and the next mesh still prepared)
                _failed(name, exc)
                continue
        name = _current.name
        try:
            done = _current.poll()
        except Exception as exc:  # noqa: BLE001
            _current = None
            _failed(name, exc)
            _redraw()
            return 0.0 if _queue else None
        if not done:
            _redraw()
            return POLL
        _current = None
        FAILED.pop(name, None)
        _redraw()
        return 0.0 if _queue else None
    return None


def progress_of(name):
    """"Preparing <name>: NN %" while the mesh ``name`` is being prepared and has taken longer than
    :data:`SHOWN_AFTER` seconds, else None."""
    current = _current
    if current is None or current.name != name or current.seconds < SHOWN_AFTER:
        return None
    return f"Preparing {name}: {int(100 * current.fraction)} %"


def _redraw():
    """Redraw the 3D views' sidebars when what the panel shows changed."""
    text = None if _current is None else progress_of(_current.name)
    if text == _shown[0]:
        return
    _shown[0] = text
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def _failed(name, exc):
    if isinstance(exc, SkinDetachError):  # the step that needs the rig reports it to the artist
        message = str(exc)
    else:  # an internal error: said, and the next mesh still prepared
        traceback.print_exception(exc)
        message = f"internal error {type(exc).__name__}: {exc}"
    FAILED[name] = f"not prepared: {message}"
    print(f"Skin Detach: {name} not prepared: {message}")


def queued():
    return list(_queue)


@persistent
def _on_load(*_args):
    global _current
    _current = None
    _queue[:] = [o.name for o in api.bound_objects(bpy.data.objects)]
    FAILED.clear()
    if _queue and not bpy.app.timers.is_registered(prepare_next):
        bpy.app.timers.register(prepare_next, first_interval=FIRST_DELAY)


#: (handler list of ``bpy.app.handlers``, function) pairs :mod:`.handlers` installs.
HANDLERS = (("load_post", _on_load),)


def unregister():
    """Stop the timer and forget the queue (:mod:`.handlers` removes the handler)."""
    global _current
    if bpy.app.timers.is_registered(prepare_next):
        bpy.app.timers.unregister(prepare_next)
    _queue.clear()
    _current = None
    FAILED.clear()
