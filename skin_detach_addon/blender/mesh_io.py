"""Positions and topology of a Blender mesh as numpy arrays, and the one place that writes them.

Arrays: ``positions`` (n, 3) float32 indexed by vertex index (the mesh's own order);
``triangles`` (t, 3) int32 vertex indices of the mesh's loop triangles (quads and ngons are
triangulated here only; the mesh keeps its polygons).
"""

import zlib

import numpy as np

from ..core import threads
from ..core.errors import SkinDetachError


def read_positions(mesh):
    """(n, 3) float32 copy of the vertex positions (the Basis key's when shape keys exist), read
    through a throw-away copy of the mesh (see :func:`read_shared`: an undo step keeps no copy of
    positions that were only read)."""
    out = np.empty((len(mesh.vertices), 3), dtype=np.float32)
    if mesh.shape_keys is not None:
        mesh.shape_keys.reference_key.data.foreach_get("co", out.ravel())
    elif out.size:
        read_shared(mesh, lambda copy: copy.attributes["position"].data.foreach_get("vector", out.ravel()))
    return out


def read_triangles(mesh, positions=None):
    """(t, 3) int32 loop triangles of ``mesh`` (Blender's own index type: half the memory of
    int64 on millions of faces; the core makes the int64 copy it works on and frees it). A mesh of
    triangles only has its corners read (through a throw-away copy, see :func:`read_shared`),
    and its :func:`mesh_fingerprint` is kept from the same read (at 10M vertices each read of
    the corners held the main thread 0.4-0.6 s).

    Blender splits a quad or an ngon into triangles by its shape (a quad folded across its first
    diagonal is split along the other), so a posed mesh's loop triangles are not its rest's. The
    skin is bound over the triangles of the shape it was built from: ``positions`` (n, 3), the
    rest positions, gives the loop triangles Blender makes of the mesh in that shape (read from a
    throw-away copy holding them), the same whatever pose the mesh is in now. Without it, the
    mesh's current shape is split."""
    counts = _counts(mesh)
    if triangles_only(mesh):
        out = np.empty(counts[2], dtype=np.int32)
        if out.size:
            read_shared(mesh, lambda copy: copy.attributes[".corner_vert"].data.foreach_get("value", out))
        if watching():
            _FINGERPRINTS.setdefault(mesh.as_pointer(), (counts, _fingerprint_of(counts, out)))
        return out.reshape(-1, 3)
    if positions is None:
        return _loop_triangles(mesh)
    shape = np.ascontiguousarray(positions, dtype=np.float32)
    if shape.shape != (counts[0], 3):
        raise SkinDetachError(f"positions: expected ({counts[0]}, 3) rest positions of mesh {mesh.name!r}, "
                              f"got {shape.shape}")

    def split(copy):
        copy.attributes["position"].data.foreach_set("vector", shape.ravel())
        copy.vertices[0].co = copy.vertices[0].co  # tags the copy: its split is made anew, not shared
        return _loop_triangles(copy)
    return read_shared(mesh, split)


def triangles_only(mesh):
    """Whether every face of ``mesh`` is a triangle (each face has at least 3 corners): its loop
    triangles are its faces, whatever its shape."""
    return len(mesh.loops) == 3 * len(mesh.polygons)


def _loop_triangles(mesh):
    """(t, 3) int32 loop triangles of ``mesh`` as Blender splits its current shape."""
    mesh.calc_loop_triangles()
    out = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", out)
    return out.reshape(-1, 3)


def group_members(obj, name):
    """(k,) int64 vertex indices of ``obj``'s vertex group ``name`` with a weight above zero."""
    group = obj.vertex_groups.get(name) if isinstance(name, str) else None
    if group is None:
        raise SkinDetachError(f"group: expected a vertex group of {obj.name!r} "
                              f"({', '.join(g.name for g in obj.vertex_groups) or 'it has none'}), got {name!r}")
    index = group.index
    members = [v.index for v in obj.data.vertices for g in v.groups if g.group == index and g.weight > 0.0]
    if not members:
        raise SkinDetachError(f"group: expected vertices with a weight above zero in {name!r}, it has none")
    return np.asarray(members, dtype=np.int64)


#: Mesh pointer -> (vertex, face and corner counts, the digest) of the fingerprints made since
#: Blender last reported a change of that mesh's geometry (see :func:`mesh_fingerprint`).
_FINGERPRINTS = {}
#: Mesh pointer -> its counts, for meshes whose positions Skin Detach wrote since Blender's last
#: geometry update: the update that reports that write keeps the mesh's fingerprint (positions
#: are not topology; at 10M reading the corners again cost api.deform 0.6 s after every step).
_POSITIONS_ONLY = {}


def _counts(mesh):
    return len(mesh.vertices), len(mesh.polygons), len(mesh.loops)


def mesh_fingerprint(mesh):
    """Digest of the vertex, face and corner counts and every corner's vertex: changes when the
    topology or the vertex order changes, not when positions do. (Face boundaries are read
    through the counts only: Blender's per-face collection is ten times slower to read than
    the whole corner array, and this runs on every solve.) The corners are read through a
    throw-away copy of the mesh (see :func:`read_shared`). A mesh's digest is kept until Blender's
    dependency graph reports its geometry changed (Edit Mode, sculpt, a script's update), an undo
    or redo, or a file load (:func:`_forget_fingerprints`; not for Skin Detach's own writes of
    positions), or its counts change: at 10M vertices
    each digest read 59M corners (0.2-0.5 s), and every step opens the binding. Kept only while
    the add-on's handlers watch for those changes (:func:`watching`: it is registered); a script
    that uses the add-on unregistered has every digest read anew."""
    counts = _counts(mesh)
    known = _FINGERPRINTS.get(mesh.as_pointer())
    if known is not None and known[0] == counts:
        return known[1]
    corners = np.empty(counts[2], dtype=np.int32)
    if corners.size:
        read_shared(mesh, lambda copy: copy.attributes[".corner_vert"].data.foreach_get("value", corners))
    digest = _fingerprint_of(counts, corners)
    if watching():
        _FINGERPRINTS[mesh.as_pointer()] = (counts, digest)
    return digest


def forget_fingerprint(mesh):
    """Drop ``mesh``'s kept fingerprint: the next :func:`mesh_fingerprint` reads its corners anew."""
    _FINGERPRINTS.pop(mesh.as_pointer(), None)
    _POSITIONS_ONLY.pop(mesh.as_pointer(), None)


def _fingerprint_of(counts, corners):
    """:func:`mesh_fingerprint` of a mesh of ``counts`` (vertices, faces, corners) whose corners'
    vertices are ``corners``."""
    return _digest(counts[0], np.array(counts[1:], dtype=np.int64), corners)


def watching():
    """Whether Blender calls :func:`_forget_fingerprints` when a mesh's geometry may have changed
    (the add-on's register installs it, see :data:`HANDLERS`): only then are fingerprints kept."""
    import bpy
    return _forget_fingerprints in bpy.app.handlers.depsgraph_update_post


def forget_all():
    """Drop every kept fingerprint and the stretch colors' buffer (the add-on's unregister leaves
    nothing behind)."""
    _FINGERPRINTS.clear()
    _POSITIONS_ONLY.clear()
    _PAINT[0] = None


def _forget_fingerprints(*args):
    """A handler: drop the kept fingerprint of every mesh whose geometry the dependency graph
    update reports changed (every one after an undo, a redo or a file load), unless the change
    was Skin Detach's write of its positions (:func:`_refresh`) and its counts are the same."""
    depsgraph = args[1] if len(args) > 1 else None
    if depsgraph is None or not hasattr(depsgraph, "updates"):
        _FINGERPRINTS.clear()
        _POSITIONS_ONLY.clear()
        return
    for update in depsgraph.updates:
        if update.is_updated_geometry and isinstance(update.id, _mesh_type()):
            mesh = update.id.original
            pointer = mesh.as_pointer()
            if _POSITIONS_ONLY.pop(pointer, None) != _counts(mesh):
                _FINGERPRINTS.pop(pointer, None)


def _mesh_type():
    import bpy
    return bpy.types.Mesh


_forget_fingerprints._bpy_persistent = True  # kept across file loads (bpy.app.handlers.persistent)
#: (handler list of ``bpy.app.handlers``, function) pairs the add-on's register installs: kept
#: fingerprints are dropped when Blender may have changed a mesh's geometry.
HANDLERS = tuple((name, _forget_fingerprints) for name in ("depsgraph_update_post", "undo_post", "redo_post",
                                                           "load_post"))


def read_shared(mesh, read):
    """``read(copy)`` on a throw-away copy of ``mesh`` that shares its arrays. Reading a mesh's
    array through Blender's Python API makes it the mesh's own first (a copy when it is shared,
    as every array is with the undo step pushed last): a read of an array never written after it
    left one more copy in every undo step (at 300,000 vertices a confirm's step grew the process
    by 12 MB where Blender's own rewrite of the positions grew it by 3.5-5 MB). The copy's array
    is made its own instead, and goes with the copy."""
    import bpy
    copy = mesh.copy()
    try:
        return read(copy)
    finally:
        bpy.data.meshes.remove(copy)


def positions_digest(positions):
    """Digest of a (n, 3) float32 position array, to notice edits made outside Skin Detach."""
    return _digest(positions.shape[0], np.ascontiguousarray(positions, dtype=np.float32))


def _digest(count, *arrays):
    """Hex CRC-32 of ``count`` and the raw bytes of ``arrays``: it only has to notice edits, not
    resist forgery, and it runs on every solve (about 1 ms per million vertices)."""
    crc = zlib.crc32(np.int64(count).tobytes())
    for array in arrays:
        crc = zlib.crc32(memoryview(np.ascontiguousarray(array)).cast("B"), crc)
    return f"{count:x}-{crc:08x}"


def check_positions(name, positions):
    """Raise :class:`SkinDetachError` unless ``positions`` (n, 3) are all finite (one pass over the
    buffer; the rows are looked at only to name a bad one)."""
    if np.isfinite(positions).all():
        return
    bad = ~np.isfinite(positions).all(axis=1)
    if bad.any():
        raise SkinDetachError(f"{name}: expected finite vertex positions, got {int(bad.sum())} vertices with NaN "
                              f"or infinite coordinates (first: {int(np.flatnonzero(bad)[0])})")


def write_positions(mesh, positions, checked=False):
    """Write (n, 3) ``positions`` into ``mesh``: the position attribute, and with shape keys the
    Basis, every other key moved by the same offset so that its offset to the Basis stays.
    Refuses (writing nothing) rows that are not finite, unless the caller ``checked`` them with
    :func:`check_positions` already (a drag move checks each array once, all before any write)."""
    buffer = np.ascontiguousarray(positions, dtype=np.float32).ravel()
    if buffer.size != 3 * len(mesh.vertices):
        raise SkinDetachError(f"positions: expected {len(mesh.vertices)} rows for mesh {mesh.name!r}, "
                              f"got {buffer.size // 3}")
    if not checked:
        check_positions(f"positions for mesh {mesh.name!r}", buffer.reshape(-1, 3))
    keys = mesh.shape_keys
    if keys is not None:
        basis = keys.reference_key
        old = np.empty_like(buffer)
        basis.data.foreach_get("co", old)
        shift = buffer.astype(np.float64) - old
        other = np.empty_like(buffer)
        for block in keys.key_blocks:
            if block == basis:
                continue
            block.data.foreach_get("co", other)
            block.data.foreach_set("co", (other + shift).astype(np.float32))
        basis.data.foreach_set("co", buffer)
    mesh.attributes["position"].data.foreach_set("vector", buffer)
    _refresh(mesh)


#: The POINT FLOAT attribute the detail's stretch against its rest is written to while it is shown.
STRETCH = "skin_detach_stretch"
#: The color attribute "Show Stretch" paints the stretch into (blue 0, red at STRETCH_FULL or more).
STRETCH_COLORS = "skin_detach_stretch_color"
STRETCH_FULL = 0.25
#: The mesh property that records, while the stretch is shown, what :func:`show_stretch` changed:
#: the names of the artist's active color, render color and active attribute ("" for none).
STRETCH_RECORD = "_skin_detach_stretch_shown"


def write_point_floats(mesh, name, values):
    """Write (n,) ``values`` into the POINT FLOAT attribute ``name`` of ``mesh``, made (or
    remade, if one of another type or domain has the name) when needed."""
    buffer = np.ascontiguousarray(values, dtype=np.float32)
    if buffer.shape != (len(mesh.vertices),):
        raise SkinDetachError(f"values: expected {len(mesh.vertices)} for mesh {mesh.name!r}, got {buffer.shape}")
    attribute = mesh.attributes.get(name)
    if attribute is not None and (attribute.data_type != 'FLOAT' or attribute.domain != 'POINT'):
        mesh.attributes.remove(attribute)
        attribute = None
    if attribute is None:
        attribute = mesh.attributes.new(name, 'FLOAT', 'POINT')
    attribute.data.foreach_set("value", buffer)


def stretch_colors(stretch, out=None):
    """(n, 4) float32 colours of (n,) ``stretch``: blue at 0, red at :data:`STRETCH_FULL` or more;
    into ``out`` (n, 4) float32 when given, in row blocks on the core's threads."""
    stretch = np.asarray(stretch, dtype=np.float32)
    n = stretch.shape[0]
    out = np.empty((n, 4), dtype=np.float32) if out is None else out

    def paint(rows):
        part, values = out[rows[0]:rows[1]], stretch[rows[0]:rows[1]]
        part[:, 1], part[:, 3] = 0.15, 1.0  # columns written in place: a stack of four cost a 3.2M confirm 0.3 s
        np.multiply(values, np.float32(1.0 / STRETCH_FULL), out=part[:, 0])
        np.clip(part[:, 0], 0.0, 1.0, out=part[:, 0])
        np.subtract(np.float32(1.0), part[:, 0], out=part[:, 2])
    threads.map_blocks(paint, threads.row_blocks(n))
    return out


#: The (n, 4) float32 buffer the last stretch was painted in, painted over by the next one of as
#: many vertices: a new one is memory the system hands out page by page (0.2 s of a 10M
#: confirm). Let go when the stretch is hidden and when the add-on is unregistered.
_PAINT = [None]


def paint_stretch(stretch):
    """(4 n,) float32 :func:`stretch_colors` of (n,) ``stretch`` flattened for ``foreach_set``, in
    the kept buffer (valid until the next call). Numpy only: a confirm paints on a pool thread
    while it writes the positions (:func:`write_stretch` takes the result)."""
    buffer = _PAINT[0]
    if buffer is None or buffer.shape[0] != stretch.shape[0]:
        _PAINT[0] = buffer = None  # the old one goes first
        buffer = _PAINT[0] = np.empty((stretch.shape[0], 4), dtype=np.float32)
    return stretch_colors(np.asarray(stretch, dtype=np.float32), out=buffer).ravel()


def stretch_shown(mesh):
    """``mesh`` shows its stretch: it has the :data:`STRETCH_COLORS` attribute (see :func:`show_stretch`)."""
    return mesh.color_attributes.get(STRETCH_COLORS) is not None


def show_stretch(mesh, stretch):
    """Show (n,) ``stretch`` on ``mesh`` (Object Mode): the first time, record the artist's active
    color, render color and active attribute in :data:`STRETCH_RECORD` and make the
    :data:`STRETCH_COLORS` attribute the active color; then (every time) write ``stretch`` into
    :data:`STRETCH` and its colours into :data:`STRETCH_COLORS` (see :func:`write_stretch`).
    Checked before anything is added; :func:`hide_stretch` gives everything back."""
    buffer = _checked_stretch(mesh, stretch)
    if stretch_shown(mesh):
        write_stretch(mesh, buffer)
        return
    colors = mesh.color_attributes
    active = mesh.attributes.active
    record = {"active_color": colors.active_color_name, "render_color": colors.default_color_name,
              "active_attribute": active.name if active is not None else ""}
    write_point_floats(mesh, STRETCH, buffer)
    attribute = colors.new(STRETCH_COLORS, 'FLOAT_COLOR', 'POINT')
    attribute.data.foreach_set("color", paint_stretch(buffer))
    colors.active_color = attribute
    colors.default_color_name = record["render_color"]  # the render color stays the artist's
    _set_active_attribute(mesh, record["active_attribute"])
    mesh[STRETCH_RECORD] = record


def write_stretch(mesh, stretch, painted=None):
    """After a step that stays: while ``mesh`` shows its stretch, write (n,) ``stretch`` into
    :data:`STRETCH` and paint it into :data:`STRETCH_COLORS` (values only: which color is active
    stays the artist's choice). While it is not shown (``stretch`` may be None) nothing is
    written, and a :data:`STRETCH` attribute left by an earlier version (which wrote it on every
    step) is removed: it would hold an old pose's figures. ``painted``: :func:`paint_stretch` of
    ``stretch``, if the caller made it already."""
    if not stretch_shown(mesh):
        _remove_attribute(mesh, STRETCH)
        return
    buffer = _checked_stretch(mesh, stretch)
    write_point_floats(mesh, STRETCH, buffer)
    attribute = mesh.color_attributes[STRETCH_COLORS]
    if attribute.domain != 'POINT' or attribute.data_type != 'FLOAT_COLOR':  # one the artist made: make ours
        name = mesh.color_attributes.active_color_name
        mesh.color_attributes.remove(attribute)
        attribute = mesh.color_attributes.new(STRETCH_COLORS, 'FLOAT_COLOR', 'POINT')
        if name == STRETCH_COLORS:
            mesh.color_attributes.active_color = attribute
    if painted is None or np.shape(painted) != (4 * buffer.shape[0],):
        painted = paint_stretch(buffer)
    attribute.data.foreach_set("color", painted)


def hide_stretch(mesh):
    """Remove what :func:`show_stretch` added (the :data:`STRETCH` and :data:`STRETCH_COLORS`
    attributes, the record) and make the recorded active color, render color and active
    attribute the artist's again (those that still exist). Also removes a :data:`STRETCH`
    attribute an earlier version left. Does nothing to a mesh that has none of them."""
    record = mesh.get(STRETCH_RECORD) if stretch_shown(mesh) else None  # (one an undo left behind: dropped)
    record = {key: record.get(key, "") for key in ("active_color", "render_color", "active_attribute")} \
        if hasattr(record, "get") else None
    _remove_attribute(mesh, STRETCH)
    _PAINT[0] = None
    attribute = mesh.color_attributes.get(STRETCH_COLORS)
    if attribute is not None:
        mesh.color_attributes.remove(attribute)
    if STRETCH_RECORD in mesh:
        del mesh[STRETCH_RECORD]
    if record is None:
        return
    colors = mesh.color_attributes
    for field, name in (("active_color_name", record["active_color"]), ("default_color_name", record["render_color"])):
        if isinstance(name, str) and (name == "" or colors.get(name) is not None):
            setattr(colors, field, name)
    _set_active_attribute(mesh, record["active_attribute"])


def _checked_stretch(mesh, stretch):
    buffer = np.ascontiguousarray(stretch, dtype=np.float32)
    if buffer.shape != (len(mesh.vertices),):
        raise SkinDetachError(f"stretch: expected {len(mesh.vertices)} values for mesh {mesh.name!r}, got "
                              f"{buffer.shape}")
    if not np.isfinite(buffer).all():
        raise SkinDetachError(f"stretch: expected finite values for mesh {mesh.name!r}, got NaN or inf")
    return buffer


def _remove_attribute(mesh, name):
    attribute = mesh.attributes.get(name)
    if attribute is not None:
        mesh.attributes.remove(attribute)


def _set_active_attribute(mesh, name):
    """Make the attribute ``name`` the active one ("": none), if it exists."""
    if name == "":
        mesh.attributes.active_index = -1
    elif isinstance(name, str) and mesh.attributes.get(name) is not None:
        mesh.attributes.active = mesh.attributes[name]


def read_point_floats(mesh, name):
    """(n,) float32 values of the POINT FLOAT attribute ``name`` of ``mesh``, or None."""
    attribute = mesh.attributes.get(name)
    if attribute is None or attribute.data_type != 'FLOAT' or attribute.domain != 'POINT':
        return None
    values = np.empty(len(mesh.vertices), dtype=np.float32)
    attribute.data.foreach_get("value", values)
    return values


def _refresh(mesh):
    """Normals and bounds are stale after a bulk attribute write: touch one vertex through RNA
    (which tags the mesh) and update. The geometry update Blender then reports is this write's,
    positions only: the mesh's kept fingerprint stays (:data:`_POSITIONS_ONLY`)."""
    if len(mesh.vertices):
        mesh.vertices[0].co = mesh.vertices[0].co
    mesh.update()
    if watching():
        _POSITIONS_ONLY[mesh.as_pointer()] = _counts(mesh)


def snapshot(mesh):
    """Exact copy of what a step may change: the positions, every shape key (what
    :func:`write_positions` writes), the :data:`STRETCH` attribute (None: there was none) and
    whether the stretch was shown (:func:`stretch_shown`: its colours follow from its values)."""
    keys = mesh.shape_keys
    blocks = {}
    if keys is not None:
        for block in keys.key_blocks:
            data = np.empty(3 * len(mesh.vertices), dtype=np.float32)
            block.data.foreach_get("co", data)
            blocks[block.name] = data
    positions = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.attributes["position"].data.foreach_get("vector", positions)
    return positions, blocks, read_point_floats(mesh, STRETCH), stretch_shown(mesh)


def restore(mesh, saved):
    """Write back a :func:`snapshot`, bit for bit (a stretch shown or hidden since is hidden or
    shown again)."""
    positions, blocks, stretch, shown = saved
    if shown and stretch is not None:
        show_stretch(mesh, stretch)
    else:
        hide_stretch(mesh)
        if stretch is not None:  # an earlier version's, not shown
            write_point_floats(mesh, STRETCH, stretch)
    if mesh.shape_keys is not None:
        for block in mesh.shape_keys.key_blocks:
            if block.name in blocks:
                block.data.foreach_set("co", blocks[block.name])
    mesh.attributes["position"].data.foreach_set("vector", positions)
    _refresh(mesh)
