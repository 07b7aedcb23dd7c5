"""The rig around a bound mesh: building the binding and its proxy object, handles from a
selection, the stretch map, and clearing it all. The mesh's positions are only read here, never
written (only the stretch map's attributes, see :func:`show_stretch`, and a build's pose shown by
the preview, see :class:`BuildJob`).
"""

import threading

import numpy as np
from mathutils import Matrix

from ..core import threads
from ..core.detached_surface import SkinDetachedSurface
from ..core.detached_surface.held_detail import held_proxy_vertices
from ..core.errors import SkinDetachError
from ..core.geometry import bbox_diagonal, component_labels
from ..core.validation import MIN_PREVIEW_VERTICES, as_vertex_ids
from . import binding as stored
from . import handle_symmetry, handles, mesh_io, preview_stand_in, rig_members

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


def is_rig_part(obj):
    """Whether ``obj`` is a proxy, a preview or a handle (an anchor too) of a rig."""
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
    """The detail mesh object that ``obj`` stands for: its proxy's or handle's mesh, the owner of
    the rig of several objects it is a member of (:mod:`.rig_members`), else ``obj`` itself; None
    for nothing and for a part of a rig whose mesh was deleted (see :func:`orphan_owner`)."""
    if obj is None or not is_rig_part(obj):
        return rig_members.owner_of(obj) or obj
    owner = _recorded_owner(obj)
    return None if _deleted(owner) else owner


def orphan_owner(obj):
    """The deleted mesh object whose rig ``obj`` (a proxy, preview or handle) is left of, or None."""
    if obj is None or not is_rig_part(obj):
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


class BuildCancelled(threads.Cancelled):
    """A :class:`BuildJob` was cancelled: nothing was written."""


class BuildJob:
    """One build of :func:`build` in three parts, so that a window can go on answering while the
    core works: made on the main thread (reads the mesh: positions (n, 3) float32, triangles
    (t, 3) int32), :meth:`run` on any thread (the core's build; touches no Blender data, reports
    :attr:`fraction` and :attr:`stage` as it goes; :meth:`start` runs it as a job of :func:`..core.threads.submit`),
    :meth:`finish` on the main thread (checks that the mesh is still what was read, then writes
    every object, or raises having written none). :meth:`cancel` stops it at the core's next
    stage (opening another file, :func:`..core.threads.cancel_all`, too); nothing is written then.

    ``positions``: (n, 3) float32 to bind instead of the mesh's own (the pose the preview shows
    where it stands in for the mesh, see ``api.start_build``); :meth:`finish` writes them into the
    mesh first."""

    def __init__(self, obj, target_faces=1000, normal_test=True, preview_above=PREVIEW_ABOVE, positions=None,
                 members=None):
        check_mesh_object(obj)
        #: The rig's objects (``obj`` first, see :mod:`.rig_members`): ``[obj]`` for one object.
        self.members = [obj] if members is None or len(members) < 2 else list(members)
        several = len(self.members) > 1
        if several and positions is not None:
            raise SkinDetachError(f"object {obj.name!r}: expected its mesh shown, its preview stands in for it; "
                                  f"press Apply first, then Build the several objects")
        for other in self.members[1:]:
            check_mesh_object(other)
            if other.mode == 'EDIT' or other.data.is_editmode:
                raise SkinDetachError(f"object {other.name!r}: expected Object Mode, its mesh is in Edit Mode")
        mesh = obj.data
        self.name, self._pointer = obj.name, obj.as_pointer()
        self._pointers = [o.as_pointer() for o in self.members]
        self._names = [o.name for o in self.members]
        locals_ = [mesh_io.read_positions(o.data) for o in self.members]
        held = locals_[0] if not several else np.concatenate(locals_)
        self.local_rest = held if several else None
        self.shown_pose = positions is not None
        if several:
            #: The members' world matrices relative to the owner's, as read (what is stored).
            relative = [np.linalg.solve(np.array(obj.matrix_world, dtype=np.float64),
                                        np.array(o.matrix_world, dtype=np.float64)) for o in self.members]
            if not all(np.isfinite(m).all() for m in relative):
                raise SkinDetachError(f"objects: expected finite world matrices of {', '.join(self._names)}, got NaN "
                                      f"or inf")
            self._relative = relative
            combined = [locals_[0]] + [(p.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
                                       for p, m in zip(locals_[1:], relative[1:])]
            self.positions = np.concatenate(combined)
        else:
            self.positions = held if positions is None else np.ascontiguousarray(positions, dtype=np.float32)
        mesh_io.check_positions(f"mesh {mesh.name!r}", self.positions)
        # Quads and ngons split as the bound shape splits (what reopening the file splits again);
        # first: the fingerprint is made from the same read.
        if several:
            offsets = np.cumsum([0] + [p.shape[0] for p in locals_])
            self.triangles = np.concatenate([mesh_io.read_triangles(o.data) + np.int32(offsets[k])
                                             for k, o in enumerate(self.members)]).astype(np.int32)
        else:
            self.triangles = mesh_io.read_triangles(mesh, self.positions if self.shown_pose else None)
        self._read = self._state(self.members, held)
        self.target_faces, self.normal_test = target_faces, normal_test
        self.attach, self.detach = _combined_overrides(self.members)
        self.preview_vertices = None
        n = self.positions.shape[0]
        # A mesh too small for a preview of at least MIN_PREVIEW_VERTICES (an eighth of it) gets
        # none; a rig of several objects gets one for all of them (it stands in for every one).
        if preview_above is not None and n > preview_above and n // 8 >= MIN_PREVIEW_VERTICES:
            self.preview_vertices = min(PREVIEW_VERTICES, n // 8)
        #: How far the core's build got (0 to 1) and the name of its current stage.
        self.fraction, self.stage = 0.0, "waiting"
        self.surface = None
        #: What the core's build raised on its thread (given by :meth:`finish`), or None.
        self.error = None
        self._cancel = threading.Event()
        self._job = None
        self._progress = None

    @staticmethod
    def _state(members, held):
        """What the build read of ``members``: their fingerprints, world matrices, positions' digest."""
        return ([mesh_io.mesh_fingerprint(o.data) for o in members],
                [tuple(np.array(o.matrix_world, dtype=np.float64).ravel()) for o in members] if len(members) > 1
                else None, mesh_io.positions_digest(held))

    def cancel(self):
        """Stop at the core's next stage (:meth:`run` then raises :class:`BuildCancelled`); a
        cancelled job never writes."""
        self._cancel.set()
        if self._job is not None:
            self._job.cancel()

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
        """:meth:`run` on the foreground lane of :func:`..core.threads.submit` (at once, beside an
        opened file's preparation; its numpy work on the pool), cancelled with :meth:`cancel`
        (see :attr:`done`, :attr:`error`)."""
        self._job = threads.submit(self._run_on_thread, lane=threads.FOREGROUND, cancel=self._cancel,
                                   name=f"the build of {self.name!r}")

    def _run_on_thread(self):
        try:
            self.run()
        except threads.Cancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 (handed to finish(), on the main thread)
            self.error = exc

    @property
    def done(self):
        """The job of :meth:`start` has ended (built, failed or cancelled)."""
        return self._job is not None and self._job.done()

    def wait(self, timeout=None):
        """Wait for the job of :meth:`start` (at most ``timeout`` seconds); returns :attr:`done`."""
        if self._job is not None:
            self._job.wait(timeout)
        return self.done

    def _object(self):
        """The mesh object read, checked to hold what was read (else :class:`SkinDetachError`)."""
        import bpy
        obj = bpy.data.objects.get(self.name)
        if obj is None or obj.as_pointer() != self._pointer:
            raise SkinDetachError(f"object {self.name!r}: expected the mesh object being bound, it was deleted or "
                                  f"renamed during the build (nothing was written); press Build again")
        members = [obj]
        for name, pointer in zip(self._names[1:], self._pointers[1:]):
            other = next((o for o in bpy.data.objects if o.as_pointer() == pointer), None)
            if other is None or not other.users_scene:
                raise SkinDetachError(f"object {name!r}: expected the mesh object being bound, it was deleted during "
                                      f"the build (nothing was written); press Build again")
            members.append(other)
        for member in members:
            check_mesh_object(member)
            if member.mode == 'EDIT' or member.data.is_editmode:
                raise SkinDetachError(f"object {member.name!r}: expected Object Mode to write the binding, it is in "
                                      f"Edit Mode (nothing was written); leave Edit Mode and press Build again")
        mesh = obj.data
        held = [mesh_io.read_positions(o.data) for o in members]
        if self._state(members, held[0] if len(held) == 1 else np.concatenate(held)) != self._read:
            raise SkinDetachError(f"mesh {mesh.name!r}: expected the mesh{'es' if len(held) > 1 else ''} the build "
                                  f"read, {'they were' if len(held) > 1 else 'it was'} changed or moved during the "
                                  f"build (nothing was written); press Build again")
        self.members = members
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
        return _write_build(obj, surface, positions, self.members, self.local_rest)


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


def _combined_overrides(members):
    """(attach, detach) of a rig's ``members`` (objects in the rig's order): each object's own
    overrides (:func:`part_overrides`) at its combined vertex ids, None where there are none."""
    out = [[], []]
    offset = 0
    for member in members:
        for k, ids in enumerate(part_overrides(member)):
            if ids is not None:
                out[k].append(ids + offset)
        offset += len(member.data.vertices)
    return tuple(np.concatenate(ids) if ids else None for ids in out)


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


def _write_build(obj, surface, positions, members=None, local_rest=None):
    """Replace ``obj``'s binding by the core ``surface`` of its (n, 3) ``positions`` (see :func:`build`)."""
    old = []  # (empty, its detail ids or None, its mirror axis): read before anything changes
    remap = _id_remap(obj, members or [obj])
    for empty in handles.handles_of(obj):
        try:
            if remap is None:
                ids = handles.detail_ids_of(empty, surface.n_detail)
            else:  # a rig of several objects: each id follows its object's vertex to its new place
                ids = remap(handles.detail_ids_of(empty))
                _store_detail_ids(empty, ids)
            old.append((empty, ids, handle_symmetry.mirror_of(empty)))
        except SkinDetachError:
            old.append((empty, None, ""))  # damaged: removed below
    _remove_proxy(obj)
    proxy = _make_proxy(obj, surface)
    preview = None if surface.preview is None else _make_preview(obj, surface.preview)
    stored.store(obj, surface, positions, proxy, preview, members, local_rest)
    # The pose bound is the new rest: a stretch shown is 0 everywhere now (an earlier version's
    # attribute, not shown, goes: nothing is added to a mesh until its stretch is shown).
    for member in members or [obj]:
        shown = mesh_io.stretch_shown(member.data)
        mesh_io.write_stretch(member.data, np.zeros(len(member.data.vertices), dtype=np.float32) if shown else None)
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
    stats["objects"] = len(members or [obj])
    return stats


def _id_remap(obj, members):
    """For a rebuild where the rig's objects change (several before or after): a function mapping
    the handles' old combined ids to new ones, each id kept with its object's vertex (ids of an
    object no longer in the rig, or whose vertex count changed, dropped); None when ``obj`` is a
    single object before and after (ids stay as they are)."""
    if not stored.has_binding(obj) or (not rig_members.is_multi(obj) and len(members) == 1):
        return None
    before, old_bounds = rig_members.objects(obj), rig_members.offsets(obj)
    old_counts = np.diff(old_bounds)
    new_bounds = np.concatenate([[0], np.cumsum([len(o.data.vertices) for o in members])])

    def remap(ids):
        out = []
        for k, member in enumerate(before):
            if member is None or member not in members:
                continue
            j = members.index(member)
            if new_bounds[j + 1] - new_bounds[j] != old_counts[k]:
                continue
            inside = ids[(ids >= old_bounds[k]) & (ids < old_bounds[k + 1])]
            out.append(inside - old_bounds[k] + new_bounds[j])
        return np.sort(np.concatenate(out)) if out else np.zeros(0, dtype=np.int64)
    return remap


def _store_detail_ids(empty, ids):
    """Replace the detail ids a handle stores (see :mod:`.handles`)."""
    props = empty[handles.TAG]
    if "detail_ids" in props:
        del props["detail_ids"]  # assigning over an ID-property array keeps its old length
    props["detail_ids"] = np.asarray(ids, dtype=np.int32)


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
    members = rig_members.objects(obj)
    editing = [o for o in members if o is not None and o.mode == 'EDIT']
    if active.mode == 'EDIT' or editing:  # every object in Edit Mode leaves it: its selection is then current
        bpy.ops.object.mode_set(mode='OBJECT')
    if obj.mode == 'EDIT':
        raise SkinDetachError(f"object {obj.name!r}: expected Object Mode, it is in Edit Mode")
    if len(members) > 1 and PROXY_TAG not in active:  # several objects: every member's selection, combined ids
        picked = rig_members.selected(obj, editing or None)
        if picked.size == 0:
            where = ", ".join(repr(o.name) for o in (editing or members) if o is not None)
            raise SkinDetachError(f"selection: expected selected vertices on {where}, got none "
                                  f"(select some in Edit Mode)")
        return obj, picked, False
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


def _members_in_object_mode(obj):
    members = rig_members.objects(obj)
    for member in members:
        stored.check_editable(member)
        if member.mode == 'EDIT' or member.data.is_editmode:
            raise SkinDetachError(f"object {member.name!r}: expected Object Mode, its mesh is in Edit Mode")
    return members


def show_stretch(obj, show=True):
    """Show the stretch of the bound mesh ``obj`` (Object Mode) in its attributes (see
    :func:`.mesh_io.show_stretch`; again: painted anew), or with ``show=False`` remove them and give
    the artist's active and render colors back (:func:`.mesh_io.hide_stretch`)."""
    if rig_members.is_multi(obj):  # every object of the rig, its own slice
        if show:
            values = rig_members.split_values(obj, current_stretch(obj))
        members = _members_in_object_mode(obj)
        for k, member in enumerate(members):
            if show:
                mesh_io.show_stretch(member.data, values[k])
            else:
                mesh_io.hide_stretch(member.data)
            member.data.update()
        return
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
    added to its mesh (the artist's active color back); the mesh keeps its shape. A rig of several
    objects goes whole: every member's stretch map and mark too (:mod:`.rig_members`)."""
    for member in rig_members.objects(obj):
        if member is not None:
            mesh_io.hide_stretch(member.data)
    proxy = stored.proxy_of(obj)
    collections = set(proxy.users_collection) if proxy is not None else set()
    for empty in handles.handles_of(obj):
        handles.remove(empty)
    _remove_proxy(obj)
    stored.forget(obj)
    _remove_empty(collections)


def _name(obj):
    return "nothing" if obj is None else repr(obj.name)
