"""The preview object standing in for its bound mesh in viewports while a drag shows it.

While it stands in, the mesh (every object of a rig of several: the preview is the whole rig's) is
hidden in the current view layer (as H hides it: the object stays
in Blender's dependency graph, so hiding and showing it costs no rebuild of the graph's relations
nor a new evaluation of millions of vertices, which ``hide_viewport`` cost the first move of every
drag: 54-112 ms at 1.2M vertices) and the binding's record names that view layer under
:data:`STAND_IN_KEY`; the stand-in's end shows the mesh there again. Files of earlier versions
hid the mesh with ``hide_viewport`` and recorded its own state under :data:`OLD_STAND_IN_KEY`.
"""

from . import binding as stored
from . import rig_members
from ..core.errors import SkinDetachError

#: The binding's record names the view layer the mesh is hidden in while the preview stands in.
STAND_IN_KEY = "mesh_hidden_in"
#: Earlier versions' record: the mesh's own ``hide_viewport`` (a bool), hidden with that toggle.
OLD_STAND_IN_KEY = "mesh_hidden"


def preview_of(obj):
    """The preview object of ``obj`` when it has one, it still exists and it matches the stored
    preview (same vertex count), else None (a drag then shows the full detail)."""
    preview = stored.stored_object(obj, "preview")
    if preview is None or preview.type != 'MESH' or preview.get(stored.PREVIEW_TAG) != obj:
        return None
    arrays = stored.arrays_of(obj)
    # one carrier per preview vertex, whether the preview is stored whole (schema 2) or compact
    count = None if arrays is None else stored.stored_length(arrays.get(stored.PREVIEW_PREFIX + "carrier"))
    if count is None or len(preview.data.vertices) != count:
        return None
    return preview


def _view_layer(obj, name):
    """The view layer ``name`` of one of ``obj``'s scenes that holds ``obj``, or None."""
    for scene in obj.users_scene:
        layer = scene.view_layers.get(name) if isinstance(name, str) else None
        if layer is not None and obj.name in layer.objects:
            return layer
    return None


def _hidden_in(obj, record):
    """``obj`` is hidden where the stand-in ``record`` says it hid it."""
    if STAND_IN_KEY in record:
        layer = _view_layer(obj, record[STAND_IN_KEY])
        return layer is not None and obj.hide_get(view_layer=layer)
    return OLD_STAND_IN_KEY in record and bool(obj.hide_viewport)


def preview_stands_in(obj):
    """The preview object stands in for the mesh ``obj``: the add-on hid the mesh and recorded
    where (a record on a visible mesh is stale: from an older file)."""
    record = stored.readable_record(obj)
    return record is not None and _hidden_in(obj, record)


def record_stand_in(obj, preview):
    """Hide the mesh ``obj`` in the current view layer and show ``preview`` in its place,
    recording where (a mesh outside the current view layer is hidden with its viewport toggle,
    recorded as earlier versions did)."""
    import bpy
    layer = bpy.context.view_layer
    preview.hide_viewport = False
    if obj.name in layer.objects:
        obj[stored.KEY][STAND_IN_KEY] = layer.name
        for member in _members(obj):  # the owner, and the other objects of a rig of several
            if member.name in layer.objects:
                member.hide_set(True, view_layer=layer)
    else:
        obj[stored.KEY][OLD_STAND_IN_KEY] = bool(obj.hide_viewport)
        obj.hide_viewport = True


def end_stand_in(obj):
    """Give the mesh ``obj`` back its own viewport state and hide its preview (if any is left)."""
    preview = preview_of(obj) if stored.has_binding(obj) else None
    if preview is not None:
        preview.hide_viewport = True
    record = stored.readable_record(obj)
    if record is None:
        return
    if STAND_IN_KEY in record:
        layer = _view_layer(obj, record[STAND_IN_KEY])
        if layer is not None:
            for member in _members(obj):
                if member.name in layer.objects:
                    member.hide_set(False, view_layer=layer)
        del record[STAND_IN_KEY]
    if OLD_STAND_IN_KEY in record:
        if obj.hide_viewport:
            obj.hide_viewport = bool(record[OLD_STAND_IN_KEY])
        del record[OLD_STAND_IN_KEY]


def _members(obj):
    """The objects the preview of ``obj`` stands for: ``obj``, and the other objects of its rig of
    several (those still there)."""
    try:
        found = rig_members.objects(obj)
    except SkinDetachError:  # a damaged record: the owner alone
        return [obj]
    return [member for member in found if member is not None and getattr(member, "type", None) == 'MESH'] or [obj]
