"""The interactive drag as a plain object: the modal operator feeds it events, tests do too.

A view maps the mouse to the world: ``view.to_world(mouse (2,), depth_point (3,)) -> (3,)``
on the plane through ``depth_point`` facing the viewer, ``view.to_screen(point (3,)) -> (2,)``
and ``view.direction`` (3,), the unit direction the view looks along. The UI wraps a 3D View
region (``ui.region_view.RegionView``); tests pass their own.
"""

import math

from mathutils import Matrix, Vector

from .deformation import DRAG_TOL, Deformation

RUNNING, FINISHED, CANCELLED = "RUNNING_MODAL", "FINISHED", "CANCELLED"
_AXES = {"X": Vector((1, 0, 0)), "Y": Vector((0, 1, 0)), "Z": Vector((0, 0, 1))}
_CONFIRM = {"LEFTMOUSE", "RET", "NUMPAD_ENTER"}
_CANCEL = {"RIGHTMOUSE", "ESC"}
_MODES = {"G": "MOVE", "R": "ROTATE", "S": "SCALE"}


class DragSession:
    """Drag the handle ``empty`` of the bound object ``obj`` with the mouse.

    Keys: X/Y/Z constrain to a world axis (again: free); G moves in the view plane, R rotates
    about the view axis (or the constrained axis), S scales about the handle's centre (the mouse's
    distance from the centre on screen over that distance when S was pressed; along the
    constrained axis only when one is set); pressing R or S again goes back to moving. LMB/Enter
    confirms, RMB/Esc restores the empties, the mesh and the proxy exactly as they were.
    """

    def __init__(self, obj, empty, view, mouse, preserve_volume=True):
        self.obj, self.empty, self.view = obj, empty, view
        self.deformation = Deformation(obj, preserve_volume)
        self._saved = self.deformation.snapshot()
        self.start = empty.matrix_world.copy()
        self.pivot = self.start.to_translation()
        self.mode, self.axis = "MOVE", None
        self.translation, self.angle = Vector((0.0, 0.0, 0.0)), 0.0
        self.stretch = Matrix.Identity(3)
        self._reference = Vector(mouse)
        self.step_ms = []
        self.last = None

    @property
    def header(self):
        axis = f" along {self.axis}" if self.axis else ""
        timing = f"{self.step_ms[-1]:.1f} ms/step" if self.step_ms else "move the mouse"
        return (f"Skin Detach {self.mode.lower()}{axis}: {timing} | "
                f"X/Y/Z axis, G move, R rotate, S scale, LMB/Enter confirm, RMB/Esc cancel")

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
        if kind in _AXES or kind in _MODES:
            self._settle(Vector(mouse))
            if kind in _MODES:
                self.mode = "MOVE" if self.mode == _MODES[kind] else _MODES[kind]
            else:
                self.axis = None if self.axis == kind else kind
            self._follow(Vector(mouse))
        return RUNNING

    def _settle(self, mouse):
        """Keep what the mouse did so far and measure from ``mouse`` on."""
        self.translation, self.angle, self.stretch = self._offsets(mouse)
        self._reference = mouse

    def _offsets(self, mouse):
        translation, angle, stretch = self.translation.copy(), self.angle, self.stretch.copy()
        if self.mode == "SCALE":
            centre = Vector(self.view.to_screen(self.pivot + self.translation))
            before, now = (self._reference - centre).length, (mouse - centre).length
            factor = now / before if before > 1e-6 else 1.0
            if self.axis:
                direction = _AXES[self.axis]
                step = Matrix.Identity(3)
                for i in range(3):
                    for j in range(3):
                        step[i][j] += (factor - 1.0) * direction[i] * direction[j]
            else:
                step = Matrix.Identity(3) * factor
            stretch = step @ stretch
        elif self.mode == "MOVE":
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
        return translation, angle, stretch

    def matrix(self, mouse):
        """World matrix of the empty for the mouse at ``mouse``."""
        translation, angle, stretch = self._offsets(Vector(mouse))
        axis = _AXES[self.axis] if self.axis else -Vector(self.view.direction)
        turn = Matrix.Rotation(angle, 4, axis)
        return (Matrix.Translation(self.pivot + translation) @ turn @ stretch.to_4x4() @
                Matrix.Translation(-self.pivot)) @ self.start

    def _follow(self, mouse):
        self.empty.matrix_world = self.matrix(mouse)
        self.last = self.deformation.step(tol=DRAG_TOL)
        self.step_ms.append(self.last.milliseconds)

    def confirm(self):
        """Keep the result, settled to the tight tolerance so it does not depend on the path."""
        if self.last is not None:
            self.last = self.deformation.step()
        return FINISHED

    def cancel(self):
        """Everything back bit for bit: empties, mesh (and shape keys), proxy, stored digest."""
        self.deformation.restore(self._saved)
        return CANCELLED
