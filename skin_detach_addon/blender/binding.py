"""The binding of a mesh object, stored in the object's ID properties so it lives in the .blend.

Stored under ``object["_skin_detach"]`` (the leading underscore hides it from the Custom Properties
panel), schema 3: the schema version, a binding id, the mesh's topology fingerprint, the digest of
the positions Skin Detach last wrote, the proxy object (an ID pointer), the rest positions ((n, 3)
float32, the mesh's own vertex order) and what of the core surface cannot be recomputed quickly
(:func:`.core.detached_surface.compact_surface.compact_arrays`: the proxy, the carrier in the
narrowest integer type its range allows, the build figures), plus the preview's
(:func:`.core.detached_surface.compact_surface.compact_preview_arrays`: its points, triangles,
carrier and representatives). Every array of :data:`PACK_FROM` values or more, the rest positions
first, is stored packed (:mod:`.core.packed_arrays`: bytes, lossless, about 72 % of float32
positions where a .blend's own compression of the raw floats gets about 92 %); a smaller one as a
flat int32 or float64 array, or an int8/int16 one as its bytes beside its type (Blender's
ID-property arrays hold int32 at the narrowest). Opening makes the skin again from the rest
positions, the mesh's triangles and the carrier
(:func:`.core.detached_surface.compact_surface.surface_from_compact`), and the preview's from its
own arrays, bit for bit the ones the build made. A record of schema 2 (the arrays whole, the
preview's skin stored) is read as it is; one of schema 1 (the whole skin stored) is read as it is
and rewritten compact once. Nothing is pickled or evaluated. The core objects rebuilt from it are cached per binding
id, so undo finds them again or rebuilds them from the properties; opening another file drops
them (:func:`drop_all`). After a file is opened they are made on a background thread
(:class:`Opening`, :mod:`.background`), and a step that needs one before then waits for it.
What reads or changes the record for one purpose has its own module: the preview standing in
for the mesh (:mod:`.preview_stand_in`), the figures the panel shows (:mod:`.binding_figures`).
"""

import concurrent.futures
import threading
import uuid

import numpy as np

from ..core import packed_arrays, threads
from ..core.detached_surface import HeldPlacement, Preview, SkinDetachedSurface, SkinStretch
from ..core.detached_surface.compact_surface import (COMPACT_PREVIEW_TAG, check_digests, compact_arrays,
                                                     compact_preview_arrays, content_digests, preview_from_compact,
                                                     surface_from_compact)
from ..core.detached_surface.held_detail import layout_of
from ..core.detached_surface.surface import BACKGROUND_ABOVE
from ..core.detached_surface.symmetry import MIRROR_TOLERANCE, is_own_mirror_image, mirror_map, symmetrize
from ..core.errors import SkinDetachError
from ..core.geometry import bbox_diagonal
from ..core.proxy_solve import ProxySolves
from . import mesh_io
from .mesh_guard import MeshGuard

KEY = "_skin_detach"
#: The record points under this key at a text datablock (named :data:`STORE_PREFIX` + the
#: object's name) whose own ``KEY`` group holds the binding's arrays: Blender's dependency graph
#: copies an object's ID properties into its evaluated copy whenever the object is updated (a
#: confirm, a hide, a new handle: 0.3 s per 160 MB), never a text's.
STORE = "store"
STORE_PREFIX = ".skin_detach "
#: A proxy object points back at its mesh under this key ...
PROXY_TAG = "_skin_detach_proxy_of"
#: ... and a preview object under this one.
PREVIEW_TAG = "_skin_detach_preview_of"
#: Stored arrays of the preview's skin carry this prefix.
PREVIEW_PREFIX = "preview_"
SCHEMA_VERSION = 3
#: The schema whose records store the whole skin: read as they are and rewritten compact once.
WHOLE_SKIN_SCHEMA = 1
#: Schemas read: 1 (the whole skin), 2 (compact, the arrays whole: read as they are), 3 (compact,
#: the arrays of at least :data:`PACK_FROM` values packed, :mod:`.core.packed_arrays`).
READABLE_SCHEMAS = (WHOLE_SKIN_SCHEMA, 2, SCHEMA_VERSION)
#: Arrays of at least this many values are stored packed (:func:`.core.packed_arrays.pack`:
#: bytes, lossless, read back by :func:`stored_array`); smaller ones as they are.
PACK_FROM = 1024
#: An integer array narrower than int32 is stored as bytes under its key, its type under the key
#: with this suffix (one of :data:`NARROW_TYPES`).
TYPE_SUFFIX = "_type"
NARROW_TYPES = {"int8": np.int8, "int16": np.int16}
#: The record's group of {key: digest} of every stored array and figure of the binding (their
#: values, :func:`.core.detached_surface.compact_surface.content_digests`), checked on opening: data
#: changed outside Skin Detach (well-formed, so every other check passes) is refused, not deformed
#: wrong. Records of earlier versions have none and are read unchecked.
DIGESTS = "digests"
#: Keys of a schema-1 record that schema 2 does not keep.
WHOLE_SKIN_KEYS = ("skin_vertex", "skin_face", "skin_bary", "skin_height", "skin_weight", "skin_case", "weld")
_CACHE = {}
#: Openings under way on the background thread, by binding id (:class:`Opening`).
_PENDING = {}


class Binding:
    """Runtime side of one stored binding.

    surface     SkinDetachedSurface over the mesh's n vertices
    rest        (n, 3) float32 rest positions, exactly as they were in the mesh
    proxy       the proxy object
    preview     core Preview (c vertices over the same proxy) or None
    solves      the proxy's solvers and warm starts (:class:`.core.proxy_solve.proxy_solves.ProxySolves`)
    mesh_guard  the mesh's :class:`.mesh_guard.MeshGuard`, armed while a drag shows the preview
    last_step   figures of the last step in this session (dict, see StepReport.figures), or None
    """

    def __init__(self, binding_id, surface, rest, proxy, preview=None):
        self.binding_id = binding_id
        self.surface = surface
        self.rest = rest
        self.proxy = proxy
        self.preview = preview
        self.solves = ProxySolves(surface, self._pulls if preview is not None else None)
        self._buffer = np.empty((surface.n_detail, 3), dtype=np.float32)
        self._preview_buffer = None if preview is None else np.empty((preview.points.shape[0], 3), dtype=np.float32)
        #: (layout key, the preview's held pairs) of the last preview rebuild's layout.
        self._preview_held = (None, [])
        self._layout = None
        #: ("detail" or "preview") -> (layout key, its HeldPlacement).
        self._placements = {}
        self.last_step = None
        self._mirrors = {}
        self._own_images = {}
        self._diagonal = None
        self.mesh_guard = MeshGuard()
        self._stretch = None
        self._stretch_lock = threading.Lock()
        #: The :class:`.core.threads.Job` of a preparation of this binding running on the
        #: background thread, or None (:mod:`.background`); :func:`open_binding` waits for it
        #: before anything uses the binding.
        self.busy = None

    def stretch(self, proxy_vertices):
        """(n,) float32 the detail's stretch against its rest when the proxy is at
        ``proxy_vertices`` (m, 3) (:class:`.core.detached_surface.stretch.SkinStretch`, made on
        first use)."""
        return self._skin_stretch()(proxy_vertices)

    def _skin_stretch(self):
        """The :class:`SkinStretch` of the surface, made once whichever thread asks first (the
        background's, a pool's, the main one); the others wait for it."""
        if self._stretch is None:
            with self._stretch_lock:
                if self._stretch is None:
                    self._stretch = SkinStretch(self.surface)
        return self._stretch

    def mirror_map(self, axis):
        """(n,) mirror twin of every mesh vertex across local ``axis`` ("X", "Y", "Z") at rest,
        -1 where there is none (cached)."""
        if axis not in self._mirrors:
            self._mirrors[axis] = mirror_map(self.rest, "XYZ".index(axis))
        return self._mirrors[axis]

    def is_own_mirror_image(self, detail_ids, axis):
        """Whether the rest positions of the mesh vertices ``detail_ids`` (k,) are their own mirror
        image across local ``axis`` ("X", "Y", "Z"), within the mirror tolerance of the mesh's
        diagonal (cached per vertex set)."""
        ids = np.asarray(detail_ids, dtype=np.int64)
        known = self._own_images.setdefault((axis, ids.size), [])
        for seen, answer in known:  # a comparison: a drag asks every move
            if seen is ids or np.array_equal(seen, ids):
                return answer
        if self._diagonal is None:
            self._diagonal = bbox_diagonal(self.rest)
        tolerance = MIRROR_TOLERANCE * self._diagonal
        answer = ids.size > 0 and bool(is_own_mirror_image(self.rest[ids], "XYZ".index(axis), tolerance))
        known.append((ids if not ids.flags.writeable else ids.copy(), answer))
        return answer

    def layout(self, groups, held):
        """The :class:`.core.detached_surface.held_detail.Layout` of ``groups`` (m,) and ``held``
        (pairs (group label, detail ids)): the last one given when they are the same, so its key, a
        digest of every held id (5 MB and 3 ms at 3.2M), is made once per layout, not once per drag
        move."""
        self._layout = layout_of(self._layout, groups, held)
        return self._layout

    def rebuild(self, proxy_vertices, layout=None, motions=(), mirror=None):
        """(n, 3) float32 detail positions from deformed proxy vertices (m, 3) (``layout``: their
        rigid groups and held detail, see :meth:`SkinDetachedSurface.reconstruct`), made exactly
        symmetric with ``mirror`` (the (n,) mirror map and the axis index, see
        :func:`.core.detached_surface.symmetry.symmetrize`), then every held vertex placed exactly
        by its group's (4, 4) motion in ``motions`` (one per pair of ``layout.held``;
        :class:`.core.detached_surface.held_detail.HeldPlacement`), in a reused buffer (copy it to
        keep it past the next call)."""
        if layout is None:  # no handles: no rig to be symmetric
            return self.surface.reconstruct(proxy_vertices, out=self._buffer)
        placement = self._placement("detail", layout, self.rest, layout.owned)
        if mirror is None and layout.held:  # the held rows placed, not rebuilt first
            return self.surface.reconstruct(proxy_vertices, out=self._buffer, groups=layout.groups, held=layout.held,
                                            place=lambda out: placement(out, motions))
        # Symmetric first, then the held rows placed (their rows left as the free rebuild gives
        # them: placed afterwards, they are not rebuilt, which would cost the whole selections).
        out = self.surface.reconstruct(proxy_vertices, out=self._buffer, groups=layout.groups,
                                       held=layout.held or None, place=(lambda out: out) if layout.held else None)
        if mirror is not None:
            out[...] = symmetrize(out, *mirror)
        return placement(out, motions)

    def _placement(self, which, layout, rest, pairs):
        """The :class:`.core.detached_surface.held_detail.HeldPlacement` of ``layout``'s ``pairs``
        over ``rest`` for the mesh or the preview (``which``), made once per layout."""
        key, placement = self._placements.get(which, (None, None))
        if key != layout.key():
            placement = HeldPlacement(rest, pairs)
            self._placements[which] = (layout.key(), placement)
        return placement

    def prepare(self, layout):
        """Prepare the rebuild of ``layout`` (a :class:`.core.detached_surface.held_detail.Layout`)
        for the mesh and its preview, and the stretch, so the first :meth:`rebuild`,
        :meth:`rebuild_preview` and :meth:`stretch` with it start at once (the rebuilds' float32
        copies too: they write into float32 buffers)."""
        # A mesh with a preview drags it: its own rebuild (and stretch) is needed at the confirm
        # only, and a large one's is made on a background thread (Add Handle does not wait for
        # it; a confirm may).
        background = self.preview is not None and self.surface.n_detail >= BACKGROUND_ABOVE
        if background and self._stretch is None:
            threads.submit(self._skin_stretch, watched=False, name=f"the stretch of {self.binding_id}")
        else:
            self._skin_stretch()
        self.surface.prepare_layout(layout.groups, layout.held or None, float32=True, background=background)
        if self.preview is not None:
            self.preview.surface.prepare_layout(layout.groups, self._preview_held_of(layout) or None, float32=True)

    def _pulls(self, layout):
        """The drop rows a mesh with a preview pulls (one (s_h, m) matrix per pair of
        ``layout.owned``): its preview's, over the preview vertices that stand for each pair's
        detail. The pull shapes the proxy around a selection's border, which the preview's
        60,000 vertices draw as well as the detail's millions (each vertex is placed by its
        handle afterwards either way), and its cost then follows the preview, not the detail: at
        3.2M the detail's drop rows of the bend's handle and anchor took 1.3-1.7 s of Add Handle."""
        return self.preview.surface.drop_rows([ids for _, ids in self._preview_held_of(layout)], layout.groups)

    def _preview_held_of(self, layout):
        """The preview's held pairs of ``layout``: (label, preview ids) per pair of its owned detail
        (:meth:`.core.detached_surface.surface.Preview.held_of`), made once per layout."""
        key = layout.key()
        if self._preview_held[0] != key:
            self._preview_held = (key, self.preview.held_of(layout.owned, self.surface.weld, self.rest))
        return self._preview_held[1]

    def rebuild_preview(self, proxy_vertices, layout=None, motions=()):
        """(c, 3) float32 preview positions from deformed proxy vertices (m, 3) (``layout`` and
        ``motions`` as for :meth:`rebuild`: the preview holds the vertices that stand for the held
        detail, placed by their group's motion), in a reused buffer."""
        if layout is None:
            return self.preview.surface.reconstruct(proxy_vertices, out=self._preview_buffer)
        pairs = self._preview_held_of(layout)
        if not pairs:
            return self.preview.surface.reconstruct(proxy_vertices, out=self._preview_buffer, groups=layout.groups)
        placement = self._placement("preview", layout, self.preview.points, pairs)
        return self.preview.surface.reconstruct(proxy_vertices, out=self._preview_buffer, groups=layout.groups,
                                                held=pairs, place=lambda out: placement(out, motions))


def has_binding(obj):
    return obj is not None and obj.type == 'MESH' and KEY in obj


def _flat_props(arrays, prefix=""):
    """(key, ID-property value) of each entry of a core ``to_arrays`` dict, made as it is asked
    for: strings, scalars, an array of at least :data:`PACK_FROM` values packed into bytes
    (:func:`_packed`), a smaller one as int32 or float64 flat arrays, or an int8 or int16 one as
    its bytes (its type under the key with :data:`TYPE_SUFFIX`)."""
    for key, value in arrays.items():
        if value.dtype.kind in "US":
            yield prefix + key, str(value)
        elif value.ndim == 0:
            yield prefix + key, value.item()
        elif value.size >= PACK_FROM:
            yield prefix + key, _packed(value)
        elif value.dtype.name in NARROW_TYPES:
            yield prefix + key + TYPE_SUFFIX, value.dtype.name
            yield prefix + key, np.ascontiguousarray(value).ravel().tobytes()
        elif value.dtype.kind in "iu":
            yield prefix + key, value.astype(np.int32).ravel()
        else:
            yield prefix + key, np.asarray(value, dtype=np.float64).ravel()  # no copy when already float64


def _packed(value):
    """:func:`.core.packed_arrays.pack`'s bytes of ``value`` (k,) or (k, c): a float array whose
    every value float32 holds exactly as float32 (the preview's points: the mesh's own floats),
    an integer one in its own type, read back as the flat array (k * c,)."""
    value = np.asarray(value)
    if value.ndim != 2 or not 1 <= value.shape[1] <= packed_arrays.MOST_COLUMNS:
        value = value.ravel()
    if value.dtype.kind == "f" and value.dtype != np.float32:
        narrow = value.astype(np.float32)
        value = narrow if np.array_equal(narrow, value) else value.astype(np.float64)
    elif value.dtype.kind in "iu" and value.dtype.name not in NARROW_TYPES:
        value = value.astype(np.int32)  # as an array of this size was stored before
    return packed_arrays.pack(value)


def stored_array(value, source):
    """The flat array stored as ``value``: a packed one (:func:`_packed`) unpacked, any other
    (a Blender ID-property array, a list) as numpy's copy of it. Damage raises
    :class:`SkinDetachError` naming ``source``."""
    if packed_arrays.is_packed(value):
        return packed_arrays.unpack(value, source)
    if isinstance(value, (bytes, bytearray)):
        raise SkinDetachError(f"{source}: expected packed bytes or an array, got {len(value)} bytes that are neither "
                              f"(damaged); press Rebuild")
    return np.array(value)


def stored_length(value):
    """The number of values stored as ``value`` (a packed array's header read, nothing unpacked),
    or None when it is not an array."""
    if packed_arrays.is_packed(value):
        try:
            return packed_arrays.packed_size(value)
        except SkinDetachError:
            return None
    return len(value) if hasattr(value, "__len__") and not isinstance(value, (str, bytes)) else None


def store(obj, surface, rest, proxy, preview=None, members=None, local_rest=None):
    """Write the binding of ``obj`` (replacing any; ``preview``: the preview object of
    ``surface.preview``, or None) and return its :class:`Binding`. ``members``: the rig's objects
    (``obj`` first) when it has several, with ``local_rest`` (n, 3) float32 their own rest
    positions concatenated (see :mod:`.rig_members`); ``rest`` is then the combined rest."""
    from . import rig_members
    rest = np.ascontiguousarray(rest, dtype=np.float32).ravel()
    several = members is not None and len(members) > 1
    entries = rig_members.record_entries(obj, members) if several else None
    props = {
        "schema_version": SCHEMA_VERSION,
        "binding_id": uuid.uuid4().hex,
        "mesh_fingerprint": (rig_members.fingerprint_of([e["fingerprint"] for e in entries]) if several
                             else mesh_io.mesh_fingerprint(obj.data)),
        "written_digest": mesh_io.positions_digest(local_rest if several else rest.reshape(-1, 3)),
        "written_matrix": _world(obj),
        "proxy": proxy,
    }
    forget(obj)
    obj[KEY] = props
    group = obj[KEY]
    if several:
        group[rig_members.MEMBERS] = entries
    rig_members.tag(obj, members if several else [obj])
    arrays = _new_store(obj, group)
    arrays["rest"] = packed_arrays.pack(rest.reshape(-1, 3))
    content = {"rest": rest}
    if several:
        content[rig_members.LOCAL_REST] = np.ascontiguousarray(local_rest, dtype=np.float32)
        arrays[rig_members.LOCAL_REST] = packed_arrays.pack(content[rig_members.LOCAL_REST])
    # The arrays one at a time: each copy goes once Blender holds its own. Their digests are of
    # their values, whatever type and packing stores them.
    compact = compact_arrays(surface)
    content.update(compact)
    entries = [_flat_props(compact)]
    if preview is not None:
        group["preview"] = preview
        previewed = compact_preview_arrays(surface.preview)
        content.update((PREVIEW_PREFIX + key, value) for key, value in previewed.items())
        entries.append(_flat_props(previewed, PREVIEW_PREFIX))
    group[DIGESTS] = content_digests(content)
    del content, compact
    for key, value in (entry for part in entries for entry in part):
        (arrays if _is_array(value) else group)[key] = value
    binding = Binding(props["binding_id"], surface, rest.reshape(-1, 3), proxy,
                      surface.preview if preview is not None else None)
    _CACHE[binding.binding_id] = binding
    return binding


def _is_array(value):
    """Whether a stored value goes to the record's text datablock (:data:`STORE`): arrays and bytes."""
    return isinstance(value, (np.ndarray, bytes)) or hasattr(value, "typecode")


def _new_store(obj, group):
    """A new text datablock for the arrays of ``obj``'s record ``group``, pointed at from it under
    :data:`STORE`; returns its (empty) property group."""
    import bpy
    side = bpy.data.texts.new(f"{STORE_PREFIX}{obj.name}")
    side.user_clear()  # its one user: the record's pointer (deleting the record frees it on save)
    side[KEY] = {}
    group[STORE] = side
    return side[KEY]


def arrays_of(obj):
    """The property group holding the arrays of ``obj``'s binding (the rest positions, the skin's,
    the preview's): the one on the text datablock its record points at under :data:`STORE`, or
    the record itself in files of earlier versions; None when there is no readable one."""
    record = readable_record(obj)
    if record is None:
        return None
    side = record.get(STORE)
    if side is None:
        return None if STORE in record else record
    group = side.get(KEY) if hasattr(side, "get") else None
    return group if hasattr(group, "get") and hasattr(group, "keys") else None


def check_editable(obj, what="object"):
    """Raise unless ``obj`` and its data can be changed and saved here (not linked from a library,
    not a library override's read-only part)."""
    for block in (obj, getattr(obj, "data", None)):
        if block is None:
            continue
        if getattr(block, "library", None) is not None or not getattr(block, "is_editable", True):
            raise SkinDetachError(f"{what} {obj.name!r}: expected local, editable data, got data linked from "
                                  f"{getattr(getattr(block, 'library', None), 'filepath', 'a library')!r}; make it "
                                  f"local first (Object > Relations > Make Local)")


def _stored(obj):
    """The stored property group of ``obj`` (raises when it is not one)."""
    props = obj[KEY]
    if not hasattr(props, "get") or not hasattr(props, "keys"):
        raise SkinDetachError(f"object {obj.name!r}: expected a Skin Detach binding group in {KEY!r}, got "
                              f"{type(props).__name__}; press Rebuild")
    return props


def _checked_record(obj):
    """(the stored property group, binding id, proxy object) of ``obj`` after checking that the
    record is of a schema this version reads and still fits the mesh, and that the proxy exists.
    Raises :class:`SkinDetachError` that says to rebuild when it does not."""
    if obj is None or obj.type != 'MESH':
        raise SkinDetachError(f"object: expected a mesh object, got {_describe(obj)}")
    if KEY not in obj:
        raise SkinDetachError(f"object {obj.name!r}: expected a Skin Detach binding, it has none; press Build first")
    check_editable(obj)
    props = _stored(obj)
    version = props.get("schema_version", -1)
    if isinstance(version, int) and version > SCHEMA_VERSION:
        raise SkinDetachError(f"object {obj.name!r}: expected binding schema version {WHOLE_SKIN_SCHEMA} to "
                              f"{SCHEMA_VERSION} (this version of Skin Detach), got {version}: the file was bound by "
                              f"a newer Skin Detach; update the add-on, or press Rebuild to bind it again here")
    if version not in READABLE_SCHEMAS:
        raise SkinDetachError(f"object {obj.name!r}: expected binding schema version {SCHEMA_VERSION}, got {version}; "
                              f"press Rebuild")
    if obj.mode == 'EDIT' or obj.data.is_editmode:
        raise SkinDetachError(f"object {obj.name!r}: expected Object Mode, its mesh is in Edit Mode (Skin Detach "
                              f"never writes a mesh under Edit Mode)")
    if not obj.users_scene:
        raise SkinDetachError(f"object {obj.name!r}: expected it in a scene, it was unlinked from every scene")
    from . import rig_members
    rig_members.check(obj)  # the other objects of a rig of several: each named when it does not fit
    fingerprint = rig_members.fingerprint(obj)
    if fingerprint != props.get("mesh_fingerprint"):
        raise SkinDetachError(f"mesh {obj.data.name!r}: expected the topology it was bound with, the mesh was "
                              f"edited after binding (now {len(obj.data.vertices)} vertices, or its faces changed); "
                              f"press Rebuild")
    binding_id = props.get("binding_id")
    if not isinstance(binding_id, str) or not binding_id:
        raise SkinDetachError(f"object {obj.name!r}: expected a binding id, got {binding_id!r}; press Rebuild")
    proxy = proxy_of(obj)
    if proxy is None:
        raise SkinDetachError(f"object {obj.name!r}: expected its proxy object, it was deleted; press Rebuild")
    if proxy.type != 'MESH' or proxy.get(PROXY_TAG) != obj:
        owner = proxy.get(PROXY_TAG)
        raise SkinDetachError(f"object {obj.name!r}: expected its own proxy, the stored one ({proxy.name!r}) belongs "
                              f"to {getattr(owner, 'name', 'no mesh')!r} (a copy of a bound object?); press Rebuild "
                              f"to bind this one")
    check_editable(proxy, "proxy")
    if proxy.mode == 'EDIT' or proxy.data.is_editmode:
        raise SkinDetachError(f"proxy {proxy.name!r}: expected Object Mode, it is in Edit Mode; leave Edit Mode first")
    return props, binding_id, proxy


def open_binding(obj):
    """:class:`Binding` of ``obj`` after checking that it still fits the mesh and the proxy exists.
    Raises :class:`SkinDetachError` that says to rebuild when it does not. A binding not yet made
    in this session is made now (or, when the background thread is making it, waited for, the
    window's progress shown); a record of schema 1 is rewritten compact (schema 2) once, said on
    the console. A preparation of the binding running in the background is waited for."""
    triangles = _early_triangles(obj)
    props, binding_id, proxy = _checked_record(obj)
    binding = _CACHE.get(binding_id)
    if binding is None:
        opening = _PENDING.get(binding_id)
        if opening is None or opening.name != obj.name or opening.cancelled:
            opening = Opening(obj, props, binding_id, triangles)
        try:
            surface, preview = opening.made()
        finally:
            _PENDING.pop(binding_id, None)
        binding = Binding(binding_id, surface, opening.rest, proxy, preview)
        if opening.version == WHOLE_SKIN_SCHEMA:
            _rewrite_compact(obj, surface)
        _CACHE[binding.binding_id] = binding
    if binding.busy is not None:
        try:  # its error, if not reported yet, is this step's
            _wait(binding.busy, lambda: 0.5)
        except threads.Cancelled:  # not prepared: the step makes what it needs
            pass
        binding.busy = None
    binding.proxy = proxy  # never keep a Blender reference across undo or reload
    _adopt_world_parenting(obj, proxy)
    return binding


def _adopt_world_parenting(obj, proxy):
    """The one place handles of files saved by earlier versions (0.1.0, an identity parent inverse
    under the proxy) are migrated to Blender's parenting (:func:`.handles.adopt_world_parenting`):
    on the first use of the rig after it was opened (the background preparation after a load uses
    it first), and again after an undo back to before it (nothing is left to do on later calls).
    Said on the console."""
    from . import handles  # handles needs mathutils; this module is read without Blender too (scripts/benchmark_scale.py)
    converted = handles.adopt_world_parenting(obj, proxy)
    if converted:
        print(f"Skin Detach: {obj.name}: {len(converted)} handle(s) of an earlier version now parented as Blender "
              f"parents objects (world matrices unchanged): {', '.join(converted)}")


def begin_opening(obj):
    """Start making the :class:`Binding` of ``obj`` on the background thread (its record and mesh
    read here, checked as :func:`open_binding` checks them); returns the :class:`Opening`, or None
    when the binding is made already. :func:`open_binding` finishes it on the main thread."""
    triangles = _early_triangles(obj)
    props, binding_id, _ = _checked_record(obj)
    if binding_id in _CACHE:
        return None
    opening = _PENDING.get(binding_id)
    if opening is None or opening.name != obj.name or opening.cancelled:
        opening = _PENDING[binding_id] = Opening(obj, props, binding_id, triangles)
        opening.start()
    return opening


def drop_all():
    """Forget every binding made in this session and every opening under way (their file is
    closed: the caller cancels their jobs, :func:`.core.threads.cancel_all`)."""
    _CACHE.clear()
    _PENDING.clear()


def _early_triangles(obj):
    """The triangles of a mesh of triangles only whose binding is to be made, read before its
    record is checked (the check then finds the fingerprint made from the same read), else None: a
    mesh of quads or ngons is split as its rest shape splits, once the rest is read (:class:`Opening`)."""
    from . import rig_members
    if _needs_opening(obj) and not rig_members.is_multi(obj) and mesh_io.triangles_only(obj.data):
        return mesh_io.read_triangles(obj.data)
    return None


def _needs_opening(obj):
    """Whether ``obj`` has a record whose binding is neither made nor being made (a mesh object)."""
    record = readable_record(obj) if obj is not None and obj.type == 'MESH' else None
    binding_id = None if record is None else record.get("binding_id")
    if not isinstance(binding_id, str) or binding_id in _CACHE:
        return False
    pending = _PENDING.get(binding_id)
    return pending is None or pending.name != obj.name


class Opening:
    """Making the core side of one stored binding. Made on the main thread, it reads what it needs
    from Blender (the record's arrays, the rest positions, the mesh's triangles; copies); then
    :meth:`make` uses numpy and scipy only, so it may run on the background thread (:meth:`start`).

    name      the object's name
    version   the record's schema version
    rest      (n, 3) float32 rest positions (checked): read here for a mesh of quads or ngons (its
              split needs them), else unpacked by :meth:`make` (at 10M vertices unpacking takes
              0.6-1 s, which the main thread is spared)
    fraction  how far :meth:`make` got, 0 to 1, and ``stage``, what it does
    """

    def __init__(self, obj, props, binding_id, triangles=None):
        self.name = obj.name
        self.binding_id = binding_id
        self.version = props["schema_version"]
        stored_arrays = arrays_of(obj)
        if stored_arrays is None:
            raise SkinDetachError(f"binding of {obj.name!r}: expected its arrays in the text datablock its record "
                                  f"points at, it was deleted or damaged; press Rebuild")
        self._arrays = {key: _copied(source, key) for source in (props, stored_arrays) for key in source.keys()
                        if key not in ("proxy", "preview", STORE, DIGESTS, "rest")}  # the rest: read below, once
        digests = props.get(DIGESTS)
        self._digests = None if digests is None else _read_digests(obj, digests)
        from . import rig_members
        self._n = rig_members.vertex_count(obj)
        stored_rest = stored_arrays.get("rest")
        self.rest, self._packed_rest = None, None
        if triangles is not None and packed_arrays.is_packed(stored_rest):
            self._packed_rest = stored_rest  # bytes: Blender gave a copy
        else:
            self.rest = np.array(_checked_rest(obj, stored_arrays, self._n))  # its own, not Blender's
        # Quads and ngons split as the rest shape splits (the skin was bound over those): a posed
        # quad mesh's own split differs where a quad folded across its first diagonal.
        if triangles is None:
            parts = rig_members.local_rest(obj) if rig_members.is_multi(obj) else [self.rest]
            triangles = rig_members.read_triangles(obj, parts)
        self._triangles = triangles
        self.fraction, self.stage = 0.0, "reading"
        self._job = None

    def start(self):
        """Run :meth:`make` (with the free rebuilds prepared) on the background thread."""
        self._job = threads.submit(self.make, True, name=f"the opening of {self.name!r}")

    def done(self):
        return self._job is None or self._job.done()

    def cancel(self):
        """Stop :meth:`make` on the background thread at its next progress report (its mesh was
        deleted, cleared or built again meanwhile) and forget it."""
        if self._job is not None:
            self._job.cancel()
        if _PENDING.get(self.binding_id) is self:
            del _PENDING[self.binding_id]

    @property
    def cancelled(self):
        """Its background job was cancelled (:func:`.core.threads.cancel_all`): nothing is made."""
        return self._job is not None and self._job.cancelled

    def made(self):
        """(surface, preview or None): the background's when started (waited for), else made now."""
        if self._job is None:
            return self.make()
        return _wait(self._job, lambda: self.fraction)

    def _report(self, low, high):
        def report(fraction, stage):
            threads.checkpoint()
            self.fraction, self.stage = low + (high - low) * fraction, stage
        return report

    def make(self, prepare=False):
        """(:class:`SkinDetachedSurface` over the mesh, its :class:`Preview` or None) from what was
        read; with ``prepare``, their free rebuilds made too (what the first rebuild would pay)."""
        source = f"binding of {self.name!r}"
        if self.rest is None:
            self.rest = _rest_of(self.name, self._packed_rest, self._n)
            self._packed_rest = None
        arrays = self._arrays
        main = {key: value for key, value in arrays.items() if not key.startswith(PREVIEW_PREFIX)}
        n = self.rest.shape[0]
        if self.version == WHOLE_SKIN_SCHEMA:
            surface = SkinDetachedSurface.from_arrays(main, source=source)
            if surface.n_detail != n:
                raise SkinDetachError(f"{source}: expected a skin over the mesh's {n} vertices, got "
                                      f"{surface.n_detail}; press Rebuild")
            surface.attach_topology(self._triangles)  # the topology was checked
        else:
            main = _unpacked(main, source)
            surface = surface_from_compact(main, self.rest, self._triangles, source,
                                           self._report(0.0, 0.5 if prepare else 1.0))
        self._triangles = None
        preview, stored = None, {}
        if PREVIEW_PREFIX + "format_tag" in arrays:
            stored = _unpacked({key[len(PREVIEW_PREFIX):]: value for key, value in arrays.items()
                                if key.startswith(PREVIEW_PREFIX)}, f"preview of {self.name!r}")
            if str(stored["format_tag"]) == COMPACT_PREVIEW_TAG:  # its skin bound again (schema 3)
                preview = preview_from_compact(stored, surface.proxy_vertices, surface.proxy_faces,
                                               f"preview of {self.name!r}")
            else:  # stored whole (schema 2 and before)
                preview = Preview.from_arrays(stored, source=f"preview of {self.name!r}")
        if self._digests is not None:  # well-formed (the checks above passed), but what the build stored?
            check_digests({**main, **{PREVIEW_PREFIX + key: value for key, value in stored.items()},
                           "rest": self.rest}, self._digests, source)
        if prepare:
            self.fraction, self.stage = 0.5, "diffusing the skin"
            surface.prepare_layout()
            if preview is not None:
                threads.checkpoint()
                self.fraction, self.stage = 0.95, "diffusing the preview's skin"
                preview.surface.prepare_layout()
        self.fraction, self.stage = 1.0, "done"
        return surface, preview


def _read_digests(obj, digests):
    """{key: hex digest} of the record's :data:`DIGESTS` group (raises when it is not one)."""
    if not hasattr(digests, "items") or not all(isinstance(value, str) for _, value in digests.items()):
        raise SkinDetachError(f"binding of {obj.name!r} {DIGESTS}: expected a group of digests (strings), got "
                              f"{type(digests).__name__}; press Rebuild")
    return dict(digests.items())


def _copied(props, key):
    """The stored value under ``key``: an array copied out of Blender (the background thread reads
    it after the main thread goes on), a string, bytes or a number as they are."""
    value = props[key]
    if hasattr(value, "__len__") and not isinstance(value, (str, bytes)):
        return np.array(value)
    return value


def _unpacked(arrays, source):
    """``arrays`` with each array stored as bytes (:func:`_flat_props`) read back in its type:
    packed ones unpacked, narrow ones (their type under the key with :data:`TYPE_SUFFIX`) viewed."""
    out = {key: value for key, value in arrays.items() if not key.endswith(TYPE_SUFFIX)}
    for key, value in out.items():
        if isinstance(value, (bytes, bytearray)) and key + TYPE_SUFFIX not in arrays:
            out[key] = stored_array(value, f"{source} {key}")
    for key in [key for key in arrays if key.endswith(TYPE_SUFFIX)]:
        name, packed = arrays[key], arrays.get(key[:-len(TYPE_SUFFIX)])
        kind = NARROW_TYPES.get(name) if isinstance(name, str) else None
        if kind is None or not isinstance(packed, bytes) or len(packed) % np.dtype(kind).itemsize:
            raise SkinDetachError(f"{source} {key[:-len(TYPE_SUFFIX)]}: expected bytes of one of "
                                  f"{sorted(NARROW_TYPES)}, got {type(packed).__name__} of type {name!r}; press Rebuild")
        out[key[:-len(TYPE_SUFFIX)]] = np.frombuffer(packed, dtype=kind)
    return out


def _wait(job, fraction):
    """The result of ``job`` (a :class:`.core.threads.Job`), waited for with the window's progress
    shown (``fraction()``: 0 to 1) when it is not done yet."""
    if job.done():
        return job.result()
    import bpy
    manager = getattr(bpy.context, "window_manager", None)
    if manager is not None:
        manager.progress_begin(0, 100)
    try:
        while True:
            try:
                return job.result(timeout=0.1)
            except concurrent.futures.TimeoutError:
                if manager is not None:
                    manager.progress_update(int(100 * fraction()))
    finally:
        if manager is not None:
            manager.progress_end()


def _rewrite_compact(obj, surface):
    """Rewrite ``obj``'s schema-1 record compact (schema 2): the whole skin goes, the carrier and the
    proxy are stored as :func:`store` stores them; the figures, rest and preview stay as they are."""
    group = obj[KEY]
    arrays = arrays_of(obj)
    for key in WHOLE_SKIN_KEYS:
        group.pop(key, None)
        arrays.pop(key, None)
    if STORE not in group:  # arrays on the object (185f42b and before): to a text datablock of their own
        moved = {key: _copied(group, key) for key in list(group.keys()) if _is_array(group[key])
                 and key != "written_matrix"}
        for key in moved:
            del group[key]
        arrays = _new_store(obj, group)
        for key, value in moved.items():
            arrays[key] = value
    for key, value in _flat_props(compact_arrays(surface)):
        (arrays if _is_array(value) else group)[key] = value
    group["schema_version"] = SCHEMA_VERSION
    print(f"Skin Detach: {obj.name}: binding of schema version {WHOLE_SKIN_SCHEMA} rewritten compact "
          f"(schema {SCHEMA_VERSION}); save the file to keep it so")


def _checked_rest(obj, props, n):
    return _rest_of(obj.name, props.get("rest"), n)


def _rest_of(name, value, n):
    """(n, 3) float32 the rest positions stored as ``value`` in the binding of object ``name``:
    packed (schema 3) or a whole float32 array (earlier schemas), bit for bit either way; checked."""
    try:
        if value is None:
            raise ValueError("none stored")
        rest = np.asarray(stored_array(value, f"binding of {name!r} rest"), dtype=np.float32).reshape(-1, 3)
    except (TypeError, ValueError) as exc:
        raise SkinDetachError(f"binding of {name!r}: expected stored rest positions ({n}, 3), got unreadable "
                              f"data ({exc}); press Rebuild") from None
    if rest.shape != (n, 3):
        raise SkinDetachError(f"binding of {name!r}: expected stored rest positions ({n}, 3), got {rest.shape}; "
                              f"press Rebuild")
    if not np.isfinite(rest).all():
        raise SkinDetachError(f"binding of {name!r}: expected finite stored rest positions, got NaN or inf; "
                              f"press Rebuild")
    return rest


def readable_record(obj):
    """The stored property group of ``obj``'s binding, or None when it has none or it is damaged
    (not a group)."""
    return obj[KEY] if has_binding(obj) and hasattr(obj[KEY], "get") else None


def stored_object(obj, key):
    """The object stored under ``key`` in ``obj``'s binding, or None when there is none or it was
    deleted (deleting an object in the viewport unlinks it; the pointer may keep an orphan alive)."""
    record = readable_record(obj)
    if record is None:
        return None
    found = record.get(key)
    if found is None or not hasattr(found, "users_scene") or getattr(found, "type", None) is None \
            or not found.users_scene:
        return None
    return found


def proxy_of(obj):
    """The proxy object of ``obj``, or None when it has none or it was deleted."""
    return stored_object(obj, "proxy")


def check_topology(obj):
    """Raise, as opening the binding does, unless every mesh of ``obj``'s rig still has the topology
    it was bound with, its corners read anew (not the fingerprint kept since Blender last reported
    a change: a script that reorders the vertices with bmesh, the counts the same, right after a
    write of Skin Detach's, is reported in one update with that write)."""
    from . import rig_members
    for member in rig_members.objects(obj):
        if member is not None and getattr(member, "type", None) == 'MESH':
            mesh_io.forget_fingerprint(member.data)
    _checked_record(obj)


def check_unedited(obj):
    """Raise unless the mesh still holds what Skin Detach last wrote (or the rest shape); where it
    does not, its topology is read anew first (:func:`check_topology`): a reordered mesh is named
    as edited in topology, to be rebuilt, not reset."""
    if not holds_written(obj):
        check_topology(obj)
        from . import rig_members
        what = f"mesh {obj.data.name!r}" if not rig_members.is_multi(obj) else \
            f"meshes of {', '.join(repr(name) for name in rig_members.names(obj))}"
        raise SkinDetachError(f"{what}: expected the positions Skin Detach last wrote, they were "
                              f"edited since (sculpt or Edit Mode?); press Rebuild to bind the new shape, or Reset "
                              f"to return to the bound rest shape")


def _world(obj):
    """The object's world matrix, 16 float64 row-major (what a mesh's positions were written under)."""
    return np.array(obj.matrix_world, dtype=np.float64).ravel()


def mark_written(obj, positions, digest=None):
    """Record the digest of the (n, 3) positions just written (``digest``: their
    :func:`.mesh_io.positions_digest`, if the caller made it) and the world matrix they were
    written under."""
    set_written_state(obj, (mesh_io.positions_digest(positions) if digest is None else digest, _world(obj)))


def written_state(obj):
    """(digest of the positions Skin Detach last wrote into ``obj``'s mesh, the object's world
    matrix then (16,) or None in files of earlier versions)."""
    stored = obj[KEY].get("written_matrix")
    try:
        matrix = None if stored is None else np.asarray(stored, dtype=np.float64).reshape(16)
    except (TypeError, ValueError):
        matrix = np.full(16, np.nan)
    if matrix is not None and not np.isfinite(matrix).all():
        raise SkinDetachError(f"binding of {obj.name!r}: expected written_matrix: 16 finite numbers, got "
                              f"{stored!r:.60}; press Apply or Rebuild")
    return obj[KEY].get("written_digest"), matrix


def set_written_state(obj, state):
    digest, matrix = state
    obj[KEY]["written_digest"] = digest
    if matrix is None:
        obj[KEY].pop("written_matrix", None)
    else:
        obj[KEY]["written_matrix"] = matrix


def holds_written(obj):
    """The mesh holds exactly what Skin Detach last wrote (or the rest shape it was bound with)."""
    from . import rig_members
    return rig_members.written_digest(obj) == _stored(obj).get("written_digest")


def moved_since_written(obj):
    """The object's world matrix differs from the one the mesh was last written under (None: not
    known, a file of an earlier version)."""
    _, matrix = written_state(obj)
    if matrix is None:
        return None
    now = _world(obj)
    return not np.allclose(now, matrix, rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(matrix).max())))


def rest_positions(obj):
    """(n, 3) float32 rest positions ``obj`` was bound with, in its mesh's vertex order (checked)."""
    _stored(obj)
    arrays = arrays_of(obj)
    if arrays is None:
        raise SkinDetachError(f"binding of {obj.name!r}: expected its arrays in the text datablock its record "
                              f"points at, it was deleted or damaged; press Rebuild")
    from . import rig_members
    return _checked_rest(obj, arrays, rig_members.vertex_count(obj))


def binding_id(obj):
    """The id of ``obj``'s binding (changes with every Build), or None without one."""
    record = readable_record(obj)
    value = None if record is None else record.get("binding_id")
    return value if isinstance(value, str) else None


def cached(obj):
    """The :class:`Binding` of ``obj`` opened in this session (its figures, its solvers), or None."""
    return _CACHE.get(binding_id(obj))


def forget(obj):
    """Remove the stored binding of ``obj`` (the caller removes proxy and handles)."""
    if KEY in obj:
        record = readable_record(obj)
        side = None if record is None else record.get(STORE)
        if record is not None:
            _CACHE.pop(record.get("binding_id"), None)
            _PENDING.pop(record.get("binding_id"), None)  # an opening of it under way: what it makes is dropped
        from . import rig_members
        rig_members.untag(obj)
        del obj[KEY]
        _remove_unused(side)


def _remove_unused(side):
    """Remove the text datablock ``side`` (a record's :data:`STORE`) once nothing points at it."""
    import bpy
    if side is not None and getattr(side, "name", "").startswith(STORE_PREFIX) and side.users == 0:
        bpy.data.texts.remove(side)


def strip_copy(obj):
    """Delete the stored binding properties from ``obj``, a copy of a bound object (the original's
    runtime cache stays)."""
    if KEY in obj:
        del obj[KEY]


def _describe(obj):
    return "nothing" if obj is None else f"{obj.name!r} of type {obj.type}"
