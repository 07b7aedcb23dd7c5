"""Deformation quality and solver trust, per mesh: the pose suite and the bend scenario.

    python scripts/benchmark_quality.py [--meshes armadillo,cow,spot,...] [--at-least 25000] [--poses 300]
                                        [--pose-meshes armadillo,spot,cow] [--faces 1000] [--json PATH]
    python scripts/benchmark_quality.py --rigs [armadillo,armadillo-300K] [--rig-faces 300,1000]
                                        [--face-handles 48] [--face-drags 4] [--moves 30] [--json PATH]
    python scripts/benchmark_quality.py --proxy-angles [--meshes ...] [--sizes 25000,300000] [--faces 1000]
                                        [--json PATH]
    python scripts/benchmark_quality.py --repair-compare [--meshes ...] [--at-least 25000] [--faces 1000]
                                        [--json PATH]

Pose suite (bench/poses.py): random handle poses (axis random, up to 90 degrees, shift up to 10 %
of the diagonal), each solved warm (from the previous pose, as dragging does) and cold at
tol 1e-12: how many converged, how far warm and cold are apart, settle ms, and a handle turned
180 degrees in 15-degree steps and back. Bend scenario (DESIGN section 4) on every mesh at the
default proxy size, meshes flat-subdivided to at least ``--at-least`` vertices: edge distortion,
dihedral change, creases (interior edges whose dihedral angle changes by more than 30 degrees) and
the share of them on proxy seams (an endpoint bound to more than one proxy face, or the two to
different faces), handle error and detail volume change (bench/quality.py bend_quality, the row every benchmark
shares), first for the bend made as a script makes it ("add-on (api.deform)": api.build,
api.add_anchor, api.add_handle, the empty moved, api.deform, where the bpy module is there) with
its pivot offset (the handle empty's distance from its selected vertices' median point, world
space, over the diagonal) and api.stretch's mean and max, then for the default solver ("rotated": the
rebuild with the skin's weights diffused over the detail mesh, as every rebuild is), the same
solve rebuilt from the skin as bound (``seam_steps`` 0, what the product did before), and the
paper's iteration; beside Blender's own stack (Decimate
to our proxy's face count + Hook + Laplacian Deform + Surface Deform, where the bpy module is
there and Surface Deform binds) and full-resolution ARAP (libigl, 20 iterations, dev-only).
Totals over the meshes close the table.

Proxy triangles (``--proxy-angles``, in place of the above; issue 45): the proxy's shape on every
mesh at each of ``--sizes`` (every edge split evenly until the mesh has at least that many
vertices, bench.meshes.split_edges: its flat triangles keep their shapes) and on the demo's 300K
armadillo (turned Z-up as the demo turns it): proxy faces, least and largest angle, the share of faces with an angle under 10 degrees
and how many have one under 1 degree or over 170, beside Blender's Decimate (collapse) of the same
mesh to the same face count where the bpy module is there, and the goals (no angle under 1 degree,
at most 1 % of faces under 10).

Sliver repair on vs off (``--repair-compare``, in place of the above; issue 52): every mesh (those of
the proxy triangles table by default) built twice, with the proxy's sliver repair (core/detached_surface/sliver_repair.py) and without it
(``no_repair``), made as the bend makes them (``--at-least``; 0 keeps each at its size), beside thin
rods (``rod-R``: a capped cylinder of radius R, length 4, 24 x 200 quads, 4,826 vertices) and a flat
sheet (``sheet``: 60 x 60 quads, z = 0): build seconds (CPU time of the process, every thread's:
the machine's other load moves it less than the clock; the best of two builds) and the repair's
own, proxy faces against the target (and the build's stat saying why, under 95 %), slivers and
least angle, and the bend's creases with the default solver (the held rig, as api.deform bends it).

Rigs (``--rigs``, in place of the above; the bpy module; issue 43): the rigs artists build, on
each mesh and proxy size (``--rig-faces``: a coarse proxy puts more of a selection's proxy faces
in its neighbours'; ``armadillo-300K``: armadillo.obj after one 6-way flat subdivision, as
benchmark_scale.py and benchmark_drag.py make it), each on a fresh build, every drag a
DragSession as the modal operator drives it (a view along the mesh's shortest axis, one pixel a
thousandth of the diagonal; each mouse move timed with Blender's depsgraph update, then Enter):
a limb (bench/rigs.py: three adjacent bands from the tip of the raised arm, upper arm, forearm
and hand, each a handle, and a shoulder anchor past a free band), each handle dragged in turn
(G by 10 % of the diagonal, then R 30 typed); the same limb with the hand's empty parented to
the forearm's (Ctrl+P, Keep Transform), the forearm dragged (G, then R 30); two painted vertex
groups sharing the forearm (weights fading from 1 to 0.2, a handle from each, the lower one
newer), each dragged; a face rig: the feet anchored and ``--face-handles`` small disjoint
selections spread over the head (each Add Handle, api.add_handle with its layout prepared,
timed), ``--face-drags`` of them dragged by 3 % of the diagonal. After every confirm, each
handle's off (the largest distance of a vertex it owns, the newest selection containing it, from
where its empty's motion in the object's local space puts it, over the rest diagonal) and each
anchor's motion (bench/rigs.py held_errors); per rig the worst of them over its confirms, the
move ms (median, p95) and confirm ms (median, max); goals printed beside the figures (bench/rigs.py GOALS).

With the bpy module (the rigs, the bend as a script makes it) the add-on runs as an artist has it:
registered (bench/addon.py; its handlers installed), unregistered at the end; the JSON's meta says
``registered`` (absent without bpy).
"""

import argparse
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))  # the repository root: bench, the add-on

from bench import report
from bench.arap import arap_reference
from bench.meshes import named, subdivide
from bench.poses import pose_suite
from bench.quality import bend_quality
from bench.rigs import base, failed_goals, falloff, head, held_errors, limb, make, spots, weighted_group
from bench.scenario import bend_scenario

from skin_detach_addon.core import DualLaplacian, SkinDetachedSurface
from skin_detach_addon.core.detached_surface import sliver_repair, surface as surface_module
from skin_detach_addon.core.detached_surface.sliver_repair import face_angles
from skin_detach_addon.core.detached_surface.seam_weights import SEAM_STEPS
from skin_detach_addon.core.detached_surface.stretch import SkinStretch

MESHES = "armadillo,cow,spot,homer,alligator,cheburashka,horse,ogre,beetle-alt"
RIG_MESHES = "armadillo,armadillo-300K"
ANGLE_MESHES = "alligator,armadillo,bunny,cheburashka,cow,fandisk,homer,rocker-arm,spot,horse,ogre,beetle-alt"
REPAIR_MESHES = ANGLE_MESHES + ",rod-0.02,rod-0.05,rod-0.1,sheet"


def mesh(name, at_least):
    """A mesh of tests/data or bench/data (the unseen ones), flat-subdivided (4 ways) until it has
    ``at_least`` vertices, positions rounded to float32 as Blender stores them; ``rod-R`` and
    ``sheet`` are made (see :func:`made`) and kept as they are."""
    if name.startswith("rod-") or name == "sheet":
        return made(name)
    points, triangles = named(name)
    while points.shape[0] < at_least:
        points, triangles = subdivide(points, triangles, 4)
    return points.astype(np.float32).astype(np.float64), triangles


def made(name):
    """(points (n, 3), triangles (f, 3)) of ``rod-R`` (a capped cylinder along z of radius R, length
    4: 24 vertices around, 200 quads along, a fan at each end) or ``sheet`` (60 x 60 quads over the
    unit square, z = 0, each split along one diagonal)."""
    if name == "sheet":
        g = np.linspace(0.0, 1.0, 61)
        gx, gy = np.meshgrid(g, g, indexing="ij")
        points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
        ids = np.arange(61 * 61).reshape(61, 61)
        a, b, c, d = ids[:-1, :-1].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel(), ids[:-1, 1:].ravel()
        return points, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    radius, around, along, length = float(name[4:]), 24, 200, 4.0
    angle = 2 * np.pi * np.arange(around) / around
    ring = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    z = np.linspace(0.0, length, along + 1)
    points = np.concatenate([np.column_stack([np.tile(ring, (along + 1, 1)), np.repeat(z, around)]),
                             [[0.0, 0.0, 0.0], [0.0, 0.0, length]]])
    ids = np.arange((along + 1) * around).reshape(along + 1, around)
    a, b = ids[:-1], np.roll(ids[:-1], -1, axis=1)
    c, d = ids[1:], np.roll(ids[1:], -1, axis=1)
    low, high = points.shape[0] - 2, points.shape[0] - 1
    return points.astype(np.float32).astype(np.float64), np.concatenate([
        np.stack([a.ravel(), b.ravel(), d.ravel()], 1), np.stack([a.ravel(), d.ravel(), c.ravel()], 1),
        np.stack([np.full(around, low), np.roll(ids[0], -1), ids[0]], 1),
        np.stack([np.full(around, high), ids[-1], np.roll(ids[-1], -1)], 1)])


def held_bend_creases(points, triangles, scenario, surface):
    """The bend's creases (bench/quality.py) with the default solver on the held rig, as
    api.deform bends it (``surface`` gets the detail's topology)."""
    from bench.quality import creases
    surface.attach_topology(triangles)
    rig = scenario.held_rig(surface)
    surface.seam_steps = SEAM_STEPS
    solver = DualLaplacian(surface.proxy_vertices, surface.proxy_faces, rig["ids"], method="rotated",
                           pulls=rig["pulls"])
    result = solver.solve(rig["targets"], max_iter=500, tol=1e-12, pull_motions=rig["motions"])
    detail = surface.reconstruct(result.vertices, groups=rig["groups"], held=rig["layout"].held)
    return creases(points, detail, triangles)


def repair_compare_rows(args):
    """The sliver repair on vs off table (see the module): a row per mesh."""
    print(f"## Sliver repair on vs off (proxy target {args.faces} faces, meshes at least {args.at_least:,} "
          "vertices; build and repair: CPU seconds of this process, the best of two builds)\n")
    print("| mesh | vertices | build s on / off | repair s | faces on / off | slivers on / off "
          "| least angle on / off | creases on / off | short of target |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for name in [n for n in args.meshes.split(",") if n]:
        points, triangles = mesh(name, args.at_least)
        scenario = bend_scenario(points)
        row = dict(mesh=name, vertices=int(points.shape[0]), target=args.faces)
        for label, repair in (("on", sliver_repair.repair_slivers), ("off", sliver_repair.no_repair)):
            spent = []

            def timed(*a, repair=repair, spent=spent):
                start = time.process_time()
                out = repair(*a)
                spent.append(time.process_time() - start)
                return out
            surface_module.repair_slivers = timed
            try:
                builds = []
                for _ in range(2):
                    start = time.process_time()
                    surface = SkinDetachedSurface.build(points, triangles, target_faces=args.faces)
                    builds.append(time.process_time() - start)
            finally:
                surface_module.repair_slivers = sliver_repair.repair_slivers
            stats = surface.stats
            row[label] = dict(build_s=min(builds), repair_s=min(spent), faces=stats["proxy_faces"],
                              slivers=stats["proxy_slivers"], least=stats["proxy_least_angle"],
                              short=stats["proxy_short_of_target"], angle_rows=stats["sliver_angle_rows"],
                              passes=stats["sliver_passes"],
                              creases=held_bend_creases(points, triangles, scenario, surface))
        on, off = row["on"], row["off"]
        rows.append(row)
        print(f"| {name} | {row['vertices']:,} | {on['build_s']:.2f} / {off['build_s']:.2f} "
              f"({on['build_s'] / off['build_s']:.2f}x) | {on['repair_s']:.3f} | {on['faces']} / {off['faces']} | "
              f"{on['slivers']} / {off['slivers']} | {on['least']:.2f} / {off['least']:.2f} | "
              f"{on['creases']} / {off['creases']} | {on['short'] or '-'} |", flush=True)
    slower = max(r["on"]["build_s"] / r["off"]["build_s"] for r in rows)
    kept = min(r["on"]["faces"] / r["target"] for r in rows)
    worse = [r["mesh"] for r in rows if r["on"]["creases"] > r["off"]["creases"]]
    print(f"\nslowest build with the repair {slower:.2f}x without; fewest faces {100 * kept:.1f} % of the target; "
          f"creases on {sum(r['on']['creases'] for r in rows)} / off {sum(r['off']['creases'] for r in rows)}; "
          f"more creases with the repair on {', '.join(worse) or 'no mesh'}")
    return rows


def seam_vertices(surface):
    """(first face (u,), face count (u,)) of every welded detail vertex's associations."""
    skin = surface.skin
    u = skin.case.shape[0]
    first = np.full(u, -1)
    first[skin.vertex[::-1]] = skin.face[::-1]
    return first, np.bincount(skin.vertex, minlength=u)


def creases_on_seams(rest, detail, triangles, surface):
    """Share of the creased edges on a proxy seam: an endpoint bound to more than one proxy face,
    or the two bound to different faces (nan without creases)."""
    from bench.quality import CREASE_DEGREES, dihedral_angles, dihedral_changes
    _, pairs = dihedral_angles(rest, triangles)
    creased = pairs[dihedral_changes(rest, detail, triangles) > CREASE_DEGREES]
    if not creased.size:
        return float("nan")
    corners = np.sort(np.concatenate([triangles[creased[:, 0]], triangles[creased[:, 1]]], axis=1), axis=1)
    shared = corners[:, 1:][corners[:, 1:] == corners[:, :-1]].reshape(-1, 2)  # the edge's two vertices
    first, count = seam_vertices(surface)
    a, b = surface.weld[shared[:, 0]], surface.weld[shared[:, 1]]
    return float(np.mean((count[a] > 1) | (count[b] > 1) | (first[a] != first[b])))


def bend_rows(name, faces, at_least):
    points, triangles = mesh(name, at_least)
    scenario = bend_scenario(points)
    surface = SkinDetachedSurface.build(points, triangles, target_faces=faces)
    ids, targets = scenario.proxy_constraints(surface)
    rows = []
    scripted = through_api(name, points, triangles, scenario, faces)
    if scripted is not None:
        rows.append(quality_row(name, "add-on (api.deform)", points, scripted["detail"], triangles, scenario, surface,
                                converged=scripted["deform"]["converged"], settle_ms=scripted["deform"]["milliseconds"],
                                stretch_mean=float(scripted["stretch"].mean()),
                                stretch_max=float(scripted["stretch"].max()),
                                pivot_offset_diag=scripted["pivot"]))
    surface.attach_topology(triangles)
    rig = scenario.held_rig(surface)
    stretch = SkinStretch(surface)
    for method, steps in (("rotated", SEAM_STEPS), ("rotated, every corner held", SEAM_STEPS),
                          ("rotated, skin as bound", 0), ("paper", SEAM_STEPS)):
        surface.seam_steps = steps
        held = method == "rotated"
        solver = DualLaplacian(surface.proxy_vertices, surface.proxy_faces, rig["ids"] if held else ids,
                               method=method.split(",")[0], pulls=rig["pulls"] if held else ())
        start = time.perf_counter()
        result = solver.solve(rig["targets"] if held else targets, max_iter=500, tol=1e-12,
                              pull_motions=rig["motions"] if held else None)
        settle = time.perf_counter() - start
        layout = dict(groups=rig["groups"], held=rig["layout"].held) if held else \
            dict(groups=scenario.proxy_groups(surface))
        surface.reconstruct(result.vertices, **layout)  # the layout's first rebuild prepares its matrix
        start = time.perf_counter()
        detail = surface.reconstruct(result.vertices, **layout)
        rebuild = time.perf_counter() - start
        start = time.perf_counter()
        stretched = stretch(result.vertices)
        stretch_s = time.perf_counter() - start
        rows.append(quality_row(name, method, points, detail, triangles, scenario, surface,
                                converged=result.converged, settle_ms=1000 * settle,
                                stretch_mean=float(stretched.mean()), stretch_max=float(stretched.max()),
                                stretch_pct_of_step=100 * stretch_s / (settle + rebuild + stretch_s)))
    stack = blender_stack_pose(points, triangles, scenario, int(surface.proxy_faces.shape[0]))
    if stack is not None:
        rows.append(quality_row(name, "Blender stack", points, stack, triangles, scenario, surface))
    arap, _ = arap_reference(points, triangles, scenario, 20)
    if arap is not None:
        rows.append(quality_row(name, "ARAP (full resolution)", points, arap, triangles, scenario, surface))
    return rows


def blender_stack_pose(points, triangles, scenario, proxy_faces):
    """Blender's Decimate + Hook + Laplacian Deform + Surface Deform at the full pose, or None
    (no bpy module, or Surface Deform refuses the proxy)."""
    try:
        import bpy  # noqa: F401
    except ImportError:
        return None
    from bench.blender_stack import stack_pose
    return stack_pose(points, triangles, scenario, proxy_faces)


def quality_row(name, method, points, detail, triangles, scenario, surface, **extra):
    """bench/quality.py's bend row for one method, with the share of its creases on proxy seams."""
    return dict(mesh=name, method=method, vertices=int(points.shape[0]),
                **bend_quality(points, detail, triangles, scenario),
                creases_on_seams=creases_on_seams(points, detail, triangles, surface), **extra)


def through_api(name, points, triangles, scenario, faces):
    """The bend as a script does it on a Blender mesh of ``points``: api.build, api.add_anchor,
    api.add_handle, the empty moved by the scenario's motion, api.deform. A dict: ``pivot`` (the
    empty's distance from its selection's median point at rest, a fraction of the diagonal),
    ``detail`` (n, 3) the written positions, ``deform`` (api.deform's figures) and ``stretch``
    (n,) api.stretch; None without the bpy module."""
    try:
        import bpy
    except ImportError:
        return None
    from mathutils import Matrix

    from bench.meshes import blender_mesh
    from bench.quality import pivot_offset
    from skin_detach_addon import api
    from skin_detach_addon.blender import mesh_io
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = blender_mesh(name, points, triangles)
    api.build(obj, target_faces=faces)
    api.add_anchor(obj, scenario.anchor_ids)
    handle = api.add_handle(obj, scenario.handle_ids)
    pivot = pivot_offset(obj, handle, scenario.handle_ids)
    handle.matrix_world = Matrix((scenario.motion() @ np.array(handle.matrix_world)).tolist())
    figures = api.deform(obj)
    return dict(pivot=pivot, detail=mesh_io.read_positions(obj.data).astype(np.float64), deform=figures,
                stretch=api.stretch(obj))


def rig_mesh(name):
    """(points (n, 3) rounded to float32, triangles) of ``name``: a mesh of tests/data or
    bench/data as it is, or "NAME-SIZE" (a size of bench.meshes.SIZES) flat-subdivided to it."""
    from bench.meshes import SIZES, subdivided
    stem, _, size = name.rpartition("-")
    points, triangles = subdivided(stem, SIZES[size]) if stem and size in SIZES else named(name)
    return points.astype(np.float32).astype(np.float64), triangles


class RigRun:
    """One rig on a fresh build of a mesh: its handles as made (bench.rigs.Held, oldest first),
    the drags' move and confirm times and the worst held errors after each confirm."""

    def __init__(self, name, points, triangles, faces):
        import bpy

        from bench.meshes import blender_mesh
        from bench.views import AxisView
        from skin_detach_addon import api
        bpy.ops.wm.read_homefile(use_empty=True)
        self.obj = blender_mesh(name, points, triangles)
        self.proxy_faces = int(api.build(self.obj, target_faces=faces)["proxy_faces"])
        self.rest, self.made, self.moves, self.confirms = points, [], [], []
        self.worst = {}
        axis = np.zeros(3)
        axis[int(np.argmin(np.ptp(points, axis=0)))] = 1.0
        self.view = AxisView(-axis, scale=float(np.linalg.norm(np.ptp(points, axis=0))) / 1000.0)

    def add(self, kind, ids=None, group=None):
        return make(self.obj, kind, ids, group, self.made)

    def drag(self, held, pixels, moves, keys=()):
        """Drag ``held``'s empty: ``moves`` mouse moves (none: ``pixels`` is not used) to ``pixels`` (2,)
        from its centre on screen, then the key presses ``keys`` (typed input), then Enter; the held
        errors after it."""
        import bpy

        from skin_detach_addon import api
        centre = np.array(self.view.to_screen(held.empty.matrix_world.to_translation()))
        session = api.DragSession(self.obj, held.empty, self.view, tuple(centre))
        mouse = tuple(centre)
        for k in range(1, moves + 1):
            mouse = tuple(centre + np.asarray(pixels, dtype=float) * k / moves)
            start = time.perf_counter()
            session.event("MOUSEMOVE", "NOTHING", mouse)
            bpy.context.view_layer.update()
            self.moves.append(1000 * (time.perf_counter() - start))
        for key in keys:  # Blender evaluates the depsgraph after each event (a child empty follows its parent)
            session.event(key, "PRESS", mouse)
            bpy.context.view_layer.update()
        start = time.perf_counter()
        session.event("RET", "PRESS", mouse)
        bpy.context.view_layer.update()
        self.confirms.append(1000 * (time.perf_counter() - start))
        self.measure()

    def measure(self):
        """Keep the worst held errors so far: over the handles, the anchors and per empty."""
        per = self.worst.setdefault("per_handle", {})
        for error in held_errors(self.obj, self.rest, self.made):
            key = "worst_off" if error["kind"] == "HANDLE" else "worst_anchor"
            self.worst[key] = max(self.worst.get(key, 0.0), error["off"])
            per[error["name"]] = max(per.get(error["name"], 0.0), error["off"])

    def row(self, **extra):
        """The rig's figures (dict): counts, worst off and anchor motion (and per empty), the drags'
        move ms median and p95 and confirm ms median and max, and ``extra``."""
        handles = sum(held.kind == "HANDLE" for held in self.made)
        out = dict(vertices=int(self.rest.shape[0]), proxy_faces=self.proxy_faces, handles=handles,
                   anchors=len(self.made) - handles, worst_off=self.worst.get("worst_off", 0.0),
                   worst_anchor=self.worst.get("worst_anchor", 0.0), per_handle=self.worst.get("per_handle", {}))
        if self.moves:
            out.update(move_ms_median=float(np.median(self.moves)), move_ms_p95=float(np.percentile(self.moves, 95)),
                       confirm_ms_median=float(np.median(self.confirms)), confirm_ms_max=float(np.max(self.confirms)))
        return dict(out, **extra)


TURN_30 = ("R", "THREE", "ZERO")


def limb_run(name, points, triangles, faces):
    """A :class:`RigRun` of the limb: the shoulder anchored, (upper arm, forearm, hand) handles."""
    parts = limb(points, triangles)
    run = RigRun(name, points, triangles, faces)
    run.add("ANCHOR", parts["shoulder"])
    return run, [run.add("HANDLE", parts[part]) for part in ("upper arm", "forearm", "hand")]


def limb_rig(name, points, triangles, faces, moves):
    """The limb: shoulder anchor, upper arm, forearm, hand; each handle dragged in turn (G, then R 30)."""
    run, arm = limb_run(name, points, triangles, faces)
    for held in arm:
        run.drag(held, (70, 70), moves)
        run.drag(held, (0, 0), 0, TURN_30)
    return run.row(rig="limb: 3 adjacent handles + shoulder anchor")


def parented_rig(name, points, triangles, faces, moves):
    """The limb with the hand's empty parented to the forearm's (Ctrl+P, Keep Transform); the forearm dragged."""
    import bpy
    run, (_, forearm, hand) = limb_run(name, points, triangles, faces)
    for other in bpy.context.view_layer.objects:
        other.select_set(False)
    hand.empty.select_set(True)
    forearm.empty.select_set(True)
    bpy.context.view_layer.objects.active = forearm.empty
    bpy.ops.object.parent_set(type='OBJECT', keep_transform=True)
    run.drag(forearm, (70, 70), moves)
    run.drag(forearm, (0, 0), 0, TURN_30)
    return run.row(rig="hand parented to the forearm's empty")


def weighted_rig(name, points, triangles, faces, moves):
    """Two painted groups sharing the forearm (weights 1 to 0.2), a handle from each; each dragged."""
    parts = limb(points, triangles)
    run = RigRun(name, points, triangles, faces)
    upper = np.union1d(parts["upper arm"], parts["forearm"])
    lower = np.union1d(parts["forearm"], parts["hand"])
    weighted_group(run.obj, "upper", upper, falloff(points, upper, 0.2))
    weighted_group(run.obj, "lower", lower, falloff(points, lower, 0.2))
    run.add("ANCHOR", parts["shoulder"])
    for held in (run.add("HANDLE", group="upper"), run.add("HANDLE", group="lower")):
        run.drag(held, (70, 70), moves)
        run.drag(held, (0, 0), 0, TURN_30)
    return run.row(rig="weighted vertex groups (overlapping)")


def face_rig(name, points, triangles, faces, moves, count, drags):
    """The feet anchored, ``count`` small handles over the head, each Add Handle timed; ``drags`` of them dragged."""
    run = RigRun(name, points, triangles, faces)
    run.add("ANCHOR", base(points))
    added, grips = [], []
    for selection in spots(points, head(points), count):
        start = time.perf_counter()
        grips.append(run.add("HANDLE", selection))
        added.append(time.perf_counter() - start)
    for held in grips[::max(1, count // max(drags, 1))][:drags]:
        run.drag(held, (21, 21), moves)
    return run.row(rig=f"face rig: {count} small handles", add_handle_s_max=float(np.max(added)),
                   add_handle_s_median=float(np.median(added)),
                   selection_vertices_median=float(np.median([held.ids.size for held in grips])))


def rig_rows(name, faces, moves, face_handles, face_drags):
    """Every rig on mesh ``name`` bound to a proxy of about ``faces`` faces: a list of rows (dict,
    see :meth:`RigRun.row`), a rig refused by the add-on with its message under "refused"."""
    from skin_detach_addon.core.errors import SkinDetachError
    points, triangles = rig_mesh(name)
    rows = []
    for rig in (limb_rig, parented_rig, weighted_rig, face_rig):
        extra = (face_handles, face_drags) if rig is face_rig else ()
        try:
            row = rig(name, points, triangles, faces, moves, *extra)
        except SkinDetachError as error:
            row = dict(rig=rig.__name__, vertices=int(points.shape[0]), refused=str(error))
        rows.append(dict(mesh=name, target_faces=faces, **row))
    return rows


def rig_line(row):
    """A table row of a rigs row."""
    if "refused" in row:
        return (f"| {row['mesh']} | {row['vertices']:,} | {row['target_faces']} | {row['rig']} | refused: "
                f"{row['refused'][:120]} |" + " - |" * 6)
    moving = (f"{row['move_ms_median']:.1f} / {row['move_ms_p95']:.1f} | {row['confirm_ms_median']:.0f} / "
              f"{row['confirm_ms_max']:.0f}") if "move_ms_median" in row else "- | -"
    added = (f"{row['add_handle_s_max']:.2f} / {row['add_handle_s_median']:.2f}" if "add_handle_s_max" in row
             else "-")
    return (f"| {row['mesh']} | {row['vertices']:,} | {row['proxy_faces']} | {row['rig']} | "
            f"{row['handles']} + {row['anchors']} | "
            f"{row['worst_off']:.1e} | {row['worst_anchor']:.1e} | {moving} | {added} | "
            f"{', '.join(failed_goals(row)) or 'none'} |")


def run_rigs(args):
    # The add-on is driven through its API and DragSession, registered as an artist has it (main).
    print("## Rigs artists build (off and anchor motion over the diagonal)\n")
    print("| mesh | vertices | proxy faces | rig | handles + anchors | worst off (goal <= 1e-5) "
          "| worst anchor motion (<= 1e-5) | move ms median (<= 16) / p95 | confirm ms median / max (<= 150) "
          "| Add Handle s max (<= 0.5) / median | fails |")
    print("|---" * 11 + "|")
    rows = []
    for name in [n for n in args.rigs.split(",") if n]:
        for faces in [int(f) for f in args.rig_faces.split(",") if f]:
            for row in rig_rows(name, faces, args.moves, args.face_handles, args.face_drags):
                rows.append(row)
                print(rig_line(row), flush=True)
    return rows


def angle_figures(points, triangles):
    """Least / largest angle (degrees), % of faces under 10 degrees, faces under 1 and over 170, and
    whether the proxy's goals are met (no angle under 1 degree, at most 1 % of faces under 10)."""
    angles = face_angles(points, triangles)
    least, largest = angles.min(axis=1), angles.max(axis=1)
    under_10_pct, under_1 = 100 * float(np.mean(least < 10.0)), int(np.sum(least < 1.0))
    return dict(faces=int(triangles.shape[0]), least=float(least.min()), largest=float(largest.max()),
                under_10_pct=under_10_pct, under_1=under_1, over_170=int(np.sum(largest > 170.0)),
                goals_met=under_1 == 0 and under_10_pct <= 1.0)


def decimated(points, triangles, faces):
    """(points, triangles) of Blender's Decimate (collapse, triangulated) of the mesh to ``faces``
    triangles, or None without the bpy module."""
    try:
        import bpy
    except ImportError:
        return None
    from bench.meshes import blender_mesh
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = blender_mesh("decimated", points, triangles)
    modifier = obj.modifiers.new("decimate", 'DECIMATE')
    modifier.ratio = faces / triangles.shape[0]
    modifier.use_collapse_triangulate = True
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    out_points = np.array([v.co[:] for v in mesh.vertices])
    out_faces = np.array([p.vertices[:] for p in mesh.polygons if len(p.vertices) == 3], dtype=np.int64)
    return out_points, out_faces


def proxy_angle_rows(args):
    """The proxy triangles table (see the module): a row per mesh and size."""
    from bench.meshes import armadillo, split_edges
    print(f"## Proxy triangles (proxy target {args.faces} faces; goals: no angle under 1 degree, "
          "at most 1 % of faces under 10)\n")
    print("| mesh | vertices | proxy faces | least angle | largest angle | faces < 10 deg | faces < 1 deg "
          "| faces > 170 deg | goals | Decimate: least angle / < 10 deg |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    cases = []
    for name in [n for n in args.meshes.split(",") if n]:
        points, triangles = named(name)
        for size in [int(s) for s in args.sizes.split(",") if s]:
            parts = 1
            while points.shape[0] * parts * parts < size:
                parts += 1
            cases.append((name, lambda p=points, t=triangles, k=parts: split_edges(p, t, k) if k > 1 else (p, t)))
    demo = armadillo("300K")  # as scripts/demo.py turns it: OBJ's Y-up to Blender's Z-up
    cases.append(("armadillo (demo 300K)", lambda: (demo[0][:, [0, 2, 1]] * [1, -1, 1], demo[1])))
    rows = []
    for name, make_mesh in cases:
        points, triangles = make_mesh()
        points = points.astype(np.float32).astype(np.float64)
        surface = SkinDetachedSurface.build(points, triangles, target_faces=args.faces)
        row = dict(mesh=name, vertices=int(points.shape[0]),
                   **angle_figures(surface.proxy_vertices, surface.proxy_faces))
        blender = decimated(points, triangles, row["faces"])
        if blender is not None:
            row["decimate"] = angle_figures(*blender)
        rows.append(row)
        other = (f"{row['decimate']['least']:.2f} / {row['decimate']['under_10_pct']:.1f} %" if "decimate" in row
                 else "-")
        print(f"| {name} | {row['vertices']:,} | {row['faces']} | {row['least']:.2f} | {row['largest']:.1f} | "
              f"{row['under_10_pct']:.1f} % | {row['under_1']} | {row['over_170']} | "
              f"{'met' if row['goals_met'] else 'NOT met'} | {other} |", flush=True)
    met = sum(row["goals_met"] for row in rows)
    print(f"\ngoals met on {met} of {len(rows)}")
    return rows


def totals(rows):
    """Per method: meshes, total creases and mean dihedral change over the meshes every method has."""
    meshes = set.intersection(*[{r["mesh"] for r in rows if r["method"] == m} for m in {r["method"] for r in rows}])
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        picked = [r for r in rows if r["method"] == method and r["mesh"] in meshes]
        out.append(dict(method=method, meshes=len(picked), creases=int(sum(r["creases"] for r in picked)),
                        dihedral_change_deg=float(np.mean([r["dihedral_change_deg"] for r in picked]))))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", default=MESHES)
    parser.add_argument("--pose-meshes", default="armadillo,spot,cow")
    parser.add_argument("--poses", type=int, default=300)
    parser.add_argument("--faces", type=int, default=1000)
    parser.add_argument("--at-least", type=int, default=25_000, help="flat-subdivide smaller meshes to this many vertices")
    parser.add_argument("--rigs", nargs="?", const=RIG_MESHES, help="run the rigs scenario on these meshes "
                        f"(default {RIG_MESHES}) instead of the pose suite and the bend")
    parser.add_argument("--rig-faces", default="300,1000", help="rigs: proxy target faces, each size in turn")
    parser.add_argument("--face-handles", type=int, default=48, help="rigs: handles of the face rig")
    parser.add_argument("--face-drags", type=int, default=4, help="rigs: face handles dragged")
    parser.add_argument("--moves", type=int, default=30, help="rigs: mouse moves of a drag")
    parser.add_argument("--proxy-angles", action="store_true", help="the proxy triangles table instead of the "
                        "pose suite and the bend")
    parser.add_argument("--sizes", default="25000,300000", help="proxy angles: mesh sizes (vertices at least)")
    parser.add_argument("--repair-compare", action="store_true", help="the sliver repair on vs off table "
                        "instead of the pose suite and the bend")
    parser.add_argument("--json")
    args = parser.parse_args()
    if args.repair_compare:
        if args.meshes == MESHES:
            args.meshes = REPAIR_MESHES
        rows = repair_compare_rows(args)
        if args.json:
            report.save(args.json, {"repair_compare": rows})
        return
    if args.proxy_angles:
        if args.meshes == MESHES:
            args.meshes = ANGLE_MESHES
        rows = proxy_angle_rows(args)
        if args.json:
            report.save(args.json, {"proxy_angles": rows})
        return
    registered = as_an_artist_has_it()
    if args.rigs:
        figures = {"rigs": run_rigs(args)}
        if args.json:
            report.save(args.json, figures, registered=registered)
        finished(registered)
        return
    figures = {"poses": [], "bend": []}
    print(f"## Pose suite ({args.poses} random poses, tol 1e-12, proxy target {args.faces} faces)\n")
    print("| mesh | method | proxy faces | factor ms | warm / cold converged | warm-cold within 1e-5 diag "
          "| max warm-cold (diag) | settle ms (median) | 180 deg and back (diag) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in args.pose_meshes.split(",") if n]:
        points, triangles = named(name)
        surface = SkinDetachedSurface.build(points, triangles, target_faces=args.faces)
        for method in ("rotated", "paper"):
            row = dict(mesh=name, method=method, **pose_suite(surface, bend_scenario(points), count=args.poses,
                                                             method=method))
            figures["poses"].append(row)
            print(f"| {name} | {method} | {row['proxy_faces']} | {row['factor_ms']:.1f} | {row['warm_converged']} / "
                  f"{row['cold_converged']} of {row['poses']} | {100 * row['within_1e-5']:.1f} % | "
                  f"{row['max_warm_cold']:.1e} | {row['settle_ms_median']:.1f} | {row['turned_back_to_rest']:.1e} |",
                  flush=True)
    print(f"\n## Bend scenario, proxy target {args.faces} faces\n")
    print("| mesh | vertices | method | edge distortion | dihedral change deg | creases (> 30 deg) | on proxy seams "
          "| handle error % diag | volume change % | converged | settle ms | stretch mean / max | stretch % of a step "
          "| pivot offset (diag) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in args.meshes.split(",") if n]:
        for row in bend_rows(name, args.faces, args.at_least):
            figures["bend"].append(row)
            settle = f"{row['converged']} | {row['settle_ms']:.0f}" if "settle_ms" in row else "- | -"
            settle += (f" | {row['stretch_mean']:.3f} / {row['stretch_max']:.3f}" if "stretch_mean" in row else " | -")
            settle += f" | {row['stretch_pct_of_step']:.1f}" if "stretch_pct_of_step" in row else " | -"
            settle += f" | {row['pivot_offset_diag']:.1e}" if "pivot_offset_diag" in row else " | -"
            print(f"| {name} | {row['vertices']:,} | {row['method']} | {row['edge_distortion']:.3f} | "
                  f"{row['dihedral_change_deg']:.2f} | {row['creases']} | {100 * row['creases_on_seams']:.0f} % | "
                  f"{row['handle_error_pct_diag']:.2e} | {row['volume_change_pct']:+.2f} | {settle} |", flush=True)
    figures["totals"] = totals(figures["bend"])
    print("\n## Totals over the meshes\n\n| method | meshes | creases | mean dihedral change deg |\n|---|---|---|---|")
    for row in figures["totals"]:
        print(f"| {row['method']} | {row['meshes']} | {row['creases']} | {row['dihedral_change_deg']:.3f} |")
    if args.json:
        report.save(args.json, figures, registered=registered)
    finished(registered)


def as_an_artist_has_it():
    """Register the add-on for the parts that drive it through bpy (the rigs, the bend as a script
    makes it): whether it runs registered (bench/addon.py), None without the bpy module."""
    try:
        import bpy  # noqa: F401
    except ImportError:
        return None
    from bench.addon import register
    return register()


def finished(registered):
    """Unregister what :func:`as_an_artist_has_it` registered (bench/addon.py's finish: call it last)."""
    if registered is not None:
        from bench.addon import finish
        finish()


if __name__ == "__main__":
    main()
