"""The preview object standing in for its bound mesh in viewports while a drag shows it.

While it stands in, the mesh is hidden in viewports and the binding's record keeps the mesh's
own viewport state under :data:`STAND_IN_KEY` (a bool), given back when the stand-in ends.
"""

from . import binding as stored

#: The binding's record keeps the mesh's own ``hide_viewport`` under this key while the preview stands in.
STAND_IN_KEY = "mesh_hidden"


def preview_of(obj):
    """The preview object of ``obj`` when it has one, it still exists and it matches the stored
    preview (same vertex count), else None (a drag then shows the full detail)."""
    preview = stored.stored_object(obj, "preview")
    if preview is None or preview.type != 'MESH' or preview.get(stored.PREVIEW_TAG) != obj:
        return None
    arrays = stored.arrays_of(obj)
    count = None if arrays is None else arrays.get(stored.PREVIEW_PREFIX + "weld")
    if count is None or len(preview.data.vertices) != len(count):
        return None
    return preview


def _has_stand_in_record(obj):
    record = stored.readable_record(obj)
    return record is not None and STAND_IN_KEY in record


def preview_stands_in(obj):
    """The preview object stands in for the mesh ``obj``: the add-on hid the mesh in viewports
    and recorded its own state (a record on a visible mesh is stale: from an older file)."""
    return _has_stand_in_record(obj) and bool(obj.hide_viewport)


def record_stand_in(obj, preview):
    """Hide the mesh ``obj`` and show ``preview`` in its place, recording the mesh's own state."""
    obj[stored.KEY][STAND_IN_KEY] = bool(obj.hide_viewport)
    preview.hide_viewport = False
    obj.hide_viewport = True


def end_stand_in(obj):
    """Give the mesh ``obj`` back its own viewport state and hide its preview (if any is left)."""
    preview = preview_of(obj) if stored.has_binding(obj) else None
    if preview is not None:
        preview.hide_viewport = True
    if preview_stands_in(obj):
        obj.hide_viewport = bool(obj[stored.KEY][STAND_IN_KEY])
    if _has_stand_in_record(obj):
        del obj[stored.KEY][STAND_IN_KEY]
