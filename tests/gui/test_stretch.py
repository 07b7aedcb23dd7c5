"""Show Stretch from the panel's button and from F3, in Object and Edit Mode, with a Solid 3D
View open (items 6, 12, 13 and 14 of issue 43): the stretch's colours are drawn, and pressing it
again gives back the artist's own colors and the view's coloring."""

import numpy as np

import bpy

import rigs

BUTTON = "bpy.ops.skin_detach.show_stretch"
STRETCH_COLORS = "skin_detach_stretch_color"


def _painted_rig(ui):
    """The rig with the artist's own color "paint" (orange, the active and render color), bent
    by a drag so that its stretch is not 0 everywhere; the Solid view colours by Material."""
    obj, handle = rigs.rig(ui)
    paint = obj.data.color_attributes.new("paint", 'BYTE_COLOR', 'CORNER')
    paint.data.foreach_set("color", np.tile([1.0, 0.45, 0.05, 1.0], len(obj.data.loops)).astype(np.float32))
    obj.data.color_attributes.active_color_name = "paint"
    shading = ui.area().spaces.active.shading
    assert shading.type == 'SOLID', f"the 3D View is not in Solid shading ({shading.type})"
    shading.color_type = 'MATERIAL'
    rigs.undo_push(ui, "Paint")
    yield from rigs.drag(ui, 60, 0)
    stretch = rigs.api().stretch(obj)
    assert stretch.max() > 0.05, f"the drag stretched the mesh by {stretch.max()} at most"
    rigs.activate(ui, obj)
    yield 0.3
    return obj


def _state(ui, obj):
    """What the artist sees: the view's coloring, the active and render colors, the attributes."""
    colors = obj.data.color_attributes
    return (ui.area().spaces.active.shading.color_type, colors.active_color_name, colors.default_color_name,
            sorted(a.name for a in obj.data.attributes))


def _stretch_share(ui, obj):
    """The share of the pixels of the mesh's box on screen (as drawn in the window) in the stretch
    map's colours, blue to red through purple (linear (s, 0.15, 1 - s)): more blue than green,
    which neither the grey material and background nor the orange paint are."""
    world = np.asarray(obj.matrix_world)
    points = rigs.positions(obj).astype(np.float64) @ world[:3, :3].T + world[:3, 3]
    xy = np.array([ui.on_screen(p) for p in points[::7]])
    region = ui.view
    x0, y0 = np.maximum(xy.min(axis=0), (region.x, region.y))
    x1, y1 = np.minimum(xy.max(axis=0), (region.x + region.width, region.y + region.height))
    path = f"/tmp/skin_detach_stretch_{id(region)}.png"
    ui.screenshot(path, (int(x0), int(y0), int(x1), int(y1)))
    image = bpy.data.images.load(path, check_existing=False)
    try:
        pixels = np.asarray(image.pixels[:], dtype=np.float32).reshape(-1, 4)
    finally:
        bpy.data.images.remove(image)
    g, b = pixels[:, 1], pixels[:, 2]
    return float(np.mean(b > g + 0.1))


def _shown_then_hidden(ui, obj, press, mode, least=0.15):
    """Press (``press``) Show Stretch, check, press again, check; ``least``: the share of the
    mesh's box in the stretch's colours when shown (Edit Mode's wire and vertices cover more)."""
    before = _state(ui, obj)
    share = _stretch_share(ui, obj)
    assert share < 0.01, f"the mesh shows the stretch's colours before Show Stretch ({share:.1%} of its box)"
    yield from press()
    assert obj.mode == mode, f"Show Stretch left {mode} for {obj.mode}"
    view, active, render, names = _state(ui, obj)
    assert view == 'VERTEX', f"the Solid view colours by {view!r}, not by Attribute"
    assert active == STRETCH_COLORS and render == "paint", (active, render)
    yield 1.0
    share = _stretch_share(ui, obj)
    assert share > least, f"the stretch's colours are not drawn on the mesh ({share:.1%} of its box)"
    yield from press()
    assert obj.mode == mode
    assert _state(ui, obj) == before, f"not given back: {_state(ui, obj)} instead of {before}"
    yield 1.0
    share = _stretch_share(ui, obj)
    assert share < 0.01, f"the stretch's colours are still drawn ({share:.1%} of the mesh's box)"


def _button(ui):
    def press():
        yield from ui.click_button(BUTTON)
    return press


def test_show_stretch_button_in_object_mode(ui):
    yield from ui.setup()
    obj = yield from _painted_rig(ui)
    yield from _shown_then_hidden(ui, obj, _button(ui), 'OBJECT')


def test_show_stretch_button_in_edit_mode(ui):
    yield from ui.setup()
    obj = yield from _painted_rig(ui)
    yield from ui.hover_view()
    yield from ui.press('TAB', wait=0.5)
    assert obj.mode == 'EDIT', "Tab did not enter Edit Mode"
    yield from ui.press('A', alt=True, wait=0.5)                  # nothing selected: no selection tint over it
    yield from _shown_then_hidden(ui, obj, _button(ui), 'EDIT', least=0.05)


def test_f3_finds_show_stretch(ui):
    yield from ui.setup()
    obj = yield from _painted_rig(ui)

    def press():
        yield from ui.menu_search("show stretch")
    yield from _shown_then_hidden(ui, obj, press, 'OBJECT')


def test_undo_and_redo_of_show_stretch_take_the_views_along(ui):
    yield from ui.setup()
    name = (yield from _painted_rig(ui)).name

    def state():
        return _state(ui, bpy.data.objects[name])  # an undo makes every object anew

    before = state()
    yield from ui.click_button(BUTTON)
    shown = state()
    assert shown[:2] == ('VERTEX', STRETCH_COLORS), shown
    yield from ui.hover_view()
    yield from ui.press('Z', ctrl=True, wait=1.0)
    assert state() == before, f"Ctrl+Z left {state()} instead of {before}"
    yield from ui.press('Z', ctrl=True, shift=True, wait=1.0)
    assert state() == shown, f"Ctrl+Shift+Z gave {state()} instead of {shown}"
