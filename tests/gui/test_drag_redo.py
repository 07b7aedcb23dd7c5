"""Bug 1: the Redo panel (Adjust Last Operation) after a mouse drag with Drag Handle."""

import bpy
import numpy as np

import rigs


def _hud(ui):
    found = [r for r in ui.area().regions if r.type == 'HUD' and r.width > 1 and r.height > 1]
    assert found, "no Adjust Last Operation panel in the 3D View after the drag"
    return found[0]


def _fields(ui, hud):
    """Generator; afterwards ``ui.fields`` lists (x, y, value) of the Redo panel's number fields,
    top down, found by hovering and Ctrl+C (which copies a field's value) as an artist could."""
    wm = bpy.context.window_manager
    hits = []
    for y in range(hud.y + hud.height - 8, hud.y, -5):
        x = hud.x + int(hud.width * 0.7)
        wm.clipboard = ""
        yield from ui.move(x, y, wait=0.02)
        yield from ui.press('C', ctrl=True, wait=0.03)
        try:
            float(wm.clipboard)
        except ValueError:
            continue
        hits.append((x, y, wm.clipboard))
    fields = []  # one per run of hits with the same text, at the run's middle
    for x, y, text in hits:
        if fields and fields[-1][-1][2] == text and fields[-1][-1][1] - y <= 5:
            fields[-1].append((x, y, text))
        else:
            fields.append([(x, y, text)])
    ui.fields = [(run[len(run) // 2][0], run[len(run) // 2][1], float(run[0][2])) for run in fields]


def test_redo_panel_redoes_the_drag(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    sd = rigs.api()
    proxy = sd.proxy_of(obj)
    held = np.array(handle["_skin_detach_handle"]["proxy_ids"], dtype=np.int64)  # a copy: the undo frees the data
    rest_proxy = rigs.positions(proxy).astype(np.float64)
    start = handle.matrix_world.copy()
    yield from rigs.drag(ui, 60, 20)
    moved = handle.matrix_world.translation - start.translation
    assert moved.length > 0.1, f"the drag did not move the handle ({moved.length})"
    dragged = rigs.positions(obj).copy()
    hud = _hud(ui)
    if hud.height < 40:  # collapsed: the artist opens it
        yield from ui.click(hud.x + 40, hud.y + hud.height // 2, wait=0.5)
        hud = _hud(ui)
    yield from _fields(ui, hud)
    offsets = [value for _, _, value in ui.fields]
    assert len(offsets) >= 3 and np.allclose(offsets[:3], moved[:], atol=1e-3), \
        f"the Redo panel shows {offsets}, the drag moved the handle by {tuple(moved)}"
    # X typed anew (an artist's click in the field, the value, Enter): the drag redone with it.
    x, y, _ = ui.fields[0]
    yield from ui.click(x, y, wait=0.3)
    yield from ui.press('A', ctrl=True)
    yield from ui.type("0.1")
    names = handle.name, obj.name, proxy.name
    yield from ui.press('RET', wait=2.0)
    handle, obj, proxy = (bpy.data.objects[name] for name in names)  # the redo's undo made them anew
    now = handle.matrix_world
    assert np.allclose(np.array(now.to_3x3()), np.array(start.to_3x3()), atol=1e-6), \
        f"the redo turned the handle: {now.to_euler()}"
    expected = start.translation + type(moved)((0.1, moved.y, moved.z))
    assert (now.translation - expected).length < 1e-5, f"handle at {tuple(now.translation)}, expected {tuple(expected)}"
    shift = rigs.positions(proxy)[held].astype(np.float64) - rest_proxy[held]
    assert np.allclose(shift, [0.1, moved.y, moved.z], atol=1e-4), f"the handle's proxy vertices moved {shift[:3]}"
    after = rigs.positions(obj)
    size = np.ptp(after, axis=0)
    assert np.isfinite(after).all() and size.min() > 1.5, f"the mesh collapsed: extent {size}"
    assert not np.allclose(after, dragged), "the redo changed nothing"
    # The drag's own X typed back: the drag as it was (solved from rest, as Apply solves).
    yield from ui.click(x, y, wait=0.3)
    yield from ui.press('A', ctrl=True)
    yield from ui.type(f"{moved.x:.6f}")
    yield from ui.press('RET', wait=2.0)
    obj = bpy.data.objects[names[1]]
    again = rigs.positions(obj)
    assert np.abs(again - dragged).max() < 1e-3 * np.ptp(dragged, axis=0).max(), \
        f"the redo with the drag's own values differs from the drag by {np.abs(again - dragged).max()}"
