"""The public object: a detail mesh bound as a skin to a small proxy.

    sds = SkinDetachedSurface.build(vertices (n, 3), triangles (f, 3), target_faces=1000)
    sds.reconstruct(deformed_proxy (m, 3)) -> (n, 3) detail vertices
"""

import hashlib
import json
import threading
import time
from collections import OrderedDict

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .clustering import cluster_mesh
from .. import threads
from ..errors import SkinDetachError
from ..geometry import face_cross, flat_ranges, half_edge_graph, rows_any
from .held_detail import layout_of, owned_pairs
from .checked_collapse import cluster_quadrics, collapse_with_normal_test
from .prepared_mesh import prepare_mesh
from .reconstruction import LayoutRebuild, Rebuild, rebuild_matrix
from .riders import RigidRiders, find_riders, ride_carriers, rider_groups, still_vertices
from .seam_weights import SEAM_STEPS, SeamWeights
from .simplification import follow_nearest, simplify
from .sliver_repair import face_angles, is_sliver, repair_slivers
from .skin import (CASE_LOOSE, CASE_ONE, CASE_THREE, CASE_TWO, ProxyFrames, Skin, bind_skin, bound_disagreement,
                   check_coefficients)
from ..validation import as_points, as_preview_vertices, as_target_faces, as_triangles, as_vertex_ids

#: Version of the saved format; files of another version are refused.
FORMAT_VERSION = 1
FORMAT_TAG = "skin_detach_surface"
#: With the normal test on, the library simplifies to this many times the target first.
NORMAL_TEST_OVERSAMPLE = 1.5
#: ... and 1.25 times when it simplifies a clustered copy: measured on the armadillo at 800K, the
#: test then stops at 1,036 faces for 1,000 (1,204 from 1.5) with fewer disagreeing normals.
CLUSTERED_OVERSAMPLE = 1.25

#: Detail meshes of at least this many welded vertices make their free rebuild (the skin
#: diffused over every vertex, its matrix: a third of the build at 10M) on a background thread
#: after the build (:meth:`SkinDetachedSurface.prepare_free_rebuild`): the build returns, a drag
#: that shows the preview and Add Handle do not need it, a full-detail rebuild waits for it.
BACKGROUND_ABOVE = 1_000_000

#: Selections whose drop rows are kept (:meth:`SkinDetachedSurface.drop_rows`): a rig of a few
#: dozen handles, its last layouts' selections shared.
KEPT_DROP_ROWS = 256

_SKIN_FIELDS = ("vertex", "face", "bary", "height", "weight", "case")


#: Triangles hashed at once by :func:`topology_fingerprint` (bounds its int64 copy).
FINGERPRINT_ROWS = 1 << 18


def topology_fingerprint(n_vertices, triangles):
    """Hex digest of the vertex count and the triangle index array (f, 3) as int64, hashed in
    slices of :data:`FINGERPRINT_ROWS` rows (the digest of the whole, without a copy of it)."""
    digest = hashlib.blake2b(digest_size=16)
    digest.update(np.int64(n_vertices).tobytes())
    for start in range(0, triangles.shape[0], FINGERPRINT_ROWS):
        digest.update(np.ascontiguousarray(triangles[start:start + FINGERPRINT_ROWS], dtype=np.int64))
    return digest.hexdigest()


@dataclass
class Preview:
    """The light stand-in of a large detail mesh, bound to the same proxy.

    points     (c, 3) float64  rest positions (cluster representatives, see :mod:`.clustering`)
    triangles  (q, 3) int64    faces
    surface    :class:`SkinDetachedSurface` whose detail is this mesh
    representatives (c,) int64 the welded detail vertex each preview vertex is, or None (a file
               of an earlier version: the preview then holds no detail of its own)
    """

    points: np.ndarray
    triangles: np.ndarray
    surface: "SkinDetachedSurface"
    representatives: np.ndarray = None

    def __post_init__(self):
        if self.surface.triangles is None:
            self.surface.attach_topology(self.triangles)

    def held_of(self, held, weld, rest):
        """Pairs (group label, preview ids (h',)) of ``held`` (pairs (group label, detail ids (h,)),
        see :meth:`SkinDetachedSurface.reconstruct`), so the preview holds what the detail holds:
        the preview vertices whose representative is among the pair's detail vertices (``weld``
        (n,): the detail's welded ids) or, for a selection with no representative (a few vertices;
        a file without representatives), the preview vertex nearest each of its vertices at rest
        (``rest`` (n, 3)); a later pair wins a preview vertex two pairs claim."""
        pairs, tree, chosen = [], None, None
        for label, ids in held:
            ids = np.asarray(ids, dtype=np.int64)
            mine = np.zeros(0, dtype=np.int64)
            if self.representatives is not None and ids.size:
                if chosen is None:
                    chosen = np.zeros(int(max(weld.max(), self.representatives.max())) + 1, dtype=bool)
                welded = weld[ids]
                chosen[welded] = True  # a scatter: np.isin would sort the whole selection
                mine = np.flatnonzero(chosen[self.representatives])
                chosen[welded] = False
            if not mine.size and ids.size:
                tree = tree if tree is not None else cKDTree(self.points)
                mine = np.unique(tree.query(np.asarray(rest[ids], dtype=np.float64))[1])
            pairs.append((label, mine))
        return owned_pairs(pairs)

    def to_arrays(self):
        """Dict of plain arrays that :meth:`from_arrays` reads back."""
        arrays = dict(self.surface.to_arrays(), points=self.points, triangles=self.triangles)
        if self.representatives is not None:
            arrays["representatives"] = self.representatives
        return arrays

    @classmethod
    def from_arrays(cls, arrays, source="arrays"):
        """Check and read a dict written by :meth:`to_arrays` (see :meth:`SkinDetachedSurface.from_arrays`)."""
        surface = SkinDetachedSurface.from_arrays(arrays, source)
        try:
            points = as_points(f"{source} points", np.asarray(arrays["points"], dtype=np.float64).reshape(-1, 3),
                               surface.n_detail)
            triangles = as_triangles(f"{source} triangles", np.asarray(arrays["triangles"]).reshape(-1, 3),
                                     surface.n_detail)
        except (KeyError, TypeError, ValueError) as exc:
            raise SkinDetachError(f"{source}: expected the preview's points and triangles, got malformed data "
                                  f"({type(exc).__name__}: {exc}); rebuild the skin") from None
        if topology_fingerprint(points.shape[0], triangles) != surface.fingerprint:
            raise SkinDetachError(f"{source}: expected preview triangles matching its skin, got others; rebuild the skin")
        representatives = arrays.get("representatives")
        if representatives is not None:
            representatives = np.asarray(representatives).ravel()
            if (representatives.shape != (surface.n_detail,) or representatives.dtype.kind not in "iu"
                    or (representatives.size and representatives.min() < 0)):
                raise SkinDetachError(f"{source} representatives: expected ({surface.n_detail},) detail ids >= 0, got "
                                      f"{representatives.shape} {representatives.dtype}; rebuild the skin")
            representatives = representatives.astype(np.int64)
        if surface.riders is not None:  # their rest: the preview's own points
            surface.set_riders(*surface.riders[:2], points, still=surface.riders[3])
        return cls(points, triangles, surface, representatives)


class SkinDetachedSurface:
    """Detail mesh (n vertices) bound to a proxy (m vertices, k faces).

    proxy_vertices  (m, 3) float64 rest proxy
    proxy_faces     (k, 3) int64 proxy triangles
    weld            (n,) int64 welded id of every detail vertex (exact duplicates share one)
    carrier         (u,) int64 proxy vertex each welded vertex collapsed into (-1: loose)
    skin            :class:`Skin` over welded ids
    fingerprint     str, topology of the detail mesh it was built from
    stats           dict of counts, timings and normal-test figures
    preview         :class:`Preview` or None (set by :meth:`build` with ``preview_vertices``)
    riders          :class:`.riders.RigidRiders` or None: loose parts riding on others, each moved
                    rigidly onto where the skin puts it (set by :meth:`set_riders`)
    """

    preview = None
    riders = None

    def __init__(self, proxy_vertices, proxy_faces, weld, carrier, skin, fingerprint, stats):
        self.proxy_vertices = proxy_vertices
        self.proxy_faces = proxy_faces
        self.weld = weld
        self.carrier = carrier
        self.skin = skin
        self.fingerprint = fingerprint
        self.stats = stats
        #: The detail mesh's triangles (f, 3), once :meth:`attach_topology` gave them (:meth:`build`
        #: and :meth:`load` do), their welded edges where the build has them, the diffused skin
        #: made from them on first use, the free rebuild and the rebuilds of the last few
        #: rigid-group layouts (read and written under :attr:`_layout_lock` only).
        self.triangles = None
        self._edges = None
        self._seams = None
        self._free = None
        self._rebuilds = {}
        #: The layout of the last rebuild asked for (its key made once, not once per drag move).
        self._layout = None
        self._seam_steps = SEAM_STEPS
        #: Drop rows of recent selections (:meth:`drop_rows`), and their reach (by selection).
        self._drops = OrderedDict()
        self._reaches = OrderedDict()
        self._corner_weights = None
        #: The diffused skin is made once, the free rebuild once, whichever thread asks first
        #: (a background job may be making it: :meth:`prepare_free_rebuild`).
        self._seams_lock = threading.Lock()
        self._free_lock = threading.Lock()
        #: Jobs (:func:`..threads.submit`) of the free rebuild and of layouts' rebuilds.
        self._free_job = None
        self._layout_lock = threading.RLock()
        self._layout_jobs = []
        #: (fraction done, stage) of the free rebuild while it is being made, else None.
        self.free_progress = None

    @property
    def seam_steps(self):
        """How many one-ring steps the skin's weights are diffused over the detail mesh
        (:mod:`.seam_weights`; 0: the skin as bound, which creases where the proxy bends)."""
        return self._seam_steps

    @seam_steps.setter
    def seam_steps(self, steps):
        if not isinstance(steps, (int, np.integer)) or isinstance(steps, bool) or steps < 0:
            raise SkinDetachError(f"seam_steps: expected an integer >= 0, got {steps!r}")
        self._seam_steps = int(steps)
        self._forget_rebuilds()

    def attach_topology(self, triangles, edges=None):
        """Give the detail mesh's ``triangles`` (f, 3) (indices into the n detail vertices), over
        which the rebuild diffuses the skin's weights (:meth:`build` and :meth:`load` attach them);
        ``edges``, if the caller has it: the (u, u) graph of their directed edges in welded ids
        (see :func:`.seam_weights.one_ring`), kept until the diffused skin is made."""
        self.triangles = as_triangles("triangles", triangles, self.n_detail, narrow=True)
        self._edges = edges
        self._forget_rebuilds()

    def _forget_rebuilds(self):
        """Drop the diffused skin, the rebuilds made from it and the drop rows (a new topology or
        diffusion)."""
        with self._layout_lock, self._free_lock, self._seams_lock:  # the order they are taken in elsewhere
            self._seams = None
            self._free = None
            self._rebuilds = {}
        self._drops.clear()
        self._reaches.clear()

    def _seam_weights(self):
        if self.triangles is None:
            raise SkinDetachError("triangles: expected the detail triangles (attach_topology) before a rebuild, got "
                                  "none; pass the mesh's triangles to attach_topology")
        with self._seams_lock:
            if self._seams is None:
                u = self.skin.case.shape[0]
                frames = ProxyFrames(self.proxy_vertices, self.proxy_faces)
                edges = self._edges if self._edges is not None else half_edge_graph(self.weld[self.triangles], u)
                self._seams = SeamWeights(self.skin, edges, frames, self._seam_steps)
                self._edges = None
            return self._seams

    def _held_labels(self, held):
        """(u,) group of each welded detail vertex from ``held`` (pairs (group label, detail ids)),
        -1 where none; a later pair overrides an earlier one."""
        labels = np.full(self.skin.case.shape[0], -1, dtype=np.int32)
        for label, ids in held:
            if np.size(ids):  # a pair a later one took whole holds nothing
                labels[self.weld[as_vertex_ids("held ids", ids, self.n_detail)]] = int(label)
        return labels

    def _free_rebuild(self, wait=True, float32=False):
        """The :class:`.reconstruction.Rebuild` of the free diffused skin, every detail row: what
        every layout's rebuild shares (made once, by whichever thread asks first; :meth:`build`
        makes it or starts its background job). ``wait=False``: None unless it is made;
        ``float32``: its float32 copy made too."""
        if not wait:
            return self._free
        with self._free_lock:
            if self._free is None:
                self.free_progress = (0.0, "diffusing the skin")
                try:
                    skin = self._seam_weights().skin(progress=self._free_progressed)
                    check_coefficients(skin, "the diffused skin")
                    self.free_progress = (0.9, "making the rebuild")
                    threads.checkpoint()
                    self._free = Rebuild(skin, self.weld, self.proxy_vertices, self.proxy_faces)
                    del skin
                finally:
                    self.free_progress = None
            rebuild = self._free
        if float32:
            rebuild.float32_blocks()
        return rebuild

    def _free_progressed(self, fraction):
        threads.checkpoint()
        self.free_progress = (0.7 * fraction, "diffusing the skin")

    def prepare_free_rebuild(self, background=None, float32=False):
        """Make the free rebuild (see :meth:`_free_rebuild`) now, or with ``background`` (None: for
        meshes of :data:`BACKGROUND_ABOVE` welded vertices or more) on the background thread
        (:func:`..threads.submit`, one core); :attr:`free_progress` says how far it got,
        :attr:`free_rebuild_ready` when it is done, and whatever needs it meanwhile waits for it (a
        failure there is raised again by the next call that needs it)."""
        if background is None:
            background = self.skin.case.shape[0] >= BACKGROUND_ABOVE and self._free is None
        if not background:  # waits for a running job, if any
            self._free_rebuild(float32=float32)
        elif self._free is None and (self._free_job is None or self._free_job.done()):
            self.free_progress = (0.0, "diffusing the skin")
            self._free_job = threads.submit(self._free_rebuild, True, float32, watched=False,
                                            name="the free rebuild")

    @property
    def free_rebuild_ready(self):
        """Whether the free rebuild is made (a full-detail rebuild then starts at once)."""
        return self._free is not None

    def _layout_rebuild(self, groups, held):
        """The :class:`.reconstruction.LayoutRebuild` of a layout: the free rebuild with the rows
        within the diffusion's reach of its held vertices rebuilt from their own associations.
        The held rows themselves (``held``'s detail: their handles place them) are rebuilt only
        when a caller asks for them (:meth:`_held_rebuild`): preparing a layout costs the band
        along its selections' borders (:meth:`.seam_weights.SeamWeights.layout_band`), not the
        selections (at 3.2M the bend's anchor and handle hold 640,000 vertices)."""
        seams = self._seam_weights()
        labels = self._held_labels(held or [])
        welded, parts = seams.layout_band(groups, labels)
        changed = np.zeros(self.skin.case.shape[0], dtype=bool)
        changed[welded] = True
        rows = np.flatnonzero(changed[self.weld])
        placed = np.flatnonzero((labels >= 0)[self.weld])
        return LayoutRebuild(self._free_rebuild, rows, self._own_rebuild(parts, rows),
                             placed, lambda: self._held_rebuild(groups, held, placed))

    def _own_rebuild(self, parts, rows):
        """The :class:`.reconstruction.Rebuild` of the detail ``rows`` (r,) from the associations
        ``parts`` (vertex, face, weight, bary, height) of their welded rows."""
        vertex, face, weight, bary, height = parts
        skin = Skin(vertex=vertex, face=face, bary=bary, height=height, weight=weight, case=self.skin.case)
        check_coefficients(skin, "the diffused skin")
        return Rebuild(skin, self.weld[rows], self.proxy_vertices, self.proxy_faces)

    def _held_rebuild(self, groups, held, rows):
        """(rows (h',), their :class:`.reconstruction.Rebuild`): the held detail ``rows`` (h,) of a
        layout whose rows the layout's diffused skin changes (the others keep the free rebuild's),
        what a rebuild without their handles' placement gives them (made when first asked for: it
        costs the selections, not their border)."""
        seams = self._seam_weights()
        keep, replacement = seams.held_by(groups, self._held_labels(held))
        welded, parts = seams.layout_associations(keep, replacement)
        changed = np.zeros(self.skin.case.shape[0], dtype=bool)
        changed[welded] = True
        rows = rows[changed[self.weld[rows]]]  # the others' rows are the free rebuild's
        return rows, self._own_rebuild(parts, rows)

    def _rebuild_for(self, groups, held=None):
        """The rebuild with the vertices carried by one rigid group held (``groups`` (m,) int64 or
        None: the free rebuild) and those ``held`` names (pairs (group label, detail ids) or None)
        bound to faces their group holds (:meth:`_layout_rebuild`); the free rebuild and the last
        two layouts are kept, keyed by :meth:`.held_detail.Layout.key` (a drag move looks its
        matrix up without a pass over the detail)."""
        if groups is None:
            return self._free_rebuild()
        with self._layout_lock:  # one thread makes a layout; another asking for it waits
            self._layout = layout_of(self._layout, groups, held or [])
            key = self._layout.key()
            if key not in self._rebuilds:
                if len(self._rebuilds) >= 2:
                    self._rebuilds.pop(next(iter(self._rebuilds)))
                self._rebuilds[key] = self._layout_rebuild(groups, held)
            return self._rebuilds[key]

    def drop_rows(self, selections, groups=None):
        """One (k_i, m) CSR per detail ids ``selections[i]`` (k_i,): row r the drop point of
        detail vertex ``selections[i][r]`` in a rebuild with the rigid ``groups`` (m,) (see
        :meth:`reconstruct`, without ``held``: where the rebuild would put it from the proxy
        alone), the proxy-vertex part of its rebuild row, which sums to 1 (what
        :class:`..proxy_solve.pulled_energy.PulledEnergy` pulls). The layout's skin is diffused once
        for all, over the selections' neighbourhood only (:meth:`.seam_weights.SeamWeights.skin_of`)."""
        selections = [as_vertex_ids("selections", ids, self.n_detail) if np.size(ids) else np.zeros(0, dtype=np.int64)
                      for ids in selections]  # a selection a later group took whole pulls nothing
        seams = self._seam_weights()
        keep, _ = seams.held_by(None if groups is None else np.asarray(groups, dtype=np.int64))
        m = self.proxy_vertices.shape[0]
        keys = [self._drop_key(ids, keep) if ids.size else None for ids in selections]
        missing = [i for i, key in enumerate(keys) if key is not None and key[0] not in self._drops]
        if missing:
            # The selections a layout changed, diffused at once over their joint reach (a row's
            # diffusion is the same bit for bit over any sub-mesh that holds its reach): their
            # reaches overlap where the handles crowd, and each is diffused once, not per selection.
            welded = np.unique(np.concatenate([keys[i][1] for i in missing]))
            chosen = np.zeros(keep.shape[0], dtype=bool)
            chosen[welded] = True
            region = np.unique(np.concatenate([keys[i][2] for i in missing]))
            skin = seams.skin_of(welded, keep, (chosen, region))
            for i in missing:
                self._drops[keys[i][0]] = sp.csr_matrix(
                    rebuild_matrix(skin, self.proxy_faces, m, self.weld[selections[i]])[:, :m])
        out = []
        for key in keys:
            if key is None:
                out.append(sp.csr_matrix((0, m)))
                continue
            self._drops.move_to_end(key[0])
            out.append(self._drops[key[0]])
        while len(self._drops) > KEPT_DROP_ROWS:
            self._drops.popitem(last=False)
        return out

    def _drop_key(self, ids, keep):
        """(key, welded (s,) sorted ids, reach (r,) sorted ids) of :meth:`drop_rows` of one
        selection of detail ids ``ids`` (k,) with the held vertices ``keep`` (u,) bool: its drop
        rows are kept per selection and the held vertices within its reach (a new handle makes
        the drop rows of its own selection, and of those whose neighbourhood its proxy vertices
        change)."""
        seams = self._seam_weights()
        digest = hashlib.blake2b(ids.tobytes(), digest_size=20)
        selection = digest.digest()
        if selection not in self._reaches:  # a walk over the mesh's rings: once per selection, not per layout
            welded = np.unique(self.weld[ids])
            self._reaches[selection] = (welded, seams.reach(welded)[1])
            while len(self._reaches) > KEPT_DROP_ROWS:
                self._reaches.popitem(last=False)
        self._reaches.move_to_end(selection)
        welded, region = self._reaches[selection]
        digest.update(b"|" + region[keep[region]].tobytes())
        return digest.digest(), welded, region

    @property
    def n_detail(self):
        """Number of detail vertices n."""
        return self.weld.shape[0]

    @classmethod
    def build(cls, vertices, triangles, target_faces=1000, normal_test=True, preview_vertices=None, progress=None,
              attach=None, detach=None):
        """Simplify, detach the skin and prepare the rebuild of a triangle mesh.

        ``vertices`` (n, 3) float, ``triangles`` (f, 3) int indices into ``vertices``.
        ``preview_vertices``, if given and the mesh has more (welded) vertices, clusters the mesh
        to about that many vertices first (:mod:`.clustering`): the library simplifies the
        clustered mesh, which is much faster on millions of faces, and the clustered mesh, bound
        to the same proxy, becomes :attr:`preview`. The detail's skin is bound as without it.
        ``progress``, if given, is called as ``progress(fraction, stage)`` before each stage.
        Loose parts that touch a larger part ride on it (:mod:`.riders`): they get no proxy of their
        own and their skin binds to the proxy under them. ``attach`` and ``detach`` (k,) vertex ids
        (or None) name parts the artist made riders or free whatever they touch.
        """
        report = progress if progress is not None else (lambda fraction, stage: None)
        start = time.perf_counter()
        report(0.0, "checking the mesh")
        points = as_points("vertices", vertices)
        faces = as_triangles("triangles", triangles, points.shape[0], narrow=True)
        target = as_target_faces(target_faces)
        preview_vertices = as_preview_vertices(preview_vertices)
        if not isinstance(normal_test, (bool, np.bool_)):
            raise SkinDetachError(f"normal_test: expected True or False, got {normal_test!r}")
        attach, detach = (None if ids is None else as_vertex_ids(name, ids, points.shape[0])
                          for name, ids in (("attach", attach), ("detach", detach)))

        mesh = prepare_mesh(points, faces)
        if mesh.triangles.shape[0] == 0:
            raise SkinDetachError(
                f"triangles: expected at least one face of non-zero area, got {faces.shape[0]} degenerate faces")
        n_detail, n_faces = points.shape[0], faces.shape[0]
        fingerprint = topology_fingerprint(n_detail, faces)
        n_components = int(np.count_nonzero(np.bincount(mesh.components[mesh.triangles[:, 0]])))
        riders = find_riders(mesh.points, mesh.triangles, mesh.components,
                             *(None if ids is None else mesh.weld[ids] for ids in (attach, detach)))
        riders.settle_still(riders.part[mesh.triangles[:, 0]], target)
        del points, faces  # the prepared mesh holds what is still needed (often the same arrays)
        prepared = time.perf_counter()
        clustered = None
        if preview_vertices is not None and mesh.points.shape[0] > preview_vertices:
            report(0.1, "clustering")
            area = 0.5 * float(np.sqrt(np.einsum("ij,ij->i", mesh.cross, mesh.cross)).sum())
            clustered = cluster_mesh(mesh.points, mesh.triangles, mesh.normals, mesh.components, mesh.graph, area,
                                     preview_vertices)
        clustering = time.perf_counter()
        report(0.2, "simplifying")
        oversample = (CLUSTERED_OVERSAMPLE if clustered is not None else NORMAL_TEST_OVERSAMPLE) if normal_test else 1.0
        if clustered is None:
            free = riders.free_faces(mesh.triangles, mesh.components)
            proxy = simplify(mesh.points, mesh.triangles if free.all() else mesh.triangles[free], mesh.components,
                             target, oversample)
            carrier = proxy.carrier
        else:
            # The library simplifies the clustered mesh; detail vertex -> cluster -> proxy vertex.
            free = riders.free_faces(clustered.triangles, clustered.components)
            proxy = simplify(clustered.points, clustered.triangles if free.all() else clustered.triangles[free],
                             clustered.components, target, oversample)
            carrier = follow_nearest(proxy.carrier[clustered.cluster], mesh.triangles, mesh.points, proxy.points)
            mesh.cross = None  # the detail's quadrics come from the clustered copy: not needed
        simplified = time.perf_counter()
        report(0.5, "normal test")
        refused = 0
        proxy_points, proxy_faces = proxy.points, proxy.triangles
        remap = np.arange(proxy_points.shape[0])
        if normal_test:
            quadrics = None
            if clustered is not None:
                quadrics = cluster_quadrics(clustered.points, clustered.triangles,
                                            face_cross(clustered.points, clustered.triangles), proxy.carrier,
                                            proxy.points.shape[0])
            checked = collapse_with_normal_test(proxy.points, proxy.triangles, proxy.component, carrier, mesh, target,
                                                quadrics)
            remap = checked.remap
            carrier = np.where(carrier >= 0, remap[np.maximum(carrier, 0)], -1)
            proxy_points, proxy_faces, refused = checked.points, checked.triangles, checked.refused
        # The collapses' needles and caps taken out: flipped, merged, their vertices moved.
        proxy_points, proxy_faces, merged, repaired = repair_slivers(proxy_points, proxy_faces, target)
        remap = merged[remap]
        carrier = np.where(carrier >= 0, merged[np.maximum(carrier, 0)], -1)
        mesh.cross = mesh.triangles = None  # binding needs points and normals only (the graph: the seams)
        carrier = ride_carriers(riders, mesh.points, carrier)  # riders: carried by the proxy under them
        tested = time.perf_counter()
        report(0.7, "binding the skin")

        skin, ring_disagree = bind_skin(mesh.points, mesh.normals, carrier, proxy_points, proxy_faces)
        preview = None
        if clustered is not None:
            preview_carrier = np.where(proxy.carrier >= 0, remap[np.maximum(proxy.carrier, 0)], -1)
            preview_carrier = ride_carriers(riders, clustered.points, preview_carrier,
                                            riders.part[clustered.representatives])
            preview_skin = bind_skin(clustered.points, clustered.normals, preview_carrier, proxy_points,
                                     proxy_faces)[0]
            c = clustered.points.shape[0]
            preview = Preview(clustered.points, clustered.triangles,
                              cls(proxy_points, proxy_faces, np.arange(c), preview_carrier, preview_skin,
                                  topology_fingerprint(c, clustered.triangles), {"preview_of": n_detail}),
                              clustered.representatives)
            if riders.riding.any() or riders.still.any():
                part = riders.part[clustered.representatives]
                preview.surface.set_riders(*rider_groups(riders, part), clustered.points,
                                           still=still_vertices(riders, part))
        bound = time.perf_counter()
        with_normal = max(int(rows_any(mesh.normals).sum()), 1)
        bound_share = bound_disagreement(skin, mesh.normals, proxy_points, proxy_faces).sum() / with_normal
        ring_share = ring_disagree.sum() / with_normal
        counts = np.bincount(skin.case, minlength=5)
        angles = face_angles(proxy_points, proxy_faces)
        stats = {
            "detail_vertices": n_detail,
            "detail_faces": n_faces,
            "proxy_vertices": int(proxy_points.shape[0]),
            "proxy_faces": int(proxy_faces.shape[0]),
            "target_faces": target,
            "target_reached": bool(proxy_faces.shape[0] <= target),
            "case1": int(counts[CASE_ONE]),
            "case2": int(counts[CASE_TWO]),
            "case3": int(counts[CASE_THREE]),
            "loose": int(counts[CASE_LOOSE]),
            "associations": int(skin.vertex.shape[0]),
            "welded_duplicates": mesh.welded_vertices,
            "dropped_faces": mesh.dropped_faces,
            "components": n_components,
            "components_kept_whole": proxy.kept_whole,
            **riders.summary(),
            "normal_test": bool(normal_test),
            "normal_test_refused": int(refused),
            "proxy_least_angle": float(angles.min(initial=180.0)),
            "proxy_slivers": int(is_sliver(angles).sum()),
            **repaired,
            "normal_disagree_bound": float(bound_share),
            "normal_disagree_ring": float(ring_share),
            "preview_vertices": 0 if preview is None else int(preview.points.shape[0]),
            "preview_faces": 0 if preview is None else int(preview.triangles.shape[0]),
        }
        report(0.9, "preparing the rebuild")
        surface = cls(proxy_points, proxy_faces, mesh.weld, carrier, skin, fingerprint, stats)
        if riders.riding.any() or riders.still.any():
            surface.set_riders(*rider_groups(riders, riders.part[mesh.weld]), mesh.points[mesh.weld],
                               still=still_vertices(riders, riders.part[mesh.weld]))
        edges = mesh.graph
        if mesh.degenerate.size:
            edges = edges + half_edge_graph(mesh.degenerate, mesh.points.shape[0])
        del mesh, clustered  # their normals, components and cluster map: not needed for the seams
        surface.attach_topology(triangles, edges)  # the caller's array (validated again, not kept twice)
        del edges  # the seams drop it once made
        # The skin diffused over the whole detail mesh and its rebuild, once: every layout's rebuild
        # is this one with the rows near its held vertices replaced (a large mesh's on a background
        # thread: the preview stands in for it until a full-detail rebuild).
        if preview is not None:  # the drag shows the preview: its free rebuild too, not in the first Add Handle
            preview.surface.prepare_free_rebuild(background=False)
        surface.prepare_free_rebuild(float32=True)
        surface.preview = preview
        surface.corner_weights()  # every Add Handle reads it (0.2 s at 3.2M)
        done = time.perf_counter()
        stats["seconds"] = {
            "prepare": prepared - start, "cluster": clustering - prepared, "simplify": simplified - clustering, "normal_test": tested - simplified,
            "skin": bound - tested, "rebuild_setup": done - bound, "total": done - start,
        }
        report(1.0, "done")
        return surface

    def reconstruct(self, proxy_vertices, out=None, groups=None, held=None, place=None):
        """(n, 3) detail vertices rebuilt from deformed ``proxy_vertices`` (m, 3), into ``out`` if
        given: an (n, 3) float64 or float32 array (float32 computes in float32). ``groups`` (m,)
        int, optional: label of the rigid group (handle or anchor) each proxy vertex was moved
        with, -1 for none; detail carried by one group then moves exactly with it. The skin's
        weights are diffused over the detail mesh (:mod:`.seam_weights`: no creases where the
        proxy bends); the first rebuild with a new layout of groups prepares its matrix. ``held``
        (pairs (group label, detail ids (h,)), optional, with ``groups``): detail vertices that
        move exactly with their group although some proxy corners they bind to are free (a
        handle's selection: :mod:`.held_detail`); a later pair overrides an earlier one. ``place``
        (with ``held``): a callable that writes the held vertices into the (n, 3) result itself
        (:class:`.held_detail.HeldPlacement` with their handles' motions), instead of their rebuild."""
        points = as_points("proxy_vertices", proxy_vertices, self.proxy_vertices.shape[0])
        groups, held = self._checked_layout(groups, held)
        if out is not None and (not isinstance(out, np.ndarray) or out.shape != (self.n_detail, 3)
                                or out.dtype not in (np.float32, np.float64)):
            raise SkinDetachError(f"out: expected a ({self.n_detail}, 3) float32 or float64 array, got "
                                  f"{getattr(out, 'shape', type(out).__name__)} {getattr(out, 'dtype', '')}")
        if place is not None and held is None:
            raise SkinDetachError("place: expected held detail (pairs of group label and detail ids) with it, got none")
        rebuild = self._rebuild_for(groups, held)
        result = rebuild(points, out=out) if groups is None else rebuild(points, out=out, place=place)
        if self.riders is not None:
            self._rigid_riders().place(result, keep=self._riders_held(held))
        return result

    def set_riders(self, ids, starts, rest=None, still=None):
        """Make the riders keep their shape (:class:`.riders.RigidRiders`): ``ids`` (r,) detail
        vertex ids rider after rider, ``starts`` (k + 1,) their bounds, ``rest`` (n, 3) the detail's
        rest positions (None: the rebuild of the rest proxy, made on first use); ``still`` (s,)
        detail vertex ids of the parts that keep their rest (too small for a share of the proxy:
        :meth:`.riders.Riders.settle_still`), unless a handle holds them."""
        ids = np.asarray(ids, dtype=np.int64).ravel()
        if ids.size:
            ids = as_vertex_ids("rider_ids", ids, self.n_detail)
        starts = np.asarray(starts, dtype=np.int64).ravel()
        if starts.size < 1 or starts[0] != 0 or starts[-1] != ids.size or (np.diff(starts) <= 0).any():
            raise SkinDetachError(f"rider_starts: expected increasing bounds from 0 to {ids.size}, got "
                                  f"{starts[:4].tolist()}...{starts[-2:].tolist()}")
        still = np.zeros(0, dtype=np.int64) if still is None else np.asarray(still, dtype=np.int64).ravel()
        if still.size:
            still = as_vertex_ids("still_ids", still, self.n_detail)
        self.riders = (ids, starts, rest, still)
        self._riders_by_held = (None, None)

    def _rigid_riders(self):
        if not isinstance(self.riders, RigidRiders):
            ids, starts, rest, still = self.riders
            if rest is None:
                self.riders = None  # the rest as the skin rebuilds it, riders not yet placed
                rest = self.reconstruct(self.proxy_vertices)
            free = np.ones(self.n_detail, dtype=bool)
            free[ids] = False
            free[still] = False
            self.riders = RigidRiders(rest, ids, starts, free, still)
        return self.riders

    def _riders_held(self, held):
        """:meth:`.riders.RigidRiders.holding` of ``held``: the riders and still vertices it holds
        (they follow their handle, not a fit); kept for the last held pairs, the very same arrays
        (a drag asks with them every move; they are kept here, so no other array takes their id)."""
        if not held:
            return None
        kept = self._riders_by_held[0]
        if kept is None or len(kept) != len(held) or any(
                label != old_label or ids is not old_ids for (label, ids), (old_label, old_ids) in zip(held, kept)):
            self._riders_by_held = (list(held), self._rigid_riders().holding(held))
        return self._riders_by_held[1]

    def prepare_layout(self, groups=None, held=None, float32=False, background=False):
        """Prepare the rebuild of a layout (``groups``, ``held`` as for :meth:`reconstruct`) now, so
        that the first :meth:`reconstruct` with it finds its matrix ready (the last two layouts
        prepared or used are kept); ``float32``: also the float32 copy a float32 ``out`` uses
        (:meth:`.reconstruction.Rebuild.float32_blocks`). ``background``: on the background thread
        (:func:`..threads.submit`; a rebuild asking for the layout meanwhile waits for it, and
        makes it again, raising, if it failed there)."""
        checked = self._checked_layout(groups, held)

        def prepare():
            rebuild = self._rebuild_for(*checked)
            if float32:
                rebuild.float32_blocks()

        if not background:
            prepare()
        else:  # what it raises stays in its Future: made again, and raised, where it is needed
            self._layout_jobs = [job for job in self._layout_jobs if not job.done()] + [
                threads.submit(prepare, watched=False, name="a layout's rebuild")]

    def finish_preparing(self):
        """Wait for what background threads make for this surface (its free rebuild, made now if
        nothing makes it; its layouts' rebuilds)."""
        self.prepare_free_rebuild(background=False, float32=True)
        for job in self._layout_jobs:
            job.wait()

    @property
    def preparing(self):
        """(fraction done, stage) of what a background thread is making for this surface (its free
        rebuild, a layout's rebuild), or None."""
        if self.free_progress is not None or (self._free_job is not None and not self._free_job.done()):
            return self.free_progress or (0.0, "diffusing the skin")
        if not all(job.done() for job in self._layout_jobs):
            return (0.5, "preparing the layout")
        return None

    def _checked_layout(self, groups, held):
        """(``groups`` as (m,) int64 or None, ``held`` as a list of pairs or None), refused unless
        one integer label per proxy vertex, and held detail only with groups."""
        if groups is not None:
            m = self.proxy_vertices.shape[0]
            groups = np.asarray(groups)
            if groups.shape != (m,) or groups.dtype.kind not in "iu":
                raise SkinDetachError(f"groups: expected ({m},) integer labels, got {groups.shape} {groups.dtype}")
            groups = groups.astype(np.int64)
        if held is not None and groups is None:
            raise SkinDetachError("held: expected groups (the rigid group of every proxy vertex) with held detail, got none")
        return groups, None if held is None else [(label, ids) for label, ids in held]

    def corner_weights(self):
        """(m,) float64: the skin's weight on each proxy vertex, summed over every association (its
        rest-area weight times the corner's barycentric, negatives as 0; see
        :func:`.held_detail.proxy_ownership`), made once."""
        if self._corner_weights is None:
            m, skin = self.proxy_vertices.shape[0], self.skin

            def summed(start):  # a slice's small scratch arrays stay in the cache (10M: 1.2 s whole)
                part = slice(start, start + threads.PIECE)
                share = skin.weight[part, None] * np.clip(skin.bary[part], 0.0, None)
                return np.bincount(self.proxy_faces[skin.face[part]].ravel(), weights=share.ravel(), minlength=m)

            parts = threads.map_blocks(summed, list(range(0, skin.face.shape[0], threads.PIECE)))
            self._corner_weights = np.sum(parts, axis=0) if parts else np.zeros(m)  # the slices' order: the same bits
        return self._corner_weights

    def proxy_vertices_for(self, ids):
        """Sorted unique proxy vertex ids that carry the detail vertices ``ids``: every corner of
        every proxy triangle they are bound to. Moving these rigidly moves the detail vertices
        rigidly; constraining them makes a handle."""
        detail = as_vertex_ids("ids", ids, self.n_detail)
        welded = np.unique(self.weld[detail])
        rows, _ = flat_ranges(np.searchsorted(self.skin.vertex, welded),
                              np.searchsorted(self.skin.vertex, welded, side="right"))
        return np.unique(self.proxy_faces[self.skin.face[rows]])

    def to_arrays(self):
        """Dict of plain numpy arrays (numbers and 0-d strings) that :meth:`from_arrays` reads back."""
        arrays = {f"skin_{name}": getattr(self.skin, name) for name in _SKIN_FIELDS}
        arrays.update(format_tag=np.array(FORMAT_TAG), format_version=np.array(FORMAT_VERSION),
                      proxy_vertices=self.proxy_vertices, proxy_faces=self.proxy_faces, weld=self.weld,
                      carrier=self.carrier, fingerprint=np.array(self.fingerprint),
                      stats=np.array(json.dumps(self.stats)))
        arrays.update(self.rider_arrays())
        return arrays

    def rider_arrays(self):
        """{"rider_ids", "rider_starts"} of :meth:`set_riders`, or {} without riders."""
        if self.riders is None:
            return {}
        riders = self.riders
        ids, starts, still = (riders.ids, riders.starts, riders.still) if isinstance(riders, RigidRiders) \
            else (riders[0], riders[1], riders[3])
        return {"rider_ids": ids, "rider_starts": starts, "still_ids": still}

    @classmethod
    def from_arrays(cls, arrays, source="arrays"):
        """Check and read a dict written by :meth:`to_arrays` (index arrays may come back as int32,
        flat arrays are reshaped); ``source`` names where it came from in error messages. Anything
        malformed (wrong types or shapes, non-finite or absurd numbers, indices out of range,
        unreadable figures) raises :class:`SkinDetachError`."""
        try:
            return cls._from_arrays(arrays, source)
        except SkinDetachError:
            raise
        except (TypeError, ValueError, KeyError, AttributeError, IndexError, OverflowError) as exc:
            raise SkinDetachError(f"{source}: expected the arrays of a Skin Detach binding, got malformed data "
                                  f"({type(exc).__name__}: {exc}); rebuild the skin") from None

    @classmethod
    def _from_arrays(cls, arrays, source):
        if str(arrays.get("format_tag", "")) != FORMAT_TAG:
            raise SkinDetachError(f"{source}: expected format_tag {FORMAT_TAG!r}, got {str(arrays.get('format_tag'))!r}")
        version = int(arrays.get("format_version", -1))
        if version != FORMAT_VERSION:
            raise SkinDetachError(f"{source}: expected format version {FORMAT_VERSION}, got {version}; rebuild the skin")
        missing = {"proxy_vertices", "proxy_faces", "weld", "carrier", "fingerprint", "stats"}
        missing |= {f"skin_{name}" for name in _SKIN_FIELDS}
        missing -= arrays.keys()
        if missing:
            raise SkinDetachError(f"{source}: expected arrays {sorted(missing)}, they are missing")
        index = lambda key: np.asarray(arrays[key]).astype(np.int64).ravel()  # noqa: E731
        skin = Skin(vertex=index("skin_vertex"), face=index("skin_face"),
                    bary=np.asarray(arrays["skin_bary"], dtype=np.float64).reshape(-1, 3),
                    height=np.asarray(arrays["skin_height"], dtype=np.float64).ravel(),
                    weight=np.asarray(arrays["skin_weight"], dtype=np.float64).ravel(),
                    case=np.asarray(arrays["skin_case"]).astype(np.int8).ravel())
        check_coefficients(skin, source)
        n_assoc = skin.vertex.shape[0]
        if not (skin.face.shape[0] == skin.bary.shape[0] == skin.height.shape[0] == skin.weight.shape[0] == n_assoc):
            raise SkinDetachError(f"{source}: expected skin arrays of {n_assoc} associations each, got lengths "
                                  f"{[skin.face.shape[0], skin.bary.shape[0], skin.height.shape[0], skin.weight.shape[0]]}")
        proxy_vertices = as_points("proxy_vertices", np.asarray(arrays["proxy_vertices"], dtype=np.float64).reshape(-1, 3))
        proxy_faces = as_triangles("proxy_faces", index("proxy_faces").reshape(-1, 3), proxy_vertices.shape[0])
        if skin.face.size and (skin.face.max() >= proxy_faces.shape[0] or skin.face.min() < 0):
            raise SkinDetachError(f"{source}: expected skin_face to index the {proxy_faces.shape[0]} proxy faces, "
                                  f"got values out of range")
        if n_assoc and (skin.vertex.min() < 0 or skin.vertex.max() >= skin.case.shape[0]):
            raise SkinDetachError(f"{source}: expected skin_vertex to index the {skin.case.shape[0]} welded vertices, "
                                  f"got values out of range")
        weld = index("weld")
        if weld.size and (weld.min() < 0 or weld.max() >= skin.case.shape[0]):
            raise SkinDetachError(f"{source}: expected weld to index the {skin.case.shape[0]} welded vertices, "
                                  f"got values out of range")
        stats = json.loads(str(arrays["stats"]))
        if not isinstance(stats, dict):
            raise SkinDetachError(f"{source}: expected the build figures as a JSON object, got {type(stats).__name__}")
        surface = cls(proxy_vertices, proxy_faces, weld, index("carrier"), skin, str(arrays["fingerprint"]), stats)
        if "rider_ids" in arrays:
            surface.set_riders(index("rider_ids"), index("rider_starts"),
                               still=index("still_ids") if "still_ids" in arrays else None)
        return surface

    def save(self, path):
        """Write an .npz file (no pickled objects) that :meth:`load` reads back, with the detail
        triangles when they were given."""
        extra = {} if self.triangles is None else {"detail_triangles": self.triangles}
        if self.riders is not None:  # the riders' rest is the detail's: kept, not rebuilt on load
            rest = self._rider_rest()
            if rest is not None:
                extra["detail_rest"] = rest
        np.savez(path, **self.to_arrays(), **extra)

    def _rider_rest(self):
        """(n, 3) the detail's rest the riders were set with, or None (not given)."""
        riders = self.riders
        return riders.rest if isinstance(riders, RigidRiders) else riders[2]

    @classmethod
    def load(cls, path):
        """Read a file written by :meth:`save`; refuses pickled content and other versions."""
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {key: data[key] for key in data.files}
        except (OSError, ValueError, EOFError) as exc:
            raise SkinDetachError(f"path: expected a skin-detach .npz file, could not read {path!s}: {exc}") from None
        surface = cls.from_arrays(arrays, source=f"path {path!s}")
        if surface.riders is not None and "detail_rest" in arrays:
            surface.set_riders(*surface.riders[:2], as_points(f"path {path!s} detail_rest",
                                                               np.asarray(arrays["detail_rest"], dtype=np.float64)
                                                               .reshape(-1, 3), surface.n_detail),
                               still=surface.riders[3])
        if "detail_triangles" in arrays:
            try:
                surface.attach_topology(np.asarray(arrays["detail_triangles"]).astype(np.int64).reshape(-1, 3))
            except (TypeError, ValueError) as exc:
                raise SkinDetachError(f"path {path!s}: expected detail_triangles (f, 3), got malformed data "
                                      f"({exc}); rebuild the skin") from None
            if topology_fingerprint(surface.n_detail, surface.triangles) != surface.fingerprint:
                raise SkinDetachError(f"path {path!s}: expected detail_triangles matching the skin's topology, got "
                                      f"others; rebuild the skin")
        return surface
