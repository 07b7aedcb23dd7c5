"""Every ``bpy.app.handlers`` function of the add-on, installed by :func:`register` and removed by
:func:`unregister`, in one place: the api layer's first (:func:`skin_detach_addon.api.handlers`:
cancelling a closed file's background work, dropping kept mesh fingerprints), then live update's,
saving's, the idle preparation's and the stretch shading's, in that order within each list."""

import bpy

from .. import api
from . import idle_preparation, live_update, saving, stretch_shading


def installed():
    """(handler list name, function) of every handler of the add-on, in the order installed."""
    return (api.handlers() + live_update.HANDLERS + saving.HANDLERS + idle_preparation.HANDLERS
            + stretch_shading.HANDLERS)


def register():
    for name, function in installed():
        handlers = getattr(bpy.app.handlers, name)
        if function not in handlers:
            handlers.append(function)


def unregister():
    for name, function in installed():
        handlers = getattr(bpy.app.handlers, name)
        while function in handlers:
            handlers.remove(function)
