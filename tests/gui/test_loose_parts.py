"""Issue 51: loose parts that ride on the body, in the window: the panel's Build button builds a
sphere with an eye half sunk into it (one mesh, two parts), the panel's Parts line says the eye
rides, a drag by the keys carries the eye with the head; the panel's Detach button frees it (the
next drag leaves it), its By Rule button gives it back, each one undo step."""

import bpy
import bmesh
import numpy as np
from mathutils import Matrix

import gui
import rigs


def _sphere_with_an_eye(ui):
    """The 48x24 sphere with a small UV sphere (radius 0.15) half sunk into it at +Y, joined into
    one mesh (two loose parts); the eye's vertex ids."""
    obj = rigs.sphere(ui)
    mesh = obj.data
    body = len(mesh.vertices)
    work = bmesh.new()
    work.from_mesh(mesh)
    bmesh.ops.create_uvsphere(work, u_segments=12, v_segments=8, radius=0.15,
                              matrix=Matrix.Translation((0.0, 0.97, 0.3)))
    work.to_mesh(mesh)
    work.free()
    mesh.update()
    rigs.undo_push(ui, "Eye")
    return obj, np.arange(body, len(mesh.vertices))


def test_the_panels_build_and_detach_decide_the_eye(ui):
    yield from ui.setup()
    obj, eye = _sphere_with_an_eye(ui)
    sd = rigs.api()
    bpy.context.scene.skin_detach.target_faces = 300
    rigs.activate(ui, obj)
    yield from ui.click_button("bpy.ops.skin_detach.build()", wait=1.0)
    builds = gui.addon().ui.operators.BUILDS
    for _ in range(120):  # the Build button runs modal: wait for its end
        if obj.name not in builds:
            break
        yield 0.5
    yield 0.5
    assert sd.is_bound(obj), "the panel's Build did not bind the mesh"
    figures = sd.figures(obj)["build"]
    assert (figures.get("parts"), figures.get("riders")) == (2, 1), figures
    rest = sd.rest_positions(obj).copy()
    body = np.setdiff1d(np.arange(rest.shape[0]), eye)
    sd.add_anchor(obj, body[rest[body, 2] < -0.6], mirror="")
    handle = sd.add_handle(obj, body[rest[body, 2] > 0.1], mirror="")  # the head, not the eye
    rigs.activate(ui, handle)
    rigs.undo_push(ui, "Rig")
    yield from rigs.drag(ui, 80, 0)
    posed = rigs.positions(obj)
    assert np.abs(posed[eye] - rest[eye]).max() > 0.1, "the eye stayed behind the head"
    # The artist selects the eye (set up by script) and presses the panel's Detach.
    rigs.select_vertices(obj, eye[:1])
    rigs.activate(ui, obj)
    rigs.undo_push(ui, "Select")
    # The Parts row's middle button (Attach, Detach, By Rule side by side).
    yield from ui.find_button("bpy.ops.skin_detach.set_parts(mode=", columns=(0.5,))
    assert ui.found is not None, "no Detach button in the panel's Parts row"
    yield from ui.click(*ui.found, wait=2.0)
    yield from ui.reports()
    figures = sd.figures(obj)["build"]
    assert (figures.get("riders"), figures.get("parts_detached")) == (0, 1), (figures, ui.last_reports[-1:])
    rest = sd.rest_positions(obj).copy()  # Detach rebuilt: the posed shape is the new rest
    handle = [e for e in sd.handles_of(obj) if sd.handle_kind(e) == sd.HANDLE][0]
    rigs.activate(ui, handle)
    rigs.undo_push(ui, "Handle")
    yield from rigs.drag(ui, -60, 0)
    after = rigs.positions(obj)
    assert np.abs(after[body] - rest[body]).max() > 0.1, "the drag did not move the head"
    assert np.abs(after[eye] - rest[eye]).max() < 1e-5, "a detached eye with no handle moved"
    # Ctrl+Z three times: the drag, the set-up's step (the handle made active), the Detach (one
    # step each): the eye rides again.
    name = obj.name  # an undo step loads the file's data anew: references made before go
    yield from ui.hover_view()
    for _ in range(3):
        yield from ui.press('Z', ctrl=True, wait=1.0)
    yield 1.0
    obj = bpy.data.objects[name]
    assert sd.part_overrides(obj) == (None, None), sd.part_overrides(obj)
    assert np.array_equal(rigs.positions(obj), posed), "Ctrl+Z did not bring back the pose before Detach"
