"""Skin Detach: deform huge detail meshes through a small proxy, detail kept intact.

This file only registers. The layers import one way: ``ui`` (operators, panel, settings, live
update) -> ``api`` (the scripting API) -> ``blender`` (Blender services) -> ``core`` (numpy and
scipy only, importable without Blender).
"""


def register():
    from . import ui
    ui.register()


def unregister():
    from . import ui
    ui.unregister()
