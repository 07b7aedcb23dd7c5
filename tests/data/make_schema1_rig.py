"""Writes tests/data/schema1_rig.blend: a rig bound by the add-on as it was at commit 185f42b
(binding schema 1: the whole skin stored). Run with that commit's add-on on the path:
    git worktree add /tmp/old 185f42b && cd /tmp/old && PYTHONPATH=. .venv42/bin/python THIS_FILE OUT.blend
(bpy 4.2: Blender 4.2 cannot read a file that 5.x wrote, 5.x reads 4.2 files)
A box of 6x6x6 cells with one vertex split into an exact duplicate, a zero-area face and a
loose little sheet beside it; an anchor on its bottom, a handle on its top, raised and deformed."""

import sys

import numpy as np

import bpy

import skin_detach_addon
from skin_detach_addon import api

sys.path.insert(0, "tests")
from shapes import box, merge, plane  # noqa: E402

points, tris = box(cells=(6, 6, 6))
n = points.shape[0]
victim = tris[0, 0]
split = np.flatnonzero((tris == victim).any(axis=1))[::2]
points = np.concatenate([points, points[victim:victim + 1]])
tris[split] = np.where(tris[split] == victim, n, tris[split])
a, b = tris[0, 0], tris[0, 1]
points = np.concatenate([points, [(points[a] + points[b]) / 2]])
tris = np.concatenate([tris, [[a, b, points.shape[0] - 1]]])
sheet, sheet_tris = plane(4, size=0.2)
points, tris = merge((points, tris), (sheet + [2.0, 0.0, 0.0], sheet_tris))

skin_detach_addon.register()
bpy.ops.wm.read_homefile(use_empty=True)
mesh = bpy.data.meshes.new("box")
mesh.from_pydata(points.tolist(), [], tris.tolist())
obj = bpy.data.objects.new("box", mesh)
bpy.context.scene.collection.objects.link(obj)
bpy.context.view_layer.objects.active = obj
api.build(obj, target_faces=60)
z = points[:, 2]
api.add_anchor(obj, np.flatnonzero((z < 0.1) & (points[:, 0] < 1.5)))
top = api.add_handle(obj, np.flatnonzero((z > 0.9) & (points[:, 0] < 1.5)), mirror="")
top.location.z += 0.2
bpy.context.view_layer.update()
api.deform(obj)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1], compress=True)
