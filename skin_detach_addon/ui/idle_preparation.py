"""After a file is opened, every bound mesh's handle layout is prepared in idle time (see
:func:`skin_detach_addon.api.prepare`), one mesh per timer tick, so the artist's first drag move
and first confirm do not pay it (seconds at millions of vertices). A load handler only queues;
the timer does the work, after the file is up and drawn.
"""

import bpy
from bpy.app.handlers import persistent

from .. import api
from ..api import SkinDetachError

#: Names of the bound meshes still to prepare (in order).
_queue = []
#: Seconds after a load before the first mesh is prepared (the window draws the file first).
FIRST_DELAY = 0.2


def prepare_next():
    """Prepare the next queued mesh (the timer's body; tests call it directly); returns the
    interval to the next call, or None when the queue is empty."""
    while _queue:
        obj = bpy.data.objects.get(_queue.pop(0))
        if obj is None or not api.is_bound(obj) or api.mesh_of(obj) != obj or not api.handles_of(obj):
            continue
        try:
            api.prepare(obj, bpy.context.scene.skin_detach.preserve_volume)
        except SkinDetachError as exc:  # the step that needs the rig reports it to the artist
            print(f"Skin Detach: not prepared: {exc}")
        return 0.0 if _queue else None
    return None


def queued():
    return list(_queue)


@persistent
def _on_load(*_args):
    _queue[:] = [o.name for o in api.bound_objects(bpy.data.objects)]
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
