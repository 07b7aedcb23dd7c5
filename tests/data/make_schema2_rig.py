"""Writes tests/data/schema2_rig.blend: a rig bound, rigged and posed by the add-on of release 0.1.0
(binding schema 2: the compact record on its text datablock), with a preview, Show Stretch on and a
keyed handle: the file every later release must open, drag and bake (tests/test_blender_release_files.py).
Run from the repository with bpy 4.2 (Blender 4.2 cannot read a file that 5.x wrote; 5.x reads 4.2's):
    PYTHONPATH=. .venv42/bin/python tests/data/make_schema2_rig.py tests/data/schema2_rig.blend
A box of 12x12x12 cells and a loose little sheet beside it; an anchor on the box's bottom, a
handle on its top raised, turned and keyed at frames 1 and 3, the mesh deformed at frame 1."""

import sys

import numpy as np

import bpy

import skin_detach_addon
from skin_detach_addon import api

sys.path.insert(0, "tests")
from shapes import box, merge, plane  # noqa: E402

points, tris = box(cells=(12, 12, 12))
sheet, sheet_tris = plane(4, size=0.2)
points, tris = merge((points, tris), (sheet + [2.0, 0.0, 0.0], sheet_tris))

skin_detach_addon.register()
bpy.ops.wm.read_homefile(use_empty=True)
mesh = bpy.data.meshes.new("box")
mesh.from_pydata(points.tolist(), [], tris.tolist())
obj = bpy.data.objects.new("box", mesh)
bpy.context.scene.collection.objects.link(obj)
bpy.context.view_layer.objects.active = obj
api.build(obj, target_faces=120, preview_above=500)
z = points[:, 2]
api.add_anchor(obj, np.flatnonzero((z < 0.1) & (points[:, 0] < 1.5)))
top = api.add_handle(obj, np.flatnonzero((z > 0.9) & (points[:, 0] < 1.5)), mirror="")
top.keyframe_insert("location", frame=3)
top.keyframe_insert("rotation_euler", frame=3)
top.location.z += 0.2
top.rotation_euler.x += 0.3
top.keyframe_insert("location", frame=1)
top.keyframe_insert("rotation_euler", frame=1)
bpy.context.scene.frame_set(1)
bpy.context.view_layer.update()
api.deform(obj)
api.show_stretch(obj)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1], compress=True)
