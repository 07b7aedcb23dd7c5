"""Pictures for the README (bpy module): columns of objects side by side, each under a label,
seen orthographically from the front; Workbench, or Cycles on the CPU where there is no OpenGL.

Colours are materials (Workbench shows them with ``color_type='MATERIAL'``, Cycles renders
them).
"""

import numpy as np


def material(name, colour):
    import bpy
    out = bpy.data.materials.new(name)
    out.diffuse_color = colour
    out.use_nodes = True
    out.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = colour
    return out


def colour_object(obj, colour):
    """``obj`` (mesh or text) drawn in ``colour`` (RGBA)."""
    obj.data.materials.clear()
    obj.data.materials.append(material(f"{obj.name}_colour", colour))


def world_points(obj):
    """(n, 3) world positions of ``obj``'s evaluated mesh."""
    import bpy
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    points = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", points)
    evaluated.to_mesh_clear()
    matrix = np.array(obj.matrix_world)
    points = points.reshape(-1, 3).astype(np.float64)
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def render_row(columns, labels, path, pixels=1600, up=None, look=None):
    """Render ``columns`` (a list of lists of objects, already linked to the scene and coloured)
    side by side, each column moved along the screen's right axis and labelled with
    ``labels[k]`` below it, to the PNG ``path``. ``up``/``look``: world axes 0-2 (default: the
    longest and the shortest extent of the first column). Returns the engine used."""
    import bpy
    from mathutils import Vector
    scene = bpy.context.scene
    reference = np.vstack([world_points(o) for o in columns[0] if o.type == 'MESH'])
    extent = np.ptp(reference, axis=0)
    order = np.argsort(extent)[::-1]
    up = int(order[0]) if up is None else up
    look = int(order[2]) if look is None else look
    right = 3 - up - look
    view = Vector([-1.0 if i == look else 0.0 for i in range(3)])
    facing = view.to_track_quat('-Z', 'Y')
    screen_right = facing @ Vector((1.0, 0.0, 0.0))
    sign = float(np.sign(screen_right[right])) or 1.0
    boxes = [np.vstack([world_points(o) for o in column if o.type == 'MESH']) for column in columns]
    widths = [np.ptp(b[:, right]) for b in boxes]
    gap = 0.15 * max(widths)
    cursor, centres = 0.0, []
    for column, box, width in zip(columns, boxes, widths):
        shift = np.zeros(3)
        target = cursor + width / 2
        shift[right] = sign * target - box[:, right].mean()
        for obj in column:
            obj.location = obj.location + Vector(shift)
        centres.append(sign * target)
        cursor += width + gap
    bpy.context.view_layer.update()
    allpoints = np.vstack([world_points(o) for column in columns for o in column if o.type == 'MESH'])
    size = float(np.ptp(allpoints[:, up]))
    bottom = allpoints[:, up].min() - 0.1 * size
    top = allpoints[:, up].max()
    depth = allpoints[:, look].mean()
    for k, text in enumerate(labels):
        curve = bpy.data.curves.new(f"label{k}", 'FONT')
        curve.body, curve.align_x, curve.size = text, 'CENTER', 0.06 * size
        label = bpy.data.objects.new(f"label{k}", curve)
        scene.collection.objects.link(label)
        place = np.zeros(3)
        place[right], place[up], place[look] = centres[k], bottom, depth
        label.location = Vector(place)
        label.rotation_euler = facing.to_euler()
        colour_object(label, (0.05, 0.05, 0.05, 1.0))
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    camera.data.type = 'ORTHO'
    aim = np.zeros(3)
    aim[right] = (min(centres) + max(centres)) / 2
    aim[up] = (bottom + top) / 2
    aim[look] = depth
    camera.location = Vector(aim) - 4.0 * size * view  # behind the aim point, looking along view
    camera.rotation_euler = facing.to_euler()
    width = cursor - gap + 0.1 * size
    height = 1.2 * (top - bottom)
    scene.render.resolution_x, scene.render.resolution_y = pixels, max(16, int(pixels * height / width))
    camera.data.ortho_scale = max(width, height)
    camera.data.clip_end = 20 * size
    scene.camera = camera
    scene.world = scene.world or bpy.data.worlds.new("white")
    scene.world.color = (1, 1, 1)
    scene.view_settings.view_transform = 'Standard'
    scene.render.filepath = str(path)
    scene.render.image_settings.file_format = 'PNG'
    try:
        scene.render.engine = 'BLENDER_WORKBENCH'
        shading = scene.display.shading
        shading.light, shading.color_type, shading.show_cavity = 'STUDIO', 'MATERIAL', True
        bpy.ops.render.render(write_still=True)
        return "Workbench"
    except RuntimeError:  # no OpenGL/EGL on this machine: the CPU path tracer
        scene.render.engine = 'CYCLES'
        scene.cycles.device, scene.cycles.samples = 'CPU', 16
        bpy.ops.render.render(write_still=True)
        return "Cycles"
