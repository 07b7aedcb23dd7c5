"""Scripting API: plain functions on a mesh object. The add-on's operators call these same
functions, so a script and a click do the same thing.

    from skin_detach_addon import api          # installed extension: from bl_ext.user_default.skin_detach_addon import api

    api.build(obj, target_faces=1000)          # bind obj (n vertices) to a proxy of ~1,000 faces
    api.add_anchor(obj, base_ids)              # (k,) vertex indices of obj held in place
    grip = api.add_handle(obj, top_ids)        # an empty that carries those vertices
    grip.location.x += 0.2                     # world space: its transform is its world matrix
    api.deform(obj)                            # solve from every handle, write obj's positions
    api.bake(obj, "1-250", into="FILES", path="out/mesh_####.obj")
    api.reset(obj); api.clear(obj)

Every function takes the bound mesh object (its proxy, one of its handles, or any object of a
rig of several objects are accepted and mean the same rig; so is a list whose first is its
owner) and raises :class:`SkinDetachError` with a message naming the argument,
the expected and the actual value; nothing is written when it raises.
"""

import numpy as np

from .blender import (background, baking, binding_cache, binding_figures, handle_symmetry, handles, mesh_io, preview_stand_in, rig_members,
                      skin_rig)
from .blender import binding as stored
from .blender.baking import FILES, OBJECTS, SHAPE_KEYS
from .blender.deformation import DRAG_TOL, SETTLE_TOL, Deformation
from .blender import drag_session
from .blender.drag_session import CANCELLED, FINISHED, RUNNING, DragSession, moved_matrix
from .blender.skin_rig import PREVIEW_ABOVE, BuildCancelled, BuildJob
from .core import threads
from .core.detached_surface.held_detail import held_proxy_vertices
from .core.detached_surface.symmetry import mirrored_ids
from .core.errors import SkinDetachError
from .core.validation import as_vertex_ids

__all__ = ["SkinDetachError", "build", "start_build", "finish_build", "BuildJob", "BuildCancelled", "add_handle", "add_anchor", "deform", "reset", "clear", "bake",
           "is_bound", "preview_stands_in", "handles_of", "mesh_of", "is_handle", "handle_kind", "handle_vertex_count", "proxy_of",
           "remove_handle", "handle_conflicts", "set_parts", "part_overrides", "is_rig_part", "preparing", "finish_preparing", "handle_group", "rest_positions", "figures", "bound_objects", "selected_vertices", "frame_list",
           "bake_file_path", "shutdown", "before_load", "handlers", "prepare_in_background", "check_output_file", "DragSession", "is_dragged", "moved_matrix", "mirror_twin",
           "handle_mirror", "members", "member_ranges", "orphan_owner", "clear_orphan", "before_save", "HANDLE", "ANCHOR", "SHAPE_KEYS", "OBJECTS", "FILES", "DRAG_TOL",
           "SETTLE_TOL", "PREVIEW_ABOVE", "RUNNING", "FINISHED", "CANCELLED"]

HANDLE, ANCHOR = handles.HANDLE, handles.ANCHOR


def _owner(obj):
    if isinstance(obj, (list, tuple)):  # a rig given as its objects: the first is its owner
        if not obj:
            raise SkinDetachError("obj: expected a mesh object or a non-empty list of them, got an empty list")
        obj = obj[0]
    owner = skin_rig.mesh_of(obj)
    if owner is None:
        raise SkinDetachError("obj: expected a mesh object, got None")
    return owner


def _bound(obj):
    owner = _owner(obj)
    if not stored.has_binding(owner):
        raise SkinDetachError(f"obj {owner.name!r}: expected a mesh bound by Skin Detach, it has no binding; "
                              f"call build() first")
    return owner


def build(obj, target_faces=1000, normal_test=True, progress=None, preview_above=PREVIEW_ABOVE):
    """Bind ``obj`` (a mesh object in Object Mode) to a proxy of about ``target_faces`` triangles
    and make the proxy object. ``obj`` may be a list of mesh objects posed as one (a character's
    body, eyes, belt...): ONE rig for all of them, owned by the first (it holds the binding and the
    proxy), its *members* the first then the others sorted by name (:func:`members`); vertex ids
    of such a rig are combined ids (:func:`member_ranges`). A single object that is an object of
    a rig of several rebuilds that whole rig; a list of one binds that object alone. Returns the build figures (dict: seconds per stage, proxy_faces,
    preview_vertices, case1/2/3 counts, handles_kept, ...). A previous binding is replaced:
    handles made from mesh vertices are kept (back at rest), those made from proxy vertices are
    removed. ``progress(fraction, stage)`` is called as the build goes.

    A mesh of more than ``preview_above`` vertices (None: never) also gets a preview: a hidden
    object of about 60,000 vertices bound to the same proxy, which :class:`DragSession` (and
    :func:`deform` with ``preview=True``) shows in place of the mesh while handles move.

    The same as :func:`start_build`, ``job.run(progress)`` and :func:`finish_build` in a row."""
    job = start_build(obj, target_faces, normal_test, preview_above)
    job.run(progress)
    return finish_build(job)


def start_build(obj, target_faces=1000, normal_test=True, preview_above=PREVIEW_ABOVE):
    """:func:`build` in parts, for a caller that keeps a window answering while the core works
    (the Build button): reads ``obj``'s mesh (main thread, writing nothing) and returns its
    :class:`BuildJob`. ``job.run(progress)`` runs the core's build on any thread (``job.start()``:
    on a thread of its own; ``job.done``, ``job.fraction``, ``job.stage`` tell how far it got;
    ``job.cancel()`` stops it at its next stage), then :func:`finish_build` writes every object
    on the main thread, or none. Where the preview stands in for the mesh, the pose it shows is
    what is bound (solved here, written into the mesh by :func:`finish_build`)."""
    if preview_above is not None and (isinstance(preview_above, bool) or not isinstance(preview_above, (int, np.integer))
                                      or preview_above < 0):
        raise SkinDetachError(f"preview_above: expected None or a vertex count >= 0, got {preview_above!r}")
    objs = _build_members(obj)
    obj = objs[0]
    for member in objs:
        if member.mode == 'EDIT' or member.data.is_editmode:
            raise SkinDetachError(f"obj {member.name!r}: expected Object Mode, its mesh is in Edit Mode")
    return BuildJob(obj, target_faces, normal_test, preview_above, _shown_pose(obj), members=objs)


def _build_members(obj):
    """The objects a build of ``obj`` binds, in the rig's order (the owner first, the others by
    name), checked: mesh objects, none twice, none bound by or a member of another rig."""
    if isinstance(obj, (list, tuple)):
        if not obj:
            raise SkinDetachError("obj: expected a mesh object or a non-empty list of them, got an empty list")
        for k, one in enumerate(obj):
            if one is None or getattr(one, "type", None) != 'MESH':
                raise SkinDetachError(f"obj[{k}]: expected a mesh object, got "
                                      f"{'None' if one is None else repr(getattr(one, 'name', one))}")
        objs = list(obj)
    else:
        owner = _owner(obj)
        objs = [owner] + [o for o in rig_members.objects(owner)[1:] if o is not None] \
            if stored.has_binding(owner) else [owner]
    for one in objs:
        skin_rig.check_mesh_object(one)
    if len({o.as_pointer() for o in objs}) != len(objs):
        raise SkinDetachError(f"obj: expected distinct mesh objects, got {[o.name for o in objs]} (one twice)")
    owner = objs[0]
    for one in objs:
        other = rig_members.owner_of(one)
        if other is not None and other != owner:
            raise SkinDetachError(f"obj {one.name!r}: expected a mesh of no other rig, it is an object of the rig of "
                                  f"{other.name!r}; Clear Skin of that rig first")
        if one != owner and stored.has_binding(one):
            raise SkinDetachError(f"obj {one.name!r}: expected a mesh of no other rig, it is bound itself; Clear Skin "
                                  f"of it first (or make it the owner: first in the list)")
    return rig_members.order(objs)


def finish_build(job):
    """Write what the :class:`BuildJob` ``job`` built (main thread, after ``job.run`` or once
    ``job.done``): the binding, the proxy and preview objects, the handles carried over, then
    prepares their layout (see :func:`prepare`); returns the build figures (see :func:`build`).
    Raises, writing nothing, when the build failed, was cancelled (:class:`BuildCancelled`) or
    the mesh was changed, deleted or put in Edit Mode since :func:`start_build` read it."""
    import bpy
    stats = job.finish()
    if stats["handles_kept"]:
        _prepare_after_change(bpy.data.objects[job.name])
    return stats


def set_parts(obj, vertex_ids, mode):
    """Decide the loose parts of ``obj`` (a mesh object, one of a rig of several objects too: its
    own vertex ids) holding ``vertex_ids`` (k,) whatever they touch: "ATTACH"
    makes each ride on the nearest part of larger area (however far), "DETACH" makes each free (its
    own proxy: it deforms on its own), "RULE" gives them back to the rule (a part that touches a
    part of at least twice its area rides on it; docs/addon.md). Stored on the object; the next
    :func:`build` uses it (a bound mesh: press Rebuild, or call build again). Returns how many
    parts were named."""
    if obj is None or obj.type != 'MESH' or is_rig_part(obj):
        obj = _owner(obj)  # a proxy or a preview: its mesh (an object of a rig is itself: its own ids)
    skin_rig.check_mesh_object(obj)
    stored.check_editable(obj)
    return skin_rig.set_parts(obj, vertex_ids, mode)


def part_overrides(obj):
    """(attach, detach): the vertex ids (k,) naming ``obj``'s parts made riders or free by
    :func:`set_parts`, None where there are none."""
    return skin_rig.part_overrides(_owner(obj))


def prepare(obj, preserve_volume=True):
    """Prepare the layout of ``obj``'s current handles and anchors (which proxy vertices and
    detail each holds): the factored solver, the rebuild of the mesh and of its preview, the
    symmetry checks. The first move and the first confirm of a layout then pay none of it (at
    3 million vertices, seconds); a rig of anchors only has nothing to drag and is not prepared.
    :func:`add_handle`, :func:`add_anchor`, :func:`remove_handle`
    and a Rebuild call it, and the add-on calls it for every bound mesh in idle time after a file
    is opened; a script that opens a file and drags may call it first. Nothing is written."""
    obj = _bound(obj)
    Deformation(obj, preserve_volume, require_unedited=False).prepare()


def preparing(obj):
    """(fraction done, stage) of the background job a large mesh's build left running (the
    full-detail rebuild: a drag shows the preview meanwhile and Add Handle does not wait for it; a
    confirm, Apply or bake does), or None when nothing is being prepared."""
    record = stored.cached(_bound(obj))
    return None if record is None else record.surface.preparing


def finish_preparing(obj):
    """Wait until what :func:`preparing` reports is done (or make it now when nothing is making
    it): the next full-detail rebuild then starts at once."""
    stored.open_binding(_bound(obj)).surface.finish_preparing()


def prepare_in_background(obj, preserve_volume=True):
    """Start :func:`prepare` of ``obj`` (and the making of its binding, after a file is opened) on
    a background thread; returns a :class:`.blender.background.Preparation` whose ``poll()``, called
    from a timer on the main thread, advances it and returns True once done (raising what failed),
    with ``fraction`` (0 to 1) and ``stage`` for a progress display. A step asked for meanwhile
    waits for it. The add-on does this for every bound mesh after a file is opened."""
    return background.begin(_bound(obj), preserve_volume)


def _prepare_after_change(obj):
    """:func:`prepare` after the rig changed; a rig that cannot be solved (its proxy edited, say)
    is left unprepared: the change itself stands, and the step that needs the rig says what is wrong."""
    try:
        prepare(obj)
    except SkinDetachError:
        pass


def add_handle(obj, vertex_ids=None, on_proxy=False, group=None, mirror=None):
    """A handle empty carrying ``vertex_ids`` (k,): vertex indices of ``obj``'s mesh (or of the
    proxy with ``on_proxy=True``), or the members of vertex group ``group`` (weight above zero).
    On a rig of several objects: combined ids (see :func:`member_ranges`) or a dict {object of
    the rig: its own vertex ids}; a group is the union of that group in every object that has it.
    Move, rotate or animate the empty, then :func:`deform`.

    ``mirror`` ("X", "Y" or "Z", the mesh's local axis, as Blender's Mesh Symmetry; None: the
    axis whose mesh symmetry toggle ``mesh.use_mirror_x/y/z`` is on, refused when two or three
    are; "": none): also make the mirrored twin from the vertices at the mirror images (refused,
    naming how many have none, when the mesh is not symmetric enough); moving either one moves
    both, mirrored. A selection that is its own mirror image makes one handle that keeps the rig
    symmetric. When every handle and anchor of a rig has a twin across one axis or is its own
    mirror image across it, the result is made exactly symmetric: across an axis asked for (its
    mesh toggle or a mirror flag) always, self-symmetric handles moving only symmetrically;
    across any other only while every handle moves symmetrically. Returns the handle made from
    ``vertex_ids``; its twin is in :func:`handles_of`."""
    return _add(obj, vertex_ids, handles.HANDLE, on_proxy, group, mirror)


def add_anchor(obj, vertex_ids=None, on_proxy=False, group=None, mirror=None):
    """An anchor empty holding ``vertex_ids`` (k,) (or vertex group ``group``) in place; indices,
    groups and ``mirror`` as in :func:`add_handle`."""
    return _add(obj, vertex_ids, handles.ANCHOR, on_proxy, group, mirror)


def _add(obj, vertex_ids, kind, on_proxy, group, mirror):
    import bpy
    obj = _bound(obj)
    binding = stored.open_binding(obj)
    surface = binding.surface
    if mirror not in (None, "", *handle_symmetry.AXES):
        raise SkinDetachError(f"mirror: expected None, 'X', 'Y' or 'Z', got {mirror!r}")
    if mirror is None and not on_proxy:  # the mesh's own symmetry setting (Edit Mode's X/Y/Z toggles)
        toggles = [axis for axis in handle_symmetry.AXES if getattr(obj.data, f"use_mirror_{axis.lower()}", False)]
        if len(toggles) > 1:
            raise SkinDetachError(f"mesh {obj.data.name!r}: expected at most one of its X/Y/Z mirror toggles on to make "
                                  f"mirror twins, got {' and '.join(toggles)} (a handle mirrors across one axis); turn "
                                  f"all but one off, or pass mirror='{toggles[0]}' (or '' for none)")
        mirror = toggles[0] if toggles else None
    if (vertex_ids is None) == (group is None):
        raise SkinDetachError("vertex_ids, group: expected exactly one of them, got "
                              f"{'both' if group is not None else 'neither'}")
    if group is not None:
        if on_proxy:
            raise SkinDetachError("group: expected a vertex group of the mesh, not of the proxy (on_proxy=False)")
        vertex_ids = rig_members.group_members(obj, group)
    elif isinstance(vertex_ids, dict):
        if on_proxy:
            raise SkinDetachError("vertex_ids: expected proxy vertex ids with on_proxy=True, got a dict of objects")
        vertex_ids = rig_members.combined_ids(obj, vertex_ids)
    if on_proxy:
        if mirror:
            raise SkinDetachError("mirror: expected mesh vertices (the proxy is not symmetric); select on the mesh")
        proxy_ids = as_vertex_ids("vertex_ids", vertex_ids, surface.proxy_vertices.shape[0])
        detail = None
    else:
        detail = np.unique(as_vertex_ids("vertex_ids", vertex_ids, surface.n_detail))
        proxy_ids = held_proxy_vertices(surface, detail)
    twin_detail = None
    if mirror:
        twin_detail = np.unique(mirrored_ids(binding.mirror_map(mirror), detail, mirror))
        if np.array_equal(twin_detail, detail):
            twin_detail = None  # its own mirror image: one symmetric handle
    if detail is None:  # proxy vertices: the median point of the proxy's
        rest, current, selected = surface.proxy_vertices, mesh_io.read_positions(binding.proxy.data), proxy_ids
    else:
        rest, current, selected = binding.rest, rig_members.read_positions(obj), detail
    on_plane = mirror if mirror and twin_detail is None else ""  # its own mirror image: on the plane
    rest_center = handle_symmetry.median_point(rest, selected, on_plane)
    now_center = (rest_center + handle_symmetry.median_point(current, selected)
                  - handle_symmetry.median_point(rest, selected))
    size = skin_rig.handle_size(obj)
    empty = handles.add(obj, binding.proxy, kind, proxy_ids, rest_center, now_center, detail_ids=detail,
                        size=size, group=group or "", mirror=mirror or "")
    if twin_detail is not None:
        reflect = handle_symmetry.mirror_matrix(mirror)[:3, :3]  # the twin's pivot: this one's, mirrored exactly
        twin_rest = reflect @ rest_center
        twin_now = (twin_rest + handle_symmetry.median_point(current, twin_detail)
                    - handle_symmetry.median_point(rest, twin_detail))
        twin = handles.add(obj, binding.proxy, kind, held_proxy_vertices(surface, twin_detail), twin_rest, twin_now,
                           detail_ids=twin_detail, size=size, group=group or "", mirror=mirror)
        handle_symmetry.pair(empty, twin)
    bpy.context.view_layer.update()  # the new empty's matrix_world is current when this returns
    _prepare_after_change(obj)
    return empty


def deform(obj, preserve_volume=True, tol=SETTLE_TOL, preview=False, follow=False):
    """Solve the proxy from the current transforms of every handle and anchor of ``obj`` and
    write the rebuilt positions into its mesh (and the proxy). ``tol``: :data:`SETTLE_TOL` for a
    result to keep, :data:`DRAG_TOL` while interacting. The solve starts from rest, so the same
    handles always give the same shape; ``follow=True`` (interactive updates) continues from the
    last solves instead, so the shape follows the handles' path. Returns a dict: milliseconds,
    iterations, converged, volume_change (of the proxy), preview. Raises, writing nothing, when
    the mesh was edited since Skin Detach last wrote it.

    ``preview=True`` on a mesh with a preview object writes the preview instead and shows it in
    place of the mesh, which keeps what it holds until the next full deform (falls back to the
    full detail without a preview)."""
    import bpy
    obj = _bound(obj)
    bpy.context.view_layer.update()  # world matrices of handles moved by a script
    deformation = Deformation(obj, preserve_volume)
    if preview and deformation.preview is not None:
        return dict(deformation.preview_step(tol, follow=follow, budget=None).figures(), preview=True)
    return dict(deformation.step(tol, follow=follow).figures(), preview=False)


def reset(obj):
    """Put the mesh and proxy back to the bound rest shape (bit-exact) and every handle back at rest."""
    Deformation(_bound(obj), require_unedited=False).reset()


def clear(obj):
    """Remove the proxy, every handle and the binding of ``obj``; the mesh keeps its current shape
    (the one shown: where the preview stands in, its pose is written in full detail first)."""
    obj = _bound(obj)
    _write_shown_pose(obj)
    skin_rig.clear(obj)


def orphan_owner(obj):
    """The deleted mesh object whose rig ``obj`` (a proxy, preview or handle) is left of, or None
    (deleting a bound mesh in the viewport leaves its proxy and handles)."""
    return skin_rig.orphan_owner(obj)


def clear_orphan(obj):
    """Remove what is left of a deleted mesh's rig, given any part ``obj`` of it; returns the
    deleted mesh's name."""
    return skin_rig.clear_orphan(obj)


def is_dragged(obj):
    """Whether a drag (:class:`DragSession`) of a handle of the bound ``obj`` is running."""
    return drag_session.dragged(obj)


def before_save():
    """Make every bound mesh consistent for a file written now (Blender's save_pre; the add-on
    registers it): a drag that writes the mesh as it goes records what it wrote, so the saved
    file holds the pose with its digest."""
    drag_session.before_save()


def _shown_pose(obj):
    """(n, 3) float32 the pose the preview shows where it stands in for ``obj`` (solved, nothing
    written), else None; where that cannot be solved the mesh is shown again and the error raised."""
    if not preview_stand_in.preview_stands_in(obj):
        return None
    try:
        return Deformation(obj).solve(follow=True)[1].copy()
    except SkinDetachError:
        preview_stand_in.end_stand_in(obj)
        raise


def _write_shown_pose(obj):
    """Where the preview stands in for ``obj``, write the pose it shows into the mesh in full detail
    (the mesh is shown again); the mesh is shown again even when that cannot be solved."""
    if not preview_stand_in.preview_stands_in(obj):
        return
    try:
        Deformation(obj).step(follow=True)
    finally:
        preview_stand_in.end_stand_in(obj)


def members(obj):
    """The objects of the rig ``obj`` belongs to, in the rig's order: the owner first, then the
    others as sorted by name at build time; ``[obj]`` for a rig of one object (a deleted member: None)."""
    return rig_members.objects(_bound(obj))


def member_ranges(obj):
    """{object: (first, stop)}: the combined vertex ids of each object of ``obj``'s rig are
    ``range(first, stop)``; combined id ``first + i`` is that object's vertex ``i``."""
    owner = _bound(obj)
    bounds = rig_members.offsets(owner)
    return {member: (int(bounds[k]), int(bounds[k + 1])) for k, member in enumerate(rig_members.objects(owner))
            if member is not None}


def bake(obj, frames, into=SHAPE_KEYS, path=None, preserve_volume=True, apply_modifiers=False, progress=None,
         stretch=None):
    """Evaluate the scene at each of ``frames`` (``"1-250"``, ``"1-10,20"`` or an iterable of
    ints) and store the rebuilt mesh: ``into`` SHAPE_KEYS (one animated key per frame), OBJECTS
    (one object per frame) or FILES (``path`` like ``"out/mesh_####.obj"`` or ``.ply``, with UVs).
    ``stretch`` (OBJECTS and FILES): True gives each frame's object or file its own frame's
    stretch (the ``skin_detach_stretch`` attribute and its colours, as :func:`show_stretch`), False
    none; None (default): each frame's own when ``obj`` shows its stretch, else none.
    Returns one dict per frame (frame, milliseconds, iterations, converged, volume_change,
    output). A rig of several objects bakes each of them: a key on each object, a baked object
    per object and frame, or one file per object and frame (the object's name inserted before
    the frame digits: ``out/char_####.obj`` -> ``out/char_eye_0012.obj``; see
    :func:`bake_file_path`); ``output`` is then a list, one per object in :func:`members` order. Idempotent; the mesh and the scene frame are left as they were. See
    :func:`skin_detach_addon.blender.baking.bake`."""
    return baking.bake(_bound(obj), frames, into, path, preserve_volume, apply_modifiers, progress, stretch)


def preview_stands_in(obj):
    """The preview object is shown in place of the mesh ``obj`` (which holds an older pose until
    the next full :func:`deform`)."""
    return preview_stand_in.preview_stands_in(_owner(obj))


def is_bound(obj):
    """True when ``obj`` (or the mesh it belongs to) carries a Skin Detach binding."""
    return stored.has_binding(skin_rig.mesh_of(obj))


def mesh_of(obj):
    """The mesh object ``obj`` stands for: the bound mesh of a proxy or handle, else ``obj`` itself (or None)."""
    return skin_rig.mesh_of(obj)


def handles_of(obj):
    """The handle and anchor empties of ``obj`` (bound or not, e.g. a file whose binding was
    lost), sorted by name; later names win where they share proxy vertices."""
    owner = _owner(obj)
    return handles.handles_of(owner)


def is_rig_part(obj):
    """Whether ``obj`` is a part of a rig (a proxy, a preview, a handle or anchor), not a mesh of it."""
    return obj is not None and skin_rig.is_rig_part(obj)


def is_handle(obj):
    """True when ``obj`` is a Skin Detach handle or anchor empty."""
    return handles.is_handle(obj)


def handle_kind(empty):
    """:data:`HANDLE` or :data:`ANCHOR` for a handle or anchor empty."""
    _check_handle(empty)
    return handles.kind_of(empty)


def mirror_twin(empty):
    """The mirror twin of a handle or anchor empty (made with it from the mesh's mirror toggle or
    ``mirror``), or None."""
    _check_handle(empty)
    return handle_symmetry.twin_of(empty)


def handle_mirror(empty):
    """The local axis ("X", "Y", "Z") a handle is mirrored across or symmetric about, or ""."""
    _check_handle(empty)
    return handle_symmetry.mirror_of(empty)


def handle_vertex_count(empty):
    """How many proxy vertices a handle or anchor empty holds."""
    _check_handle(empty)
    return int(handles.proxy_ids_of(empty).size)


def remove_handle(empty):
    """Delete a handle or anchor empty and put the mesh where the rig left says at once: solved
    from rest as :func:`deform` solves, or the rest shape (bit-exact) when every handle and anchor
    left is at rest (anchors alone hold the mesh at rest). A mesh edited since Skin Detach last
    wrote it (sculpted), or a rig that cannot be opened (its proxy edited), keeps its shape: the
    handle just goes. Then prepares the layout of those left (see :func:`prepare`). Raises,
    removing nothing, while the mesh is in Edit Mode (a pose is never written there); raises
    after the removal only when the rig left cannot be solved (a non-finite transform), saying so."""
    import bpy
    _check_handle(empty)
    obj = handles.owner(empty)
    name = empty.name
    deformation = None
    if obj is not None and is_bound(obj) and stored.holds_written(obj):
        if obj.mode == 'EDIT' or obj.data.is_editmode:
            raise SkinDetachError(f"object {obj.name!r}: expected Object Mode to remove {name!r} (the mesh is "
                                  f"then solved without it), it is in Edit Mode")
        try:
            deformation = Deformation(obj, require_unedited=False)
        except SkinDetachError:
            deformation = None
    handles.remove(empty)
    if deformation is not None:
        bpy.context.view_layer.update()  # world matrices of handles moved by a script
        try:
            if all(_at_rest(obj, other) for other in deformation.handles()):
                deformation.reset()
            else:
                deformation.step()
        except SkinDetachError as exc:
            raise SkinDetachError(f"handle {name!r} was removed, but the rig left cannot be solved: {exc}") from None
    if obj is not None and is_bound(obj):
        _prepare_after_change(obj)


def _at_rest(obj, empty):
    """The handle or anchor ``empty`` of ``obj`` is where it was made (to float32 rounding)."""
    motion = handles.local_motion(obj, empty)
    scale = max(1.0, float(np.abs(handles.rest_local_of(empty)[:3, 3]).max()))
    return bool(np.allclose(motion, np.eye(4), rtol=0.0, atol=1e-6 * scale))


def _check_handle(empty):
    if not handles.is_handle(empty):
        raise SkinDetachError(f"empty: expected a Skin Detach handle or anchor, got "
                              f"{'nothing' if empty is None else repr(empty.name)}")


def handle_conflicts(obj):
    """Handles and anchors of ``obj`` that share proxy vertices: a list of dicts (loser, winner: the
    empties' names; shared: how many proxy vertices). The newer one wins, whatever its kind (the
    rule of :func:`.core.detached_surface.held_detail.owned_pairs`: it also decides which one a
    selected mesh vertex follows)."""
    empties = handles_of(obj)
    proxy = stored.proxy_of(_bound(obj))  # cheap enough for every redraw of the panel
    m = len(proxy.data.vertices) if proxy is not None else None
    sets = []
    for empty in empties:
        try:
            sets.append((empty, set(handles.proxy_ids_of(empty, m).tolist())))
        except SkinDetachError:
            continue  # damaged: the panel marks it, the solve refuses it
    out = []
    for i, (older, older_ids) in enumerate(sets):
        for newer, newer_ids in sets[i + 1:]:
            shared = len(older_ids & newer_ids)
            if shared:
                out.append({"loser": older.name, "winner": newer.name, "shared": shared})
    return out


def handle_group(empty):
    """The vertex group a handle or anchor was made from, or ""."""
    _check_handle(empty)
    return handles.group_of(empty)


def stretch(obj):
    """(n,) float32 how much ``obj``'s mesh (Object Mode) stretches against its rest at each
    vertex in the pose of the last step (computed from its proxy: the mesh needs no attribute):
    the mean relative change of the edge lengths of the proxy faces the vertex is bound to,
    under its skin weights (0 at rest and under rigid motion; 0.1: edges about 10 % longer or
    shorter). While it is shown (:func:`show_stretch`) the same values are in the mesh's POINT
    FLOAT attribute ``skin_detach_stretch``, written by every step that stays."""
    return skin_rig.current_stretch(_bound(obj))


def show_stretch(obj, show=True):
    """Show ``obj``'s :func:`stretch` (Object Mode) on its mesh: the POINT FLOAT attribute
    ``skin_detach_stretch`` and its colours (blue 0, red 0.25 or more) in the color attribute
    ``skin_detach_stretch_color``, made the active color (the render color stays the artist's),
    both kept up to date by every step that stays, so that Solid shading with Attribute coloring
    shows a tension map. Nothing is added to a mesh before. ``show=False`` removes both and makes
    the artist's own active color and active attribute active again. (The panel's Show Stretch
    also sets every Solid 3D View's coloring to Attribute and back.)"""
    skin_rig.show_stretch(_bound(obj), show)


def stretch_shown(obj):
    """``obj``'s mesh shows its stretch (:func:`show_stretch`)."""
    return mesh_io.stretch_shown(_bound(obj).data)


def handle_has_old_pivot(empty):
    """The handle was made by an earlier version: R and S turn it about the centroid of the proxy
    vertices it holds, not its selection's median point (a Rebuild moves the pivot there)."""
    _check_handle(empty)
    return handles.has_old_pivot(empty)


def proxy_of(obj):
    """The proxy object of the bound mesh ``obj`` stands for, or None."""
    return stored.proxy_of(skin_rig.mesh_of(obj))


def rest_positions(obj):
    """(n, 3) float32 rest positions the mesh was bound with, in its vertex order (a rig of
    several objects: combined, in the owner's local space)."""
    return stored.rest_positions(_bound(obj)).copy()


def figures(obj):
    """What the panel shows for the mesh ``obj`` stands for: the build figures (dict, see
    :func:`build`) under "build" and the last step in this session under "last_step" (dict as
    returned by :func:`deform`, or None)."""
    obj = _bound(obj)
    return {"build": binding_figures.stats_of(obj), "last_step": binding_figures.last_step(obj)}


def bound_objects(objects=None):
    """The bound mesh objects among ``objects`` (default: every object in the file)."""
    import bpy
    return [o for o in (bpy.data.objects if objects is None else objects) if stored.has_binding(o)]


def selected_vertices(context):
    """The bound mesh behind the active object and the vertices selected on the active object
    (the mesh's Edit Mode selection, Edit Mode left first, or its proxy's): (obj, vertex ids (k,),
    on_proxy)."""
    return skin_rig.selection(context)


def shutdown():
    """Cancel the background work and stop the core's worker threads (unregistering the add-on
    calls it; they start again when next needed), and drop the kept mesh fingerprints and every
    cached binding."""
    threads.shutdown()
    mesh_io.forget_all()
    stored.drop_all()


def before_load(*_args):
    """A file is about to be opened (a ``load_pre`` handler): the background work of the file
    open now (its build, its preparation) is cancelled, and what was made for its bindings
    dropped, so the next file's preparation starts at once."""
    threads.cancel_all()
    stored.drop_all()


before_load._bpy_persistent = True  # kept across file loads (bpy.app.handlers.persistent)


def handlers():
    """(handler list of ``bpy.app.handlers``, function) pairs the add-on installs for this layer
    (its register, in one place with the interface's): :func:`before_load`, and the handlers that
    drop kept mesh fingerprints when Blender may have changed a mesh's geometry (first: the
    interface's handlers read fingerprints), and those that keep the binding cache to the open
    file's objects (:mod:`.blender.binding_cache`)."""
    return mesh_io.HANDLERS + binding_cache.HANDLERS + (("load_pre", before_load),)


def frame_list(frames):
    """``frames`` (``"1-250"``, ``"1-10,20"``, ``"1..250"``, ``"1-250:5"`` or an iterable of ints)
    as a list of distinct frame numbers in order; absurd ranges are refused (see :func:`bake`)."""
    return baking.check_frames(frames)


def bake_file_path(pattern, frame, member=None):
    """The file :func:`bake` writes ``frame`` to for ``pattern`` (``"out/scan_####.obj"`` ->
    ``"out/scan_0012.obj"``: the last run of ``#`` in the file name is the zero-padded frame);
    ``member`` (an object of a rig of several, or its name): that object's file
    (``"out/scan_eye_0012.obj"``)."""
    if member is not None:
        pattern = baking.member_pattern(pattern, getattr(member, "name", member))
    return baking.file_path(pattern, frame)


def check_output_file(argument, path):
    """Raise unless the folder of file ``path`` exists (or can be made) and is writable, as is
    ``path`` itself if it exists; ``argument`` names it in the message."""
    baking.check_folder(argument, path)

