"""Before Blender writes a file (a save, a save as copy, autosave): every bound mesh goes into it
consistent with its binding (see :func:`skin_detach_addon.api.before_save`)."""

import bpy
from bpy.app.handlers import persistent

from .. import api


@persistent
def _before_save(*_args):
    api.before_save()


#: (handler list of ``bpy.app.handlers``, function) pairs :mod:`.handlers` installs.
HANDLERS = (("save_pre", _before_save),)
