"""Issue 44: a drag's confirm pushes an undo step no larger than Blender's own rewrite of the same
positions (Blender's undo memory, ``bpy.app.memory_usage_undo()``, per step, over several steps)."""

import statistics
import time

import bpy
import numpy as np

import rigs
import test_build_progress

#: Steps of each kind measured (the median growth per step is compared).
STEPS = 6


def _undo_mb():
    return bpy.app.memory_usage_undo() / 2**20


def _growth(samples):
    return statistics.median(b - a for a, b in zip(samples, samples[1:]))


def test_a_confirms_undo_step_is_no_larger_than_blenders_own_rewrite(ui):
    yield from ui.setup()
    plain = test_build_progress._big_mesh(ui, n=550)  # 302,500 vertices, not bound: Blender's own rewrites
    plain.name = "Plain"
    obj = test_build_progress._big_mesh(ui, n=550)
    sd = rigs.api()
    sd.build(obj, target_faces=300)
    rest = sd.rest_positions(obj)
    sd.add_anchor(obj, np.flatnonzero(rest[:, 0] < -0.8), mirror="")
    handle = sd.add_handle(obj, np.flatnonzero(rest[:, 0] > 0.8), mirror="")
    rigs.activate(ui, handle)
    rigs.undo_push(ui, "Rig")
    yield from rigs.drag(ui, 20, 10)  # the first drag prepares what every drag reuses
    yield 1.0
    # Blender's own: a mesh of as many vertices rewritten from Python, an undo step each.
    own = [_undo_mb()]
    for k in range(STEPS):
        positions = rigs.positions(plain)
        positions[:, 2] += 1e-3
        plain.data.attributes["position"].data.foreach_set("vector", positions.ravel())
        plain.data.update()
        rigs.undo_push(ui, f"Rewrite {k}")
        yield 1.0
        own.append(_undo_mb())
    # The add-on's: a drag confirmed with Enter, an undo step each.
    ours = [_undo_mb()]
    for k in range(STEPS):
        before = rigs.positions(obj).copy()
        yield from rigs.drag(ui, 10 if k % 2 else -10, 5)
        yield 1.0
        assert np.abs(rigs.positions(obj) - before).max() > 1e-4, f"drag {k + 1} did not move the mesh"
        ours.append(_undo_mb())
    step_own, step_ours = _growth(own), _growth(ours)
    positions_mb = 12 * len(obj.data.vertices) / 2**20
    print(f"undo step: Blender's rewrite {step_own:.1f} MB, the confirm's {step_ours:.1f} MB "
          f"(undo memory {[round(x, 2) for x in own]} / {[round(x, 2) for x in ours]})")
    assert step_own > 0.9 * positions_mb, f"Blender's own rewrite: {step_own:.2f} MB, its positions {positions_mb:.2f} MB"
    assert step_ours <= 1.2 * step_own, \
        f"a confirm's undo step holds {step_ours:.2f} MB, Blender's own rewrite of the positions {step_own:.2f} MB"
