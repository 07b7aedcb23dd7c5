"""Mirror symmetry of handles and anchors: mirror twins, selections that are their own mirror
image, and motions kept symmetric about a mirror plane (through the bound object's origin,
normal to one of its local axes).

Twins made together point at each other under ``"twin"`` in their records (see
:mod:`.handles`), each with the axis under ``"mirror"`` and its basis matrix at the last sync
under ``"synced"`` (16 float64, row-major); moving either moves the other, mirrored.
"""

import numpy as np
from mathutils import Matrix

from ..core.errors import SkinDetachError
from . import handles

AXES = ("X", "Y", "Z")


def median_point(positions, ids, on_plane=""):
    """(3,) the median point (Blender's: the mean) of ``positions`` (n, 3) at vertex ids (k,);
    ``on_plane`` ("X", "Y", "Z" or ""): the selection is its own mirror image across that local
    axis, so the point is put exactly on the mirror plane."""
    point = np.asarray(positions[np.asarray(ids, dtype=np.int64)], dtype=np.float64).mean(axis=0)
    if on_plane:
        point[AXES.index(on_plane)] = 0.0
    return point


def mirror_matrix(axis):
    """(4, 4) reflection across the plane through the origin normal to local ``axis``."""
    out = np.eye(4)
    out[AXES.index(axis), AXES.index(axis)] = -1.0
    return out


def pair(first, second):
    """Make two empties mirror twins: moving either moves the other, mirrored across their axis."""
    first[handles.TAG]["twin"] = second
    second[handles.TAG]["twin"] = first
    for empty in (first, second):
        _mark_synced(empty)


def twin_of(empty):
    """The mirror twin of a handle or anchor, or None: twins point at each other (a Shift+D copy
    of one keeps a pointer its original's twin does not return)."""
    twin = handles.value_of(empty, "twin")
    return twin if handles.is_handle(twin) and handles.value_of(twin, "twin") == empty else None


def mirror_of(empty):
    """The local axis a handle is mirrored across or symmetric about ("X", "Y", "Z"), or "" (raises
    naming the record's ``mirror`` when it holds anything else)."""
    axis = handles.value_of(empty, "mirror", "")
    if not isinstance(axis, str) or axis not in ("", *AXES):
        raise SkinDetachError(f"handle {empty.name!r}: expected mirror '', 'X', 'Y' or 'Z', got {axis!r}; remove it")
    return axis


def _basis(empty):
    return np.array(empty.matrix_basis, dtype=np.float64).ravel()


def _mark_synced(empty):
    empty[handles.TAG]["synced"] = _basis(empty)


def _moved(empty):
    """The empty moved since the last sync (a ``synced`` record that is not 16 numbers counts as
    moved: the twins are synced again and it is written anew)."""
    try:
        synced = np.asarray(handles.value_of(empty, "synced", []), dtype=np.float64)
    except (TypeError, ValueError):
        return True
    return synced.shape != (16,) or not np.array_equal(synced, _basis(empty))


def sync_twins(obj, empties):
    """Move every twin whose partner moved since the last sync to the mirror image of the
    partner's motion (in ``obj``'s local space); when both moved, the older one leads. Raises
    (:func:`.handles.local_motion`) before a twin is moved to a non-finite motion."""
    done = set()
    for empty in empties:
        twin = twin_of(empty)
        if twin is None or empty.name in done or mirror_of(empty) == "":
            continue
        done.update((empty.name, twin.name))
        if not (_moved(empty) or _moved(twin)):
            continue
        lead, follow = (empty, twin) if _moved(empty) or not _moved(twin) else (twin, empty)
        reflect = mirror_matrix(mirror_of(empty))
        motion = reflect @ handles.local_motion(obj, lead) @ reflect
        world = np.array(obj.matrix_world, dtype=np.float64) @ motion @ handles.rest_local_of(follow)
        follow.matrix_world = Matrix(world.tolist())
        _mark_synced(lead)
        _mark_synced(follow)


def symmetry_axis(obj, empties, own_mirror_image):
    """(axis, asked): the local axis ("X", "Y", "Z") a rig of ``obj`` is symmetric about, or "",
    and whether symmetry was asked for across it (the mesh's mirror toggle for the axis is on or
    a handle carries its mirror flag); an axis asked for comes first. Symmetric: each handle and
    anchor of ``empties`` has a mirror twin across the axis or holds mesh vertices that are their
    own mirror image (``own_mirror_image(detail_ids (k,), axis) -> bool``). A lone flagged handle
    (its twin deleted) or a Shift+D copy of a twin (nobody's twin) makes the rig asymmetric, so
    the detail is never averaged with a side the proxy does not mirror; a rig symmetric across
    an axis nobody asked for counts as symmetric only while it moves symmetrically (see
    :func:`moves_symmetrically`)."""
    from . import rig_members
    n = rig_members.vertex_count(obj)
    found = []
    for axis in AXES if empties else ():
        if all(_twinned(e, axis) or self_symmetric(e, axis, own_mirror_image, n) for e in empties):
            asked = getattr(obj.data, f"use_mirror_{axis.lower()}", False) or any(mirror_of(e) == axis for e in empties)
            found.append((not asked, axis))
    return (min(found)[1], not min(found)[0]) if found else ("", False)


def moves_symmetrically(obj, empties, axis):
    """Every handle of ``empties`` without a twin across ``axis`` (its own mirror image there, a
    twin across another axis included) moves by a motion that commutes with the mirror across
    ``axis`` (twins across it are mirrored by :func:`sync_twins`)."""
    return not any(_made_symmetric(obj, empty, axis) is not None for empty in _untwinned_handles(empties, axis))


def _twinned(empty, axis):
    """The handle or anchor has its mirror twin across ``axis``."""
    return mirror_of(empty) == axis and twin_of(empty) is not None


def _untwinned_handles(empties, axis):
    """The handles of ``empties`` without a mirror twin across ``axis`` (anchors hold their rest,
    twins across it are mirrored by :func:`sync_twins`)."""
    return [e for e in empties if handles.kind_of(e) == handles.HANDLE and not _twinned(e, axis)]


def _made_symmetric(obj, empty, axis):
    """(4, 4) the nearest motion to the handle's that commutes with the mirror across ``axis``, or
    None when its own already does (within 1e-9 of its size)."""
    motion = handles.local_motion(obj, empty)
    symmetric = symmetric_motion(motion, axis)
    return symmetric if np.abs(symmetric - motion).max() > 1e-9 * max(1.0, np.abs(motion[:3, 3]).max()) else None


def self_symmetric(empty, axis, own_mirror_image, n=None):
    """The handle was made from mesh vertices (ids checked against ``n``) that are their own mirror
    image across ``axis``."""
    ids = handles.detail_ids_of(empty, n)
    return ids.size > 0 and own_mirror_image(ids, axis)


def symmetric_motion(motion, axis):
    """(4, 4) the motion nearest to ``motion`` (4, 4) that commutes with the mirror across
    ``axis``, of the same kind: the linear part's polar factors A = Q P (Q orthogonal, P the
    symmetric stretch: a uniform scale, negative or zero included) are each made symmetric, Q by
    the nearest orthogonal matrix of the same handedness to its average with its mirror image, P
    and the translation by that average. A rigid motion stays rigid, a uniform scale (S) about a
    centre on the plane is kept as it is."""
    reflect = mirror_matrix(axis)
    flip = reflect[:3, :3]
    u, sigma, vt = np.linalg.svd(motion[:3, :3])
    turn, stretch = u @ vt, (vt.T * sigma) @ vt
    w, _, zt = np.linalg.svd(0.5 * (turn + flip @ turn @ flip))
    if np.linalg.det(w @ zt) * np.linalg.det(turn) < 0:
        w[:, -1] *= -1.0
    out = 0.5 * (motion + reflect @ motion @ reflect)
    out[:3, :3] = (w @ zt) @ (0.5 * (stretch + flip @ stretch @ flip))
    return out


def keep_symmetric(obj, empties, axis):
    """Put every handle of a rig symmetric about ``axis`` that has no twin across it (it is its
    own mirror image there; a twin across another axis included) on the nearest symmetric
    motion (a move across the plane cannot keep the mesh symmetric); returns the names of those
    it moved."""
    moved = []
    for empty in _untwinned_handles(empties, axis):
        symmetric = _made_symmetric(obj, empty, axis)
        if symmetric is not None:
            world = np.array(obj.matrix_world, dtype=np.float64) @ symmetric @ handles.rest_local_of(empty)
            empty.matrix_world = Matrix(world.tolist())
            moved.append(empty.name)
    return moved
