"""Scene settings shown in the panel (saved with the .blend; no drag state lives here)."""

import bpy

from .. import api


def _toggle_live(self, context):
    from . import live_update
    if self.live_update:
        live_update.notice(context.scene)


class SkinDetachSettings(bpy.types.PropertyGroup):
    target_faces: bpy.props.IntProperty(
        name="Proxy Faces", description="Number of faces of the proxy the detail mesh is bound to",
        default=1000, min=4, max=200_000, soft_min=100, soft_max=20_000)
    normal_test: bpy.props.BoolProperty(
        name="Normal Test", default=True,
        description="Refuse proxy edge collapses that would turn proxy faces away from the detail they carry")
    preview_above: bpy.props.IntProperty(
        name="Preview Above", default=api.PREVIEW_ABOVE, min=0, soft_min=10_000, soft_max=10_000_000,
        description="Meshes with more vertices get a light preview at Build (about 60,000 vertices), shown while "
                    "a handle is dragged; the full detail is written on confirm")
    preserve_volume: bpy.props.BoolProperty(
        name="Preserve Volume", default=True,
        description="Keep the enclosed volume of closed proxies while deforming")
    mirror: bpy.props.EnumProperty(
        name="Mirror", default='NONE',
        items=(('NONE', "Off", "Handles and anchors are made from the selection only"),
               ('X', "X", "Also make the mirrored twin across local X"),
               ('Y', "Y", "Also make the mirrored twin across local Y"),
               ('Z', "Z", "Also make the mirrored twin across local Z")),
        description="Add Handle/Anchor also makes the mirrored twin (the mesh must be symmetric); moving either "
                    "moves both")
    handle_group: bpy.props.StringProperty(
        name="Group", default="", description="Vertex group to make a handle or anchor from (weights above zero)")
    live_update: bpy.props.BoolProperty(
        name="Live Update", default=False, update=_toggle_live,
        description="Deform the mesh whenever a handle moves (G/R/S, drivers, animation, frame change)")


CLASSES = (SkinDetachSettings,)


def register():
    bpy.types.Scene.skin_detach = bpy.props.PointerProperty(type=SkinDetachSettings)


def unregister():
    del bpy.types.Scene.skin_detach
