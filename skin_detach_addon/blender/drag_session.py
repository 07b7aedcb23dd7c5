"""The interactive drag as a plain object: the modal operator feeds it events, tests do too.

A view maps the mouse to the world: ``view.to_world(mouse (2,), depth_point (3,)) -> (3,)``
on the plane through ``depth_point`` facing the viewer, ``view.to_screen(point (3,)) -> (2,)``
and ``view.direction`` (3,), the unit direction the view looks along. The UI wraps a 3D View
region (``ui.region_view.RegionView``); tests pass their own.
"""

import math
import weakref

import numpy as np
from mathutils import Matrix, Vector

from ..core import blas_threads
from ..core.errors import SkinDetachError
from ..core.geometry import bbox_diagonal
from . import binding as stored
from . import handles, rig_members
from .deformation import DRAG_BUDGET_UNITS, DRAG_TOL, SETTLE_SLICE_UNITS, SETTLE_TOL, Deformation
from .skin_rig import PREVIEW_ABOVE

RUNNING, FINISHED, CANCELLED = "RUNNING_MODAL", "FINISHED", "CANCELLED"
#: A typed move goes at most this many times the mesh's size (world diagonal) ...
TYPED_MOVE_SIZES = 10.0
#: ... a typed scale factor is at most this (and at least its inverse) in magnitude ...
TYPED_SCALE = 100.0
#: ... and a typed number has at most this many characters.
TYPED_CHARACTERS = 10
#: Sessions between their start and their confirm or cancel (see :func:`before_save`).
_RUNNING = weakref.WeakSet()
_AXES = {"X": Vector((1, 0, 0)), "Y": Vector((0, 1, 0)), "Z": Vector((0, 0, 1))}
_CONFIRM = {"LEFTMOUSE", "RET", "NUMPAD_ENTER"}
_CANCEL = {"RIGHTMOUSE", "ESC"}
_MODES = {"G": "MOVE", "R": "ROTATE", "S": "SCALE"}
#: Keys of numeric input, as in Blender's transform: digits, point, minus (toggles the sign).
_TYPED = {**{name: str(k) for k, name in enumerate(("ZERO", "ONE", "TWO", "THREE", "FOUR", "FIVE", "SIX", "SEVEN",
                                                   "EIGHT", "NINE"))},
          **{f"NUMPAD_{k}": str(k) for k in range(10)},
          "PERIOD": ".", "NUMPAD_PERIOD": ".", "MINUS": "-", "NUMPAD_MINUS": "-"}


def _typed(text, key):
    """``text`` with one more typed ``key``: minus toggles the sign, a second point is ignored."""
    if key == "-":
        return text[1:] if text.startswith("-") else "-" + text
    if key == "." and "." in text:
        return text
    return text + key


def moved_matrix(start, translation, rotation, scale):
    """(4, 4) world matrix of a handle whose world matrix was ``start``, scaled by ``scale`` (3,)
    along the world axes, then turned by the (3, 3) ``rotation``, both about its own position,
    then moved by ``translation`` (3,): what a drag does, and what its Redo panel redoes."""
    pivot = start.to_translation()
    linear = Matrix(rotation).to_3x3() @ Matrix.Diagonal(Vector(scale))
    return Matrix.Translation(pivot + Vector(translation)) @ linear.to_4x4() @ Matrix.Translation(-pivot) @ start


def _stretch(factor, axis):
    """(3, 3) scale by ``factor`` along world ``axis`` ("X", "Y", "Z"), or uniform when None."""
    if not axis:
        return Matrix.Identity(3) * factor
    direction = _AXES[axis]
    out = Matrix.Identity(3)
    for i in range(3):
        for j in range(3):
            out[i][j] += (factor - 1.0) * direction[i] * direction[j]
    return out


class DragSession:
    """Drag the handle ``empty`` of the bound object ``obj`` with the mouse.

    Keys: X/Y/Z constrain to a world axis (again: free); G moves in the view plane, R rotates
    about the view axis (or the constrained axis), S scales about the handle's centre (the mouse's
    distance from the centre on screen over that distance when S was pressed; along the
    constrained axis only when one is set); pressing R or S again goes back to moving. Typing a
    number (digits, point, minus; Backspace edits) sets the move distance along the axis (X when
    free), the angle in degrees (turning as Blender's R turns) or the scale factor exactly, on top
    of what the mouse did before; the mouse is ignored while a number is typed. G, R or S keeps
    what the typed number did and clears it (a number belongs to its mode, as in Blender). LMB/Enter confirms, RMB/Esc restores the
    empties, the mesh and the proxy exactly as they were. A session ends with one of them:
    only the confirm records the written positions (moves skip that per-move checksum).

    A move solves within :data:`DRAG_BUDGET_UNITS` and shows where it got. While the mouse rests, TIMER
    events (the modal operator's window timer) go on with the same solve, a slice of
    :data:`SETTLE_SLICE_UNITS` each, and show it, until it certifies to the settle tolerance (both
    budgets counted in work done, :mod:`..core.proxy_solve.work_budget`: a machine busy with other
    programs shows the same shapes, later): the header says
    "settling", then "settled", and further TIMER events do nothing. The confirm of a settled
    drag writes the shape shown (rebuilt in full detail from the same proxy when the preview
    showed it); of an unsettled one, the solve continued to the settle tolerance first.

    A mesh of more than ``preview_above`` vertices (None: never) that has a preview object shows
    the preview while the mouse moves and the mesh itself is left alone; the confirm hides the
    preview and writes the full detail from a settled solve, the cancel hides it.
    """

    def __init__(self, obj, empty, view, mouse, preserve_volume=True, preview_above=PREVIEW_ABOVE):
        self.obj, self.empty, self.view = obj, empty, view
        self.deformation = Deformation(obj, preserve_volume)
        n = self.deformation.binding.surface.n_detail
        self.previewing = (preview_above is not None and n > preview_above
                           and self.deformation.preview is not None)
        # A previewing session writes the mesh only in its confirm, after which nothing is restored;
        # should anything else write it meanwhile (a save settles the preview), the guard keeps it.
        self._saved = self.deformation.snapshot(mesh=not self.previewing)
        if self.previewing:
            self.deformation.binding.mesh_guard.arm()
        self.start = empty.matrix_world.copy()
        #: Handles' empties parented under the dragged one (a hand's under the forearm's): their
        #: world matrices are evaluated again after every move, before the solve reads them.
        self._carries = any(handles.is_handle(child) for child in empty.children_recursive)
        self.pivot = self.start.to_translation()
        self.mode, self.axis = "MOVE", None
        self.translation, self.angle = Vector((0.0, 0.0, 0.0)), 0.0
        #: (3, 3) the turns of the rotate modes left before (``angle`` is the current one's, about
        #: the current axis: an axis key in another mode does not turn them about another axis).
        self.turned = Matrix.Identity(3)
        self.stretch = Matrix.Identity(3)
        #: What the drag did to the handle, as :func:`moved_matrix` takes it: translation (3,),
        #: rotation (3, 3), scale (3,) along the world axes (a stretch is always along them).
        self.motion = (Vector((0.0, 0.0, 0.0)), Matrix.Identity(3), Vector((1.0, 1.0, 1.0)))
        self.typed = ""
        self._reference = Vector(mouse)
        self.step_ms = []
        self.last = None
        corners = [obj.matrix_world @ Vector(corner) for corner in obj.bound_box]
        #: The mesh's size in the world (its bounding box diagonal), which bounds typed moves.
        self.size = max(bbox_diagonal(np.array([c[:] for c in corners])), 1e-9)
        _RUNNING.add(self)
        #: The shown shape is the solve certified to the settle tolerance (nothing left to do).
        self.settled = False
        #: Why the last keystroke was refused ("" when it was not).
        self.refused = ""

    @property
    def header(self):
        axis = f" along {self.axis}" if self.axis else ""
        timing = f"{self.step_ms[-1]:.1f} ms/step" if self.step_ms else "move the mouse"
        if self.previewing:
            binding = self.deformation.binding
            timing = (f"preview of {binding.preview.points.shape[0]:,} of {binding.surface.n_detail:,} vertices "
                      f"(full detail on confirm), {timing}")
        if self.typed:
            unit = {"MOVE": "", "ROTATE": " deg", "SCALE": "x"}[self.mode]
            timing = f"{self.typed}{unit} typed, {timing}"
        if self.refused:
            timing = f"{self.refused} | {timing}"
        if self.last is not None and not self.typed:
            timing = f"{'settled' if self.settled else 'settling'}, {timing}"
        if self.deformation.kept_symmetric:
            timing = f"symmetric rig: the handle moves only symmetrically | {timing}"
        return (f"Skin Detach {self.mode.lower()}{axis}: {timing} | "
                f"X/Y/Z axis, G move, R rotate, S scale, LMB/Enter confirm, RMB/Esc cancel")

    def event(self, kind, value, mouse):
        """Feed one event (Blender's type and value names); returns RUNNING_MODAL, FINISHED or CANCELLED.
        Its BLAS calls run on one thread (:func:`..core.blas_threads.one_thread`: on a busy machine
        the small ones waited for OpenBLAS's unscheduled worker thread)."""
        with blas_threads.one_thread():
            return self._event(kind, value, mouse)

    def _event(self, kind, value, mouse):
        if kind == "TIMER":
            self.settle_slice()
            return RUNNING
        if kind == "MOUSEMOVE":
            if not self.typed:  # while a number is typed, the mouse does not move the handle
                self._follow(Vector(mouse))
            return RUNNING
        if value != "PRESS":
            return RUNNING
        if kind in _CONFIRM:
            return self.confirm()
        if kind in _CANCEL:
            return self.cancel()
        if kind in _TYPED or (kind == "BACK_SPACE" and self.typed):
            if not self.typed:
                self._settle(Vector(mouse))  # the number applies on top of what the mouse did so far
            before = self.typed
            self.typed = self.typed[:-1] if kind == "BACK_SPACE" else _typed(self.typed, _TYPED[kind])
            try:
                if len(self.typed.lstrip("-")) > TYPED_CHARACTERS:
                    raise SkinDetachError(f"at most {TYPED_CHARACTERS} digits")
                self._apply_typed()
                self.refused = ""
            except SkinDetachError as exc:  # the keystroke is refused, the drag goes on
                self.typed = before
                self.refused = f"{_TYPED.get(kind, kind)!r} refused: {str(exc)[:100]}"
                self._apply_typed()
        elif kind in _MODES:  # the typed number belongs to its mode (as in Blender): done, and cleared
            if self.typed:  # the mouse was ignored meanwhile: it counts from here
                self.translation, self.angle, self.stretch = self._typed_offsets()
                self.typed = self.refused = ""
                self._reference = Vector(mouse)
            else:
                self._settle(Vector(mouse))
            self.turned, self.angle = self._turn(self.angle) @ self.turned, 0.0
            self.mode = "MOVE" if self.mode == _MODES[kind] else _MODES[kind]
            self._follow(Vector(mouse))
        elif kind in _AXES:  # a typed number stays, now along the new axis
            if not self.typed:
                self._settle(Vector(mouse))
            self.axis = None if self.axis == kind else kind
            if self.typed:
                self._apply_typed()
            else:
                self._follow(Vector(mouse))
        return RUNNING

    def _apply_typed(self):
        self._place(*self._typed_offsets())

    def _typed_offsets(self):
        """(translation (3,), angle, stretch (3, 3)): the typed number as a distance (move: along
        the constrained axis, X when free), an angle in degrees (rotate: as Blender's R turns,
        clockwise as seen from the view when free, by the right hand about a constrained axis) or
        a factor (scale), on top of the settled offsets."""
        try:
            number = float(self.typed)
        except ValueError:  # "-" or "." so far: nothing yet
            number = None
        translation, angle, stretch = self.translation.copy(), self.angle, self.stretch.copy()
        if number is not None:
            self._check_typed(number)
            if self.mode == "MOVE":
                translation += _AXES[self.axis or "X"] * number
            elif self.mode == "ROTATE":  # free: _turn's axis points at the viewer, Blender's R away from them
                angle += math.radians(number) if self.axis else -math.radians(number)
            else:
                stretch = _stretch(number, self.axis) @ stretch
        return translation, angle, stretch

    def _check_typed(self, number):
        """Raise (a short message, for the header) for a typed number that would fling the mesh away."""
        if self.mode == "MOVE" and abs(number) > TYPED_MOVE_SIZES * self.size:
            raise SkinDetachError(f"a move of at most {TYPED_MOVE_SIZES * self.size:.4g} "
                                  f"({TYPED_MOVE_SIZES:g}x the mesh's size)")
        if self.mode == "SCALE" and not 1.0 / TYPED_SCALE <= abs(number) <= TYPED_SCALE:
            raise SkinDetachError(f"a scale of {1.0 / TYPED_SCALE:g} to {TYPED_SCALE:g} (or its negative)")

    def _settle(self, mouse):
        """Keep what the mouse did so far and measure from ``mouse`` on."""
        self.translation, self.angle, self.stretch = self._offsets(mouse)
        self._reference = mouse

    def _offsets(self, mouse):
        translation, angle, stretch = self.translation.copy(), self.angle, self.stretch.copy()
        if self.mode == "SCALE":
            centre = Vector(self.view.to_screen(self.pivot + self.translation))
            before, now = (self._reference - centre).length, (mouse - centre).length
            stretch = _stretch(now / before if before > 1e-6 else 1.0, self.axis) @ stretch
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
        return moved_matrix(self.start, *self._motion(*self._offsets(Vector(mouse))))

    def _turn(self, angle):
        return Matrix.Rotation(angle, 3, _AXES[self.axis] if self.axis else -Vector(self.view.direction))

    def _motion(self, translation, angle, stretch):
        return translation.copy(), self._turn(angle) @ self.turned, Vector([stretch[i][i] for i in range(3)])

    def _follow(self, mouse):
        self._place(*self._offsets(mouse))

    def _place(self, translation, angle, stretch):
        self.motion = self._motion(translation, angle, stretch)
        self.empty.matrix_world = moved_matrix(self.start, *self.motion)
        if self._carries:  # else the solve would read their world matrices of the move before
            import bpy
            bpy.context.view_layer.update()
        self._show(DRAG_TOL, DRAG_BUDGET_UNITS)
        self.step_ms.append(self.last.milliseconds)

    def _show(self, tol, budget, idle=False):
        """Solve (following the last solves, within ``budget``; ``idle``: a settle slice, which
        may also factor the Hessian the next moves precondition with) and show the result."""
        if self.previewing:
            self.last = self.deformation.preview_step(tol, follow=True, budget=budget, idle=idle)
        else:  # the confirm marks (or the cancel restores)
            self.last = self.deformation.step(tol, mark=False, follow=True, budget=budget, idle=idle)
        self.settled = tol == SETTLE_TOL and self.last.converged

    def settle_slice(self):
        """One slice of the settle while the mouse rests (a TIMER event): go on with the solve to
        the settle tolerance within :data:`SETTLE_SLICE_UNITS` and show it; nothing once settled (or before
        the first move). Returns whether the shown shape is settled."""
        if self.last is not None and not self.settled:
            self._show(SETTLE_TOL, SETTLE_SLICE_UNITS, idle=True)
        return self.settled

    def confirm(self):
        """Keep the result: a settled drag's shape as shown (in full detail), else the last
        move's shape certified to the settle tolerance (continued from it)."""
        self.deformation.binding.mesh_guard.release()
        _RUNNING.discard(self)
        if self.last is not None:
            self.last = self.deformation.commit() if self.settled else self.deformation.step(follow=True)
        return FINISHED

    def cancel(self):
        """Everything back bit for bit: empties, mesh (and shape keys), proxy, stored digest."""
        kept = self.deformation.binding.mesh_guard.release()
        _RUNNING.discard(self)
        if self._saved.mesh is None and kept is not None:  # written meanwhile by a save: put it back too
            self._saved.mesh = kept
        self.deformation.restore(self._saved)
        return CANCELLED


def dragged(obj):
    """Whether a drag of one of ``obj``'s handles is running (between its start and its confirm or
    cancel): its poses are the drag's own, which live update leaves alone."""
    for session in list(_RUNNING):
        try:
            if session.obj == obj:
                return True
        except ReferenceError:  # its objects went with a file loaded during the drag
            _RUNNING.discard(session)
    return False


def before_save():
    """A file is about to be written: every running drag that writes the mesh as it goes
    records the positions it wrote (with the transform they were written under), so the file
    holds its pose with a matching digest; its cancel restores the digest as well. A drag
    showing the preview leaves the mesh to the live update's settle (and keeps its guard)."""
    for session in list(_RUNNING):
        try:
            if not session.previewing and session.last is not None:
                stored.mark_written(session.obj, rig_members.read_local(session.obj))
        except ReferenceError:  # its objects went with a file loaded during the drag: it is over
            _RUNNING.discard(session)
