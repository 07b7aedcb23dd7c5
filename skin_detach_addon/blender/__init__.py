"""Blender services under the scripting API: arrays in and out of meshes (``mesh_io``), the
stored binding (``binding``), handles (``handles``), the rig (``skin_rig``), one deformation
step (``deformation``), the drag as a plain object (``drag_session``) and baking (``baking``).
They import ``core`` and bpy, never ``api`` or ``ui``; this file imports nothing, so importing
one of them loads no UI class."""
