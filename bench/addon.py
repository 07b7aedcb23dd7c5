"""The add-on in a benchmark as an artist has it: registered (``skin_detach_addon.register()``:
its properties, operators and panels, live update's depsgraph and frame handlers, the save and
load handlers, the binding cache's), unregistered at the end. Since issue 52 the add-on keeps the
meshes' fingerprints only while its handlers are installed: an unregistered run pays corner reads
an artist's Blender does not (issue 53)."""

import os
import sys


def register():
    """Register the add-on (see the module); returns :func:`registered`."""
    import skin_detach_addon
    skin_detach_addon.register()
    return registered()


def registered():
    """Whether the add-on runs as an artist has it: registered, live update's handler installed."""
    import bpy
    return hasattr(bpy.types.Scene, "skin_detach") and any(
        getattr(h, "__module__", "").startswith("skin_detach_addon") for h in bpy.app.handlers.depsgraph_update_post)


def finish():
    """The end of a benchmark that :func:`register` ed the add-on: unregistered; with bpy 4.2, whose
    module crashes at interpreter exit once the add-on was registered (its live-update toggle's
    update callback, whatever is unregistered before; tests/conftest.py), the process ends here
    instead, its output flushed (call it last)."""
    import bpy
    if bpy.app.version[:2] == (4, 2):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    import skin_detach_addon
    skin_detach_addon.unregister()
