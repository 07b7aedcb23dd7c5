"""The rigs artists build (issue 43), for the tests and the quality benchmark's rigs scenario:
where their selections lie on a mesh, and how far each handle's selection is from where its
transform puts it.

Arrays: ``points`` (n, 3) float64 rest positions of the mesh's vertices, ``triangles`` (f, 3)
int64 vertex ids. Selections are sorted vertex ids (k,) int64. Distances are fractions of the
rest mesh's bounding-box diagonal.

The rule measured (issue 43): a selected vertex follows the newest of the handles and anchors
whose selection contains it; a handle carries it by its empty's motion in the object's local
space since it was made (``object_world^-1 @ empty_world @ rest_local^-1``, any affine map an
empty can hold), an anchor holds it at rest.
"""

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import cKDTree

from skin_detach_addon.core.geometry import unique_edges

#: The goals of issue 43: name -> (figure of a rigs row of scripts/benchmark_quality.py --rigs, the
#: value it must not pass); a figure the row lacks is not judged.
GOALS = {"off": ("worst_off", 1e-5), "anchor": ("worst_anchor", 1e-5), "Add Handle": ("add_handle_s_max", 0.5),
         "move": ("move_ms_median", 16.0), "confirm": ("confirm_ms_max", 150.0)}
#: Geodesic bands of a limb from its tip, fractions of the diagonal: hand, forearm, upper arm,
#: (a free band), the shoulder's anchor.
LIMB_BANDS = {"hand": (0.0, 0.08), "forearm": (0.08, 0.16), "upper arm": (0.16, 0.24), "shoulder": (0.28, 0.36)}


def diagonal(points):
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def geodesic_from(points, triangles, source):
    """(n,) length of the shortest path along the mesh's edges from vertex ``source`` (inf where
    there is none)."""
    edges = unique_edges(triangles)[0]
    lengths = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    n = points.shape[0]
    graph = scipy.sparse.coo_matrix((lengths, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    return scipy.sparse.csgraph.dijkstra(graph, directed=False, indices=int(source))


def limb_tip(points):
    """The vertex farthest from the centroid in the upper half of the longest axis (the
    armadillo's raised right hand, the cow's head)."""
    coordinate = points[:, int(np.argmax(np.ptp(points, axis=0)))]
    reach = np.linalg.norm(points - points.mean(axis=0), axis=1)
    reach[coordinate < (coordinate.min() + coordinate.max()) / 2] = -1.0
    return int(np.argmax(reach))


def limb(points, triangles):
    """A limb as an artist rigs it: dict name -> selection for "hand", "forearm", "upper arm"
    (three adjacent bands along the mesh from :func:`limb_tip`, each touching the next) and
    "shoulder" (a band past a free band, for the anchor); :data:`LIMB_BANDS`."""
    distance = geodesic_from(points, triangles, limb_tip(points)) / diagonal(points)
    return {name: np.flatnonzero((distance >= low) & (distance < high)) for name, (low, high) in LIMB_BANDS.items()}


def head(points, radius=0.15):
    """Vertices within ``radius`` (of the diagonal) of the top of the longest axis: the head of
    a standing character (the armadillo's; a cow's rump)."""
    axis = int(np.argmax(np.ptp(points, axis=0)))
    top = points[int(np.argmax(points[:, axis]))]
    return np.flatnonzero(np.linalg.norm(points - top, axis=1) <= radius * diagonal(points))


def base(points, fraction=0.2):
    """Vertices in the lowest ``fraction`` of the longest axis (a character's feet)."""
    coordinate = points[:, int(np.argmax(np.ptp(points, axis=0)))]
    return np.flatnonzero(coordinate <= coordinate.min() + fraction * np.ptp(coordinate))


def spots(points, region, count):
    """``count`` small disjoint selections spread over ``region`` (r,) (farthest-point sampling
    of their centres from the region's first vertex; each the vertices within a quarter of the
    smallest distance between centres of its centre, at least the centre itself): a face rig."""
    centres = [int(region[0])]
    nearest = np.linalg.norm(points[region] - points[centres[0]], axis=1)
    for _ in range(count - 1):
        centres.append(int(region[int(np.argmax(nearest))]))
        nearest = np.minimum(nearest, np.linalg.norm(points[region] - points[centres[-1]], axis=1))
    spread = cKDTree(points[centres]).query(points[centres], k=2)[0][:, 1].min()
    tree = cKDTree(points[region])
    return [np.union1d(region[tree.query_ball_point(points[c], 0.25 * spread)], [c]).astype(np.int64)
            for c in centres]


def falloff(points, ids, low=0.1):
    """(k,) weights of the vertices ``ids`` falling linearly from 1 at their centroid to ``low``
    at the farthest of them (a painted group)."""
    reach = np.linalg.norm(points[ids] - points[ids].mean(axis=0), axis=1)
    return 1.0 - (1.0 - low) * reach / max(float(reach.max()), 1e-300)


def weighted_group(obj, name, ids, weights):
    """A vertex group ``name`` on ``obj`` holding ``ids`` (k,) with ``weights`` (k,) (zeros kept:
    in the group, not a member for Skin Detach)."""
    group = obj.vertex_groups.new(name=name)
    for index, weight in zip(np.asarray(ids).tolist(), np.asarray(weights, dtype=float).tolist()):
        group.add([index], weight, 'REPLACE')
    return group


class Held:
    """A handle or anchor as made: its ``empty``, ``kind`` ("HANDLE" or "ANCHOR"), the selection
    ``ids`` (k,) it was made from and its rest frame in the object's local space (4, 4), taken
    from the empty's world matrix when it was made on the mesh at rest (the add-on's record is
    not read, so a wrong record shows as an error)."""

    def __init__(self, obj, empty, kind, ids):
        import bpy
        bpy.context.view_layer.update()
        self.empty, self.kind, self.ids = empty, kind, np.unique(np.asarray(ids, dtype=np.int64))
        self.name = empty.name
        self.rest_local = np.linalg.solve(np.array(obj.matrix_world), np.array(empty.matrix_world))

    def motion(self, obj):
        """(4, 4) the empty's motion in ``obj``'s local space since it was made (identity for an anchor)."""
        if self.kind == "ANCHOR":
            return np.eye(4)
        return np.linalg.solve(np.array(obj.matrix_world), np.array(self.empty.matrix_world)) @ \
            np.linalg.inv(self.rest_local)


def make(obj, kind, ids=None, group=None, made=None):
    """api.add_handle or api.add_anchor on ``ids`` (or vertex group ``group``, whose members,
    weight above zero, are then its selection), recorded as :class:`Held` in ``made`` (the
    list of the rig's handles, oldest first); returns the Held."""
    from skin_detach_addon import api
    add = api.add_handle if kind == "HANDLE" else api.add_anchor
    empty = add(obj, ids, group=group, mirror="")
    if group is not None:
        index = obj.vertex_groups[group].index
        ids = [v.index for v in obj.data.vertices for g in v.groups if g.group == index and g.weight > 0.0]
    held = Held(obj, empty, kind, ids)
    if made is not None:
        made.append(held)
    return held


def held_errors(obj, rest, made):
    """Per handle and anchor of ``made`` (oldest first), how far the vertices it owns (those
    whose newest selection is its) are from where it puts them: a list of dicts (name, kind,
    vertices: how many it owns, off: the largest distance over the diagonal of ``rest`` (n, 3),
    the mesh's positions when it was bound). ``obj``'s mesh is read as written."""
    from skin_detach_addon.blender import mesh_io
    now = mesh_io.read_positions(obj.data).astype(np.float64)
    rest = np.asarray(rest, dtype=np.float64)
    owner = np.full(rest.shape[0], -1)
    for k, held in enumerate(made):
        owner[held.ids] = k
    out = []
    for k, held in enumerate(made):
        ids = np.flatnonzero(owner == k)
        motion = held.motion(obj)
        target = rest[ids] @ motion[:3, :3].T + motion[:3, 3]
        off = float(np.linalg.norm(now[ids] - target, axis=1).max()) / diagonal(rest) if ids.size else 0.0
        out.append({"name": held.name, "kind": held.kind, "vertices": int(ids.size), "off": off})
    return out


def worst(errors, kind):
    """The largest ``off`` of :func:`held_errors` over the handles (kind "HANDLE") or anchors."""
    return max((e["off"] for e in errors if e["kind"] == kind), default=0.0)



def failed_goals(row):
    """The :data:`GOALS` a rigs row fails (["refused"] when the add-on refused the rig)."""
    if "refused" in row:
        return ["refused"]
    return [goal for goal, (key, limit) in GOALS.items() if key in row and not row[key] <= limit]
