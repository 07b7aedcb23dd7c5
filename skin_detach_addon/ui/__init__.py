"""Everything an artist touches: operators, the N-panel, scene settings and live update. It
calls :mod:`skin_detach_addon.api` only (never ``blender`` or ``core`` directly). Only
:func:`register` and :func:`unregister` are meant to be called from outside."""

import bpy

from .. import api
from . import handlers, idle_preparation, live_update, menus, operators, panel, properties

CLASSES = properties.CLASSES + operators.CLASSES + panel.CLASSES + menus.CLASSES


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    properties.register()
    handlers.register()
    menus.register()


def unregister():
    operators.cancel_builds()
    menus.unregister()
    handlers.unregister()
    idle_preparation.unregister()
    live_update.unregister()
    properties.unregister()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    api.shutdown()  # no worker thread outlives the add-on
