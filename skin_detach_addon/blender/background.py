"""The preparation of a bound mesh after its file is opened, its numpy and scipy work on the
background thread (:func:`.core.threads.submit`) so Blender's window answers events meanwhile,
its reads and writes of Blender data on the main thread, in :meth:`Preparation.poll` (a timer's
tick). First the binding is made (:class:`.binding.Opening`: the skin bound again, the free
rebuilds), then the handles' layout is prepared (:meth:`.deformation.Deformation.preparation`).
A step asked for meanwhile (:func:`.binding.open_binding`) waits for what is under way. Opening
another file cancels it (:func:`.core.threads.cancel_all`): the next file's starts at once.
"""

import time

import bpy

from ..core import threads
from ..core.errors import SkinDetachError
from . import binding as stored
from . import handle_symmetry, handles
from .deformation import Deformation

#: Share of the progress the making of the binding stands for (the layout's preparation the rest).
OPENING_SHARE = 0.7


class Preparation:
    """The preparation of the bound mesh object named ``name``, advanced by :meth:`poll`.

    fraction  how far it got, 0 to 1; ``stage`` what it does; ``seconds`` since it started
    """

    def __init__(self, obj, preserve_volume=True):
        self.name = obj.name
        self.preserve_volume = preserve_volume
        self.started = time.perf_counter()
        self.binding_id = stored.binding_id(obj)
        self._opening = stored.begin_opening(obj)  # reads the record and the mesh here
        self._job = None
        self._layout = False
        self._fraction, self.stage = 0.0, "reading"

    @property
    def fraction(self):
        if self._opening is not None:
            return OPENING_SHARE * self._opening.fraction
        return OPENING_SHARE + (1.0 - OPENING_SHARE) * self._fraction

    @property
    def seconds(self):
        return time.perf_counter() - self.started

    def poll(self):
        """Advance one step without waiting: True once done (the binding made and its layout
        prepared, or the mesh gone, cleared or built again meanwhile: nothing of its binding is
        then kept), False while work runs in the background. Raises what the preparation raised
        (:class:`SkinDetachError` for a damaged record or rig)."""
        obj = bpy.data.objects.get(self.name)
        if obj is None or stored.binding_id(obj) != self.binding_id:
            if self._opening is not None:
                self._opening.cancel()
            if self._job is not None:
                self._job.cancel()
            return True
        if self._opening is not None:
            self.stage = self._opening.stage
            if not self._opening.done():
                return False
            if self._opening.cancelled:  # its file was closed, or the add-on unregistered
                return True
            self._opening = None
        if self._job is None:  # the symmetry checks the layout's reading asks for, made in the background
            binding = stored.open_binding(obj)  # takes what the background made: cached, an old record rewritten
            self._job = binding.busy = threads.submit(_own_images, binding, _asked_images(obj, binding),
                                                      name=f"the symmetry checks of {self.name!r}")
            self.stage = "symmetry"
            return False
        if not self._job.done():
            return False
        if self._job.cancelled:
            return True
        self._job.result()
        if not self._layout:
            self._layout = True
            binding = stored.open_binding(obj)
            work = Deformation(obj, self.preserve_volume, require_unedited=False).preparation()
            if work is None:
                return True
            self._job = binding.busy = threads.submit(work, self._report, name=f"the layout of {self.name!r}")
            return False
        return True

    def _report(self, fraction, stage):
        threads.checkpoint()
        self._fraction, self.stage = fraction, stage


def _asked_images(obj, binding):
    """Pairs (detail ids, axis) that :func:`.handle_symmetry.symmetry_axis` may ask
    :meth:`.binding.Binding.is_own_mirror_image` about for ``obj``'s handles (each answered yes,
    so none is skipped): reading them is quick, answering them is not (1.4 s at 1M vertices)."""
    asked = []

    def record(ids, axis):
        asked.append((ids, axis))
        return True
    handle_symmetry.symmetry_axis(obj, handles.handles_of(obj), record)
    return asked


def _own_images(binding, asked):
    """Answer each of ``asked`` (:func:`_asked_images`) into the binding's cache."""
    for ids, axis in asked:
        binding.is_own_mirror_image(ids, axis)


def begin(obj, preserve_volume=True):
    """A :class:`Preparation` of the bound mesh ``obj``, started (raises :class:`SkinDetachError`
    when its record cannot be opened)."""
    if obj is None:
        raise SkinDetachError("object: expected a bound mesh object, got nothing")
    return Preparation(obj, preserve_volume)
