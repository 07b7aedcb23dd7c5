"""Headless bpy: the stretch map (Show Stretch) adds nothing until shown, gives the artist's own
colors and views back, works in Edit Mode, goes with Clear Skin, and bakes each frame's own."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_support import activate, band, quad_sphere  # noqa: E402

from skin_detach_addon import api, bake_cli  # noqa: E402
from skin_detach_addon.blender import binding, mesh_io  # noqa: E402
from skin_detach_addon.core.errors import SkinDetachError  # noqa: E402
from skin_detach_addon.core.detached_surface.stretch import SkinStretch  # noqa: E402


def painted_sphere(uvs=True):
    """quad_sphere with the artist's own colors: "paint" (corners, bytes) active and rendered,
    "mask" (points) beside it, and "temperature" the active attribute."""
    obj = quad_sphere()
    mesh = obj.data
    if not uvs:
        mesh.uv_layers.remove(mesh.uv_layers[0])
    paint = mesh.color_attributes.new("paint", 'BYTE_COLOR', 'CORNER')
    paint.data.foreach_set("color", np.tile([0.8, 0.5, 0.2, 1.0], len(mesh.loops)).astype(np.float32))
    mesh.color_attributes.new("mask", 'FLOAT_COLOR', 'POINT')
    mesh.color_attributes.active_color_name = "paint"
    mesh.color_attributes.default_color_name = "paint"
    mesh.attributes.active = mesh.attributes["temperature"]
    return obj


def rigged(obj, target_faces=300):
    api.build(obj, target_faces=target_faces)
    api.add_anchor(obj, np.flatnonzero(band(obj, 0.0, 0.15)))
    handle = api.add_handle(obj, np.flatnonzero(band(obj, 0.85, 1.0)))
    activate(obj)
    return handle


def bend(handle, x=0.5, turn=0.5):
    handle.location.x += x
    handle.rotation_euler.y += turn
    bpy.context.view_layer.update()


def colors_state(mesh):
    """What the artist sees of a mesh's attributes: names (in order), active color, render
    color, active attribute."""
    colors = mesh.color_attributes
    active = mesh.attributes.active
    return ([a.name for a in mesh.attributes], colors.active_color_name, colors.default_color_name,
            active.name if active is not None else "")


def views():
    """{(screen, area index, space index): (shading type, coloring)} of every 3D View of the file
    (headless Blender keeps the startup file's screens: real 3D View spaces, only not drawn)."""
    return {(screen.name, a, s): (space.shading.type, space.shading.color_type)
            for screen in bpy.data.screens for a, area in enumerate(screen.areas)
            for s, space in enumerate(area.spaces) if space.type == 'VIEW_3D'}


def stretch_values(mesh):
    return mesh_io.read_point_floats(mesh, mesh_io.STRETCH)


def test_build_and_steps_add_nothing_until_shown_and_api_stretch_needs_no_attribute(scene):
    obj = painted_sphere()
    before = colors_state(obj.data)
    handle = rigged(obj)
    assert colors_state(obj.data) == before                        # Build added nothing
    assert np.array_equal(api.stretch(obj), np.zeros(len(obj.data.vertices), dtype=np.float32))
    bend(handle)
    api.deform(obj)
    assert colors_state(obj.data) == before                        # nor did a step that stays
    stretch = api.stretch(obj)
    proxy = api.proxy_of(obj)
    expected = SkinStretch(binding.open_binding(obj).surface)(mesh_io.read_positions(proxy.data))
    assert np.array_equal(stretch, expected) and stretch.max() > 1e-3
    api.show_stretch(obj)
    assert np.array_equal(stretch_values(obj.data), stretch)       # shown: the same figures
    bend(handle, x=0.3)
    api.deform(obj)
    assert np.array_equal(stretch_values(obj.data), api.stretch(obj))  # every step that stays paints anew
    assert not np.array_equal(api.stretch(obj), stretch)
    api.show_stretch(obj, False)
    assert colors_state(obj.data) == before and mesh_io.STRETCH_RECORD not in obj.data
    api.deform(obj)
    assert colors_state(obj.data) == before


def test_an_earlier_versions_stretch_attribute_goes_with_the_next_step(scene):
    obj = quad_sphere()
    handle = rigged(obj)
    mesh_io.write_point_floats(obj.data, mesh_io.STRETCH, np.full(len(obj.data.vertices), 0.3, dtype=np.float32))
    bend(handle)
    api.deform(obj)
    assert mesh_io.STRETCH not in obj.data.attributes


def test_hiding_gives_the_artists_own_active_and_render_colors_back(scene):
    obj = painted_sphere()
    rigged(obj)
    obj.data.color_attributes.active_color_name = "mask"          # not the first: no fallback finds it
    before = colors_state(obj.data)
    api.show_stretch(obj)
    colors = obj.data.color_attributes
    assert colors.active_color_name == mesh_io.STRETCH_COLORS      # what Attribute coloring shows
    assert colors.default_color_name == "paint"                    # the render color stays theirs
    assert api.stretch_shown(obj)
    api.show_stretch(obj, False)
    assert colors_state(obj.data) == before and not api.stretch_shown(obj)
    # A mesh without colors of its own gets none left behind.
    plain = quad_sphere("plain")
    rigged(plain)
    before = colors_state(plain.data)
    api.show_stretch(plain)
    api.show_stretch(plain, False)
    assert colors_state(plain.data) == before


def test_show_stretch_button_colours_every_solid_view_by_attribute_and_gives_each_view_back(scene):
    """Item 6 (TypeError: 'ATTRIBUTE' is no coloring; Attribute is 'VERTEX') and item 13's views."""
    obj = painted_sphere()
    rigged(obj)
    before = views()
    solid = [key for key, (kind, _) in before.items() if kind == 'SOLID']
    other = [key for key, (kind, _) in before.items() if kind != 'SOLID']
    assert solid and other, before                                 # the startup file's workspaces
    screens = {screen.name: screen for screen in bpy.data.screens}

    def shading(key):
        return screens[key[0]].areas[key[1]].spaces[key[2]].shading

    shading(solid[0]).color_type = 'VERTEX'                        # one set to Attribute by hand before
    before = views()
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert obj.data.color_attributes.active_color_name == mesh_io.STRETCH_COLORS
    shown = views()
    assert all(shown[key] == ('SOLID', 'VERTEX') for key in solid)
    assert all(shown[key] == before[key] for key in other)         # Material Preview and the like untouched
    shading(other[0]).type = 'SOLID'                               # the artist looks at another view ...
    shading(other[0]).color_type = 'VERTEX'                        # ... by Attribute, while it is shown
    shading(other[0]).type = before[other[0]][0]
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert views() == before                                       # every view as it was
    assert obj.data.color_attributes.active_color_name == "paint"
    assert not any(screen.get("_skin_detach_stretch_shading") for screen in bpy.data.screens)


def test_views_stay_on_attribute_while_another_mesh_still_shows_its_stretch(scene):
    first, second = painted_sphere(), quad_sphere("second")
    rigged(first)
    rigged(second)
    before = views()
    for obj in (first, second):
        activate(obj)
        assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    activate(first)
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert all(v == ('SOLID', 'VERTEX') for v in views().values() if v[0] == 'SOLID')
    activate(second)
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert views() == before


def test_show_stretch_in_edit_mode_shows_and_hides_and_stays_in_edit_mode(scene):
    """Item 12: the mesh's data is empty in Edit Mode (foreach_get length mismatch)."""
    obj = painted_sphere()
    handle = rigged(obj)
    bend(handle)
    api.deform(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.object.mode_set(mode='OBJECT')                        # (Edit Mode itself reorders Blender's own attributes)
    before = colors_state(obj.data)
    expected = api.stretch(obj)
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert obj.mode == 'EDIT'
    bpy.ops.object.mode_set(mode='OBJECT')
    assert np.array_equal(stretch_values(obj.data), expected)
    assert obj.data.color_attributes.active_color_name == mesh_io.STRETCH_COLORS
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert obj.mode == 'EDIT'
    bpy.ops.object.mode_set(mode='OBJECT')
    assert colors_state(obj.data) == before


def test_clear_skin_removes_the_stretch_map_and_gives_colors_and_views_back(scene):
    """Item 8."""
    obj = painted_sphere()
    handle = rigged(obj)
    bend(handle)
    api.deform(obj)
    before, shading = colors_state(obj.data), views()
    assert bpy.ops.skin_detach.show_stretch() == {'FINISHED'}
    assert bpy.ops.skin_detach.clear() == {'FINISHED'}
    assert not api.is_bound(obj)
    assert colors_state(obj.data) == before and mesh_io.STRETCH_RECORD not in obj.data
    assert views() == shading


def animated_rig(uvs=True):
    obj = painted_sphere(uvs)
    handle = rigged(obj)
    rest = handle.location.copy()
    for frame, offset, turn in ((1, 0.1, 0.0), (3, 0.6, 0.7)):
        handle.location = rest + type(rest)((offset, 0.0, 0.0))
        handle.rotation_euler.y = turn
        handle.keyframe_insert("location", frame=frame)
        handle.keyframe_insert("rotation_euler", frame=frame)
    return obj, handle


def live_pose(obj, frame):
    """The pose of ``frame`` solved and shown (the artist scrubbed there)."""
    bpy.context.scene.frame_set(frame)
    api.deform(obj)


def own_stretch_shown(obj, frames=(1, 3)):
    """Each frame's own stretch (api.stretch of its live pose), then the stretch shown."""
    own = {}
    for frame in frames:
        live_pose(obj, frame)
        own[frame] = api.stretch(obj)
    api.show_stretch(obj)
    return own


def test_baked_objects_carry_each_frames_own_stretch_whatever_pose_is_shown(scene):
    """Item 7, OBJECTS: default (the stretch shown) and True: each frame's own; False: none."""
    obj, _ = animated_rig()
    own = own_stretch_shown(obj)
    baked = {}
    for shown_at in (3, 1):
        live_pose(obj, shown_at)
        mesh_before = (stretch_values(obj.data).copy(), colors_state(obj.data))
        names = {r["frame"]: r["output"] for r in api.bake(obj, [1, 3], into=api.OBJECTS)}
        assert (stretch_values(obj.data), colors_state(obj.data))[1] == mesh_before[1]
        assert np.array_equal(stretch_values(obj.data), mesh_before[0])   # the mesh's own map as it was
        baked[shown_at] = {f: stretch_values(bpy.data.objects[n].data).copy() for f, n in names.items()}
        for name in names.values():
            mesh = bpy.data.objects[name].data
            assert mesh.color_attributes.active_color_name == mesh_io.STRETCH_COLORS
    for frame in (1, 3):
        assert np.array_equal(baked[3][frame], baked[1][frame])   # not the pose shown when it started
        assert np.abs(baked[3][frame] - own[frame]).max() < 1e-4 * max(own[3].max(), 1e-3)
    assert own[3].max() > 4 * own[1].max()
    names = [r["output"] for r in api.bake(obj, [1, 3], into=api.OBJECTS, stretch=False)]
    for name in names:                                            # a re-run without: none left on them
        mesh = bpy.data.objects[name].data
        assert mesh_io.STRETCH not in mesh.attributes and not mesh_io.stretch_shown(mesh)
        assert mesh.color_attributes.active_color_name == "paint"
    api.show_stretch(obj, False)
    before = colors_state(obj.data)
    names = [r["output"] for r in api.bake(obj, [3], into=api.OBJECTS, stretch=True)]
    assert np.abs(stretch_values(bpy.data.objects[names[0]].data) - own[3]).max() < 1e-4 * own[3].max()
    assert colors_state(obj.data) == before                        # the mesh itself still shows nothing


def ply_vertices(path):
    """The vertex table of a binary little-endian PLY file as a numpy structured array, and its header."""
    data = open(path, "rb").read()
    head, body = data.split(b"end_header\n", 1)
    header = head.decode()
    kinds = {"float": "<f4", "double": "<f8", "uchar": "u1", "char": "i1", "int": "<i4", "uint": "<u4",
             "short": "<i2", "ushort": "<u2"}
    fields, count, inside = [], 0, False
    for line in header.splitlines():
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count, inside = int(words[2]), True
        elif words[:1] == ["element"]:
            inside = False
        elif inside and words[:1] == ["property"]:
            fields.append((words[2], kinds[words[1]]))
    return np.frombuffer(body, dtype=np.dtype(fields), count=count), header


def test_ply_bakes_carry_each_frames_own_stretch_or_none_and_no_byte_depends_on_the_live_pose(scene, tmp_path):
    """Item 7, FILES (.ply)."""
    obj, _ = animated_rig(uvs=False)                              # no UV seams: one PLY vertex per vertex
    own = own_stretch_shown(obj)
    files = {}
    for shown_at in (3, 1):
        live_pose(obj, shown_at)
        before = (stretch_values(obj.data).copy(), colors_state(obj.data))
        records = api.bake(obj, [1, 3], into=api.FILES, path=str(tmp_path / f"live{shown_at}" / "s_####.ply"))
        files[shown_at] = {r["frame"]: open(r["output"], "rb").read() for r in records}
        assert np.array_equal(stretch_values(obj.data), before[0]) and colors_state(obj.data) == before[1]
    assert files[3] == files[1]                                   # a frame's bytes: its own pose only
    for frame in (1, 3):
        table, header = ply_vertices(tmp_path / "live1" / f"s_{frame:04d}.ply")
        assert len(table) == len(obj.data.vertices)
        assert np.abs(table[mesh_io.STRETCH] - own[frame]).max() < 1e-4 * own[3].max()
        share = np.clip(own[frame] / mesh_io.STRETCH_FULL, 0, 1).astype(np.float64)
        srgb = np.where(share <= 0.0031308, 12.92 * share, 1.055 * share ** (1 / 2.4) - 0.055)
        assert np.abs(table["red"] - 255 * srgb).max() <= 1.01    # its colours (sRGB bytes) are its own too
    records = api.bake(obj, [3], into=api.FILES, path=str(tmp_path / "none" / "s_####.ply"), stretch=False)
    table, header = ply_vertices(records[0]["output"])
    assert mesh_io.STRETCH not in header
    paint = np.array([0.8, 0.5, 0.2]) ** (1 / 2.4) * 1.055 - 0.055   # the artist's own active color instead (sRGB)
    rgb = np.stack([table["red"], table["green"], table["blue"]], axis=1).astype(np.float64)
    assert np.abs(rgb - 255 * paint).max() <= 2.0          # (stored as bytes, exported as bytes)
    assert api.stretch_shown(obj) and np.array_equal(stretch_values(obj.data), api.stretch(obj))


def test_bake_stretch_option_is_checked_and_the_command_line_passes_it(scene):
    obj, _ = animated_rig()
    with pytest.raises(SkinDetachError, match="stretch: expected False or None for SHAPE_KEYS"):
        api.bake(obj, [1], into=api.SHAPE_KEYS, stretch=True)
    with pytest.raises(SkinDetachError, match="stretch: expected True, False or None"):
        api.bake(obj, [1], into=api.OBJECTS, stretch="yes")
    assert bake_cli.parse_args(["--output", "o.ply"]).stretch is None
    assert bake_cli.parse_args(["--output", "o.ply", "--stretch"]).stretch is True
    assert bake_cli.parse_args(["--output", "o.ply", "--no-stretch"]).stretch is False


def test_the_colours_are_blue_to_red_in_row_blocks_and_a_kept_buffer_takes_the_next_stretch_whole():
    n = 250_000  # above the threads' row blocks
    stretch = np.linspace(-0.1, 0.5, n).astype(np.float32)
    colours = mesh_io.stretch_colors(stretch)
    red = np.clip(stretch / mesh_io.STRETCH_FULL, 0.0, 1.0)
    assert np.array_equal(colours[:, 0], red.astype(np.float32))
    assert np.array_equal(colours[:, 2], (np.float32(1.0) - red).astype(np.float32))
    assert (colours[:, 1] == np.float32(0.15)).all() and (colours[:, 3] == 1.0).all()
    first = mesh_io.paint_stretch(stretch).copy()
    again = mesh_io.paint_stretch(stretch[::-1].copy())  # the same buffer painted over
    assert np.array_equal(first, colours.ravel())
    assert np.array_equal(again, colours[::-1].ravel())


def test_hiding_the_stretch_lets_the_painted_buffer_go():
    obj = painted_sphere()
    rigged(obj)
    api.show_stretch(obj)
    assert mesh_io._PAINT[0] is not None and mesh_io._PAINT[0].shape == (len(obj.data.vertices), 4)
    api.show_stretch(obj, False)
    assert mesh_io._PAINT[0] is None
