"""The interactive drag as a plain object: the modal operator feeds it events, tests do too.

A view maps the mouse to the world: ``view.to_world(mouse (2,), depth_point (3,)) -> (3,)``
on the plane through ``depth_point`` facing the viewer, ``view.to_screen(point (3,)) -> (2,)``
and ``view.direction`` (3,), the unit direction the view looks along. :class:`RegionView`
wraps a 3D View region; tests pass their own.
"""

import math

from mathutils import Matrix, Vector

from . import binding as stored
from . import mesh_io
from .deformation import DRAG_TOL, Deformation, remember_handles

RUNNING, FINISHED, CANCELLED = "RUNNING_MODAL", "FINISHED", "CANCELLED"
_AXES = {"X": Vector((1, 0, 0)), "Y": Vector((0, 1, 0)), "Z": Vector((0, 0, 1))}
_CONFIRM = {"LEFTMOUSE", "RET", "NUMPAD_ENTER"}
_CANCEL = {"RIGHTMOUSE", "ESC"}


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


class DragSession:
    """Drag the handle ``empty`` of the bound object ``obj`` with the mouse.

    Keys: X/Y/Z constrain to a world axis (again: free), R switches between moving in the view
    plane and rotating about the view axis (or the constrained axis); LMB/Enter confirms,
    RMB/Esc restores the empties, the mesh and the proxy exactly as they were.
    """

    def __init__(self, obj, empty, view, mouse, preserve_volume=True):
        self.obj, self.empty, self.view = obj, empty, view
        self.deformation = Deformation(obj, preserve_volume)
        stored.check_unedited(obj)
        proxy = self.deformation.proxy
        self._saved_mesh = mesh_io.snapshot(obj.data)
        self._saved_proxy = mesh_io.snapshot(proxy.data)
        self._saved_matrices = {e.name: e.matrix_basis.copy() for e in proxy.children}
        self._saved_digest = obj[stored.KEY]["written_digest"]
        self.start = empty.matrix_world.copy()
        self.pivot = self.start.to_translation()
        self.mode, self.axis = "MOVE", None
        self.translation, self.angle = Vector((0.0, 0.0, 0.0)), 0.0
        self._reference = Vector(mouse)
        self.step_ms = []
        self.last = None

    @property
    def header(self):
        axis = f" along {self.axis}" if self.axis else ""
        timing = f"{self.step_ms[-1]:.1f} ms/step" if self.step_ms else "move the mouse"
        return (f"Skin Detach {'rotate' if self.mode == 'ROTATE' else 'move'}{axis}: {timing} | "
                f"X/Y/Z axis, R rotate/move, LMB/Enter confirm, RMB/Esc cancel")

    def event(self, kind, value, mouse):
        """Feed one event (Blender's type and value names); returns RUNNING_MODAL, FINISHED or CANCELLED."""
        if kind == "MOUSEMOVE":
            self._follow(Vector(mouse))
            return RUNNING
        if value != "PRESS":
            return RUNNING
        if kind in _CONFIRM:
            return self.confirm()
        if kind in _CANCEL:
            return self.cancel()
        if kind in _AXES or kind == "R":
            self._settle(Vector(mouse))
            if kind == "R":
                self.mode = "ROTATE" if self.mode == "MOVE" else "MOVE"
            else:
                self.axis = None if self.axis == kind else kind
            self._follow(Vector(mouse))
        return RUNNING

    def _settle(self, mouse):
        """Keep what the mouse did so far and measure from ``mouse`` on."""
        self.translation, self.angle = self._offsets(mouse)
        self._reference = mouse

    def _offsets(self, mouse):
        translation, angle = self.translation.copy(), self.angle
        if self.mode == "MOVE":
            here = self.pivot + self.translation
            delta = self.view.to_world(mouse, here) - self.view.to_world(self._reference, here)
            if self.axis:
                direction = _AXES[self.axis]
                delta = direction * delta.dot(direction)
            translation += delta
        else:
            centre = Vector(self.view.to_screen(self.pivot + self.translation))
            a, b = self._reference - centre, mouse - centre
            if a.length > 1e-6 and b.length > 1e-6:
                angle += math.atan2(a.x * b.y - a.y * b.x, a.dot(b))
        return translation, angle

    def matrix(self, mouse):
        """World matrix of the empty for the mouse at ``mouse``."""
        translation, angle = self._offsets(Vector(mouse))
        axis = _AXES[self.axis] if self.axis else -Vector(self.view.direction)
        turn = Matrix.Rotation(angle, 4, axis)
        return (Matrix.Translation(self.pivot + translation) @ turn @ Matrix.Translation(-self.pivot)) @ self.start

    def _follow(self, mouse):
        self.empty.matrix_world = self.matrix(mouse)
        self.last = self.deformation.step(tol=DRAG_TOL)
        self.step_ms.append(self.last.milliseconds)

    def confirm(self):
        """Keep the result, settled to the tight tolerance so it does not depend on the path."""
        if self.last is not None:
            self.last = self.deformation.step()
            stored.mark_written(self.obj, self.last.positions)
        return FINISHED

    def cancel(self):
        """Everything back bit for bit: empties, mesh (and shape keys), proxy, stored digest."""
        proxy = self.deformation.proxy
        for child in proxy.children:
            if child.name in self._saved_matrices:
                child.matrix_basis = self._saved_matrices[child.name]
        mesh_io.restore(self.obj.data, self._saved_mesh)
        mesh_io.restore(proxy.data, self._saved_proxy)
        self.obj[stored.KEY]["written_digest"] = self._saved_digest
        self.deformation.binding.forget_warm_starts()
        remember_handles(self.obj, proxy)
        return CANCELLED
