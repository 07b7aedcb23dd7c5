"""After a file is opened, every bound mesh's handle layout is prepared in idle time (see
:func:`skin_detach_addon.api.prepare`), one mesh per timer tick, so the artist's first drag move
and first confirm do not pay it (seconds at millions of vertices). A load handler only queues;
the timer does the work, after the file is up and drawn.
"""

import traceback

import bpy
from bpy.app.handlers import persistent

from .. import api
from ..api import SkinDetachError

#: Names of the bound meshes still to prepare (in order).
_queue = []
#: Why a bound mesh could not be prepared, by name (the panel shows it; a mesh prepared later,
#: or the next file loaded, clears it).
FAILED = {}
#: Seconds after a load before the first mesh is prepared (the window draws the file first).
FIRST_DELAY = 0.2


def prepare_next():
    """Prepare the next queued mesh (the timer's body; tests call it directly); returns the
    interval to the next call, or None when the queue is empty. A mesh that cannot be prepared
    is reported once (console and :data:`FAILED`) and skipped: whatever it raises, the timer goes
    on to the next (Blender never calls again a timer that raised)."""
    while _queue:
        name = _queue.pop(0)
        obj = bpy.data.objects.get(name)
        try:
            if obj is None or not api.is_bound(obj) or api.mesh_of(obj) != obj or not api.handles_of(obj):
                continue
            api.prepare(obj, bpy.context.scene.skin_detach.preserve_volume)
            FAILED.pop(name, None)
        except SkinDetachError as exc:  # the step that needs the rig reports it to the artist
            _failed(name, str(exc))
        except Exception as exc:  # noqa: BLE001 (an internal error: said, and the next mesh still prepared)
            traceback.print_exc()
            _failed(name, f"internal error {type(exc).__name__}: {exc}")
        return 0.0 if _queue else None
    return None


def _failed(name, message):
    FAILED[name] = f"not prepared: {message}"
    print(f"Skin Detach: {name} not prepared: {message}")


def queued():
    return list(_queue)


@persistent
def _on_load(*_args):
    _queue[:] = [o.name for o in api.bound_objects(bpy.data.objects)]
    FAILED.clear()
    if _queue and not bpy.app.timers.is_registered(prepare_next):
        bpy.app.timers.register(prepare_next, first_interval=FIRST_DELAY)


def register():
    if _on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_on_load)


def unregister():
    while _on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load)
    if bpy.app.timers.is_registered(prepare_next):
        bpy.app.timers.unregister(prepare_next)
    _queue.clear()
    FAILED.clear()
