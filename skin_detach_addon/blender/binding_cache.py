"""The binding cache holds nothing for an object that is not in the open file.

:data:`.binding._CACHE` keeps the core side of each binding opened in this session (at millions of
vertices, hundreds of MB), :data:`.binding._PENDING` the openings under way on the background
thread, both by binding id. A Rebuild or Clear drops its own entry (:func:`.binding.forget`), a
file about to be opened drops them all (:func:`skin_detach_addon.api.before_load`); what else
leaves an id held by no object, a mesh deleted, an undo or redo back to before its build, is
dropped here (:func:`prune`), from handlers the add-on's register installs: after every undo and
redo, and after a dependency graph update that finds fewer objects than the last (a delete; the
count is cheap, the scan of every object's record is done only then). An undo that brings a
deleted mesh back makes its binding again from the record, as a reopened file does.
"""

from . import binding as stored

#: The object count the last prune saw (a depsgraph update with fewer objects prunes again).
_SEEN = [None]


def held_ids():
    """The binding ids the objects of the open file hold."""
    import bpy
    held = {stored.binding_id(obj) for obj in bpy.data.objects if obj.type == 'MESH'}
    held.discard(None)
    return held


def prune(*_args):
    """Drop every cached binding and opening under way whose id no object of the open file holds
    (an opening's thread runs on; what it makes is dropped with it). A handler (any arguments)."""
    import bpy
    _SEEN[0] = len(bpy.data.objects)
    if not (stored._CACHE or stored._PENDING):
        return
    held = held_ids()
    for table in (stored._CACHE, stored._PENDING):
        for binding_id in [key for key in table if key not in held]:
            table.pop(binding_id, None)


def _after_update(*_args):
    """A depsgraph_update_post handler: prune when objects went since the last prune (a delete)."""
    import bpy
    count = len(bpy.data.objects)
    if _SEEN[0] is None or count < _SEEN[0]:
        prune()
    else:
        _SEEN[0] = count


prune._bpy_persistent = True  # kept across file loads (bpy.app.handlers.persistent)
_after_update._bpy_persistent = True


#: (handler list name of ``bpy.app.handlers``, function) pairs the add-on's register installs
#: (:func:`skin_detach_addon.api.handlers`, in one place with the others).
HANDLERS = (("undo_post", prune), ("redo_post", prune), ("depsgraph_update_post", _after_update))
