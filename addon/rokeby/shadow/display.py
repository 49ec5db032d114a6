"""How a shadow edit's meshes show in the 3D views.

A shadow mesh (and a self-shadow mesh) is a deformed copy of its caster that only shadow rays
see. Solid shading draws every mesh whatever its ray visibility, so there it is displayed as a wire
(a solid copy would z-fight the caster). Material Preview and Rendered shading hide it from camera
rays, as F12 does, and draw the shadow it casts; a wire display would only add its cage over the
caster there. So the display follows the views: a wire while any 3D view of the open windows is in
Solid shading, solid otherwise. It changes when a view's shading changes (a message-bus
subscription) and after each scene update (new shadow meshes); renders never depend on it.
"""

from __future__ import annotations

OWNER = "shadow.display"
_owner = object()  # the message-bus subscription's owner


def wanted_display() -> str:
    """'WIRE' while a 3D view of an open window shows Solid shading (or no window is open: background
    mode keeps the saved display), else 'SOLID'."""
    import bpy  # noqa: PLC0415

    wm = getattr(bpy.context, "window_manager", None)
    shadings = [space.shading.type
                for window in getattr(wm, "windows", [])
                for area in window.screen.areas if area.type == "VIEW_3D"
                for space in area.spaces if space.type == "VIEW_3D"]
    if not shadings or "SOLID" in shadings:
        return "WIRE"
    return "SOLID"


def sync(meshes) -> int:
    """Give each of ``meshes`` (shadow and self-shadow meshes) the display the views want; returns
    how many changed (only changed values are written, so a scene update settles)."""
    want = wanted_display()
    changed = 0
    for ob in meshes:
        if ob.display_type != want:
            ob.display_type = want
            changed += 1
    return changed


def _on_shading_changed(*_args):
    from . import linking  # noqa: PLC0415

    try:
        meshes, _twins, _lights = linking._parts()
        sync([*meshes, *linking._self_blockers()])
    except Exception as exc:  # noqa: BLE001 - a message-bus callback must never raise into Blender
        print(f"Rokeby: shadow mesh display not updated: {type(exc).__name__}: {exc}")


def subscribe(*_args) -> None:
    """Follow every 3D view's shading type (again after a file load, which clears subscriptions)."""
    import bpy  # noqa: PLC0415

    bpy.msgbus.clear_by_owner(_owner)
    bpy.msgbus.subscribe_rna(key=(bpy.types.View3DShading, "type"), owner=_owner, args=(), notify=_on_shading_changed)


def _on_load(*_args):
    subscribe()
    _on_shading_changed()


def register():
    from ..blender import hooks  # noqa: PLC0415

    subscribe()
    hooks.add(OWNER, "load_post", _on_load)


def unregister():
    import bpy  # noqa: PLC0415

    from ..blender import hooks  # noqa: PLC0415

    hooks.remove(OWNER)
    bpy.msgbus.clear_by_owner(_owner)
