"""Where Blender users look for commands: a Skin Detach submenu in the 3D View's Object menu and,
in Edit Mode, its Mesh menu (so F3 menu search finds every operator in both modes), the same
submenu in the object context menu (right click), Add Handle and Add Anchor in Edit Mode's
context menu, and an add-on keymap entry for Drag Handle that users can change in Preferences >
Keymap."""

import bpy

from .. import api

#: The Drag Handle key in Object Mode (Preferences > Keymap > Object Mode > Skin Detach).
DRAG_KEY = {"type": 'D', "value": 'PRESS', "shift": True, "alt": True}
_keymaps = []


class VIEW3D_MT_skin_detach_handles(bpy.types.Menu):
    """The rig's handles and anchors, as the panel lists them: each entry makes it active."""
    bl_idname = "VIEW3D_MT_skin_detach_handles"
    bl_label = "Select Handle"

    def draw(self, context):
        obj = api.mesh_of(context.active_object)
        empties = api.handles_of(obj) if api.is_bound(obj) else []
        for empty in empties:
            try:
                icon = 'EMPTY_AXIS' if api.handle_kind(empty) == api.HANDLE else 'PINNED'
            except api.SkinDetachError:
                icon = 'ERROR'  # a damaged handle: listed, as in the panel, so that it can be removed
            self.layout.operator("skin_detach.select_handle", text=empty.name, icon=icon).name = empty.name
        if not empties:
            self.layout.label(text="No handles (Add Handle first)")


class VIEW3D_MT_skin_detach(bpy.types.Menu):
    """Every command of the add-on (F3 searches menus: each is found there, in Object and Edit Mode)."""
    bl_idname = "VIEW3D_MT_skin_detach"
    bl_label = "Skin Detach"

    def draw(self, context):
        layout = self.layout
        layout.operator("skin_detach.build", icon='MOD_DECIM')
        layout.separator()
        layout.operator("skin_detach.add_handle", icon='EMPTY_SINGLE_ARROW')
        layout.operator("skin_detach.add_anchor", icon='PINNED')
        layout.menu(VIEW3D_MT_skin_detach_handles.bl_idname, icon='RESTRICT_SELECT_OFF')
        layout.operator("skin_detach.remove_handle", icon='X')
        layout.operator_menu_enum("skin_detach.set_parts", "mode", text="Loose Parts", icon='MOD_EXPLODE')
        layout.separator()
        layout.operator("skin_detach.drag", icon='VIEW_PAN')
        layout.operator("skin_detach.apply", icon='CHECKMARK')
        layout.operator("skin_detach.show_stretch", icon='MOD_SMOOTH')
        layout.separator()
        layout.operator("skin_detach.reset", icon='LOOP_BACK')
        layout.operator("skin_detach.clear", icon='TRASH')


def _menu_entry(self, context):
    self.layout.menu(VIEW3D_MT_skin_detach.bl_idname)


def _edit_context_entries(self, context):
    """Edit Mode's right-click menu: what an artist does with selected vertices."""
    layout = self.layout
    layout.separator()
    layout.operator("skin_detach.add_handle", icon='EMPTY_SINGLE_ARROW')
    layout.operator("skin_detach.add_anchor", icon='PINNED')


CLASSES = (VIEW3D_MT_skin_detach_handles, VIEW3D_MT_skin_detach)
#: Menu -> the entry appended to it.
_MENUS = {"VIEW3D_MT_object": _menu_entry, "VIEW3D_MT_object_context_menu": _menu_entry,
          "VIEW3D_MT_edit_mesh": _menu_entry, "VIEW3D_MT_edit_mesh_context_menu": _edit_context_entries}


def register():
    for name, entry in _MENUS.items():
        getattr(bpy.types, name).append(entry)
    keyconfig = bpy.context.window_manager.keyconfigs.addon
    if keyconfig is not None:  # none in background mode
        keymap = keyconfig.keymaps.new(name="Object Mode", space_type='EMPTY')
        item = keymap.keymap_items.new("skin_detach.drag", **DRAG_KEY)
        _keymaps.append((keymap, item))


def unregister():
    for keymap, item in _keymaps:
        keymap.keymap_items.remove(item)
    _keymaps.clear()
    for name, entry in _MENUS.items():
        getattr(bpy.types, name).remove(entry)
