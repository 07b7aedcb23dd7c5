"""Issue 43, item 20: the proxy looks in the window as the docs say (they said orange; it is drawn
in the theme's wire colour, black)."""

import pathlib
import re
import tempfile

import bpy
import numpy as np

import rigs

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent


def _said_colour():
    """The colour words the README and the add-on page give the proxy's wire."""
    words = set()
    for page in (ROOT / "README.md", ROOT / "docs" / "addon.md"):
        text = " ".join(page.read_text().split())
        words |= set(re.findall(r"\b(black|orange|red|blue|green|white|grey|gray|yellow)\b[^.]{0,40}\bwire", text))
    return words


def test_the_proxy_is_drawn_the_colour_the_docs_say(ui):
    yield from ui.setup()
    obj, handle = rigs.rig(ui)
    rigs.activate(ui, obj)
    yield from ui.hover_view()
    yield from ui.press('NUMPAD_PERIOD', wait=1.0)  # View Selected: the sphere fills the view
    yield 1.0
    view = ui.view
    shot = pathlib.Path(tempfile.mkdtemp()) / "view.png"
    ui.screenshot(shot, (view.x, view.y, view.x + view.width, view.y + view.height))
    image = bpy.data.images.load(str(shot))
    pixels = np.array(image.pixels[:], dtype=np.float32).reshape(image.size[1], image.size[0], -1)[..., :3]
    proxy = rigs.api().proxy_of(obj)
    points = np.array([proxy.matrix_world @ v.co for v in proxy.data.vertices])
    edges = np.array([e.vertices[:] for e in proxy.data.edges])
    colours = []
    for a, b in edges[::3]:  # the drawn colour at edge midpoints facing the view (the darkest of 3x3)
        x, y = ui.on_screen((points[a] + points[b]) / 2)
        x, y = x - view.x, y - view.y
        if 2 <= x < view.width - 2 and 2 <= y < view.height - 2:
            patch = pixels[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3)
            colours.append(patch[np.argmin(patch.sum(axis=1))])
    colours = np.array(colours)
    assert len(colours) > 50, f"only {len(colours)} proxy edges in the view"
    orange = (colours[:, 0] > 0.6) & (colours[:, 1] > 0.2) & (colours[:, 1] < 0.7) & (colours[:, 2] < 0.25)
    dark = colours.max(axis=1) < 0.2
    drawn = "orange" if orange.mean() > 0.5 else "black" if dark.mean() > 0.5 else None
    said = _said_colour()
    assert drawn is not None, f"the proxy's wire is neither orange nor black: median colour {np.median(colours, axis=0)}"
    assert said == {drawn}, f"the docs say the proxy's wire is {sorted(said)}; the window draws it {drawn} " \
                            f"({100 * max(orange.mean(), dark.mean()):.0f} % of its edges)"
