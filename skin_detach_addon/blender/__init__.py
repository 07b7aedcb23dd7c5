"""Everything that touches bpy: operators, panel, settings, handlers. Only
:func:`register` and :func:`unregister` are meant to be called from outside."""

import bpy

from . import live_update, operators, panel, properties

CLASSES = properties.CLASSES + operators.CLASSES + panel.CLASSES


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    properties.register()
    live_update.register()


def unregister():
    live_update.unregister()
    properties.unregister()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
