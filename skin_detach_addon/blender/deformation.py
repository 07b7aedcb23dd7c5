"""One deformation step of a bound object: handles -> proxy solve -> detail rebuild -> write-back.

Every step starts from the stored rest (the solve targets are rigid motions of rest proxy
positions and the rebuild reads only the solved proxy), so thousands of steps do not drift.
"""

import time
from dataclasses import dataclass

import numpy as np
from mathutils import Matrix

from ..core.errors import SkinDetachError
from . import binding as stored
from . import handles, mesh_io

#: Tolerance of the normal-update iteration while the mouse moves (the API default) ...
DRAG_TOL = 1e-6
#: ... and when a result is kept (Apply, live update, confirm): tight enough that the result
#: does not depend on where the warm start came from.
SETTLE_TOL = 1e-12
#: Last step per binding id, for the panel (runtime only, never saved).
LAST_STEP = {}


@dataclass
class StepReport:
    milliseconds: float
    iterations: int
    converged: bool
    volume_change: float
    positions: np.ndarray  # (n, 3) float32 as written; a buffer the next step reuses


def handle_signature(obj, proxy, empties=None):
    """Tuple of the object's world matrix, the proxy's and every handle's own (basis) matrix:
    changes when any of them moves, by any means, and is current as soon as it is set.
    ``empties``: the handles of ``obj`` when the caller has them already."""
    values = [tuple(v for col in obj.matrix_world.col for v in col),
              tuple(v for col in proxy.matrix_basis.col for v in col)]
    for empty in handles.handles_of(obj, proxy) if empties is None else empties:
        values.append((empty.name,) + tuple(v for col in empty.matrix_basis.col for v in col))
    return tuple(values)


class Deformation:
    """Drives one bound mesh object. Opening checks the binding (topology, proxy, Object Mode);
    :meth:`step` then solves from the current handle transforms and writes the result."""

    def __init__(self, obj, preserve_volume=True):
        self.obj = obj
        self.binding = stored.open_binding(obj)
        self.preserve_volume = bool(preserve_volume)
        self.proxy = self.binding.proxy
        m = self.binding.surface.proxy_vertices.shape[0]
        if len(self.proxy.data.vertices) != m:
            raise SkinDetachError(f"proxy {self.proxy.name!r}: expected {m} vertices, got "
                                  f"{len(self.proxy.data.vertices)} (its mesh was edited); press Rebuild")

    def solve(self, tol=SETTLE_TOL):
        """Solve (to ``tol``, see :class:`DualLaplacian`) and rebuild without writing anything.
        Returns the :class:`DualLaplacianResult` (proxy, (m, 3)), the (n, 3) float32 detail
        positions (a buffer the next call reuses) and the handle empties it read."""
        empties = handles.handles_of(self.obj, self.proxy)
        ids, targets = handles.constraints(self.obj, empties, self.binding.surface.proxy_vertices)
        if ids.size == 0:
            raise SkinDetachError(f"object {self.obj.name!r}: expected at least one handle or anchor, got none; "
                                  f"select vertices and press Add Handle")
        result = self.binding.solve_proxy(ids, targets, self.preserve_volume, tol)
        return result, self.binding.rebuild(result.vertices), empties

    def step(self, tol=SETTLE_TOL):
        """:meth:`solve`, then write the mesh and the proxy; returns a :class:`StepReport`."""
        start = time.perf_counter()
        result, detail, empties = self.solve(tol)
        mesh_io.write_positions(self.obj.data, detail)
        mesh_io.write_positions(self.proxy.data, result.vertices)
        report = StepReport(1000 * (time.perf_counter() - start), result.iterations, result.converged,
                            result.volume_change, detail)
        LAST_STEP[self.binding.binding_id] = (report.milliseconds, handle_signature(self.obj, self.proxy, empties))
        return report

    def reset(self):
        """Rest shape back in the mesh and the proxy (bit-exact), every empty back at its rest frame."""
        for empty in handles.handles_of(self.obj, self.proxy):
            rest_local = np.asarray(empty[handles.TAG]["rest_local"], dtype=np.float64).reshape(4, 4)
            empty.matrix_basis = Matrix(rest_local.tolist())
        mesh_io.write_positions(self.obj.data, self.binding.rest)
        mesh_io.write_positions(self.proxy.data, self.binding.surface.proxy_vertices)
        stored.mark_written(self.obj, self.binding.rest)
        self.binding.forget_warm_starts()
        remember_handles(self.obj, self.proxy)


def last_step_ms(obj):
    """Milliseconds of the last step of ``obj``'s binding in this session, or None."""
    if not stored.has_binding(obj):
        return None
    entry = LAST_STEP.get(obj[stored.KEY].get("binding_id"))
    return None if entry is None else entry[0]


def remember_handles(obj, proxy):
    """Take the handles' current transforms as solved (after a cancel put them back)."""
    key = obj[stored.KEY].get("binding_id")
    milliseconds = LAST_STEP[key][0] if key in LAST_STEP else 0.0
    LAST_STEP[key] = (milliseconds, handle_signature(obj, proxy))


def solved_signature(obj):
    if not stored.has_binding(obj):
        return None
    entry = LAST_STEP.get(obj[stored.KEY].get("binding_id"))
    return None if entry is None else entry[1]
