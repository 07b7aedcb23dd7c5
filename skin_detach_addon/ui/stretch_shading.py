"""The 3D Views' coloring while a stretch map is shown. Show Stretch records every 3D View's
coloring on its screen and sets the Solid ones to Attribute (the active color attribute: the
stretch map's); when no bound mesh shows its stretch any more (Show Stretch again, Clear Skin,
an undo to before Show Stretch), every recorded view still on Attribute gets the coloring it had
back (one the artist set to something else meanwhile keeps that) and the records go. After an
undo, a redo or a file load the views follow the meshes again (:func:`sync`)."""

import bpy
from bpy.app.handlers import persistent

from .. import api

#: Screen property: {"area index:space index": the coloring (shading.color_type) the view had}.
RECORD = "_skin_detach_stretch_shading"
#: shading.color_type's identifier of the coloring the UI calls "Attribute".
ATTRIBUTE = 'VERTEX'


def _views(screen):
    """("area index:space index", shading) of every 3D View of ``screen`` (open or not)."""
    for a, area in enumerate(screen.areas):
        for s, space in enumerate(area.spaces):
            if space.type == 'VIEW_3D':
                yield f"{a}:{s}", space.shading


def show():
    """Record the coloring of every 3D View of the file not recorded yet, and set the Solid ones
    to Attribute."""
    for screen in bpy.data.screens:
        record = dict(screen.get(RECORD, {}))
        for key, shading in _views(screen):
            if key not in record:
                record[key] = shading.color_type
                if shading.type == 'SOLID':
                    shading.color_type = ATTRIBUTE
        if record:
            screen[RECORD] = record


def _any_shown():
    return any(api.stretch_shown(obj) for obj in api.bound_objects())


def settle():
    """When no bound mesh shows its stretch: every recorded view still on Attribute gets its
    recorded coloring back; the records go."""
    if _any_shown():
        return
    for screen in bpy.data.screens:
        record = screen.get(RECORD)
        if record is None:
            continue
        views = dict(_views(screen))
        for key, color in record.items():
            shading = views.get(key)
            if shading is not None and shading.color_type == ATTRIBUTE and color != ATTRIBUTE:
                shading.color_type = color
        del screen[RECORD]


@persistent
def sync(*_):
    """The views as the meshes say (an undo, a redo or a file load changes the meshes, never the
    views): Attribute while a bound mesh shows its stretch (:func:`show`), else given back (:func:`settle`)."""
    if _any_shown():
        show()
    else:
        settle()


#: (handler list of ``bpy.app.handlers``, function) pairs :mod:`.handlers` installs.
HANDLERS = (("undo_post", sync), ("redo_post", sync), ("load_post", sync))
