"""The rig around a bound mesh: building the binding and its proxy object, handles from a
selection, the stretch map, and clearing it all. The mesh's positions are only read here, never
written (only the stretch map's attributes, see :func:`show_stretch`, and a build's pose shown by
the preview, see :class:`BuildJob`).
"""

import threading

import numpy as np
from mathutils import Matrix

from ..core.detached_surface import SkinDetachedSurface
from ..core.detached_surface.held_detail import held_proxy_vertices
from ..core.errors import SkinDetachError
from ..core.geometry import bbox_diagonal, component_labels
from ..core.validation import MIN_PREVIEW_VERTICES, as_vertex_ids
from . import binding as stored
from . import handle_symmetry, handles, mesh_io, preview_stand_in

#: The collection of each scene that holds its rigs (proxies, previews, handles). Not named after
#: the add-on: F3 "skin detach" would list "Add > Collection Instance > Skin Detach" first (a
#: whole name matched), and Enter would instance the rigs.
RIG_COLLECTION = "Proxy Rigs"
#: A collection the add-on made carries its name under this key (its role: renamed by hand, it is
#: still found).
COLLECTION_TAG = "_skin_detach_collection"
#: Names (and tags) of the add-on's collections in files of earlier versions -> the name now;
#: such a collection is renamed when found.
OLD_COLLECTION_NAMES = {"Skin Detach": RIG_COLLECTION, "Skin Detach Bake": "Baked Frames"}
PROXY_TAG = stored.PROXY_TAG
PREVIEW_TAG = stored.PREVIEW_TAG
#: Meshes with more vertices than this get a preview by default (see :func:`build`): a drag move
#: writing every vertex (solve + rebuild + write + Blender's update) takes 28.6 ms at 200K and
#: 33.9 ms at 300K vertices on the 2-core reference machine (headless, without Blender's update,
#: 20-25 ms at 300K with a 48-handle face rig), so above it a move no longer fits in 16 ms; with
#: the preview the face rig's moves take 14 ms (median) and the build is faster (the library
#: simplifies the clustered mesh: 2.6 s against 3.3 s at 300K).
PREVIEW_ABOVE = 200_000
#: Vertices of the preview (clusters of the detail mesh).
PREVIEW_VERTICES = 60_000


def check_mesh_object(obj):
    """Raise unless ``obj`` is a mesh object with vertices and faces."""
    if obj is None:
        raise SkinDetachError("object: expected an active mesh object, got nothing active")
    if obj.type != 'MESH':
        raise SkinDetachError(f"object {obj.name!r}: expected a mesh object, got type {obj.type}")
    if PROXY_TAG in obj or PREVIEW_TAG in obj:
        raise SkinDetachError(f"object {obj.name!r}: expected a detail mesh, got a Skin Detach "
                              f"{'proxy' if PROXY_TAG in obj else 'preview'}; select the original mesh")
    stored.check_editable(obj)
    if len(obj.data.vertices) == 0 or len(obj.data.polygons) == 0:
        raise SkinDetachError(f"mesh {obj.data.name!r}: expected vertices and faces, got "
                              f"{len(obj.data.vertices)} vertices and {len(obj.data.polygons)} faces")


def _is_rig_part(obj):
    return handles.is_handle(obj) or PROXY_TAG in obj or PREVIEW_TAG in obj


def _recorded_owner(obj):
    """The mesh object a proxy, preview or handle records as its own (deleted or not), else None."""
    if handles.is_handle(obj):
        return handles.owner(obj)
    for tag in (PROXY_TAG, PREVIEW_TAG):
        if tag in obj:
            return obj[tag]
    return None


def _deleted(obj):
    """``obj`` is in no scene: deleted in the viewport (a pointer of its rig may keep it alive)."""
    return obj is None or getattr(obj, "type", None) is None or not obj.users_scene


def mesh_of(obj):
    """The detail mesh object that ``obj`` stands for: its proxy's or handle's mesh, else ``obj``
    itself; None for nothing and for a part of a rig whose mesh was deleted (see :func:`orphan_owner`)."""
    if obj is None or not _is_rig_part(obj):
        return obj
    owner = _recorded_owner(obj)
    return None if _deleted(owner) else owner


def orphan_owner(obj):
    """The deleted mesh object whose rig ``obj`` (a proxy, preview or handle) is left of, or None."""
    if obj is None or not _is_rig_part(obj):
        return None
    owner = _recorded_owner(obj)
    return owner if owner is not None and _deleted(owner) else None


def clear_orphan(obj):
    """Remove what is left of the rig of a deleted mesh: ``obj`` (a part of it) and its proxy,
    preview and handles. Returns the deleted mesh's name."""
    import bpy
    owner = orphan_owner(obj)
    if owner is None:
        raise SkinDetachError(f"object {_name(obj)}: expected a part of a rig whose mesh was deleted, got "
                              f"{'a part of a live rig' if mesh_of(obj) is not None else 'no rig part'}")
    name = owner.name
    parts = [o for o in bpy.data.objects if _recorded_owner(o) == owner]
    collections = {c for part in parts for c in part.users_collection}
    for part in sorted(parts, key=lambda o: not handles.is_handle(o)):  # handles first: they hang on the proxy
        if handles.is_handle(part):
            handles.remove(part)
        else:
            remove_with_mesh(part)
    _remove_empty(collections)
    return name


def build(obj, target_faces=1000, normal_test=True, preview_above=PREVIEW_ABOVE, progress=None):
    """Bind ``obj`` (Object Mode) and make its proxy object; returns the core build stats.
    A mesh of more than ``preview_above`` vertices (None: never) also gets a hidden preview
    object, about :data:`PREVIEW_VERTICES` vertices (an eighth of the mesh at most) bound to the same proxy, which drags show
    instead of the detail (and the build simplifies through it: much faster at millions).
    A previous binding is replaced: its proxy goes, handles made from detail vertices are
    carried over to the new proxy (back at rest), handles made from proxy vertices are removed.
    The three parts of a :class:`BuildJob`, one after the other."""
    job = BuildJob(obj, target_faces, normal_test, preview_above)
    job.run(progress)
    return job.finish()


class BuildCancelled(Exception):
    """A :class:`BuildJob` was cancelled: nothing was written."""


class BuildJob:
    """One build of :func:`build` in three parts, so that a window can go on answering while the
    core works: made on the main thread (reads the mesh: positions (n, 3) float32, triangles
    (t, 3) int32), :meth:`run` on any thread (the core's build; touches no Blender data, reports
    :attr:`fraction` and :attr:`stage` as it goes; :meth:`start` runs it on a thread of its own),
    :meth:`finish` on the main thread (checks that the mesh is still what was read, then writes
    every object, or raises having written none). :meth:`cancel` stops it at the core's next
    stage; nothing is written then.

    ``positions``: (n, 3) float32 to bind instead of the mesh's own (the pose the preview shows
    where it stands in for the mesh, see ``api.start_build``); :meth:`finish` writes them into the
    mesh first."""

    def __init__(self, obj, target_faces=1000, normal_test=True, preview_above=PREVIEW_ABOVE, positions=None):
        check_mesh_object(obj)
        mesh = obj.data
        self.name, self._pointer = obj.name, obj.as_pointer()
        held = mesh_io.read_positions(mesh)
        self.shown_pose = positions is not None
        self.positions = held if positions is None else np.ascontiguousarray(positions, dtype=np.float32)
        mesh_io.check_positions(f"mesh {mesh.name!r}", self.positions)
        # Quads and ngons split as the bound shape splits (what reopening the file splits again);
        # first: the fingerprint is made from the same read.
        self.triangles = mesh_io.read_triangles(mesh, self.positions if self.shown_pose else None)
        self._read = (mesh_io.mesh_fingerprint(mesh), mesh_io.positions_digest(held))
        self.target_faces, self.normal_test = target_faces, normal_test
        self.attach, self.detach = part_overrides(obj)
        self.preview_vertices = None
        n = self.positions.shape[0]
        # A mesh too small for a preview of at least MIN_PREVIEW_VERTICES (an eighth of it) gets none.
        if preview_above is not None and n > preview_above and n // 8 >= MIN_PREVIEW_VERTICES:
            self.preview_vertices = min(PREVIEW_VERTICES, n // 8)
        #: How far the core's build got (0 to 1) and the name of its current stage.
        self.fraction, self.stage = 0.0, "waiting"
        self.surface = None
        #: What the core's build raised on its thread (given by :meth:`finish`), or None.
        self.error = None
        self._cancel = threading.Event()
        self._thread = None
        self._progress = None

    def cancel(self):
        """Stop at the core's next stage (:meth:`run` then raises :class:`BuildCancelled`); a
        cancelled job never writes."""
        self._cancel.set()

    @property
    def cancelled(self):
        return self._cancel.is_set()

    def _report(self, fraction, stage):
        if self._cancel.is_set():
            raise BuildCancelled(f"the build of {self.name!r} was cancelled at {stage!r}")
        self.fraction, self.stage = float(fraction), stage
        if self._progress is not None:
            self._progress(fraction, stage)

    def run(self, progress=None):
        """The core's build of the mesh read (any thread: no Blender data is touched);
        ``progress(fraction, stage)`` is called as it goes. Raises :class:`SkinDetachError` (a mesh
        that cannot be bound) or :class:`BuildCancelled`."""
        self._progress = progress
        # float32 as read: the core's float64 copy is its own, gone before the diffusion (77 MB at 3.2M).
        self.surface = SkinDetachedSurface.build(self.positions, self.triangles, target_faces=self.target_faces,
                                                 normal_test=self.normal_test,
                                                 preview_vertices=self.preview_vertices, progress=self._report,
                                                 attach=self.attach, detach=self.detach)
        self.triangles = None  # the surface holds what it needs of them
        self._report(1.0, "writing the binding")

    def start(self):
        """:meth:`run` on a thread of its own (see :attr:`done`, :attr:`error`)."""
        self._thread = threading.Thread(target=self._run_on_thread, name=f"skin_detach build {self.name}",
                                        daemon=True)
        self._thread.start()

    def _run_on_thread(self):
        try:
            self.run()
        except BuildCancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 (handed to finish(), on the main thread)
            self.error = exc

    @property
    def done(self):
        """The thread of :meth:`start` has ended (built, failed or cancelled)."""
        return self._thread is not None and not self._thread.is_alive()

    def wait(self, timeout=None):
        """Wait for the thread of :meth:`start` (at most ``timeout`` seconds); returns :attr:`done`."""
        if self._thread is not None:
            self._thread.join(timeout)
        return self.done

    def _object(self):
        """The mesh object read, checked to hold what was read (else :class:`SkinDetachError`)."""
        import bpy
        obj = bpy.data.objects.get(self.name)
        if obj is None or obj.as_pointer() != self._pointer:
            raise SkinDetachError(f"object {self.name!r}: expected the mesh object being bound, it was deleted or "
                                  f"renamed during the build (nothing was written); press Build again")
        check_mesh_object(obj)
        if obj.mode == 'EDIT' or obj.data.is_editmode:
            raise SkinDetachError(f"object {obj.name!r}: expected Object Mode to write the binding, it is in Edit "
                                  f"Mode (nothing was written); leave Edit Mode and press Build again")
        mesh = obj.data
        if (mesh_io.mesh_fingerprint(mesh), mesh_io.positions_digest(mesh_io.read_positions(mesh))) != self._read:
            raise SkinDetachError(f"mesh {mesh.name!r}: expected the mesh the build read, it was changed during the "
                                  f"build (nothing was written); press Build again")
        return obj

    def finish(self):
        """Write the binding, the proxy (and preview) objects, carry the handles over (main
        thread): all of it or, raising, nothing. Returns the build stats (see :func:`build`)."""
        if self.error is not None:
            raise self.error
        if self.cancelled:
            raise BuildCancelled(f"the build of {self.name!r} was cancelled")
        if self.surface is None:
            raise SkinDetachError(f"object {self.name!r}: expected a finished build to write, the build has not run")
        obj = self._object()
        surface, positions = self.surface, self.positions
        self.surface = self.positions = None  # written once
        if self.shown_pose:  # the pose the preview showed becomes the mesh's, and the mesh is shown again
            mesh_io.write_positions(obj.data, positions, checked=True)
            preview_stand_in.end_stand_in(obj)
        return _write_build(obj, surface, positions)


#: The object's custom property holding the artist's part overrides: {"attach": (k,) int32,
#: "detach": (k,) int32} vertex ids, each naming the loose part it lies in (see
#: :mod:`..core.detached_surface.riders`). An object's own property: it goes with the object,
#: survives Clear Skin and is read by every Build.
PARTS_KEY = "skin_detach_parts"
PART_MODES = ("ATTACH", "DETACH", "RULE")


def part_overrides(obj):
    """(attach, detach): the vertex ids (k,) int64 of ``obj``'s parts the artist made riders or free
    (None where there are none), those past the mesh's vertices dropped (the mesh was edited)."""
    stored = obj.get(PARTS_KEY)
    n = len(obj.data.vertices)
    out = []
    for key in ("attach", "detach"):
        ids = None if stored is None or not hasattr(stored, "get") else stored.get(key)
        ids = np.asarray(ids if ids is not None else [], dtype=np.int64).ravel()
        ids = ids[(ids >= 0) & (ids < n)]
        out.append(ids if ids.size else None)
    return tuple(out)


def set_parts(obj, vertex_ids, mode):
    """Make the loose parts of ``obj`` holding ``vertex_ids`` (k,) riders ("ATTACH"), free ("DETACH")
    or decided by the rule again ("RULE"); read by the next Build. Returns how many parts that named."""
    if mode not in PART_MODES:
        raise SkinDetachError(f"mode: expected one of {', '.join(PART_MODES)}, got {mode!r}")
    n = len(obj.data.vertices)
    ids = np.unique(as_vertex_ids("vertex_ids", vertex_ids, n))
    triangles = mesh_io.read_triangles(obj.data).astype(np.int64)
    labels = component_labels(triangles, n)
    named = np.unique(labels[ids])
    attach, detach = (np.zeros(0, dtype=np.int64) if part is None else part for part in part_overrides(obj))
    attach = attach[~np.isin(labels[attach], named)]  # the parts named lose what they had
    detach = detach[~np.isin(labels[detach], named)]
    if mode == "ATTACH":
        attach = np.concatenate([attach, ids])
    elif mode == "DETACH":
        detach = np.concatenate([detach, ids])
    obj[PARTS_KEY] = {"attach": attach.astype(np.int32), "detach": detach.astype(np.int32)}
    return int(named.size)


def _write_build(obj, surface, positions):
    """Replace ``obj``'s binding by the core ``surface`` of its (n, 3) ``positions`` (see :func:`build`)."""
    mesh = obj.data
    old = []  # (empty, its detail ids or None, its mirror axis): read before anything changes
    for empty in handles.handles_of(obj):
        try:
            old.append((empty, handles.detail_ids_of(empty, surface.n_detail), handle_symmetry.mirror_of(empty)))
        except SkinDetachError:
            old.append((empty, None, ""))  # damaged: removed below
    _remove_proxy(obj)
    proxy = _make_proxy(obj, surface)
    preview = None if surface.preview is None else _make_preview(obj, surface.preview)
    stored.store(obj, surface, positions, proxy, preview)
    # The pose bound is the new rest: a stretch shown is 0 everywhere now (an earlier version's
    # attribute, not shown, goes: nothing is added to a mesh until its stretch is shown).
    shown = mesh_io.stretch_shown(mesh)
    mesh_io.write_stretch(mesh, np.zeros(positions.shape[0], dtype=np.float32) if shown else None)
    kept = removed = 0
    centers = {}
    for empty, detail, axis in old:
        if detail is not None and detail.size:
            ids = held_proxy_vertices(surface, detail)
            twin = handle_symmetry.twin_of(empty)
            if twin is not None and twin.name in centers:  # the twin's, mirrored: exact
                center = handle_symmetry.mirror_matrix(axis)[:3, :3] @ centers[twin.name]
            else:
                center = handle_symmetry.median_point(positions, detail, axis if twin is None else "")
            centers[empty.name] = center
            handles.rebind(empty, proxy, ids, center)
            kept += 1
        else:
            handles.remove(empty)
            removed += 1
    handles.place_at_rest(obj, handles.handles_of(obj))  # children of other handles: after them
    stats = dict(surface.stats)
    stats["handles_kept"], stats["handles_removed"] = kept, removed
    return stats


def _new_mesh_object(name, points, faces, owner, tag):
    """A mesh object ``name`` of (m, 3) ``points`` and (k, 3) ``faces`` in the rig collection,
    parented to ``owner`` with identity transforms and tagged as belonging to it."""
    import bpy
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(points.shape[0])
    mesh.loops.add(faces.size)
    mesh.polygons.add(faces.shape[0])
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    mesh.loops.foreach_set("vertex_index", faces.astype(np.int32).ravel())
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update()
    made = bpy.data.objects.new(name, mesh)
    scene_collection(RIG_COLLECTION, scene_of(owner)).objects.link(made)
    made.parent = owner
    made.matrix_parent_inverse = Matrix.Identity(4)
    made.matrix_basis = Matrix.Identity(4)
    made.hide_render = True
    made[tag] = owner
    return made


def _make_proxy(obj, surface):
    proxy = _new_mesh_object(f"{obj.name}_proxy", surface.proxy_vertices, surface.proxy_faces, obj, PROXY_TAG)
    proxy.display_type = 'WIRE'
    proxy.show_in_front = True
    proxy.hide_select = True  # drawn in front, it would take the first click meant for the mesh
    return proxy


def _make_preview(obj, preview):
    """The preview object: hidden in viewports except while a drag shows it; the mesh's first
    material, so it looks like the mesh it stands for."""
    made = _new_mesh_object(f"{obj.name}_preview", preview.points, preview.triangles, obj, PREVIEW_TAG)
    if obj.data.materials and obj.data.materials[0] is not None:
        made.data.materials.append(obj.data.materials[0])
    made.hide_viewport = True
    made.hide_select = True
    return made


def scene_of(obj):
    """The scene a rig of ``obj`` goes into: the current one when ``obj`` is in it, else its first."""
    import bpy
    scene = bpy.context.scene
    return scene if obj.name in scene.objects or not obj.users_scene else obj.users_scene[0]


def scene_collection(name, scene=None):
    """The add-on's collection ``name`` directly under ``scene``'s collection (default: the current
    scene), made and linked there if missing: each scene has its own, so a new scene never shows
    another scene's rig (Blender would share one found by name)."""
    import bpy
    scene = scene or bpy.context.scene
    for child in scene.collection.children:
        tag = child.get(COLLECTION_TAG)
        if tag == name:
            return child
        if OLD_COLLECTION_NAMES.get(tag) == name:  # an earlier version's: renamed as it is now
            child[COLLECTION_TAG] = name
            if child.name == tag:
                child.name = name
            return child
    collection = bpy.data.collections.new(name)
    collection[COLLECTION_TAG] = name
    scene.collection.children.link(collection)
    return collection


def _remove_empty(collections):
    """Remove those of ``collections`` that are the add-on's rig collections and hold nothing now
    (also the untagged one of files from earlier versions)."""
    import bpy
    for collection in collections:
        tag = collection.get(COLLECTION_TAG, collection.name)  # untagged: an earlier version's, by name
        if OLD_COLLECTION_NAMES.get(tag, tag) == RIG_COLLECTION and not collection.all_objects:
            bpy.data.collections.remove(collection)


def _remove_proxy(obj):
    """Remove every proxy and preview object made for ``obj`` (its current ones and any left from a
    lost binding)."""
    import bpy
    for made in [o for o in bpy.data.objects if o.get(PROXY_TAG) == obj or o.get(PREVIEW_TAG) == obj]:
        remove_with_mesh(made)


def remove_with_mesh(obj):
    """Delete a mesh object and its mesh when nothing else uses it."""
    import bpy
    mesh = obj.data
    bpy.data.objects.remove(obj, do_unlink=True)
    if mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def handle_size(obj):
    return 0.03 * bbox_diagonal(np.array([v[:] for v in obj.bound_box]))


def selection(context):
    """The bound mesh object behind the active object and the vertices selected on the active
    object: the bound mesh (its Edit Mode selection; Edit Mode is left first so the selection is
    current) or its proxy. Returns (obj, vertex ids (k,), whether they are proxy vertices)."""
    import bpy
    active = context.active_object
    obj = mesh_of(active)
    if obj is None or not stored.has_binding(obj):
        raise SkinDetachError(f"object: expected a bound mesh or its proxy, got {_name(active)}; press Build first")
    if active.mode == 'EDIT':
        bpy.ops.object.mode_set(mode='OBJECT')
    if obj.mode == 'EDIT':
        raise SkinDetachError(f"object {obj.name!r}: expected Object Mode, it is in Edit Mode")
    if active.type != 'MESH':  # a handle is active: take the selection of the mesh itself
        active = obj
    selected = np.zeros(len(active.data.vertices), dtype=bool)
    active.data.vertices.foreach_get("select", selected)
    picked = np.flatnonzero(selected)
    if picked.size == 0:
        raise SkinDetachError(f"selection: expected selected vertices on {active.name!r}, got none "
                              f"(select some in Edit Mode)")
    return obj, picked, active is not obj


def current_stretch(obj):
    """(n,) float32 the stretch of the bound mesh ``obj`` (Object Mode) against its rest in the pose
    its proxy holds (the last step's: :class:`.core.detached_surface.stretch.SkinStretch`); needs no
    attribute."""
    binding = stored.open_binding(obj)
    return binding.stretch(mesh_io.read_positions(binding.proxy.data))


def show_stretch(obj, show=True):
    """Show the stretch of the bound mesh ``obj`` (Object Mode) in its attributes (see
    :func:`.mesh_io.show_stretch`; again: painted anew), or with ``show=False`` remove them and give
    the artist's active and render colors back (:func:`.mesh_io.hide_stretch`)."""
    if show:
        mesh_io.show_stretch(obj.data, current_stretch(obj))
    else:
        stored.check_editable(obj)
        if obj.mode == 'EDIT' or obj.data.is_editmode:
            raise SkinDetachError(f"object {obj.name!r}: expected Object Mode, its mesh is in Edit Mode")
        mesh_io.hide_stretch(obj.data)
    obj.data.update()


def clear(obj):
    """Remove the proxy, every handle and the stored binding of ``obj``, and what Show Stretch
    added to its mesh (the artist's active color back); the mesh keeps its shape."""
    mesh_io.hide_stretch(obj.data)
    proxy = stored.proxy_of(obj)
    collections = set(proxy.users_collection) if proxy is not None else set()
    for empty in handles.handles_of(obj):
        handles.remove(empty)
    _remove_proxy(obj)
    stored.forget(obj)
    _remove_empty(collections)


def _name(obj):
    return "nothing" if obj is None else repr(obj.name)
