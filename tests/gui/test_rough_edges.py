"""The rough edges an artist met in the window: Edit Mode's F3 and context menu, the first click,
the panel during a drag, the mirror twin's report, typed values, the panel's labels and widths."""

import types

import blf
import bpy
import numpy as np

import gui
import rigs


def _edit_mode_with(ui, obj, ids):
    rigs.select_vertices(obj, ids)
    rigs.activate(ui, obj)
    yield from ui.hover_view()
    yield from ui.press('TAB', wait=0.5)
    assert obj.mode == 'EDIT', "Tab did not enter Edit Mode"


def _rig_in_edit_mode(ui, axis):
    """The rig, in Edit Mode with the side beyond 0.8 along ``axis`` selected: (obj, side ids,
    the handles before)."""
    yield from ui.setup()
    obj, _ = rigs.rig(ui)
    side = np.flatnonzero(rigs.api().rest_positions(obj)[:, axis] > 0.8)
    before = set(rigs.api().handles_of(obj))
    yield from _edit_mode_with(ui, obj, side)
    return obj, side, before


def test_f3_in_edit_mode_finds_add_handle(ui):
    obj, side, before = yield from _rig_in_edit_mode(ui, 0)
    yield from ui.menu_search("add handle", wait=1.5)
    made = set(rigs.api().handles_of(obj)) - before
    assert len(made) == 1, f"F3 'add handle' in Edit Mode made {len(made)} handles"
    assert np.array_equal(np.sort(made.pop()["_skin_detach_handle"]["detail_ids"]), side)


def test_edit_mode_context_menu_has_add_anchor(ui):
    obj, side, before = yield from _rig_in_edit_mode(ui, 1)
    x, y = ui.mouse
    yield from ui.press('RIGHTMOUSE', wait=0.8)
    yield from ui.find_button("bpy.ops.skin_detach.add_anchor", box=(x - 20, y - 700, x + 320, y + 40),
                              columns=(0.15, 0.45, 0.75), step=8)
    assert ui.found, "no Add Anchor in Edit Mode's context menu"
    yield from ui.click(*ui.found, wait=1.5)
    made = set(rigs.api().handles_of(obj)) - before
    assert len(made) == 1 and rigs.api().handle_kind(made.pop()) == rigs.api().ANCHOR


def test_the_first_click_on_the_mesh_selects_the_mesh(ui):
    yield from ui.setup()
    obj, _ = rigs.rig(ui)
    yield from ui.hover_view()
    yield from ui.press('A', alt=True)  # deselect all
    yield from ui.click(*ui.on_screen(obj.matrix_world @ obj.data.vertices[len(obj.data.vertices) // 3].co))
    active = bpy.context.view_layer.objects.active
    assert active == obj, f"the click selected {active.name if active else None!r}, not the mesh"


class _Recorder:
    """Stands in for a panel's layout: records what it would draw (texts, icons, labelled props)."""

    def __init__(self, lines):
        self.lines = lines

    def label(self, text="", icon='NONE', **_):
        self.lines.append(("label", text, icon))

    def prop(self, data, name, text=None, icon='NONE', **_):
        self.lines.append(("prop", data.bl_rna.properties[name].name if text is None else text, icon))

    def prop_search(self, data, name, *args, text=None, **_):
        self.lines.append(("prop", data.bl_rna.properties[name].name if text is None else text, 'NONE'))

    def operator(self, idname, text=None, icon='NONE', **_):
        self.lines.append(("operator", text if text is not None else idname, icon))
        return types.SimpleNamespace()

    def __getattr__(self, name):  # box, row, column, separator...
        return lambda *a, **k: self


def panel_lines():
    """(kind, text, icon) of everything the Skin Detach panel draws now."""
    lines = []
    panel = bpy.types.VIEW3D_PT_skin_detach
    context = types.SimpleNamespace(scene=bpy.context.scene, active_object=bpy.context.view_layer.objects.active)
    panel.draw(types.SimpleNamespace(layout=_Recorder(lines)), context)
    return lines


def test_the_panel_does_not_cry_failure_while_a_drag_settles(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    rigs.api().build(obj, target_faces=2000)  # a proxy whose solve a move's budget cannot finish at once
    yield from ui.hover_view()
    yield from ui.press('D', shift=True, alt=True, wait=0.3)
    yield from ui.press('R', wait=0.1)
    yield from ui.press('NINE', wait=0.02)
    yield from ui.press('ZERO', wait=0.02)  # read at once: the timer settles the solve while the mouse rests
    last = rigs.api().figures(obj)["last_step"]
    assert not last["converged"], f"the move's solve finished within its budget: nothing to settle ({last})"
    lines = panel_lines()
    errors = [text for kind, text, icon in lines if icon == 'ERROR']
    assert not errors, f"the panel shows {errors} during the drag (last step {last})"
    assert any("Settling" in text for _, text, _ in lines), lines
    yield from ui.press('RET', wait=0.5)
    last = rigs.api().figures(obj)["last_step"]
    assert last["converged"] and not any(icon == 'ERROR' for _, _, icon in panel_lines()), last


def test_add_handle_says_it_made_a_mirror_twin(ui):
    yield from ui.setup()
    obj = rigs.sphere(ui, mirror_x=True)
    rigs.api().build(obj, target_faces=300)
    side = np.flatnonzero(rigs.api().rest_positions(obj)[:, 0] > 0.8)
    yield from _edit_mode_with(ui, obj, side)
    yield from ui.menu_search("add handle", wait=1.5)
    yield from ui.reports()
    assert "mirrored twin" in ui.last_reports[-1], ui.last_reports[-1]
    assert len(rigs.api().handles_of(obj)) == 2


def test_typed_values_cannot_fling_the_mesh(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    start = handle.matrix_world.translation.copy()
    yield from rigs.drag(ui, 0, 0, steps=1, keys=('X', 'NINE', 'NINE', 'NINE', 'NINE', 'NINE', 'NINE', 'NINE'))
    moved = handle.matrix_world.translation - start
    assert abs(moved.x - 9.0) < 1e-4 and abs(moved.y) < 1e-4 and abs(moved.z) < 1e-4, \
        f"typed 9999999 along X moved the handle by {tuple(moved)} (the first 9 only is in bounds)"
    assert np.isfinite(rigs.positions(obj)).all()


def test_panel_texts_are_labelled_and_fit_the_sidebar(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    sd = rigs.api()
    group = obj.vertex_groups.new(name="cap")
    group.add([0, 1, 2], 1.0, 'REPLACE')
    sd.build(obj, target_faces=8)  # the normal test stops above so small a target: the panel says so
    wider = sd.add_handle(obj, np.flatnonzero(sd.rest_positions(obj)[:, 2] > 0.4), mirror="")  # shares vertices
    wider.location.x += 0.3
    sd.deform(obj)
    rigs.activate(ui, obj)
    yield 0.3
    lines = panel_lines()
    texts = [text for _, text, _ in lines]
    assert any("not reached" in text for text in texts) and any("shares" in text for text in texts), texts
    assert "Mirror" in texts, "the Mirror choice has no label"
    assert "Group" in texts, "the vertex group field has no label"
    scale = bpy.context.preferences.system.ui_scale
    blf.size(0, 11 * scale)  # Blender's UI text at 100 %
    # Room of a label in a box of the sidebar at its default width, measured in this window: the
    # category tabs, the box's margins, and the icon when there is one.
    room = {False: ui.sidebar.width - 72 * scale, True: ui.sidebar.width - 104 * scale}
    too_wide = [text for kind, text, icon in lines
                if kind == "label" and blf.dimensions(0, text)[0] > room[icon != 'NONE']]
    assert not too_wide, f"cut at the sidebar's default width ({ui.sidebar.width} px): {too_wide}"
