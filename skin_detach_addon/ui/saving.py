"""Before Blender writes a file (a save, a save as copy, autosave): every bound mesh goes into it
consistent with its binding (see :func:`skin_detach_addon.api.before_save`)."""

import bpy
from bpy.app.handlers import persistent

from .. import api


@persistent
def _before_save(*_args):
    api.before_save()


def register():
    if _before_save not in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.append(_before_save)


def unregister():
    while _before_save in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.remove(_before_save)
