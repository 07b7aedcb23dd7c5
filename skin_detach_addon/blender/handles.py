"""Handles and anchors: empties parented to the proxy, each holding a set of proxy vertices.

A handle carries its proxy vertices by the rigid motion of its empty since it was made: in the
bound object's local space, ``delta = object_world^-1 @ empty_world @ rest_local^-1`` applied to
the rest proxy positions. An anchor holds its proxy vertices at rest wherever its empty is.
Each empty stores under ``empty["_skin_detach_handle"]``: its owner (an ID pointer), kind,
``proxy_ids`` (int32), ``detail_ids`` (int32, empty when made from the proxy), ``rest_local``
(16 float64, row-major) and ``parenting`` (:data:`WORLD_PARENTING`: parented to the proxy as
Blender parents objects, its transform its world frame; none in files of earlier versions). Handles made from detail vertices survive a Rebuild. Mirror twins
and symmetric rigs: :mod:`.handle_symmetry`.
"""

import numpy as np
from mathutils import Matrix

from ..core.errors import SkinDetachError
from ..core.validation import as_ids

TAG = "_skin_detach_handle"
#: Handle targets farther than this from the object's origin are refused (float32 stores the mesh).
MAX_COORDINATE = 1e12
HANDLE = "HANDLE"
ANCHOR = "ANCHOR"
#: Where an empty's rest frame sits: the selection's median point. Empties made by earlier
#: versions have no "pivot" key: theirs sits at the centroid of the proxy vertices they hold.
PIVOT = "selection median"
#: A record's "parenting" when its empty was parented as Blender parents objects (its transform its
#: world frame: :func:`_parent_in_world`); records of earlier versions have none
#: (:func:`adopt_world_parenting` migrates them once).
WORLD_PARENTING = "world"


def is_handle(obj):
    """``obj`` is a handle or anchor empty that is in a scene (one deleted in the viewport but kept
    alive by another object's pointer, such as its twin's, is gone)."""
    return getattr(obj, "type", None) == 'EMPTY' and TAG in obj and len(obj.users_scene) > 0


def owner(empty):
    """The bound mesh object a handle or anchor empty belongs to (None if it is none)."""
    found = value_of(empty, "owner") if is_handle(empty) else None
    return found if getattr(found, "type", None) is not None else None


def kind_of(empty):
    """HANDLE or ANCHOR (raises for anything else)."""
    kind = value_of(empty, "kind")
    if kind not in (HANDLE, ANCHOR):
        raise SkinDetachError(f"handle {empty.name!r}: expected kind {HANDLE!r} or {ANCHOR!r}, got {kind!r}; "
                              f"remove it")
    return kind


#: (empty name, key) -> (where Blender holds the stored array, its size, its strided sample, the
#: limit it was checked against, the checked int64 ids): a drag move reads every handle's ids,
#: a million for the bend's handle at 10M (3 ms each, and again for the symmetry checks).
_CHECKED = {}
#: Values of a stored array compared with the checked copy's before the copy is used again.
SAMPLE = 64


def _ids(empty, key, limit=None):
    """(k,) int64 the ids stored under ``key``, checked: integers in [0, ``limit``) (non-negative
    when no bound is known). The checked copy is kept while the stored array is the same one
    (Blender's memory, size and a strided sample of values): the same read-only array object is
    returned (callers compare ids by identity first)."""
    raw = value_of(empty, key, [])
    view = np.asarray(raw)
    where = view.__array_interface__["data"][0] if view.size else 0
    step = max(1, view.size // SAMPLE)
    cached = _CHECKED.get((empty.name, key))
    if cached is not None and cached[:2] == (where, view.size) and cached[3] == limit and \
            np.array_equal(cached[2], view[::step]):
        return cached[4]
    try:
        checked = as_ids(f"handle {empty.name!r}", view, limit, key)
    except SkinDetachError as exc:
        raise SkinDetachError(f"{exc}; remove it or Rebuild") from None
    checked.flags.writeable = False  # shared by every caller until the stored array changes
    if len(_CHECKED) > 4096:
        _CHECKED.clear()
    _CHECKED[empty.name, key] = (where, view.size, view[::step].copy(), limit, checked)
    return checked


def proxy_ids_of(empty, m=None):
    """(c,) int64 proxy vertex ids the empty holds (checked against ``m`` proxy vertices if given)."""
    return _ids(empty, "proxy_ids", m)


def detail_ids_of(empty, n=None):
    """(k,) int64 detail vertex ids the empty was made from (empty when made from the proxy)."""
    return _ids(empty, "detail_ids", n)


def rest_local_of(empty):
    """(4, 4) float64 rest frame of the empty in the bound object's local space (a copy: the ID
    property it is read from may be replaced, by a Rebuild, while the array is still held)."""
    stored = value_of(empty, "rest_local")
    try:
        frame = np.array(stored, dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError):
        frame = None
    if frame is None or not np.isfinite(frame).all() or not _invertible_affine(frame.tolist()):
        got = f"{np.size(stored)} values" if frame is None else \
            "non-finite values" if not np.isfinite(frame).all() else "a singular or not affine frame"
        raise SkinDetachError(f"handle {empty.name!r}: expected rest_local: 16 finite numbers of an invertible "
                              f"affine 4x4 frame, got {got if stored is not None else 'none'}; remove it or Rebuild")
    return frame


def _invertible_affine(rows):
    """The 4x4 ``rows`` (lists) end in (0, 0, 0, 1) and their 3x3 part has a non-zero determinant
    (in plain floats: numpy's det costs a drag move 10 us per handle)."""
    (a, b, c, _), (d, e, f, _), (g, h, i, _), bottom = rows
    return bottom == [0.0, 0.0, 0.0, 1.0] and a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) != 0.0


def handles_of(obj):
    """Handle and anchor empties of ``obj`` (their records name it as owner), oldest first (the
    newer wins on shared vertices; see :func:`.core.detached_surface.held_detail.owned_pairs`),
    wherever they hang: under the proxy, under another handle's empty (a hand's parented to the
    forearm's, Ctrl+P) or anywhere else (Alt+P cleared its parent)."""
    found = [o for o in _all_objects() if is_handle(o) and value_of(o, "owner") == obj]
    ages = _ages(found)
    return sorted(found, key=lambda o: ages[o.name])


def value_of(empty, key, default=None):
    """The value under ``key`` in a handle's record, or ``default`` (also when the record is damaged)."""
    tag = empty[TAG]
    return tag.get(key, default) if hasattr(tag, "get") else default


def _ages(empties):
    """Sort key of every empty by name: (serial, name's number, name). A Shift+D copy keeps its
    original's serial; where serials repeat, every copy but the first (by Blender's ".001"
    suffix) counts as made after all the others, so the copy is the newest."""
    def own(empty):
        serial = value_of(empty, "serial")
        stem, dot, tail = empty.name.rpartition(".")
        copy = int(tail) if dot and tail.isdigit() else 0
        digits = (stem if copy else empty.name).rsplit("_", 1)[-1]
        return (serial if isinstance(serial, int) else -1, copy, int(digits) if digits.isdigit() else 0, empty.name)

    keys = sorted(own(e) for e in empties)
    newest = max((key[0] for key in keys), default=0)
    out, seen = {}, set()
    for serial, copy, number, name in keys:
        if serial >= 0 and serial in seen:
            newest += 1
            serial = newest
        seen.add(serial)
        out[name] = (serial, number, name)
    return out


def next_serial(empties):
    """The serial of a handle made now: after every one of ``empties`` (copies included)."""
    return 1 + max((age[0] for age in _ages(empties).values()), default=0)


def _all_objects():
    import bpy
    return bpy.data.objects


def add(obj, proxy, kind, proxy_ids, rest_center, now_center, detail_ids=None, size=1.0, group="", mirror=""):
    """New empty holding ``proxy_ids`` (c,), placed at ``now_center`` (3,) in the bound object's
    local space, its rest frame at ``rest_center`` (3,): the selection's median point (the mean
    of its vertices, Blender's pivot for R and S) now and at rest, so an empty made on a deformed
    mesh starts out where the mesh is. ``group``: the vertex group it was made from (for the
    panel); ``mirror``: the local axis ("X", "Y", "Z") it is symmetric about or mirrored across
    (see :func:`.handle_symmetry.pair`)."""
    import bpy
    if kind not in (HANDLE, ANCHOR):
        raise SkinDetachError(f"kind: expected {HANDLE!r} or {ANCHOR!r}, got {kind!r}")
    ids = np.unique(np.asarray(proxy_ids, dtype=np.int64))
    if ids.size == 0:
        raise SkinDetachError("selection: expected at least one selected vertex, got none")
    rest_centroid = np.asarray(rest_center, dtype=np.float64)
    now_centroid = np.asarray(now_center, dtype=np.float64)
    base = f"{obj.name}_{kind.lower()}"
    empty = bpy.data.objects.new(_free_name(base), None)
    empty.empty_display_type = 'SPHERE' if kind == HANDLE else 'CUBE'
    empty.empty_display_size = size
    empty.hide_render = True
    proxy.users_collection[0].objects.link(empty)
    _parent_in_world(obj, empty, proxy, now_centroid)
    rest_local = np.eye(4)
    rest_local[:3, 3] = rest_centroid
    serial = next_serial(handles_of(obj))
    empty[TAG] = {
        "owner": obj,
        "serial": serial,
        "kind": kind,
        "proxy_ids": ids.astype(np.int32),
        "detail_ids": np.asarray(detail_ids if detail_ids is not None else [], dtype=np.int32),
        "rest_local": rest_local.ravel(),
        "group": str(group),
        "mirror": str(mirror),
        "pivot": PIVOT,
        "parenting": WORLD_PARENTING,
    }
    return empty


def _chain_world(obj, proxy):
    """(4, 4) the proxy's world matrix from its owner's (the proxy is the mesh object's child): a
    proxy made a moment ago has no evaluated matrix_world yet."""
    return np.array(obj.matrix_world, dtype=np.float64) @ np.array(proxy.matrix_parent_inverse, dtype=np.float64) \
        @ np.array(proxy.matrix_basis, dtype=np.float64)


def _parent_in_world(obj, empty, proxy, centre):
    """Parent ``empty`` to ``proxy`` at ``centre`` (3,) in the bound object's local space as Blender
    parents an object (Ctrl+P): the parent inverse is the inverse of the proxy's world matrix (its
    chain from the object, :func:`_chain_world`) and the empty's transform is its world transform,
    so its world matrix is its basis (``handle.location`` is in world space, as for any child
    object). Ctrl+P, Alt+P and Keep Transform then keep it where it is, and a world rotation of
    it (an R in a drag) stays a rotation under a non-uniform scale of the object. Where that world
    frame is sheared (a rotated child of a non-uniformly scaled parent), which Blender cannot store
    as location, rotation and scale, the parent inverse is the identity and the transform the
    local frame."""
    chain = _chain_world(obj, proxy)
    frame = np.eye(4)
    frame[:3, 3] = centre
    wanted = chain @ frame
    empty.parent = proxy
    if not _storable(wanted):
        empty.matrix_parent_inverse = Matrix.Identity(4)
        empty.matrix_basis = Matrix(frame.tolist())
        return
    empty.matrix_parent_inverse = Matrix(np.linalg.inv(chain).tolist())
    empty.matrix_basis = Matrix(wanted.tolist())


def _storable(matrix):
    """Blender keeps a transform as float32 location, rotation and scale: ``matrix`` (4, 4) survives
    that within float32 rounding (a shear shows as an error of the order of the matrix itself,
    rounding as one of 1e-7 of it)."""
    location, rotation, scale = Matrix(np.asarray(matrix).tolist()).decompose()
    kept = np.array(Matrix.LocRotScale(location, rotation, scale), dtype=np.float64)
    return bool(np.abs(kept - matrix).max() <= 1e-5 * max(1.0, float(np.abs(matrix).max())))


#: Data paths of an object's own transform: a handle keyed or driven on one of them is left as it is
#: by :func:`adopt_world_parenting`.
TRANSFORM_PATHS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale",
                   "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale")


def animated_transform(empty):
    """The empty's transform is keyed or driven (an F-curve or driver on one of
    :data:`TRANSFORM_PATHS`)."""
    animation = empty.animation_data
    if animation is None:
        return False
    curves = list(animation.drivers)
    action = animation.action
    if action is not None:
        slot = getattr(animation, "action_slot", None)
        if slot is None:
            curves += list(action.fcurves)
        else:
            from bpy_extras import anim_utils
            channelbag = anim_utils.action_get_channelbag_for_slot(action, slot)
            curves += [] if channelbag is None else list(channelbag.fcurves)
    return any(curve.data_path in TRANSFORM_PATHS for curve in curves)


def adopt_world_parenting(obj, proxy):
    """Migrate handles made by earlier versions (0.1.0: parented to the proxy with an identity
    parent inverse, so their transform was in the object's local space and Ctrl+P made them jump)
    to Blender's parenting (:func:`_parent_in_world`): each handle or anchor of ``obj`` whose record
    has no "parenting" (made by an earlier version) and whose parent is ``proxy`` with an identity
    parent inverse, under a proxy whose world matrix is not the identity, gets the inverse of that
    matrix as its parent inverse and its world matrix as its transform, so its world matrix is
    unchanged (to float32 rounding), and :data:`WORLD_PARENTING` in its record, so it is converted
    once. Left as they are: handles keyed or driven on their transform (:func:`animated_transform`:
    their keys are in the old space) and those whose world frame Blender cannot store (sheared).
    The twins' sync record follows the transform. Returns the names of the empties converted."""
    chain = _chain_world(obj, proxy)
    if np.array_equal(chain, np.eye(4)):
        return []  # both conventions agree
    identity = Matrix.Identity(4)
    converted = []
    for empty in proxy.children:
        if not is_handle(empty) or value_of(empty, "owner") != obj or value_of(empty, "parenting") is not None \
                or empty.matrix_parent_inverse != identity or animated_transform(empty):
            continue
        old = np.array(empty.matrix_basis, dtype=np.float64)
        world = chain @ old
        if not np.isfinite(world).all() or not _storable(world):
            continue
        empty.matrix_parent_inverse = Matrix(np.linalg.inv(chain).tolist())
        empty.matrix_basis = Matrix(world.tolist())
        synced = value_of(empty, "synced")
        if synced is not None and np.array_equal(np.asarray(synced, dtype=np.float64), old.ravel()):
            empty[TAG]["synced"] = np.array(empty.matrix_basis, dtype=np.float64).ravel()
        empty[TAG]["parenting"] = WORLD_PARENTING
        converted.append(empty.name)
    return converted


def place_at_rest(obj, empties):
    """Put every handle and anchor of ``empties`` back on its rest frame, parents first (a handle
    parented to another handle's empty is placed once its parent is): its world matrix becomes
    ``obj``'s world matrix times its rest frame, whatever its parent and parent inverse."""
    import bpy
    frames = {empty.name: rest_local_of(empty) for empty in empties}  # all checked before anything moves
    world = np.array(obj.matrix_world, dtype=np.float64)
    pending = list(empties)
    while pending:
        names = {e.name for e in pending}
        level = [e for e in pending if e.parent is None or e.parent.name not in names]
        for empty in level:
            parent = empty.parent
            if parent is None:
                above = np.eye(4)  # Blender ignores the parent inverse of an object without a parent
            else:
                if not is_handle(parent) and parent.parent == obj:  # the proxy
                    above = _chain_world(obj, parent)
                else:
                    above = np.array(parent.matrix_world, dtype=np.float64)
                above = above @ np.array(empty.matrix_parent_inverse, dtype=np.float64)
            empty.matrix_basis = Matrix((np.linalg.solve(above, world @ frames[empty.name])).tolist())
        pending = [e for e in pending if e not in level]
        if pending:
            bpy.context.view_layer.update()  # the placed parents' world matrices, for their children


def group_of(empty):
    """The vertex group a handle was made from, or ""."""
    return str(value_of(empty, "group", ""))


def _free_name(base):
    import bpy
    index = 1
    while f"{base}_{index}" in bpy.data.objects:
        index += 1
    return f"{base}_{index}"


def remove(empty):
    import bpy
    bpy.data.objects.remove(empty, do_unlink=True)


def rebind(empty, proxy, proxy_ids, rest_centroid):
    """After a Rebuild: new ``proxy_ids`` and rest frame at ``rest_centroid`` (3,), the selection's
    median point at rest, the empty on the new proxy (one parented to another handle's empty, a
    hand to its forearm, keeps that parent: :func:`place_at_rest` puts it back at rest once its
    parent is)."""
    if not is_handle(empty.parent):
        _parent_in_world(proxy.parent, empty, proxy, rest_centroid)  # the proxy is its mesh object's child
    rest_local = np.eye(4)
    rest_local[:3, 3] = rest_centroid
    props = empty[TAG]
    # Assigning over an existing ID-property array keeps its old length: delete it first.
    for key, value in (("proxy_ids", np.asarray(proxy_ids, dtype=np.int32)), ("rest_local", rest_local.ravel())):
        del props[key]
        props[key] = value
    props["pivot"] = PIVOT
    props["parenting"] = WORLD_PARENTING


def has_old_pivot(empty):
    """The empty was made by an earlier version: its R/S pivot is the centroid of the proxy
    vertices it holds, not the selection's median point (a Rebuild moves it there)."""
    return value_of(empty, "pivot") != PIVOT and detail_ids_of(empty).size > 0


def check_transform(obj, what="handle"):
    """Raise unless the world matrix of ``obj`` (a handle's empty, ``what`` names it, or the bound
    object) is finite, naming the first of its own transform fields that is not (location,
    rotation, scale, their deltas, the parent inverse) with its values, else its parent."""
    if np.isfinite(np.array(obj.matrix_world, dtype=np.float64)).all():
        return
    quaternion = obj.rotation_mode == 'QUATERNION'
    rotation = {'QUATERNION': "rotation_quaternion", 'AXIS_ANGLE': "rotation_axis_angle"}.get(obj.rotation_mode,
                                                                                              "rotation_euler")
    for field in ("location", rotation, "scale", "delta_location",
                  "delta_rotation_quaternion" if quaternion else "delta_rotation_euler", "delta_scale",
                  "matrix_parent_inverse"):
        values = np.array(getattr(obj, field), dtype=np.float64)
        if not np.isfinite(values).all():
            raise SkinDetachError(f"{what} {obj.name!r}: expected a finite {field}, got "
                                  f"{tuple(float(v) for v in values.ravel())} (nothing was written); fix or undo it")
    parent = getattr(obj.parent, "name", None)
    raise SkinDetachError(f"{what} {obj.name!r}: expected a finite transform, got a non-finite world matrix "
                          f"{'from its parent ' + repr(parent) if parent else 'from a constraint or driver'} "
                          f"(nothing was written); fix or undo it")


def local_motion(obj, empty):
    """(4, 4) motion of a handle in the local space of ``obj`` since it was made (raises naming
    the field when a transform is not finite)."""
    return local_motions(obj, [empty])[0]


def local_motions(obj, empties):
    """(e, 4, 4) the motion of each handle of ``empties`` in the local space of ``obj`` since it
    was made, ``obj_world^-1 @ empty_world @ rest_local^-1`` (raises naming the field when a
    transform is not finite, or the handle when it is singular): one inversion of the object's
    matrix and one batched one of the rest frames for all of them (a rig of 48 handles reads
    them on every drag move)."""
    world = np.array(obj.matrix_world, dtype=np.float64)
    placed = np.array([np.array(empty.matrix_world, dtype=np.float64) for empty in empties]).reshape(-1, 4, 4)
    rest = np.array([rest_local_of(empty) for empty in empties]).reshape(-1, 4, 4)
    if not (np.isfinite(world).all() and np.isfinite(placed).all()):
        check_transform(obj, "object")
        for empty in empties:
            check_transform(empty)
    try:
        return np.linalg.solve(world, placed) @ np.linalg.inv(rest)
    except np.linalg.LinAlgError:
        singular = [e.name for e, m in zip(empties, placed) if abs(np.linalg.det(world @ m)) == 0.0] or \
            [e.name for e in empties]
        raise SkinDetachError(f"object {obj.name!r}: expected an invertible transform (no zero scale) for its "
                              f"handle {singular[0]!r}, got a singular one") from None


def constraints(obj, empties, rest_proxy, n=None):
    """Constrained proxy ids (c,) sorted, their targets (c, 3) in local space, the rigid group
    of every proxy vertex (m,) (0: anchors, 1, 2, ...: each handle, -1: free), and the held
    detail: (group label, detail ids (h,), (4, 4) local motion) per handle or anchor made from
    detail vertices (an anchor's motion the identity), from the handle and anchor ``empties`` of
    ``obj`` (:func:`handles_of`, oldest first) in that order: where they share proxy or detail
    vertices the newer wins (:func:`.core.detached_surface.held_detail.owned_pairs`)."""
    # n: the detail's vertex count (default: obj's; a rig of several objects: all of theirs)
    m, n = rest_proxy.shape[0], len(obj.data.vertices) if n is None else n
    targets = np.full((m, 3), np.nan)
    held = np.zeros(m, dtype=bool)
    groups = np.full(m, -1, dtype=np.int64)
    detail = []
    kinds = [kind_of(empty) for empty in empties]
    moving = [empty for empty, kind in zip(empties, kinds) if kind == HANDLE]
    motions = iter(local_motions(obj, moving) if moving else ())
    for label, (empty, kind) in enumerate(zip(empties, kinds), start=1):
        ids = proxy_ids_of(empty, m)
        if ids.size == 0:
            raise SkinDetachError(f"handle {empty.name!r}: expected proxy vertex ids, got none; remove it or Rebuild")
        if kind == HANDLE:
            motion = next(motions)
            moved = rest_proxy[ids] @ motion[:3, :3].T + motion[:3, 3]
            if not np.isfinite(motion).all() or not np.isfinite(moved).all() or \
                    np.abs(moved).max() > MAX_COORDINATE:
                raise SkinDetachError(f"handle {empty.name!r}: expected a transform that keeps its vertices finite "
                                      f"and within {MAX_COORDINATE:g} of the origin, got one that moves them to "
                                      f"{np.nanmax(np.abs(moved)) if np.isfinite(moved).any() else 'inf'}")
        else:
            label, motion, moved = 0, np.eye(4), rest_proxy[ids]
        targets[ids] = moved
        groups[ids] = label
        held[ids] = True
        selected = detail_ids_of(empty, n)
        if selected.size:
            detail.append((label, selected, motion))
    ids = np.flatnonzero(held)
    return ids, targets[ids], groups, detail
