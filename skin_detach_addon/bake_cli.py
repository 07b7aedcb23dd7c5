"""Bake a Skin Detach rig frame by frame: evaluate the (animated) handle empties at every frame
of a range, rebuild the detail mesh and write it out.

On a farm worker (Blender with the extension installed from any repository, no checkout):
    blender -b scene.blend --python-exit-code 1 --python-expr "FARM_EXPR" -- ARGS
(FARM_EXPR below, as the farm job types pass it: it finds the enabled extension whatever
repository it came from and exits 1 when there is none; --python-exit-code 1 makes Blender
exit 1 after an uncaught Python error, where it would exit 0.)
From a checkout:     blender --background scene.blend --python scripts/bake.py -- ARGS
With the bpy module: python scripts/bake.py --blend scene.blend ARGS

ARGS:
  --object NAME       the bound mesh (default: the only bound mesh in the file)
  --frames 1-250      frames to bake: "1-250", "12", "1-10,20", "1..250" or "1-250:5" (every
                      5th), negative frames too (pass them as --frames=-3,-2); default: the
                      scene's range; split a long range across machines, each bakes its own part
  --output PATH       "out/mesh_####.obj" or ".ply": one file per frame (#### = frame number,
                      UVs kept; OBJ keeps the vertex order); or "baked.blend": the result saved
                      in a copy of the scene, as shape keys (default) or one object per frame
  --into shape-keys|objects   what goes into a .blend output
  --apply-modifiers   export files with the object's modifiers applied (or --modifiers apply|ignore)
  --stretch, --no-stretch   give each frame's object or PLY file its own frame's stretch map
                      (the skin_detach_stretch attribute and its colours), or none; default: its
                      own when the mesh shows its stretch in the file (Show Stretch), else none
  --no-volume         do not keep the volume of the proxy (default: kept, as in the panel; or
                      --volume keep|free)
  --target-faces N    proxy size when the binding has to be built (default 1000)
  --rebuild           build the binding again even if the file has one
  --farm              one chunk of a farm job: refuse outputs that chunks cannot share (a .blend)
  --verify            solve nothing: check that every frame's file exists (a farm job's last
                      task), exit 1 naming the missing frames

Each baked frame prints a line starting "Time: MM:SS.ss" (the frame's time), which Flamenco's
Worker counts as a finished step (as it does Blender's render lines), then "bake: frame N ...".

The binding saved in the file is reused; it is built only when the mesh has none but has
handles (a file from an older version). Re-running gives the same output. Exits 0 on success,
1 with a one-line message on any failure (missing object, no binding and no handles, unwritable
output, a frame whose file is missing after the bake, an unexpected error with its traceback),
2 on bad arguments.
"""

import argparse
import os
import signal
import sys
import threading
import time
import traceback

#: The Python expression a farm worker's Blender runs (``--python-expr``): the enabled Skin Detach
#: add-on, from whichever extension repository (``bl_ext.<repository>.skin_detach_addon``) or as a
#: legacy add-on, runs this CLI; without it Blender exits 1 with a message naming what is missing.
FARM_EXPR = ("import importlib, sys, bpy; "
             "found = sorted(a.module for a in bpy.context.preferences.addons "
             "if a.module.rsplit('.', 1)[-1] == 'skin_detach_addon'); "
             "found or sys.exit('bake: error: the Skin Detach extension is not enabled in this Blender ' "
             "+ bpy.app.version_string + '; install it on every Worker that takes bake tasks'); "
             "importlib.import_module(found[0] + '.bake_cli').main()")


def parser():
    """The command line's :class:`argparse.ArgumentParser` (options as in the module docstring)."""
    parser = argparse.ArgumentParser(prog="skin-detach-bake", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blend", help="the .blend to open (bpy-module use; Blender opens it itself)")
    parser.add_argument("--object", help="name of the bound mesh object")
    parser.add_argument("--frames", help="frames: 1-250, 12, 1-10,20, 1..250 or 1-250:5 (default: the scene's range)")
    parser.add_argument("--output", required=True, help="out/mesh_####.obj, out/mesh_####.ply or baked.blend")
    parser.add_argument("--into", choices=("shape-keys", "objects"), default="shape-keys")
    parser.add_argument("--apply-modifiers", action="store_true")
    parser.add_argument("--no-volume", action="store_true")
    # The same two choices as values, for job templates that cannot leave an argument out.
    parser.add_argument("--modifiers", choices=("apply", "ignore"), help="apply = --apply-modifiers")
    parser.add_argument("--volume", choices=("keep", "free"), help="free = --no-volume")
    parser.add_argument("--stretch", action=argparse.BooleanOptionalAction, default=None,
                        help="each frame's own stretch map in objects and PLY files, or none (default: its own "
                             "when the mesh shows its stretch)")
    parser.add_argument("--target-faces", type=int, default=1000)
    parser.add_argument("--rebuild", action="store_true")
    parser.add_argument("--farm", action="store_true", help="one chunk of a farm job: one file per frame only")
    parser.add_argument("--verify", action="store_true", help="check that every frame's file exists; solve nothing")
    return parser


def parse_args(argv):
    args = parser().parse_args(argv)
    args.apply_modifiers = args.apply_modifiers or args.modifiers == "apply"
    args.no_volume = args.no_volume or args.volume == "free"
    return args


def script_argv():
    """Arguments for this script: after ``--`` inside Blender, all of them with the bpy module."""
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


class BakeFailed(Exception):
    pass


def find_object(bpy, api, name):
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise BakeFailed(f"--object: expected an object of the file, got {name!r} (objects: "
                             f"{', '.join(sorted(o.name for o in bpy.data.objects if o.type == 'MESH')) or 'none'})")
        mesh = api.mesh_of(obj)  # a proxy or a handle stands for its mesh
        if mesh is None or mesh.type != 'MESH':
            raise BakeFailed(f"--object: expected a mesh object (or its proxy or a handle), got {name!r} of type "
                             f"{obj.type}")
        if mesh != obj:
            print(f"bake: {name!r} belongs to {mesh.name!r}; baking that mesh", flush=True)
        return mesh
    bound = api.bound_objects()
    if len(bound) != 1:
        raise BakeFailed(f"--object: expected one bound mesh in the file to pick, found {len(bound)} "
                         f"({', '.join(o.name for o in bound) or 'none'}); name it with --object")
    return bound[0]


def ensure_binding(api, obj, args):
    """Reuse the stored binding; build it when missing (or asked) and the rig has handles."""
    if api.is_bound(obj) and not args.rebuild:
        return False
    if not api.handles_of(obj):
        raise BakeFailed(f"object {obj.name!r}: expected a Skin Detach binding or handles to build one from, "
                         f"it has neither; set the rig up in Blender first")
    print(f"bake: building the binding of {obj.name!r} ({args.target_faces} proxy faces)", flush=True)
    api.build(obj, target_faces=args.target_faces)
    return True


def run(args):
    import bpy

    from . import api

    if args.blend:
        if not os.path.isfile(args.blend):
            raise BakeFailed(f"--blend: expected an existing .blend file, got {args.blend!r}")
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.blend))
    to_blend = args.output.lower().endswith(".blend")
    if to_blend and (args.farm or args.verify):
        raise BakeFailed(f"--output: expected one .obj or .ply file per frame for a farm job (chunks cannot share "
                         f"one .blend: each would overwrite it with its own frames), got {args.output!r}")
    if args.verify:
        return verify(bpy, api, args)
    source = bpy.data.filepath
    if source and os.path.exists(args.output) and os.path.samefile(args.output, source):
        raise BakeFailed(f"--output: expected a file other than the source .blend, got {args.output!r} (it would "
                         f"overwrite the source)")
    scene = bpy.context.scene
    obj = find_object(bpy, api, args.object)
    if bpy.context.view_layer.objects.active is None:
        bpy.context.view_layer.objects.active = obj
    if to_blend:
        api.check_output_file("--output", args.output)
    frames = api.frame_list(args.frames or f"{scene.frame_start}-{scene.frame_end}")  # refused before any work
    built = ensure_binding(api, obj, args)
    into = {"shape-keys": api.SHAPE_KEYS, "objects": api.OBJECTS}[args.into] if to_blend else api.FILES
    start = time.perf_counter()

    def progress(done, total, record):
        warning = "" if record["converged"] else f" (warning: the solve did not converge in {record['iterations']} iterations)"
        seconds = record["milliseconds"] / 1000.0
        print(f"Time: {int(seconds // 60):02d}:{seconds % 60:05.2f} | bake: frame {record['frame']} ({done}/{total}) "
              f"solved in {record['milliseconds']:.1f} ms -> {record['output']}{warning}", flush=True)

    records = api.bake(obj, frames, into=into, path=None if to_blend else args.output,
                       preserve_volume=not args.no_volume, apply_modifiers=args.apply_modifiers, progress=progress,
                       stretch=args.stretch)
    if not to_blend:
        missing = [r["frame"] for r in records  # a rig of several objects: one file per object
                   if not all(os.path.isfile(f) for f in (r["output"] if isinstance(r["output"], list) else [r["output"]]))]
        if len(records) != len(frames) or missing:
            raise BakeFailed(f"--output: expected one file for each of the {len(frames)} frames, "
                             f"{len(records) - len(missing)} were written (missing frames: "
                             f"{sorted(set(frames) - {r['frame'] for r in records} | set(missing))})")
    if to_blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.output), copy=True)
    seconds = time.perf_counter() - start
    print(f"bake: {len(records)} frames of {obj.name!r} ({len(obj.data.vertices):,} vertices) in {seconds:.1f} s"
          f"{' (binding built first)' if built else ''}; wrote {args.output}", flush=True)


def verify(bpy, api, args):
    """Every frame of ``--frames`` (default: the scene's range) has its file: else BakeFailed."""
    scene = bpy.context.scene
    frames = api.frame_list(args.frames or f"{scene.frame_start}-{scene.frame_end}")
    try:  # a rig of several objects has one file per object and frame
        members = api.members(find_object(bpy, api, args.object))
    except (BakeFailed, api.SkinDetachError):
        members = []
    members = [None] if len(members) < 2 else members
    missing = [f for f in frames if not all(os.path.isfile(api.bake_file_path(args.output, f, member))
                                            for member in members)]
    if missing:
        shown = ", ".join(map(str, missing[:20])) + (" ..." if len(missing) > 20 else "")
        raise BakeFailed(f"--output: expected a file for each of the {len(frames)} frames, {len(missing)} are "
                         f"missing (frames {shown})")
    print(f"bake: all {len(frames)} files of {args.output} are there", flush=True)


def main(argv=None):
    """Run the bake with ``argv`` (default: the command line's, after ``--`` inside Blender);
    exits 1 with a one-line message on failure (any error: Blender itself would exit 0 after an
    uncaught one), 2 on bad arguments."""
    args = parse_args(script_argv() if argv is None else argv)
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C stops the bake (Blender, and the bpy module, leave SIGINT to themselves): the bake
        # gives the scene back as it was, the files written so far are complete.
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        import bpy  # noqa: F401  (first: the bpy module makes mathutils importable)

        from .api import SkinDetachError
        try:
            run(args)
        except (SkinDetachError, BakeFailed) as exc:
            raise BakeFailed(str(exc)) from None
        except RuntimeError as exc:  # a Blender operator's error report
            raise BakeFailed(str(exc).strip()) from None
        except Exception as exc:  # a bug: the traceback for the task log, and a failed task
            traceback.print_exc()
            raise BakeFailed(f"unexpected {type(exc).__name__}: {exc}") from None
    except BakeFailed as exc:
        print(f"bake: error: {exc}", file=sys.stderr, flush=True)
        sys.exit(1)
    except KeyboardInterrupt:
        print("bake: interrupted (Ctrl-C); the files written so far are complete", file=sys.stderr, flush=True)
        sys.exit(130)
