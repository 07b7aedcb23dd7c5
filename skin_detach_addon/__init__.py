"""Skin Detach: deform huge detail meshes through a small proxy, detail kept intact.

This file only registers. The numpy/scipy core (``skin_detach_addon.core``) imports without
Blender; the Blender layer is imported when Blender registers the add-on.
"""


def register():
    from . import blender
    blender.register()


def unregister():
    from . import blender
    blender.unregister()
