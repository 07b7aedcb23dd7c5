"""The "Skin Detach" tab of the 3D View sidebar."""

import textwrap

import bpy

from .. import api
from .idle_preparation import FAILED, progress_of
from .live_update import ERRORS
from .operators import BUILDS, build_text, parts_text


#: Characters of a label line that fit the sidebar at its default width beside an icon (about
#: 180 pixels of Blender's UI font at 100 %); longer texts are wrapped.
LINE_CHARACTERS = 30


def wrapped_label(layout, text, icon='NONE'):
    """``text`` as label lines of at most :data:`LINE_CHARACTERS` (the icon on the first)."""
    for k, line in enumerate(textwrap.wrap(text, LINE_CHARACTERS) or [""]):
        layout.label(text=line, icon=icon if k == 0 else 'BLANK1')


#: Seconds between redraws of the sidebar while a bound mesh is being prepared (its progress).
REDRAW_SECONDS = 0.5


def _redraw_while_preparing():
    """Redraw every 3D View's sidebar while a bound mesh is being prepared (:func:`api.preparing`);
    the timer's body: the interval to the next call, or None once nothing is."""
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()
    busy = any(api.preparing(obj) is not None for obj in api.bound_objects(bpy.data.objects))
    return REDRAW_SECONDS if busy else None


class VIEW3D_PT_skin_detach(bpy.types.Panel):
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Skin Detach"
    bl_label = "Skin Detach"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.skin_detach
        obj = api.mesh_of(context.active_object)

        box = layout.box()
        box.label(text="Build", icon='MOD_DECIM')
        box.prop(settings, "target_faces")
        box.prop(settings, "normal_test")
        box.prop(settings, "preview_above")
        bound = api.is_bound(obj)
        job = BUILDS.get(getattr(obj, "name", None))
        if job is not None:  # the window answers while the core builds: how far it got
            if hasattr(box, "progress"):
                box.progress(factor=job.fraction, type='BAR', text=build_text(job))
            else:
                box.label(text=build_text(job), icon='TIME')
            box.label(text="Building (Esc cancels)", icon='TIME')
        else:
            box.operator("skin_detach.build", text="Rebuild" if bound else "Build", icon='FILE_REFRESH')
        if obj is None or obj.type != 'MESH':
            layout.label(text="Select a mesh object", icon='INFO')
            return
        if not bound:
            wrapped_label(layout, f"{obj.name}: not bound", icon='INFO')
            return
        progress = api.preparing(obj)
        if progress is not None:  # a large mesh's full-detail rebuild, made beside the artist's work
            wrapped_label(layout, f"Preparing the full detail ({progress[1]}): {100 * progress[0]:.0f} %", icon='TIME')
            if not bpy.app.timers.is_registered(_redraw_while_preparing):
                bpy.app.timers.register(_redraw_while_preparing, first_interval=REDRAW_SECONDS)

        box = layout.box()
        box.label(text="Handles", icon='EMPTY_AXIS')
        row = box.row(align=True)
        row.operator("skin_detach.add_handle", icon='ADD')
        row.operator("skin_detach.add_anchor", icon='PINNED')
        row = box.row(align=True)
        row.label(text="Mirror")
        row.prop(settings, "mirror", expand=True)
        row = box.row(align=True)
        row.prop_search(settings, "handle_group", obj, "vertex_groups", text="Group")
        if settings.handle_group:
            row.operator("skin_detach.add_handle", text="", icon='ADD').group = settings.handle_group
            row.operator("skin_detach.add_anchor", text="", icon='PINNED').group = settings.handle_group
        try:
            conflicts = {c["loser"]: c for c in api.handle_conflicts(obj)}
        except api.SkinDetachError:
            conflicts = {}
        for empty in api.handles_of(obj):
            row = box.row(align=True)
            try:
                icon = 'EMPTY_AXIS' if api.handle_kind(empty) == api.HANDLE else 'PINNED'
            except api.SkinDetachError:
                icon = 'ERROR'  # a damaged handle: listed so that it can be removed
            group = api.handle_group(empty)
            select = row.operator("skin_detach.select_handle", text=f"{empty.name} ({group})" if group else empty.name,
                                  icon=icon, depress=empty == context.active_object)
            select.name = empty.name
            row.operator("skin_detach.remove_handle", text="", icon='X').name = empty.name
            try:
                old_pivot = api.handle_has_old_pivot(empty)
            except api.SkinDetachError:
                old_pivot = False
            if old_pivot:
                wrapped_label(box, "made by an earlier version: R and S turn it about the proxy's centre; "
                                   "Rebuild to turn it about the selection", icon='INFO')
            if empty.name in conflicts:
                conflict = conflicts[empty.name]
                wrapped_label(box, f"shares {conflict['shared']} proxy vertices with {conflict['winner']}, "
                                   f"which wins there", icon='INFO')

        proxy = api.proxy_of(obj)
        if proxy is not None:  # off by default: drawn in front, the proxy would take the clicks meant for the mesh
            box.prop(proxy, "hide_select", text="Select Proxy", invert_checkbox=True, icon='RESTRICT_SELECT_OFF')

        box = layout.box()
        box.label(text="Deform", icon='MOD_SIMPLEDEFORM')
        box.prop(settings, "preserve_volume")
        box.operator("skin_detach.drag", icon='VIEW_PAN')
        row = box.row(align=True)
        row.operator("skin_detach.apply", icon='CHECKMARK')
        row.prop(settings, "live_update", toggle=True, icon='PLAY')
        box.operator("skin_detach.show_stretch", icon='MOD_SMOOTH', depress=api.stretch_shown(obj))
        row = box.row(align=True)
        row.operator("skin_detach.reset", icon='LOOP_BACK')
        row.operator("skin_detach.clear", icon='TRASH')
        preparing = progress_of(obj.name)
        if preparing:
            box.label(text=preparing, icon='TIME')
        for errors in (ERRORS, FAILED):
            if obj.name in errors:
                wrapped_label(box, errors[obj.name], icon='ERROR')

        figures = api.figures(obj)
        stats = figures["build"]
        box = layout.box()
        box.label(text="Figures", icon='INFO')
        members = api.members(obj)
        if len(members) > 1:  # a rig of several objects: how many, which (the owner first)
            box.label(text=f"Objects: {len(members)}", icon='OUTLINER_OB_MESH')
            for member in members:
                box.label(text=f"  {member.name if member is not None else '(deleted)'}"
                               f"{' (owner)' if member is obj else ''}")
        box.label(text=f"Detail: {stats.get('detail_vertices', 0):,} vertices")
        box.label(text=f"Proxy: {stats.get('proxy_vertices', 0):,} vertices, {stats.get('proxy_faces', 0):,} faces")
        if stats.get("parts", 1) > 1:
            box.label(text=f"Parts: {parts_text(stats)}")
            row = box.row(align=True)
            for mode, text in (('ATTACH', "Attach"), ('DETACH', "Detach"), ('RULE', "By Rule")):
                row.operator("skin_detach.set_parts", text=text).mode = mode
        if stats.get("target_reached") is False:
            wrapped_label(box, f"Target {stats.get('target_faces', 0):,} faces not reached: the normal test stopped "
                               f"above it", icon='INFO')
        if stats.get("preview_vertices"):
            box.label(text=f"Preview: {stats['preview_vertices']:,} vertices")
            if stats.get("detail_vertices", 0) <= settings.preview_above:
                box.label(text="  not used: below Preview Above")
        elif stats.get("detail_vertices", 0) > settings.preview_above:
            box.label(text="No preview: Rebuild to make one", icon='INFO')
        box.label(text=f"Build: {stats.get('seconds', {}).get('total', 0.0):.2f} s")
        last = figures["last_step"]
        if last is None:
            box.label(text="Last step: -")
        else:
            shown = " (preview)" if last.get("preview") else ""
            box.label(text=f"Last step{shown}: {last['milliseconds']:.1f} ms")
            box.label(text=f"  {last['iterations']} iterations")
            if last["volume_change"] == last["volume_change"]:
                box.label(text=f"  Volume {100 * last['volume_change']:+.2f} %")
            if last.get("settling"):
                box.label(text="  Settling while the mouse rests", icon='TIME')
            elif not last["converged"]:
                box.label(text="The last solve did not converge", icon='ERROR')


CLASSES = (VIEW3D_PT_skin_detach,)
