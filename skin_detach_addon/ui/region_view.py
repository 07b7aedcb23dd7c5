"""The view of a 3D View region, as :class:`DragSession` wants it (see its module docstring)."""

from mathutils import Vector


class RegionView:
    """The view of a 3D View region (``context.region``, ``context.region_data``)."""

    def __init__(self, region, region_data):
        self.region, self.region_data = region, region_data

    def to_world(self, mouse, depth_point):
        from bpy_extras.view3d_utils import region_2d_to_location_3d
        return region_2d_to_location_3d(self.region, self.region_data, Vector(mouse), Vector(depth_point))

    def to_screen(self, point):
        from bpy_extras.view3d_utils import location_3d_to_region_2d
        screen = location_3d_to_region_2d(self.region, self.region_data, Vector(point))
        return Vector((0.0, 0.0)) if screen is None else screen

    @property
    def direction(self):
        return (self.region_data.view_rotation @ Vector((0.0, 0.0, -1.0))).normalized()
