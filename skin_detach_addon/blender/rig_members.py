"""The objects of a rig: one bound mesh object (the owner) alone, or the owner and other mesh
objects posed with it as one (a character's body, eyes, belt and boots).

The core sees one combined detail mesh: the members' vertices concatenated in the members'
order (the owner first, then the others sorted by name at build time), each member's positions
mapped into the owner's local space (``owner_world^-1 @ member_world @ p``, the matrix stored at
build time), its triangles offset by its first combined index. Every write maps combined
positions back into each member's own local space (``member_world^-1 @ owner_world @ p``) and
writes its mesh with :func:`.mesh_io.write_positions`. Combined vertex ids are what handles store.

Stored in the owner's record (:mod:`.binding`) under :data:`MEMBERS` only when the rig has more
than one object (a single object's record is as it always was): one group per member, in order,
``object`` (an ID pointer: survives rename and save), ``name`` (its name at build time, to name
a deleted member), ``vertices``, ``fingerprint`` (its :func:`.mesh_io.mesh_fingerprint`) and
``matrix`` (16 float64, row-major: its world matrix relative to the owner's). The arrays' store
also holds :data:`LOCAL_REST`: every member's rest positions in its own local space, concatenated
(what Reset writes back, bit for bit). Each member other than the owner carries :data:`MEMBER_TAG`
(the owner), so that it stands for the owner when it is active.

The ``written_digest`` of a rig of several objects is the digest of the members' own positions
concatenated (for one object that is its positions, as before).
"""

import numpy as np

from ..core.errors import SkinDetachError
from . import mesh_io

MEMBERS = "members"
LOCAL_REST = "local_rest"
MEMBER_TAG = "_skin_detach_member_of"
#: A member whose world matrix relative to the owner moved more than this (relative to the
#: matrix's largest entry) since the build is refused.
MATRIX_TOLERANCE = 1e-6


def _record(owner):
    from . import binding as stored
    return stored.readable_record(owner)


def entries(owner):
    """The stored member groups of ``owner``'s rig (empty for a rig of one object)."""
    record = _record(owner) if owner is not None else None
    found = None if record is None else record.get(MEMBERS)
    return list(found) if found else []


def is_multi(owner):
    return bool(entries(owner))


def _alive(obj):
    return obj is not None and getattr(obj, "type", None) is not None and bool(obj.users_scene)


def objects(owner):
    """The rig's objects in order (owner first); a deleted member is None."""
    found = entries(owner)
    if not found:
        return [owner]
    out = []
    for entry in found:
        obj = entry.get("object")
        out.append(obj if _alive(obj) else None)
    return out


def names(owner):
    """The names of the rig's objects in order (a deleted member's name at build time)."""
    found = entries(owner)
    if not found:
        return [owner.name]
    return [obj.name if obj is not None else str(entry.get("name", "?"))
            for obj, entry in zip(objects(owner), found)]


def owner_of(obj):
    """The owner of the rig ``obj`` is a member of (not the owner itself), or None."""
    if obj is None or getattr(obj, "type", None) != 'MESH' or MEMBER_TAG not in obj:
        return None
    owner = obj[MEMBER_TAG]
    if not _alive(owner) or owner == obj:
        return None
    for entry in entries(owner)[1:]:
        if entry.get("object") == obj:
            return owner
    return None  # a copy of a member (Shift+D copies the tag), or a member of an earlier rig


def counts(owner):
    """(k,) int64 the vertex count of each member, in order."""
    found = entries(owner)
    if not found:
        return np.array([len(owner.data.vertices)], dtype=np.int64)
    return np.array([int(entry.get("vertices", -1)) for entry in found], dtype=np.int64)


def offsets(owner):
    """(k + 1,) int64 the first combined vertex id of each member, then the total."""
    return np.concatenate([[0], np.cumsum(counts(owner))]).astype(np.int64)


def vertex_count(obj):
    """The vertices of the combined detail mesh of the rig ``obj`` owns (its own for one object)."""
    return int(counts(obj).sum()) if is_multi(obj) else len(obj.data.vertices)


def _relative(owner, member):
    """(4, 4) float64 ``owner_world^-1 @ member_world`` now."""
    return np.linalg.solve(np.array(owner.matrix_world, dtype=np.float64),
                           np.array(member.matrix_world, dtype=np.float64))


def _stored_matrices(owner):
    return [np.asarray(entry.get("matrix"), dtype=np.float64).reshape(4, 4) for entry in entries(owner)]


def _describe(owner, k):
    entry = entries(owner)[k]
    obj = entry.get("object")
    name = obj.name if obj is not None and getattr(obj, "type", None) is not None else entry.get("name", "?")
    return f"object {name!r} (member {k + 1} of the rig of {owner.name!r})"


def check(owner, edit_mode=True):
    """Raise, naming the member, unless every member of ``owner``'s rig (the owner excepted: the
    binding checks it) is still there (not deleted, in a scene), a local editable mesh, in Object
    Mode (``edit_mode``), of the topology it was bound with and where it was relative to the owner.
    Nothing for a rig of one object."""
    from . import binding as stored
    found = entries(owner)
    if not found:
        return
    if not np.isfinite(np.array(owner.matrix_world, dtype=np.float64)).all():
        raise SkinDetachError(f"object {owner.name!r}: expected a finite world matrix, got NaN or inf")
    for k, (entry, matrix) in enumerate(zip(found, _stored_matrices(owner))):
        if k == 0:
            continue
        obj = entry.get("object")
        what = _describe(owner, k)
        if not _alive(obj):
            raise SkinDetachError(f"{what}: expected it in the scene, it was deleted or unlinked from every scene "
                                  f"(nothing was written); bring it back (undo) or press Rebuild")
        if obj.type != 'MESH':
            raise SkinDetachError(f"{what}: expected a mesh object, got type {obj.type}; press Rebuild")
        stored.check_editable(obj)
        if edit_mode and (obj.mode == 'EDIT' or obj.data.is_editmode):
            raise SkinDetachError(f"{what}: expected Object Mode, its mesh is in Edit Mode (nothing was written; "
                                  f"Skin Detach never writes a mesh under Edit Mode); leave Edit Mode first")
        if len(obj.data.vertices) != int(entry.get("vertices", -1)) or \
                mesh_io.mesh_fingerprint(obj.data) != entry.get("fingerprint"):
            raise SkinDetachError(f"{what}: expected the topology it was bound with ({int(entry.get('vertices', -1))} "
                                  f"vertices), its mesh was edited after binding (now {len(obj.data.vertices)} "
                                  f"vertices, or its faces changed; nothing was written); press Rebuild")
        now = _relative(owner, obj)
        scale = max(1.0, float(np.abs(matrix).max()))
        if not np.isfinite(now).all() or not np.allclose(now, matrix, rtol=0.0, atol=MATRIX_TOLERANCE * scale):
            raise SkinDetachError(f"{what}: expected it where it was bound relative to {owner.name!r}, it was moved, "
                                  f"turned or scaled since (nothing was written); move it back (undo) or press Rebuild")


def fingerprint_of(fingerprints):
    """The combined fingerprint stored as the owner's ``mesh_fingerprint``: a digest of the
    members' own fingerprints in order."""
    text = "|".join(fingerprints).encode()
    return mesh_io._digest(len(fingerprints), np.frombuffer(text, dtype=np.uint8))


def fingerprint(owner):
    """The owner's :func:`.mesh_io.mesh_fingerprint` for one object; for several, the digest of
    every member's (deleted members count as none)."""
    if not is_multi(owner):
        return mesh_io.mesh_fingerprint(owner.data)
    return fingerprint_of([mesh_io.mesh_fingerprint(obj.data) if obj is not None else "deleted"
                           for obj in objects(owner)])


def read_local(owner):
    """(n, 3) float32 every member's own positions (Basis key's), concatenated in order."""
    members = objects(owner)
    if len(members) == 1:
        return mesh_io.read_positions(owner.data)
    check(owner, edit_mode=False)
    return np.concatenate([mesh_io.read_positions(obj.data) for obj in members])


def to_combined(owner, local):
    """(n, 3) float32 combined positions (owner's space) of members' own positions ``local``
    (n, 3) concatenated; the owner's rows as they are, bit for bit."""
    found = entries(owner)
    if not found:
        return local
    out = np.empty_like(local, dtype=np.float32)
    bounds = offsets(owner)
    for k, matrix in enumerate(_stored_matrices(owner)):
        rows = slice(bounds[k], bounds[k + 1])
        if k == 0:
            out[rows] = local[rows]
        else:
            out[rows] = local[rows].astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
    return out


def read_positions(owner):
    """(n, 3) float32 the combined positions of the rig's meshes now (the owner's own for one object)."""
    return to_combined(owner, read_local(owner))


def split(owner, combined):
    """The combined (n, 3) positions as a list of each member's own (n_k, 3) float32 positions
    (for one object: ``[combined]``, no copy)."""
    found = entries(owner)
    if not found:
        return [combined]
    bounds = offsets(owner)
    parts = []
    for k, matrix in enumerate(_stored_matrices(owner)):
        rows = combined[bounds[k]:bounds[k + 1]]
        if k == 0:
            parts.append(rows)
        else:
            inverse = np.linalg.inv(matrix)
            parts.append((rows.astype(np.float64) @ inverse[:3, :3].T + inverse[:3, 3]).astype(np.float32))
    return parts


def split_values(owner, values):
    """(n,) per-vertex ``values`` as a list of each member's slice."""
    bounds = offsets(owner)
    return [values[bounds[k]:bounds[k + 1]] for k in range(len(bounds) - 1)]


def check_writable(owner, parts):
    """Raise, writing nothing, unless every member is there and in Object Mode and its part is finite."""
    check(owner)
    for obj, part in zip(objects(owner), parts):
        mesh_io.check_positions(f"object {obj.name!r} (nothing was written)", part)
        if obj.mode == 'EDIT' or obj.data.is_editmode:
            raise SkinDetachError(f"object {obj.name!r}: expected Object Mode, its mesh is in Edit Mode "
                                  f"(nothing was written)")


def write_parts(owner, parts):
    """Write each member's own positions ``parts`` (checked by :func:`check_writable`)."""
    for obj, part in zip(objects(owner), parts):
        mesh_io.write_positions(obj.data, part, checked=True)


def digest_of_parts(parts):
    """:func:`.mesh_io.positions_digest` of the parts concatenated (made without concatenating)."""
    if len(parts) == 1:
        return mesh_io.positions_digest(parts[0])
    return mesh_io._digest(sum(int(p.shape[0]) for p in parts),
                           *[np.ascontiguousarray(p, dtype=np.float32) for p in parts])


def written_digest(owner):
    """The digest of what the rig's meshes hold now (compared with the stored written digest)."""
    return mesh_io.positions_digest(read_local(owner))


def local_rest(owner):
    """The rest positions of each member in its own space, as a list (the stored ones: bit for bit
    what the build read); for one object, the binding's rest."""
    from . import binding as stored
    if not is_multi(owner):
        return [stored.rest_positions(owner)]
    arrays = stored.arrays_of(owner)
    flat = None if arrays is None else arrays.get(LOCAL_REST)
    n = int(counts(owner).sum())
    try:
        rest = np.asarray(stored.stored_array(flat, f"binding of {owner.name!r} {LOCAL_REST}"),
                          dtype=np.float32).reshape(n, 3)
    except (TypeError, ValueError):
        raise SkinDetachError(f"binding of {owner.name!r}: expected the members' rest positions ({n}, 3), got "
                              f"unreadable data; press Rebuild") from None
    bounds = offsets(owner)
    return [rest[bounds[k]:bounds[k + 1]] for k in range(len(bounds) - 1)]


def read_triangles(owner, rest_parts=None):
    """(t, 3) int32 the combined triangles: each member's loop triangles (split as its own rest
    ``rest_parts[k]`` splits, see :func:`.mesh_io.read_triangles`) offset by its first id."""
    members = objects(owner)
    if len(members) == 1:
        return mesh_io.read_triangles(owner.data, None if rest_parts is None else rest_parts[0])
    bounds = offsets(owner)
    out = [mesh_io.read_triangles(obj.data, None if rest_parts is None else rest_parts[k]) + np.int32(bounds[k])
           for k, obj in enumerate(members)]
    return np.concatenate(out).astype(np.int32)


def snapshot(owner):
    """:func:`.mesh_io.snapshot` of every member's mesh, in order."""
    return [mesh_io.snapshot(obj.data) for obj in objects(owner)]


def restore(owner, saved):
    """Every member's mesh back from :func:`snapshot`, bit for bit."""
    for obj, kept in zip(objects(owner), saved):
        if obj is not None:
            mesh_io.restore(obj.data, kept)


def group_members(owner, name):
    """(k,) int64 combined ids of vertex group ``name`` (weight above zero) of every member that
    has it; refused, naming it, when none has it."""
    members = objects(owner)
    if len(members) == 1:
        return mesh_io.group_members(owner, name)
    bounds = offsets(owner)
    found = []
    for k, obj in enumerate(members):
        if isinstance(name, str) and obj.vertex_groups.get(name) is not None:
            try:
                found.append(mesh_io.group_members(obj, name) + bounds[k])
            except SkinDetachError:
                continue  # this member's group has no weights: the others may
    if not found:
        groups = sorted({g.name for obj in members for g in obj.vertex_groups})
        raise SkinDetachError(f"group: expected a vertex group with weights in one of the rig's objects "
                              f"{', '.join(repr(o.name) for o in members)} ({', '.join(groups) or 'they have none'}), "
                              f"got {name!r}")
    return np.concatenate(found)


def combined_ids(owner, vertex_ids):
    """``vertex_ids`` as combined ids: an array of them as it is, or a dict {member object: its
    own vertex ids} mapped through the members' offsets (a member not of the rig, or an id out of
    its range, refused)."""
    from ..core.validation import as_vertex_ids
    if not isinstance(vertex_ids, dict):
        return vertex_ids
    members = objects(owner)
    bounds = offsets(owner)
    out = []
    for obj, ids in vertex_ids.items():
        if obj not in members:
            raise SkinDetachError(f"vertex_ids: expected objects of the rig of {owner.name!r} "
                                  f"({', '.join(repr(o.name) for o in members if o is not None)}) as keys, got "
                                  f"{getattr(obj, 'name', obj)!r}")
        k = members.index(obj)
        out.append(as_vertex_ids(f"vertex_ids[{obj.name!r}]", ids, int(bounds[k + 1] - bounds[k])) + bounds[k])
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


def selected(owner, editing=None):
    """(k,) combined ids of the vertices selected in the members (``editing``: the members that
    were in Edit Mode, read alone when given; else every member)."""
    members = objects(owner)
    bounds = offsets(owner)
    picked = []
    for k, obj in enumerate(members):
        if obj is None or (editing is not None and obj not in editing):
            continue
        mask = np.zeros(len(obj.data.vertices), dtype=bool)
        obj.data.vertices.foreach_get("select", mask)
        picked.append(np.flatnonzero(mask) + bounds[k])
    return np.concatenate(picked) if picked else np.zeros(0, dtype=np.int64)


def record_entries(owner, members):
    """The :data:`MEMBERS` groups to store for ``members`` (owner first) as they are now."""
    out = []
    for obj in members:
        out.append({"object": obj, "name": obj.name, "vertices": len(obj.data.vertices),
                    "fingerprint": mesh_io.mesh_fingerprint(obj.data),
                    "matrix": _relative(owner, obj).ravel()})
    return out


def tag(owner, members):
    """Mark every member but the owner as the owner's; drop the mark of members no longer listed."""
    untag(owner, keep=members)
    for obj in members[1:]:
        obj[MEMBER_TAG] = owner


def untag(owner, keep=()):
    """Drop :data:`MEMBER_TAG` from the objects marked as ``owner``'s (except ``keep``)."""
    import bpy
    for obj in bpy.data.objects:
        if obj not in keep and MEMBER_TAG in obj and obj.get(MEMBER_TAG) == owner:
            del obj[MEMBER_TAG]


def order(objs):
    """The rig's objects in their fixed order: the first (owner) first, the others by name."""
    return [objs[0]] + sorted(objs[1:], key=lambda o: o.name)
