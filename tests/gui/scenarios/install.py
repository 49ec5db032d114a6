"""Install from Disk, the Rokeby tab drawn, disable, re-enable: no traceback, panels back."""

import addon_utils  # noqa: F401 - Blender's add-on machinery (loaded with bpy)
import bpy

ADDON = "bl_ext.user_default.rokeby"


def panels():
    return sorted(n for n in dir(bpy.types) if n.startswith("ROKEBY_PT_"))


def scenario(ui):
    yield from ui.start()
    ui.result["enabled"] = ADDON in bpy.context.preferences.addons
    ui.result["panels_installed"] = panels()
    region = yield from ui.show_sidebar_tab("Rokeby")
    yield from ui.redraws(2)
    ui.screenshot("installed")
    with bpy.context.temp_override(window=ui.window):
        ui.result["disable"] = sorted(bpy.ops.preferences.addon_disable(module=ADDON))
    yield from ui.redraws(2)
    ui.result["enabled_after_disable"] = ADDON in bpy.context.preferences.addons
    ui.result["panels_disabled"] = panels()
    ui.screenshot("disabled")
    with bpy.context.temp_override(window=ui.window):
        ui.result["enable"] = sorted(bpy.ops.preferences.addon_enable(module=ADDON))
    yield from ui.redraws(2)
    ui.result["enabled_again"] = ADDON in bpy.context.preferences.addons
    ui.result["panels_enabled_again"] = panels()
    region = yield from ui.show_sidebar_tab("Rokeby")
    yield from ui.redraws(2)
    ui.result["tab"] = region.active_panel_category
    ui.screenshot("enabled-again")
