"""Baking: the rebuilt detail of a bound mesh, frame by frame over a range, into shape keys,
new objects or one mesh file per frame.

At every frame the scene is evaluated (so animated, driven or constrained handle empties are
where the animation puts them), the proxy is solved to the settle tolerance and the detail is
rebuilt from the stored rest. Re-running a bake replaces what the same frames made before
(same shape key, same baked object, same file), so it is idempotent. When it ends, or fails,
the scene frame, the mesh and its shape keys are as they were before; a failed bake also
removes the shape keys and objects it had added.
"""

import itertools
import os
import re
import socket
import time

from ..core.errors import SkinDetachError
from . import binding as stored
from . import mesh_io, rig_members, skin_rig
from .deformation import Deformation

SHAPE_KEYS = "SHAPE_KEYS"
OBJECTS = "OBJECTS"
FILES = "FILES"
MODES = (SHAPE_KEYS, OBJECTS, FILES)
#: Baked shape keys are named ``skin_detach_0012`` (the frame number, zero-padded).
KEY_PREFIX = "skin_detach_"
#: Baked objects go into this collection, tagged with ``{"owner": obj, "frame": f}``.
BAKE_COLLECTION = "Baked Frames"  # not named after the add-on: see skin_rig.RIG_COLLECTION
BAKE_TAG = "_skin_detach_bake"
FORMATS = (".obj", ".ply")


#: A bake takes at most this many frames (a larger range is refused before any frame is solved).
MAX_FRAMES = 100_000
#: This process in the names of its partial files: host and process id (then a write counter).
_PROCESS_TAG = f"{re.sub(r'[^A-Za-z0-9-]', '-', socket.gethostname())}-{os.getpid()}"
_WRITES = itertools.count()


def _remove_orphans(folder, name):
    """Remove the partial files of ``name`` in ``folder`` left by processes of this host that are
    gone (a killed bake); those of other hosts, or of live processes, are left alone."""
    prefix = f".{name}."
    host = _PROCESS_TAG.rsplit("-", 1)[0]
    for entry in os.listdir(folder):
        match = re.fullmatch(re.escape(prefix) + r"(.+)-(\d+)-\d+\.partial\.\w+", entry)
        if match is None or match.group(1) != host or int(match.group(2)) == os.getpid():
            continue
        if not _alive(int(match.group(2))):
            try:
                os.remove(os.path.join(folder, entry))
            except OSError:
                pass


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # no permission, or no such check here: count it as alive
        return True
    return True


def parse_frames(text):
    """Frame numbers from ``"1-250"``, ``"12"``, ``"1-10,20,30-40"``, Blender's ``"1..250"`` or
    a stepped range ``"1-250:5"`` (as Open Job Description writes evenly spaced chunks: 1, 6, ...,
    246); frames may be negative (``"-3,-2"``, ``"-10--5"``). Inclusive, in order, no repeats; at
    most :data:`MAX_FRAMES` of them."""
    frames, seen, work = [], set(), 0
    for part in str(text).replace(" ", "").split(","):
        match = re.fullmatch(r"(-?\d{1,9})(?:(?:-|\.\.)(-?\d{1,9})(?::(\d{1,9}))?)?", part)
        if match is None:
            raise SkinDetachError(f"frames: expected a frame or range like '1-250', '1..250', '1-250:5' or "
                                  f"'1-10,20', got {text!r}")
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) is not None else first
        step = int(match.group(3)) if match.group(3) is not None else 1
        if last < first:
            raise SkinDetachError(f"frames: expected a range that does not run backwards, got {part!r}")
        if step < 1:
            raise SkinDetachError(f"frames: expected a step of at least 1, got {part!r}")
        work += (last - first) // step + 1
        if (last - first) // step + 1 > MAX_FRAMES or work > 10 * MAX_FRAMES:
            raise SkinDetachError(f"frames: expected at most {MAX_FRAMES:,} frames, got {text!r}")
        for frame in range(first, last + 1, step):
            if frame not in seen:
                seen.add(frame)
                frames.append(frame)
        if len(frames) > MAX_FRAMES:
            raise SkinDetachError(f"frames: expected at most {MAX_FRAMES:,} frames, got {text!r}")
    return frames


def check_frames(frames):
    """``frames`` (an iterable of ints or a :func:`parse_frames` string) as a non-empty list of ints."""
    if isinstance(frames, str):
        return parse_frames(frames)
    try:
        frames = list(frames)
        values = [int(f) for f in frames]
    except (TypeError, ValueError):
        raise SkinDetachError(f"frames: expected frame numbers, got {frames!r}") from None
    if not values or any(v != f for v, f in zip(values, frames)):
        raise SkinDetachError(f"frames: expected at least one whole frame number, got {frames!r}")
    values = list(dict.fromkeys(values))
    if len(values) > MAX_FRAMES:
        raise SkinDetachError(f"frames: expected at most {MAX_FRAMES:,} frames, got {len(values):,}")
    return values


def file_path(pattern, frame):
    """The file of ``frame`` for ``pattern``: the last run of ``#`` in the file name becomes the
    zero-padded frame (``out/bunny_####.obj`` -> ``out/bunny_0012.obj``; other ``#`` stay as they
    are); without ``#`` in the file name, ``_####`` goes before the extension."""
    folder, name = os.path.split(pattern)
    if "#" not in name:
        root, ext = os.path.splitext(name)
        name = f"{root}_####{ext}"
    runs = list(re.finditer(r"#+", name))
    last = runs[-1]
    name = f"{name[:last.start()]}{frame:0{len(last.group(0))}d}{name[last.end():]}"
    return os.path.join(folder, name) if folder else name


def member_pattern(pattern, name):
    """The file name pattern of the object ``name`` of a rig of several objects: its name (characters
    other than letters, digits, ``-``, ``_`` and ``.`` made ``_``) and ``_`` inserted before the
    last run of ``#`` in the file name (``out/char_####.obj``, "Eye.L" -> ``out/char_Eye.L_####.obj``;
    without ``#``, before the ``_####`` :func:`file_path` adds)."""
    folder, base = os.path.split(pattern)
    if "#" not in base:
        root, ext = os.path.splitext(base)
        base = f"{root}_####{ext}"
    last = list(re.finditer(r"#+", base))[-1]
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", str(name))
    base = f"{base[:last.start()]}{safe}_{base[last.start():]}"
    return os.path.join(folder, base) if folder else base


def check_output(pattern):
    """Raise unless ``pattern`` names .obj or .ply files in a folder that exists (or can be made) and is writable."""
    ext = os.path.splitext(pattern)[1].lower()
    if ext not in FORMATS:
        raise SkinDetachError(f"path: expected a file name ending in {' or '.join(FORMATS)}, got {pattern!r}")
    check_folder("path", pattern)


#: A path written for Windows: a drive letter, or any backslash (a UNC share starts with two).
WINDOWS_PATH = re.compile(r"^[A-Za-z]:([\\/]|$)|\\")


def check_reachable(argument, path, platform=os.name):
    """Raise if ``path`` is written for another platform's file system than ``platform``
    (``os.name``): on Linux and macOS a UNC share (``\\\\server\\share``), a drive letter or a
    backslash would only name a folder of this machine's own disk (a farm Worker would bake there
    and report success); on Windows a POSIX absolute path (``/mnt/render``) names a folder on the
    current drive. ``argument`` names the path in the message."""
    text = os.fspath(path)
    if platform == "nt":
        foreign = text.startswith("/") and not text.startswith("//")
        kind = "a POSIX path (on Windows it would be a folder of the current drive)"
    else:
        foreign = WINDOWS_PATH.search(text) is not None
        kind = "a Windows path (here it would be a folder of this machine's own disk)"
    if foreign:
        raise SkinDetachError(f"{argument}: expected a folder this machine can reach, got {text!r}, {kind}; "
                              f"map the share to a path of this system (a farm: a two-way variable)")


def check_folder(argument, path):
    """Raise unless ``path`` is a path of this platform (:func:`check_reachable`) whose folder
    exists (or can be made) and is writable, as is ``path`` itself if it exists; ``argument``
    names it in the message."""
    check_reachable(argument, path)
    folder = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise SkinDetachError(f"{argument}: expected a folder that can be created, got {folder!r} "
                              f"({exc.strerror})") from None
    if not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise SkinDetachError(f"{argument}: expected a writable folder and file, got {path!r} (permission denied)")


def bake(obj, frames, into=SHAPE_KEYS, path=None, preserve_volume=True, apply_modifiers=False, progress=None,
         stretch=None):
    """Bake ``obj`` (a bound mesh object) at each of ``frames``; returns one dict per frame:
    frame, milliseconds (solve + rebuild), iterations, converged, volume_change, output (the
    shape key name, object name or file path).

    into             SHAPE_KEYS: one shape key per frame, keyed 0-1-0 around its frame
                     (linear), so playback shows the animation without the add-on;
                     OBJECTS: one new object per frame (a copy carrying the mesh's UVs,
                     materials and vertex groups) in the "Baked Frames" collection;
                     FILES: one .obj or .ply file per frame at ``path`` (see :func:`file_path`),
                     with UVs, written by Blender's own exporter.
    apply_modifiers  FILES only: export with the object's modifiers applied (default: the mesh
                     itself, the same vertices in the same order as the original).
    progress         called as ``progress(done, total, record)`` after every frame.
    stretch          OBJECTS and FILES: True: each frame's object or file carries that frame's own
                     stretch (the stretch map's attribute and colours, made the active color, as
                     Show Stretch makes them; a PLY file holds both), False: none (a baked object
                     keeps the artist's own active color); None (default): True when ``obj``
                     shows its stretch, else False. Never the pose shown when the bake started.
    """
    import bpy

    if into not in MODES:
        raise SkinDetachError(f"into: expected one of {', '.join(MODES)}, got {into!r}")
    frames = check_frames(frames)
    if not isinstance(stretch, (bool, type(None))):
        raise SkinDetachError(f"stretch: expected True, False or None, got {stretch!r}")
    if into == SHAPE_KEYS and stretch:
        raise SkinDetachError(f"stretch: expected False or None for {SHAPE_KEYS} (a shape key holds positions "
                              f"only), got True; bake into {OBJECTS} or PLY files to keep each frame's stretch")
    members = rig_members.objects(obj)
    if stretch is None:
        stretch = any(mesh_io.stretch_shown(member.data) for member in members if member is not None)
    if into == FILES:
        if not path:
            raise SkinDetachError("path: expected a file name pattern such as 'out/mesh_####.obj' for FILES, got none")
        check_output(path)
    scene = bpy.context.scene
    if obj.name not in scene.objects:
        raise SkinDetachError(f"object {obj.name!r}: expected it in the current scene {scene.name!r}, it is not")
    deformation = Deformation(obj, preserve_volume)
    for member in deformation.members[1:]:
        if member.name not in scene.objects:
            raise SkinDetachError(f"object {member.name!r}: expected it in the current scene {scene.name!r} with "
                                  f"the rig of {obj.name!r}, it is not")
    saved_frame = (scene.frame_current, scene.frame_subframe)
    saved = deformation.snapshot()
    kind = {SHAPE_KEYS: _ShapeKeyWriter, OBJECTS: _ObjectWriter, FILES: _FileWriter}[into]
    if deformation.several:
        names = [member.name for member in deformation.members]
        patterns = [member_pattern(path, name) if path else path for name in names]
        if into == FILES and len({file_path(p, frames[0]) for p in patterns}) != len(patterns):
            raise SkinDetachError(f"objects: expected names that give each object its own file, got {names} "
                                  f"(two give the same file name)")
        writer = _MembersWriter(obj, [kind(member, pattern, apply_modifiers)
                                      for member, pattern in zip(deformation.members, patterns)])
    else:
        writer = kind(obj, path, apply_modifiers)
    records = []
    try:
        for frame in frames:
            scene.frame_set(frame)
            start = time.perf_counter()
            result, detail = deformation.solve()
            stretched = deformation.binding.stretch(result.vertices) if stretch and into != SHAPE_KEYS else None
            milliseconds = 1000 * (time.perf_counter() - start)
            records.append({"frame": frame, "milliseconds": milliseconds, "iterations": result.iterations,
                            "converged": result.converged, "volume_change": result.volume_change,
                            "output": writer.write(frame, detail, stretched)})
            if progress is not None:
                progress(len(records), len(frames), records[-1])
    except SkinDetachError as exc:
        writer.undo()
        if into != FILES or not records:
            raise
        # Files of the frames before it stay (each is complete): say which, not "nothing was written".
        first, last = records[0]["frame"], records[-1]["frame"]
        raise SkinDetachError(f"frame {frame}: {str(exc).replace('(nothing was written)', '(nothing of this frame was written)')}; "
                              f"the files of the {len(records)} frames before it ({first} to {last}) are written and "
                              f"kept") from None
    except BaseException:
        writer.undo()
        raise
    finally:
        deformation.restore(saved)
        scene.frame_set(saved_frame[0], subframe=saved_frame[1])
    return records


class _MembersWriter:
    """Bake writer of a rig of several objects: one writer per object (:mod:`.rig_members`), each
    given its own positions (the frame's combined ones mapped into its space) and stretch; its
    output is the list of theirs, in the rig's order."""

    def __init__(self, owner, writers):
        self.owner, self.writers = owner, writers

    def write(self, frame, detail, stretch=None):
        parts = rig_members.split(self.owner, detail)
        for member, part in zip(rig_members.objects(self.owner), parts):
            mesh_io.check_positions(f"object {member.name!r} at frame {frame}", part)
        values = rig_members.split_values(self.owner, stretch) if stretch is not None else [None] * len(parts)
        return [writer.write(frame, part, value) for writer, part, value in zip(self.writers, parts, values)]

    def undo(self):
        for writer in self.writers:
            writer.undo()


class _ShapeKeyWriter:
    """Bake writer into shape keys of the mesh. Every writer has ``write(frame, detail (n, 3)
    float32 positions in the mesh's vertex order, stretch (n,) float32 that frame's stretch or
    None: none) -> output name`` and ``undo()``, which removes what it made."""

    def __init__(self, obj, path, apply_modifiers):
        self.obj = obj
        self.made = []
        if obj.data.shape_keys is None:
            self.made.append(obj.shape_key_add(name="Basis", from_mix=False).name)

    def write(self, frame, detail, stretch=None):
        blocks = self.obj.data.shape_keys.key_blocks
        name = f"{KEY_PREFIX}{frame:04d}"
        key = blocks.get(name)
        if key is None:
            key = self.obj.shape_key_add(name=name, from_mix=False)
            self.made.append(name)
        key.relative_key = blocks[0]
        key.slider_min, key.slider_max = 0.0, 1.0
        key.data.foreach_set("co", detail.ravel())
        for at, value in ((frame - 1, 0.0), (frame, 1.0), (frame + 1, 0.0)):
            key.value = value
            key.keyframe_insert("value", frame=at)
        for fcurve in _fcurves(self.obj.data.shape_keys):
            if fcurve.data_path == f'key_blocks["{name}"].value':
                for point in fcurve.keyframe_points:
                    point.interpolation = 'LINEAR'
        return name

    def undo(self):
        blocks = self.obj.data.shape_keys.key_blocks if self.obj.data.shape_keys else {}
        for name in reversed(self.made):
            if name in blocks:
                self.obj.shape_key_remove(blocks[name])


def _fcurves(id_data):
    """F-curves of the action of ``id_data`` (Blender 4.2's flat actions and 4.4+'s slotted ones)."""
    animation = id_data.animation_data
    if animation is None or animation.action is None:
        return []
    action = animation.action
    slot = getattr(animation, "action_slot", None)
    if slot is None:
        return list(action.fcurves)
    from bpy_extras import anim_utils
    channelbag = anim_utils.action_get_channelbag_for_slot(action, slot)
    return [] if channelbag is None else list(channelbag.fcurves)


class _ObjectWriter:
    """Bake writer into one object per frame (a copy of the mesh object with (n, 3) positions
    ``detail`` and the frame's ``stretch`` shown, or none), see :class:`_ShapeKeyWriter` for the
    interface."""

    def __init__(self, obj, path, apply_modifiers):
        self.obj = obj
        self.made = []
        self.collection = skin_rig.scene_collection(BAKE_COLLECTION)

    def write(self, frame, detail, stretch=None):
        baked = next((o for o in self.collection.objects if BAKE_TAG in o and o[BAKE_TAG].get("owner") == self.obj
                      and o[BAKE_TAG].get("frame") == frame and len(o.data.vertices) == len(detail)), None)
        if baked is None:
            baked = self.obj.copy()
            baked.data = self.obj.data.copy()
            stored.strip_copy(baked)
            if BAKE_TAG in baked:
                del baked[BAKE_TAG]
            baked.name = f"{self.obj.name}_bake_{frame:04d}"
            baked.parent = None
            baked.animation_data_clear()
            self.collection.objects.link(baked)
            baked[BAKE_TAG] = {"owner": self.obj, "frame": frame}
            self.made.append(baked.name)
        baked.matrix_world = self.obj.matrix_world.copy()
        mesh_io.write_positions(baked.data, detail)
        _write_stretch(baked.data, stretch)
        return baked.name

    def undo(self):
        import bpy
        for name in self.made:
            baked = bpy.data.objects.get(name)
            if baked is not None:
                skin_rig.remove_with_mesh(baked)


class _FileWriter:
    """Bake writer into one OBJ or PLY file per frame: ``detail`` (n, 3) and ``stretch`` (shown,
    or hidden when None) are written into the mesh (restored when the bake ends) and exported;
    see :class:`_ShapeKeyWriter` for the interface."""

    def __init__(self, obj, path, apply_modifiers):
        self.obj = obj
        self.pattern = path
        self.apply_modifiers = bool(apply_modifiers)

    def write(self, frame, detail, stretch=None):
        """Export to a hidden partial file beside the target, then rename it over the target: a
        frame's file is complete or absent, whenever the process is stopped (a re-run replaces
        it and removes the partial files killed bakes of this host left)."""
        target = os.path.abspath(file_path(self.pattern, frame))
        folder, name = os.path.split(target)
        # Unique to this write: two bakes of one frame into one folder (a requeued task whose
        # first Worker still runs) never write or rename each other's partial file.
        partial = os.path.join(folder, f".{name}.{_PROCESS_TAG}-{next(_WRITES)}.partial{os.path.splitext(name)[1]}")
        mesh_io.write_positions(self.obj.data, detail)
        _write_stretch(self.obj.data, stretch)
        try:
            self._export(partial, target.lower().endswith(".obj"))
            if not os.path.isfile(partial):
                raise SkinDetachError(f"path: expected {target!r} written by the exporter, it was not"
                                      + ("" if os.path.isdir(folder) else f" (its folder {folder!r} is gone)"))
            os.replace(partial, target)
        except BaseException as exc:  # an error or Ctrl-C: no partial file stays behind
            if os.path.exists(partial):
                os.remove(partial)
            if isinstance(exc, (RuntimeError, OSError)):  # the exporter's or the file system's words
                reason = f"its folder {folder!r} is gone" if not os.path.isdir(folder) else \
                    f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else exc!r}"
                raise SkinDetachError(f"path: expected to write {target!r}, could not ({reason})") from None
            raise
        _remove_orphans(folder, name)
        return target

    def _export(self, path, obj_format):
        """Export the object alone to ``path`` (OBJ when ``obj_format``, else PLY), with UVs."""
        import bpy
        view_layer = bpy.context.view_layer
        selected = [o for o in view_layer.objects if o.select_get()]
        active = view_layer.objects.active
        try:
            for o in selected:
                o.select_set(False)
            try:
                self.obj.select_set(True)
            except RuntimeError:
                raise SkinDetachError(f"object {self.obj.name!r}: expected it in the view layer to export it, "
                                      f"its collection is excluded") from None
            view_layer.objects.active = self.obj
            if obj_format:
                bpy.ops.wm.obj_export(filepath=path, check_existing=False, export_selected_objects=True,
                                      export_uv=True, export_materials=False, apply_modifiers=self.apply_modifiers)
            else:
                bpy.ops.wm.ply_export(filepath=path, check_existing=False, export_selected_objects=True,
                                      export_uv=True, apply_modifiers=self.apply_modifiers)
        finally:
            self.obj.select_set(False)
            for o in selected:
                o.select_set(True)
            view_layer.objects.active = active

    def undo(self):
        pass


def _write_stretch(mesh, stretch):
    """Show (n,) ``stretch`` on ``mesh`` (see :func:`.mesh_io.show_stretch`), or with None remove
    the stretch map a copy carried over (:func:`.mesh_io.hide_stretch`)."""
    if stretch is None:
        mesh_io.hide_stretch(mesh)
    else:
        mesh_io.show_stretch(mesh, stretch)
