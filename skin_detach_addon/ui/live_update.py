"""Live update: when a handle of a bound object moves by any means (G/R/S, drivers, animation,
frame change), re-solve without the user pressing anything.

The depsgraph and frame-change handlers only notice (comparing handle transforms with those of
the last solve) and schedule a timer; the timer does the write, outside the handler. A guard
stops the write's own depsgraph update from scheduling another. Only scenes whose
``skin_detach.live_update`` is on are watched; :func:`unregister` removes the timers (:mod:`.handlers`
the handlers).

A mesh above the scene's Preview Above that has a preview shows the preview while its handles
move; once they have been still for :data:`IDLE_SECONDS`, :func:`settle` writes the full detail.
"""

import time
import traceback

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .. import api
from ..api import SkinDetachError

_pending = set()
_state = {"busy": False}
#: Last error per object name, shown in the panel.
ERRORS = {}
#: Handle signature of every object at its last solve, write or cancel (runtime only).
_SOLVED = {}
#: Seconds without a handle move before a previewed mesh gets its full detail.
IDLE_SECONDS = 0.4
#: Objects showing their preview: object pointer (survives a rename) -> time.monotonic() of the
#: last preview step. Whether a preview stands in is stored with the binding (it survives a
#: save and reload, which this does not: a mesh with no time here is due at once).
_UNSETTLED = {}


def handle_signature(obj, proxy):
    """The bytes of the object's world matrix, the proxy's and every handle's own (basis) matrix,
    with the handles' names: changes when any of them moves, by any means, and is current as soon
    as it is set (bytes, not floats: a NaN compares equal to itself, so a handle left at NaN is
    solved, and reported, once)."""
    values = [np.array(obj.matrix_world, dtype=np.float64).tobytes(),
              np.array(proxy.matrix_basis, dtype=np.float64).tobytes()]
    for empty in api.handles_of(obj):
        values.append((empty.name, np.array(empty.matrix_basis, dtype=np.float64).tobytes()))
    return tuple(values)


def remember(obj):
    """Take the handles' current transforms of ``obj`` as solved (after Apply, a drag, Reset)."""
    proxy = api.proxy_of(obj)
    if proxy is not None:
        _SOLVED[obj.name] = handle_signature(obj, proxy)


def notice(scene):
    """Queue every bound object of ``scene`` whose handles moved since its last solve."""
    if _state["busy"] or not scene.skin_detach.live_update:
        return
    for obj in api.bound_objects(scene.objects):
        if api.is_dragged(obj):  # a running drag solves its own poses (its moves, settle, confirm)
            continue
        proxy = api.proxy_of(obj)
        if proxy is not None and handle_signature(obj, proxy) != _SOLVED.get(obj.name):
            _pending.add(obj.name)
    if _pending and not bpy.app.timers.is_registered(flush):
        bpy.app.timers.register(flush, first_interval=0.0)


@persistent
def _on_depsgraph_update(scene, depsgraph=None):
    notice(scene)


@persistent
def _on_frame_change(scene, depsgraph=None):
    notice(scene)


def flush():
    """Solve and write every queued object (the timer's body; tests call it directly)."""
    _state["busy"] = True
    try:
        scene = bpy.context.scene
        for name in sorted(_pending):
            obj = bpy.data.objects.get(name)
            if obj is None or not api.is_bound(obj) or api.is_dragged(obj):
                continue
            try:
                large = api.figures(obj)["build"].get("detail_vertices", 0) > scene.skin_detach.preview_above
                stats = api.deform(obj, scene.skin_detach.preserve_volume, api.DRAG_TOL if large else api.SETTLE_TOL,
                                   preview=large, follow=True)
                if stats["preview"]:
                    _UNSETTLED[obj.as_pointer()] = time.monotonic()
                    if not bpy.app.timers.is_registered(settle):
                        bpy.app.timers.register(settle, first_interval=IDLE_SECONDS)
                else:
                    _UNSETTLED.pop(obj.as_pointer(), None)
                if stats["converged"]:
                    ERRORS.pop(name, None)
                else:
                    _report(name, f"the last solve did not converge ({stats['iterations']} iterations)")
            except SkinDetachError as exc:
                _report(name, str(exc))
            except Exception as exc:  # noqa: BLE001 (an internal error: said once, and live update goes on)
                _report(name, f"internal error {type(exc).__name__}: {exc}", traceback.format_exc())
            remember(obj)  # report once, not on every later update
        _pending.clear()
    finally:
        _state["busy"] = False
    return None


def settle(now=None, only=None, everything=False):
    """Write the full detail of every object whose preview stands in and whose handles have been
    still for :data:`IDLE_SECONDS` (the timer's body, repeating while any preview shows; ``now``:
    the time.monotonic() to judge by, tests pass a later one). ``only``, an object name, settles
    that object at once, idle or not (a drag starting on it wants the full detail first);
    ``everything`` settles all at once (before a save, after a load)."""
    now = time.monotonic() if now is None else now
    showing = [o for o in bpy.data.objects if api.is_bound(o) and api.mesh_of(o) == o and api.preview_stands_in(o)]
    if only is not None:
        due = [o for o in showing if o.name == only]
    elif everything:
        due = showing
    else:
        due = [o for o in showing if now - _UNSETTLED.get(o.as_pointer(), -float("inf")) >= IDLE_SECONDS
               and o.name not in _pending]
    for obj in due:
        _UNSETTLED.pop(obj.as_pointer(), None)
        _state["busy"] = True
        try:
            api.deform(obj, bpy.context.scene.skin_detach.preserve_volume, follow=True)
            ERRORS.pop(obj.name, None)
        except SkinDetachError as exc:
            _report(obj.name, str(exc))
        finally:
            _state["busy"] = False
        remember(obj)
    return IDLE_SECONDS if any(api.preview_stands_in(o) for o in showing) else None


def _report(name, message, details=""):
    """Show ``message`` for object ``name`` in the panel; say it on the console (with ``details``,
    a traceback) when it is new: an error that stays while handles move is said once."""
    if ERRORS.get(name) != message:
        print(f"{details}Skin Detach live update: {name}: {message}")
    ERRORS[name] = message


@persistent
def _settle_all(*_args):
    """Before a save and after a load: the mesh holds (and shows) the pose its preview showed."""
    _UNSETTLED.clear()
    settle(everything=True)


def pending():
    return set(_pending)


#: (handler list of ``bpy.app.handlers``, function) pairs :mod:`.handlers` installs.
HANDLERS = (("depsgraph_update_post", _on_depsgraph_update), ("frame_change_post", _on_frame_change),
            ("save_pre", _settle_all), ("load_post", _settle_all))


def unregister():
    """Stop the timers and forget what was noticed (:mod:`.handlers` removes the handlers)."""
    for timer in (flush, settle):
        if bpy.app.timers.is_registered(timer):
            bpy.app.timers.unregister(timer)
    _pending.clear()
    _UNSETTLED.clear()
