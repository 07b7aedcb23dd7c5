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


class AxisView:
    """Orthographic view looking along ``direction`` (3,) (unit), one pixel ``scale`` world units;
    the screen's x and y run along two unit vectors orthogonal to it."""

    def __init__(self, direction, scale=0.01):
        self.direction = Vector(direction).normalized()
        helper = Vector((1.0, 0.0, 0.0)) if abs(self.direction.x) < 0.9 else Vector((0.0, 1.0, 0.0))
        self._x = self.direction.cross(helper).normalized()
        self._y = self._x.cross(self.direction)
        self.scale = scale

    def to_world(self, mouse, depth_point):
        depth = Vector(depth_point).dot(self.direction)
        return (self._x * mouse[0] + self._y * mouse[1]) * self.scale + self.direction * depth

    def to_screen(self, point):
        point = Vector(point)
        return Vector((point.dot(self._x) / self.scale, point.dot(self._y) / self.scale))
