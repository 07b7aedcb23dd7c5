"""Views for driving :class:`DragSession` without a window (bpy module): see the view protocol in
``skin_detach_addon/blender/drag_session.py``."""

from mathutils import Vector


class TopView:
    """Orthographic top view: one pixel is ``scale`` world units, looking down -Z."""

    direction = Vector((0.0, 0.0, -1.0))

    def __init__(self, scale=0.01):
        self.scale = scale

    def to_world(self, mouse, depth_point):
        return Vector((mouse[0] * self.scale, mouse[1] * self.scale, depth_point[2]))

    def to_screen(self, point):
        return Vector((point[0] / self.scale, point[1] / self.scale))
