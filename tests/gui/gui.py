"""Events as an artist makes them, in the real window (``--enable-event-simulate``).

Every method that sends events is a generator: ``yield from ui.press('G')``. Between events the
generator yields so Blender's event loop handles them (and redraws). Positions are window pixels;
``ui.view`` is the 3D View's WINDOW region, ``ui.sidebar`` its UI region (the N-panel).
Reading back what the window shows goes through the window too: :meth:`reports` copies the Info
editor's lines (A, Ctrl+C there), :meth:`find_button` hovers the sidebar and copies each button's
Python command or data path (Ctrl+Shift+C), as an artist finds what a button does.
"""

import pathlib
import subprocess

import bpy

#: Seconds between two events (the event loop runs in between).
STEP_S = 0.05
_NAMES = {**{str(d): n for d, n in enumerate(("ZERO", "ONE", "TWO", "THREE", "FOUR", "FIVE", "SIX", "SEVEN", "EIGHT",
                                                  "NINE"))},
          " ": "SPACE", ".": "PERIOD", "-": "MINUS", ",": "COMMA", "/": "SLASH", "_": "MINUS", "(": "NINE",
          ")": "ZERO", "'": "QUOTE", "=": "EQUAL", "\\": "BACK_SLASH", ":": "SEMI_COLON"}
_SHIFTED = set("_():") | set("ABCDEFGHIJKLMNOPQRSTUVWXYZ")


def addon():
    """The installed extension's package (``bl_ext.<repository>.skin_detach_addon``)."""
    import importlib
    for name in bpy.context.preferences.addons.keys():
        if name.rsplit(".", 1)[-1] == "skin_detach_addon":
            return importlib.import_module(name)
    raise AssertionError("the Skin Detach extension is not enabled in this Blender")


class Ui:
    def __init__(self, pictures=None):
        self.window = bpy.context.window_manager.windows[0]
        self.mouse = (0, 0)
        self.pictures = pictures

    # ----- where things are --------------------------------------------------------------------
    def area(self, kind='VIEW_3D'):
        areas = [a for a in self.window.screen.areas if a.type == kind]
        if not areas:
            raise AssertionError(f"no {kind} area in the window")
        return max(areas, key=lambda a: a.width * a.height)

    def region(self, kind='WINDOW', area='VIEW_3D'):
        return next(r for r in self.area(area).regions if r.type == kind)

    @property
    def view(self):
        return self.region('WINDOW')

    @property
    def sidebar(self):
        return self.region('UI')

    @staticmethod
    def centre(region):
        return region.x + region.width // 2, region.y + region.height // 2

    def on_screen(self, point):
        """Window pixel of the world ``point`` (3,) in the 3D View."""
        from bpy_extras.view3d_utils import location_3d_to_region_2d
        from mathutils import Vector
        region = self.view
        data = self.area().spaces.active.region_3d
        xy = location_3d_to_region_2d(region, data, Vector(point))
        assert xy is not None, f"{tuple(point)} is behind the view"
        return int(round(region.x + xy.x)), int(round(region.y + xy.y))

    # ----- events ------------------------------------------------------------------------------
    def event(self, kind, value, x=None, y=None, **modifiers):
        x, y = self.mouse if x is None else (int(round(x)), int(round(y)))
        self.mouse = (x, y)
        self.window.event_simulate(kind, value, x=x, y=y, **modifiers)

    def press(self, kind, at=None, wait=STEP_S, **modifiers):
        """Press and release key or button ``kind`` (at ``at``, else where the mouse is)."""
        x, y = at if at is not None else self.mouse
        self.event(kind, 'PRESS', x, y, **modifiers)
        self.event(kind, 'RELEASE', x, y, **modifiers)
        yield wait

    def move(self, x, y, steps=1, wait=STEP_S):
        """Move the mouse to (x, y) in ``steps`` equal moves, letting each be handled."""
        x0, y0 = self.mouse
        for k in range(1, steps + 1):
            self.event('MOUSEMOVE', 'NOTHING', x0 + (x - x0) * k / steps, y0 + (y - y0) * k / steps)
            yield wait

    def click(self, x, y, button='LEFTMOUSE', wait=0.2, **modifiers):
        yield from self.move(x, y)
        yield from self.press(button, (x, y), wait=wait, **modifiers)

    def type(self, text, wait=STEP_S):
        """Type ``text`` as keystrokes (with their characters, as a keyboard sends them)."""
        for char in text:
            kind = _NAMES.get(char, char.upper())
            shift = char in _SHIFTED
            self.window.event_simulate(kind, 'PRESS', unicode=char, x=self.mouse[0], y=self.mouse[1], shift=shift)
            self.window.event_simulate(kind, 'RELEASE', x=self.mouse[0], y=self.mouse[1], shift=shift)
            yield wait

    def hover_view(self):
        """Put the mouse in the middle of the 3D View (keys go to the editor under the mouse)."""
        yield from self.move(*self.centre(self.view))

    def menu_search(self, text, wait=1.0):
        """F3 over the 3D View, type ``text``, Enter: the first match runs."""
        yield from self.hover_view()
        yield from self.press('F3', wait=0.5)
        yield from self.type(text)
        yield 0.5
        yield from self.press('RET', wait=wait)

    # ----- reading the window back -------------------------------------------------------------
    def topbar_box(self):
        """(x0, y0, x1, y1) of the window's top bar (a global area, not in screen.areas)."""
        return 0, self.window.height - 26, self.window.width, self.window.height

    def clipboard(self):
        return bpy.context.window_manager.clipboard

    def reports(self):
        """Generator; afterwards :attr:`last_reports` holds the Info editor's lines (oldest first),
        copied as an artist would: A and Ctrl+C over the Info editor."""
        area = self.area('INFO')
        region = next(r for r in area.regions if r.type == 'WINDOW')
        bpy.context.window_manager.clipboard = ""
        yield from self.move(*self.centre(region), steps=3)
        yield from self.press('ESC', wait=0.3)  # closes an error's popup, which would take the keys
        yield from self.press('A')
        yield from self.press('C', ctrl=True, wait=0.2)
        self.last_reports = [line for line in self.clipboard().splitlines() if line.strip()]

    def find_button(self, wanted, region=None, columns=(0.3, 0.7), step=10, box=None):
        """Generator; afterwards :attr:`found` is the window pixel of the first button (top down)
        whose Python command (Ctrl+C over an operator button, as Blender copies it) or data path
        (Ctrl+Shift+C over a property) contains ``wanted``, or None. Looks in the sidebar, in
        ``region``, or in ``box`` (x0, y0, x1, y1 window pixels, for a popup menu)."""
        region = region or self.sidebar
        x0, y0, x1, y1 = box or (region.x, region.y, region.x + region.width, region.y + region.height)
        operator = wanted.startswith("bpy.ops.")
        self.found = None
        wm = bpy.context.window_manager
        for y in range(y1 - 6, y0, -step):
            for fraction in columns:
                x = x0 + int((x1 - x0) * fraction)
                wm.clipboard = ""
                yield from self.move(x, y, wait=0.02)
                yield from self.press('C', ctrl=True, shift=not operator, wait=0.03)
                if wanted in wm.clipboard:
                    self.found = (x, y)
                    return

    def click_button(self, wanted, region=None, wait=1.0, box=None):
        """Find the button ``wanted`` (see :meth:`find_button`) and click it."""
        yield from self.find_button(wanted, region, box=box)
        assert self.found is not None, f"no button {wanted!r} found"
        yield from self.click(*self.found, wait=wait)

    def screenshot(self, path, box=None):
        """The whole window, or the ``box`` (x0, y0, x1, y1 window pixels) of it, as a PNG at
        ``path`` (ImageMagick's import; Blender's own screenshot is black under Xvfb)."""
        pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
        crop = []
        if box is not None:
            x0, y0, x1, y1 = box
            crop = ["-crop", f"{x1 - x0}x{y1 - y0}+{x0}+{self.window.height - y1}", "+repage"]
        subprocess.run(["import", "-window", "root", *crop, str(path)], check=True, capture_output=True, timeout=30)

    # ----- set-up (before the artist's steps) ----------------------------------------------------
    def setup(self):
        """Close the splash (Esc), show the Info editor where the timeline was and the sidebar's
        Skin Detach tab; returns when the window has settled."""
        yield 1.0
        yield from self.press('ESC', at=self.centre(self.view), wait=0.5)
        for area in self.window.screen.areas:
            if area.type == 'DOPESHEET_EDITOR':
                area.type = 'INFO'
        space = self.area().spaces.active
        space.show_region_ui = True
        yield 0.5
        try:
            self.sidebar.active_panel_category = "Skin Detach"
        except (AttributeError, TypeError):
            pass
        yield 0.5
