"""Handles and anchors: empties parented to the proxy, each holding a set of proxy vertices.

A handle carries its proxy vertices by the rigid motion of its empty since it was made: in the
bound object's local space, ``delta = object_world^-1 @ empty_world @ rest_local^-1`` applied to
the rest proxy positions. An anchor holds its proxy vertices at rest wherever its empty is.
Each empty stores under ``empty["_skin_detach_handle"]``: its owner (an ID pointer), kind,
``proxy_ids`` (int32), ``detail_ids`` (int32, empty when made from the proxy) and ``rest_local``
(16 float64, row-major). Handles made from detail vertices survive a Rebuild. Mirror twins
and symmetric rigs: :mod:`.handle_symmetry`.
"""

import numpy as np
from mathutils import Matrix

from ..core.errors import SkinDetachError

TAG = "_skin_detach_handle"
#: Handle targets farther than this from the object's origin are refused (float32 stores the mesh).
MAX_COORDINATE = 1e12
HANDLE = "HANDLE"
ANCHOR = "ANCHOR"
#: Where an empty's rest frame sits: the selection's median point. Empties made by earlier
#: versions have no "pivot" key: theirs sits at the centroid of the proxy vertices they hold.
PIVOT = "selection median"


def is_handle(obj):
    """``obj`` is a handle or anchor empty that is in a scene (one deleted in the viewport but kept
    alive by another object's pointer, such as its twin's, is gone)."""
    return obj is not None and obj.type == 'EMPTY' and TAG in obj and len(obj.users_scene) > 0


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


def _ids(empty, key, limit=None):
    raw = np.asarray(value_of(empty, key, []))
    if raw.size and raw.dtype.kind not in "iu":
        raise SkinDetachError(f"handle {empty.name!r}: expected integer {key}, got {raw.dtype}; remove it")
    ids = raw.astype(np.int64).ravel()
    if ids.size and (ids.min() < 0 or (limit is not None and ids.max() >= limit)):
        raise SkinDetachError(f"handle {empty.name!r}: expected {key} in [0, {limit}), got values in "
                              f"[{ids.min()}, {ids.max()}]; remove it or Rebuild")
    return ids


def proxy_ids_of(empty, m=None):
    """(c,) int64 proxy vertex ids the empty holds (checked against ``m`` proxy vertices if given)."""
    return _ids(empty, "proxy_ids", m)


def detail_ids_of(empty, n=None):
    """(k,) int64 detail vertex ids the empty was made from (empty when made from the proxy)."""
    return _ids(empty, "detail_ids", n)


def rest_local_of(empty):
    """(4, 4) float64 rest frame of the empty in the bound object's local space (a copy: the ID
    property it is read from may be replaced, by a Rebuild, while the array is still held)."""
    try:
        frame = np.array(value_of(empty, "rest_local"), dtype=np.float64).reshape(4, 4)
    except (TypeError, ValueError):
        frame = np.full((4, 4), np.nan)
    if not np.isfinite(frame).all():
        raise SkinDetachError(f"handle {empty.name!r}: expected a finite 4x4 rest frame, got unreadable or "
                              f"non-finite values; remove it")
    return frame


def handles_of(obj, proxy=None):
    """Handle and anchor empties of ``obj``, oldest first (the newer wins on shared vertices); with
    ``proxy``, those under it at any depth (an artist may parent a hand's empty to the forearm's)."""
    pool = proxy.children_recursive if proxy is not None else _all_objects()
    found = [o for o in pool if is_handle(o) and value_of(o, "owner") == obj]
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
    empty.parent = proxy
    empty.matrix_parent_inverse = Matrix.Identity(4)
    empty.matrix_basis = Matrix.Translation(now_centroid.tolist())
    rest_local = np.eye(4)
    rest_local[:3, 3] = rest_centroid
    serial = next_serial(handles_of(obj, proxy))
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
    }
    return empty


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
    median point at rest, the empty back at rest on the new proxy."""
    empty.parent = proxy
    empty.matrix_parent_inverse = Matrix.Identity(4)
    empty.matrix_basis = Matrix.Translation(rest_centroid.tolist())
    rest_local = np.eye(4)
    rest_local[:3, 3] = rest_centroid
    props = empty[TAG]
    # Assigning over an existing ID-property array keeps its old length: delete it first.
    for key, value in (("proxy_ids", np.asarray(proxy_ids, dtype=np.int32)), ("rest_local", rest_local.ravel())):
        del props[key]
        props[key] = value
    props["pivot"] = PIVOT


def has_old_pivot(empty):
    """The empty was made by an earlier version: its R/S pivot is the centroid of the proxy
    vertices it holds, not the selection's median point (a Rebuild moves it there)."""
    return value_of(empty, "pivot") != PIVOT and detail_ids_of(empty).size > 0


def local_motion(obj, empty):
    """(4, 4) rigid motion of a handle in the local space of ``obj`` since it was made."""
    world = np.array(obj.matrix_world, dtype=np.float64)
    try:
        return np.linalg.solve(world, np.array(empty.matrix_world, dtype=np.float64)) @ \
            np.linalg.inv(rest_local_of(empty))
    except np.linalg.LinAlgError:
        raise SkinDetachError(f"object {obj.name!r}: expected an invertible transform (no zero scale) for its "
                              f"handle {empty.name!r}, got a singular one") from None


def constraints(obj, empties, rest_proxy):
    """Constrained proxy ids (c,) sorted, their targets (c, 3) in local space, the rigid group
    of every proxy vertex (m,) (0: anchors, 1, 2, ...: each handle, -1: free), and the held
    detail: (group label, detail ids (h,), (4, 4) local motion) per group made from detail
    vertices (the anchors' together, motion the identity), from the handle and anchor
    ``empties`` of ``obj`` (:func:`handles_of`). Handles override anchors; a later handle
    overrides an older one."""
    m = rest_proxy.shape[0]
    targets = np.full((m, 3), np.nan)
    held = np.zeros(m, dtype=bool)
    groups = np.full(m, -1, dtype=np.int64)
    anchored, detail = [], []
    for label, empty in enumerate(sorted(empties, key=lambda e: kind_of(e) == HANDLE), start=1):
        ids = proxy_ids_of(empty, m)
        if ids.size == 0:
            raise SkinDetachError(f"handle {empty.name!r}: expected proxy vertex ids, got none; remove it or Rebuild")
        if kind_of(empty) == HANDLE:
            motion = local_motion(obj, empty)
            moved = rest_proxy[ids] @ motion[:3, :3].T + motion[:3, 3]
            if not np.isfinite(motion).all() or not np.isfinite(moved).all() or \
                    np.abs(moved).max() > MAX_COORDINATE:
                raise SkinDetachError(f"handle {empty.name!r}: expected a transform that keeps its vertices finite "
                                      f"and within {MAX_COORDINATE:g} of the origin, got one that moves them to "
                                      f"{np.nanmax(np.abs(moved)) if np.isfinite(moved).any() else 'inf'}")
            targets[ids] = moved
            groups[ids] = label
            selected = detail_ids_of(empty)
            if selected.size:
                detail.append((label, selected, motion))
        else:
            targets[ids] = rest_proxy[ids]
            groups[ids] = 0
            anchored.append(detail_ids_of(empty))
        held[ids] = True
    # One anchor's ids are stored sorted and unique already (a union costs a sort of them per move).
    if len(anchored) > 1:
        anchored = [np.unique(np.concatenate(anchored))]
    anchored = anchored[0] if anchored else np.zeros(0, dtype=np.int64)
    if anchored.size:
        detail.insert(0, (0, anchored, np.eye(4)))
    ids = np.flatnonzero(held)
    return ids, targets[ids], groups, detail
