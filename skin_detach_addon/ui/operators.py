"""Operators: collect, call, write, report. Every SkinDetachError becomes one ERROR report in
:meth:`_Operator.execute` / the drag's and the build's ``invoke`` and ``modal``, and nothing has
been written by then."""

import bpy
import numpy as np
from mathutils import Euler

from .. import api
from ..api import SkinDetachError
from . import live_update, stretch_shading
from .region_view import RegionView

#: Seconds between the TIMER events that settle a drag's solve while the mouse rests.
SETTLE_INTERVAL_S = 0.02


def bound_owner(context):
    """The bound mesh object behind the active object (itself, its proxy or a handle), or None."""
    obj = api.mesh_of(context.active_object)
    return obj if api.is_bound(obj) else None


def solve_report(stats):
    """Level and text of the report of a solve's figures (a warning when it did not converge)."""
    text = f"solved in {stats['milliseconds']:.1f} ms ({stats['iterations']} iterations)"
    if not stats["converged"]:
        return {'WARNING'}, f"Skin Detach: the solve did not converge ({stats['iterations']} iterations); {text}"
    return {'INFO'}, f"Skin Detach: {text}"


def leave_edit_mode(context):
    """Object Mode when the active object is in Edit Mode (as Build and Add Handle leave it): a
    command found there (its menu, F3) then runs instead of refusing, since Skin Detach never
    writes a mesh under Edit Mode."""
    if context.active_object is not None and context.active_object.mode == 'EDIT':
        bpy.ops.object.mode_set(mode='OBJECT')


def deform_and_report(operator, context):
    """Solve the bound mesh behind the active object from its handles, tell live update, report."""
    leave_edit_mode(context)
    obj = bound_owner(context)
    stats = api.deform(obj, context.scene.skin_detach.preserve_volume)
    live_update.remember(obj)
    operator.report(*solve_report(stats))
    return {'FINISHED'}


class _Operator:
    def execute(self, context):
        try:
            return self.run(context)
        except SkinDetachError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}


class _BoundOperator(_Operator):
    """Available when the active object is a bound mesh, its proxy or one of its handles."""

    @classmethod
    def poll(cls, context):
        return bound_owner(context) is not None


#: Seconds between the TIMER events that poll a build running on its thread.
BUILD_POLL_S = 0.1
#: Builds running on their threads: the bound mesh's name -> its api.BuildJob (the panel shows them).
BUILDS = {}
#: Events a running build lets through to the window (the view still orbits, pans and zooms, and
#: redraws); every other key and click waits, Esc cancels.
_NAVIGATION_PREFIXES = ("TIMER", "MOUSE", "INBETWEEN_MOUSEMOVE", "WHEEL", "TRACKPAD", "NDOF", "WINDOW")
_NAVIGATION = {"MIDDLEMOUSE", "NONE", "HOME", "NUMPAD_0", "NUMPAD_1", "NUMPAD_2", "NUMPAD_3", "NUMPAD_4", "NUMPAD_5",
               "NUMPAD_6", "NUMPAD_7", "NUMPAD_8", "NUMPAD_9", "NUMPAD_PERIOD", "NUMPAD_PLUS", "NUMPAD_MINUS",
               "NUMPAD_SLASH", "NUMPAD_ASTERIX"}


def build_report(stats):
    """The INFO report of a finished build."""
    kept = f"; {stats['handles_kept']} handles kept" if stats["handles_kept"] else ""
    dropped = f", {stats['handles_removed']} proxy-made handles removed" if stats["handles_removed"] else ""
    preview = f"; preview of {stats['preview_vertices']:,} vertices" if stats.get("preview_vertices") else ""
    parts = f"; {parts_text(stats)}" if stats.get("parts", 1) > 1 else ""
    objects = f"{stats['objects']} objects, " if stats.get("objects", 1) > 1 else ""
    return (f"Skin Detach: {objects}{stats['detail_vertices']:,} vertices bound to a proxy of {stats['proxy_faces']:,} faces "
            f"in {stats['seconds']['total']:.2f} s (case 1/2/3: {stats['case1']:,}/{stats['case2']:,}/"
            f"{stats['case3']:,}){parts}{preview}{kept}{dropped}")


def _pressed(event):
    """The key or click of ``event`` as Blender's keymap writes it (Ctrl+Z, Tab, X)."""
    name = {'TAB': "Tab", 'DEL': "Delete", 'RET': "Enter", 'LEFTMOUSE': "a click", 'RIGHTMOUSE': "a right click"}.get(
        event.type, event.type.title())
    return "".join(f"{mod}+" for mod, on in (("Ctrl", event.ctrl), ("Shift", event.shift), ("Alt", event.alt)) if on) + name


def build_text(job):
    """What the panel and the status bar say of a running build: its stage and percent."""
    return f"{job.stage} {100 * job.fraction:.0f} %"


def cancel_builds():
    """Cancel every running build (unregistering the add-on): nothing is written."""
    for job in BUILDS.values():
        job.cancel()
    BUILDS.clear()


class SKIN_DETACH_OT_build(_Operator, bpy.types.Operator):
    """Bind the active mesh to a small proxy (replacing any earlier binding); the window goes on
    answering while it builds, with its progress in the panel and the status bar (Esc cancels)"""
    bl_idname = "skin_detach.build"
    bl_label = "Build Skin"
    bl_options = {'REGISTER', 'UNDO'}
    target_faces: bpy.props.IntProperty(
        name="Proxy Faces", description="Number of faces of the proxy the detail mesh is bound to "
        "(default: the panel's value)", default=1000, min=4, max=200_000, soft_min=100, soft_max=20_000,
        options={'SKIP_SAVE'})
    normal_test: bpy.props.BoolProperty(
        name="Normal Test", default=True, description="Refuse proxy edge collapses that would turn proxy faces "
        "away from the detail they carry (default: the panel's value)", options={'SKIP_SAVE'})

    @classmethod
    def poll(cls, context):
        obj = api.mesh_of(context.active_object)
        return obj is not None and obj.type == 'MESH' and obj.name not in BUILDS

    def _settings(self, context):
        """The mesh to build (with several meshes selected, the list of them: the active one
        first, the rig's owner), Object Mode left, the unset properties given the panel's values."""
        obj = api.mesh_of(context.active_object)
        # Other selected meshes that are no part of a rig (not a proxy, preview or this rig's object).
        others = [o for o in (getattr(context, "selected_objects", None) or ())
                  if o.type == 'MESH' and o != obj and api.mesh_of(o) == o]
        if others and obj is not None:  # several meshes selected: one rig of all of them (and of the rig's own)
            obj = (api.members(obj) if api.is_bound(obj) else [obj]) + others
        leave_edit_mode(context)
        settings = context.scene.skin_detach
        for name in ("target_faces", "normal_test"):  # unset: the panel's value (then shown in Redo)
            if not self.properties.is_property_set(name):
                setattr(self, name, getattr(settings, name))
        return obj, settings

    def run(self, context):
        """Scripted use and the Redo panel: the whole build at once (the cursor shows its progress)."""
        obj, settings = self._settings(context)
        wm = context.window_manager
        status = getattr(context, "workspace", None)

        def progress(fraction, stage):
            wm.progress_update(int(100 * fraction))
            if status is not None:
                status.status_text_set(f"Skin Detach: {stage}...")
            if bpy.app.background:
                print(f"Skin Detach build {100 * fraction:3.0f} %: {stage}")

        wm.progress_begin(0, 100)
        try:
            stats = api.build(obj, self.target_faces, self.normal_test, progress, settings.preview_above)
        finally:
            wm.progress_end()
            if status is not None:
                status.status_text_set(None)
        self.report({'INFO'}, build_report(stats))
        return {'FINISHED'}

    def invoke(self, context, event):
        """A press in the window: the core builds on a thread while the window answers (see :meth:`modal`)."""
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            obj, settings = self._settings(context)
            self.job = api.start_build(obj, self.target_faces, self.normal_test, settings.preview_above)
        except SkinDetachError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.job.start()
        BUILDS[self.job.name] = self.job
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(BUILD_POLL_S, window=context.window)
        self._writing = False
        wm.modal_handler_add(self)
        self._show(context)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        """Esc cancels (nothing is written); TIMER events show the progress and, once the core is
        done, write every object (one undo step); the view's navigation and Ctrl+S (save) pass; any
        other key or click is not taken, and a warning says so."""
        job = self.job
        if event.type == 'ESC' and event.value == 'PRESS':
            job.cancel()
            self._end(context)
            self.report({'INFO'}, f"Skin Detach: build of {job.name} cancelled at {job.stage!r}; nothing changed")
            return {'CANCELLED'}
        if event.type == 'TIMER':
            self._show(context)
            if job.done:
                if not self._writing:  # one more redraw: the panel says it writes before the window waits for it
                    self._writing = True
                    return {'PASS_THROUGH'}
                self._end(context)
                try:
                    stats = api.finish_build(job)
                except SkinDetachError as exc:
                    self.report({'ERROR'}, str(exc))
                    return {'CANCELLED'}
                self.report({'INFO'}, build_report(stats))
                return {'FINISHED'}
        if event.type in _NAVIGATION or event.type.startswith(_NAVIGATION_PREFIXES):
            return {'PASS_THROUGH'}
        if event.type == 'S' and (event.ctrl or event.oskey) and not event.alt:
            return {'PASS_THROUGH'}  # Ctrl+S (Shift+Ctrl+S): saving never waits for a build
        if event.value == 'PRESS' and not event.type.startswith(("LEFT_", "RIGHT_", "OSKEY", "EVT_")):
            # Any other key or click would change what is being bound: it is not taken, and said so.
            self.report({'WARNING'}, f"Skin Detach: building {job.name} ({build_text(job)}): "
                                     f"{_pressed(event)} not taken until the build ends (Esc cancels it; Ctrl+S saves)")
        return {'RUNNING_MODAL'}

    def _show(self, context):
        """The build's stage and percent in the status bar, the cursor's progress and the panel."""
        text = build_text(self.job)
        context.window_manager.progress_update(int(100 * self.job.fraction))
        if context.workspace is not None:
            context.workspace.status_text_set(f"Skin Detach: building {self.job.name}: {text} (Esc cancels)")
        for area in context.window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()

    def _end(self, context):
        BUILDS.pop(self.job.name, None)
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        for area in context.window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


class _AddOperator(_BoundOperator):
    kind = api.HANDLE
    bl_options = {'REGISTER', 'UNDO'}
    # SKIP_SAVE: a value is for the press it was given to (the Group field's +, the Redo panel),
    # never remembered into the next plain press.
    group: bpy.props.StringProperty(name="Vertex Group", default="", options={'SKIP_SAVE'},
                                    description="Make it from this vertex group instead of the selection")
    mirror: bpy.props.EnumProperty(name="Mirror", default='NONE', options={'SKIP_SAVE'},
                                   items=(('NONE', "Off", ""), ('X', "X", ""), ('Y', "Y", ""), ('Z', "Z", "")),
                                   description="Also make the mirrored twin (default: the panel's setting)")

    def run(self, context):
        if not self.properties.is_property_set("mirror"):
            self.mirror = context.scene.skin_detach.mirror
        mirror = None if self.mirror == 'NONE' else self.mirror
        add = api.add_handle if self.kind == api.HANDLE else api.add_anchor
        if self.group:
            empty = add(bound_owner(context), group=self.group, mirror=mirror)
        else:
            obj, ids, on_proxy = api.selected_vertices(context)
            empty = add(obj, ids, on_proxy=on_proxy, mirror=mirror)
        for obj in context.selected_objects:
            obj.select_set(False)
        empty.select_set(True)
        context.view_layer.objects.active = empty  # ready to drag
        twin = api.mirror_twin(empty)
        axis = api.handle_mirror(empty)
        made = f" and its mirrored twin {twin.name} (across {axis})" if twin is not None else \
            f" (its own mirror image across {axis}: it moves symmetrically)" if axis else ""
        self.report({'INFO'}, f"Skin Detach: {empty.name}{made} holds {api.handle_vertex_count(empty)} proxy vertices")
        return {'FINISHED'}


class SKIN_DETACH_OT_add_handle(_AddOperator, bpy.types.Operator):
    """Make a handle (a hook empty) from the selected vertices of the bound mesh or its proxy"""
    bl_idname = "skin_detach.add_handle"
    bl_label = "Add Handle"
    kind = api.HANDLE


class SKIN_DETACH_OT_add_anchor(_AddOperator, bpy.types.Operator):
    """Pin the selected vertices of the bound mesh or its proxy in place"""
    bl_idname = "skin_detach.add_anchor"
    bl_label = "Add Anchor"
    kind = api.ANCHOR


def _named_handle(context, name):
    if name:
        empty = bpy.data.objects.get(name)
        if not api.is_handle(empty):
            raise SkinDetachError(f"name: expected a Skin Detach handle or anchor, got {name!r}")
        return empty
    if api.is_handle(context.active_object):
        return context.active_object
    raise SkinDetachError("handle: expected an active handle or anchor empty, got "
                          f"{context.active_object.name if context.active_object else 'nothing'!r}")


class SKIN_DETACH_OT_remove_handle(_BoundOperator, bpy.types.Operator):
    """Remove a handle or anchor (the active one, or the one named); the mesh takes the shape of
    the handles left at once"""
    bl_idname = "skin_detach.remove_handle"
    bl_label = "Remove Handle"
    bl_options = {'REGISTER', 'UNDO'}
    name: bpy.props.StringProperty(name="Handle", default="", options={'SKIP_SAVE'})

    def run(self, context):
        empty = _named_handle(context, self.name)
        name, obj = empty.name, api.mesh_of(empty)
        leave_edit_mode(context)  # the mesh is then solved without it
        if empty == context.active_object and obj is not None and obj.name in context.view_layer.objects:
            context.view_layer.objects.active = obj  # the panel goes on listing the rig's handles
        try:
            api.remove_handle(empty)
        except SkinDetachError as exc:
            if name in bpy.data.objects:
                raise  # nothing was removed
            self.report({'WARNING'}, f"Skin Detach: {exc}")  # removed: the step stays (and is undone as one)
            return {'FINISHED'}
        live_update.remember(obj)  # the mesh is solved for the handles left
        self.report({'INFO'}, f"Skin Detach: removed {name}; the mesh follows the handles left")
        return {'FINISHED'}


class SKIN_DETACH_OT_select_handle(_Operator, bpy.types.Operator):
    """Make the named handle or anchor the active object"""
    bl_idname = "skin_detach.select_handle"
    bl_label = "Select Handle"
    bl_options = {'REGISTER', 'UNDO'}
    name: bpy.props.StringProperty(name="Handle", default="", options={'SKIP_SAVE'})

    def run(self, context):
        empty = _named_handle(context, self.name)
        leave_edit_mode(context)
        for obj in context.selected_objects:
            obj.select_set(False)
        empty.select_set(True)
        context.view_layer.objects.active = empty
        return {'FINISHED'}


class SKIN_DETACH_OT_apply(_BoundOperator, bpy.types.Operator):
    """Deform the mesh from the current transforms of all its handles"""
    bl_idname = "skin_detach.apply"
    bl_label = "Apply Handles"
    bl_options = {'REGISTER', 'UNDO'}

    def run(self, context):
        return deform_and_report(self, context)


class SKIN_DETACH_OT_drag(_Operator, bpy.types.Operator):
    """Drag the active handle with the mouse; the mesh follows on every move"""
    bl_idname = "skin_detach.drag"
    bl_label = "Drag Handle"
    bl_options = {'REGISTER', 'UNDO', 'BLOCKING'}
    # What the drag did, shown in the Redo panel (and the scripted use): scale along the world
    # axes and rotation about the handle's position, then the move; see api.moved_matrix.
    offset: bpy.props.FloatVectorProperty(name="Move", subtype='TRANSLATION', size=3, options={'SKIP_SAVE'},
                                          description="World-space move of the handle")
    rotation: bpy.props.FloatVectorProperty(name="Rotation", subtype='EULER', size=3, options={'SKIP_SAVE'},
                                            description="Turn of the handle about its own position (world axes)")
    scale: bpy.props.FloatVectorProperty(name="Scale", subtype='XYZ', size=3, default=(1.0, 1.0, 1.0),
                                         options={'SKIP_SAVE'},
                                         description="Scale of the handle along the world axes about its position")

    @classmethod
    def poll(cls, context):
        return bound_owner(context) is not None and api.is_handle(context.active_object) and \
            api.handle_kind(context.active_object) == api.HANDLE

    def run(self, context):
        """Scripted path and the Redo panel: move the active handle as the properties say and solve."""
        context.view_layer.update()  # after the Redo panel's undo, world matrices are not evaluated yet
        empty = context.active_object
        empty.matrix_world = api.moved_matrix(empty.matrix_world.copy(), self.offset,
                                              Euler(self.rotation).to_matrix(), self.scale)
        return deform_and_report(self, context)

    def invoke(self, context, event):
        if context.area is None or context.area.type != 'VIEW_3D':
            return self.execute(context)
        live_update.settle(only=bound_owner(context).name)  # a live-update preview gives way to the detail first
        try:
            self.session = api.DragSession(bound_owner(context), context.active_object,
                                       RegionView(context.region, context.region_data),
                                       (event.mouse_region_x, event.mouse_region_y),
                                       context.scene.skin_detach.preserve_volume,
                                       context.scene.skin_detach.preview_above)
        except SkinDetachError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        context.area.header_text_set(self.session.header)
        # TIMER events settle the solve while the mouse rests (removed whenever the drag ends).
        self._timer = context.window_manager.event_timer_add(SETTLE_INTERVAL_S, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        try:
            state = self.session.event(event.type, event.value, (event.mouse_region_x, event.mouse_region_y))
        except SkinDetachError as exc:
            self.session.cancel()
            self.report({'ERROR'}, str(exc))
            state = api.CANCELLED
        except ReferenceError:  # its objects are gone (a file was loaded): nothing left to restore
            self._end_timer(context)
            if context.area is not None:
                context.area.header_text_set(None)
            self.report({'WARNING'}, "Skin Detach: the drag ended, its objects were removed (a file was loaded?)")
            return {'CANCELLED'}
        except BaseException:
            self._end_timer(context)
            raise
        live_update.remember(self.session.obj)  # the drag solved this pose itself: live update keeps out
        if state in (api.FINISHED, api.CANCELLED):
            self._end_timer(context)
            context.area.header_text_set(None)
            if state == api.FINISHED:  # the Redo panel shows (and redoes) what the drag did
                translation, rotation, scale = self.session.motion
                self.offset, self.rotation, self.scale = translation, rotation.to_euler(), scale
            if state == api.FINISHED and self.session.step_ms:
                ms = sorted(self.session.step_ms)[len(self.session.step_ms) // 2]
                level, text = solve_report(self.session.last.figures())
                self.report(level, f"{text}; {len(self.session.step_ms)} drag steps, median {ms:.1f} ms")
            return {state}
        context.area.header_text_set(self.session.header)
        return {'RUNNING_MODAL'}

    def _end_timer(self, context):
        if getattr(self, "_timer", None) is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None


class SKIN_DETACH_OT_reset(_BoundOperator, bpy.types.Operator):
    """Put the mesh, proxy and handles back to the rest shape (the binding stays)"""
    bl_idname = "skin_detach.reset"
    bl_label = "Reset to Rest"
    bl_options = {'REGISTER', 'UNDO'}

    def run(self, context):
        leave_edit_mode(context)
        obj = bound_owner(context)
        api.reset(obj)
        live_update.remember(obj)
        self.report({'INFO'}, "Skin Detach: back to the rest shape")
        return {'FINISHED'}


class SKIN_DETACH_OT_clear(_Operator, bpy.types.Operator):
    """Remove the proxy, the handles and the binding (the mesh keeps its current shape); on what is
    left of the rig of a deleted mesh, remove that"""
    bl_idname = "skin_detach.clear"
    bl_label = "Clear Skin"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return bound_owner(context) is not None or api.orphan_owner(context.active_object) is not None

    def run(self, context):
        leave_edit_mode(context)
        obj = bound_owner(context)
        if obj is None:
            name = api.clear_orphan(context.active_object)
            self.report({'INFO'}, f"Skin Detach: removed the rig of the deleted mesh {name!r}")
            return {'FINISHED'}
        if context.active_object is not obj and obj.name in context.view_layer.objects:
            context.view_layer.objects.active = obj
        api.clear(obj)
        stretch_shading.settle()
        self.report({'INFO'}, f"Skin Detach: cleared {obj.name}")
        return {'FINISHED'}


class SKIN_DETACH_OT_show_stretch(_BoundOperator, bpy.types.Operator):
    """Colour the mesh by how much it stretches against its rest (blue none, red 25 % or more),
    updated by every confirm; every Solid 3D View shows it (Attribute coloring). Again to give
    back the mesh's own colors and the views' coloring"""
    bl_idname = "skin_detach.show_stretch"
    bl_label = "Show Stretch"
    bl_options = {'REGISTER', 'UNDO'}

    def run(self, context):
        obj = bound_owner(context)
        show = not api.stretch_shown(obj)
        active = context.active_object
        editing = active is not None and active.mode == 'EDIT'
        if editing:  # Edit Mode keeps the mesh in its own copy: written back first, entered again after
            bpy.ops.object.mode_set(mode='OBJECT')
        try:
            api.show_stretch(obj, show)
        finally:
            if editing:
                bpy.ops.object.mode_set(mode='EDIT')
        if show:
            stretch_shading.show()
        else:
            stretch_shading.settle()
        self.report({'INFO'}, f"Skin Detach: stretch of {obj.name} shown (blue none, red 25 % or more)" if show
                    else f"Skin Detach: stretch of {obj.name} hidden, its own colors back")
        return {'FINISHED'}


class SKIN_DETACH_OT_set_parts(_Operator, bpy.types.Operator):
    """Decide the loose parts holding the selected vertices: ride on the part under them (Attach),
    deform on their own (Detach), or as the rule decides (By Rule); a bound mesh is built again
    (as Rebuild does: its shape now becomes its rest)"""
    bl_idname = "skin_detach.set_parts"
    bl_label = "Set Parts"
    bl_options = {'REGISTER', 'UNDO'}
    mode: bpy.props.EnumProperty(
        name="Parts", default='ATTACH', options={'SKIP_SAVE'},
        items=[('ATTACH', "Attach", "The selected parts ride on the nearest larger part, however far"),
               ('DETACH', "Detach", "The selected parts get their own proxy and deform on their own"),
               ('RULE', "By Rule", "The selected parts ride when they touch a part of at least twice their area")])

    @classmethod
    def poll(cls, context):
        obj = api.mesh_of(context.active_object)
        return obj is not None and obj.type == 'MESH' and obj.name not in BUILDS

    def run(self, context):
        active = context.active_object
        # The active mesh itself (an object of a rig of several objects: its own selection), or
        # the mesh a proxy or handle stands for.
        obj = active if active is not None and active.type == 'MESH' and not api.is_rig_part(active) \
            else api.mesh_of(active)
        leave_edit_mode(context)
        selected = np.zeros(len(obj.data.vertices), dtype=bool)
        obj.data.vertices.foreach_get("select", selected)
        if not selected.any():
            raise SkinDetachError(f"selection: expected selected vertices on {obj.name!r}, got none "
                                  f"(select a vertex of each part in Edit Mode)")
        named = api.set_parts(obj, np.flatnonzero(selected), self.mode)
        said = {'ATTACH': "ride on the part under them", 'DETACH': "deform on their own",
                'RULE': "follow the rule"}[self.mode]
        if api.is_bound(obj):
            settings = context.scene.skin_detach
            target = api.figures(obj)["build"].get("target_faces", settings.target_faces)
            stats = api.build(obj, target, settings.normal_test, preview_above=settings.preview_above)
            self.report({'INFO'}, f"Skin Detach: {named} parts {said}; rebuilt: {parts_text(stats)}")
        else:
            self.report({'INFO'}, f"Skin Detach: {named} parts {said} (used by Build)")
        return {'FINISHED'}


def parts_text(stats):
    """What the panel and reports say of a build's loose parts: how many ride on how many."""
    parts, riders = stats.get("parts", 1), stats.get("riders", 0)
    if parts <= 1:
        return "one part"
    return (f"{parts} parts, {riders} riding on {stats.get('rider_hosts', 0)}"
            + (f" ({stats['riders_attached']} attached)" if stats.get("riders_attached") else "")
            + (f" ({stats['parts_detached']} detached)" if stats.get("parts_detached") else ""))


CLASSES = (SKIN_DETACH_OT_build, SKIN_DETACH_OT_add_handle, SKIN_DETACH_OT_add_anchor, SKIN_DETACH_OT_remove_handle,
           SKIN_DETACH_OT_select_handle, SKIN_DETACH_OT_apply, SKIN_DETACH_OT_drag, SKIN_DETACH_OT_reset,
           SKIN_DETACH_OT_clear, SKIN_DETACH_OT_show_stretch, SKIN_DETACH_OT_set_parts)
