"""Helpers of the add-on's modal operators (feature-agnostic): which undo shortcut an event is,
and which 3D view's main region the mouse is over.

A modal operator sees events before the window's keymap: Ctrl+Z passed on while it runs would
undo a step from before it (its own work not pushed yet), so each modal decides about the undo
keys itself (``undo_key``). A modal started from a sidebar button runs with the sidebar as its
region: ``view3d_at`` finds the 3D view's main region under the mouse from window coordinates."""

from __future__ import annotations

_UNDO_OPERATORS = {"ed.undo": "UNDO", "ed.redo": "REDO", "ed.undo_history": "HISTORY"}
# Blender's default shortcuts (Screen keymap): used where the key configuration is not readable.
_DEFAULTS = ((False, False, "UNDO"), (True, False, "REDO"), (False, True, "HISTORY"))  # (shift, alt, action)


def _mods(event) -> tuple:
    return tuple(bool(getattr(event, m, False)) for m in ("ctrl", "shift", "alt", "oskey"))


def undo_key(event, context=None) -> "str | None":
    """'UNDO', 'REDO' or 'HISTORY' when ``event`` presses a shortcut of Blender's undo operators
    (the user's key configuration, Screen keymap; else the defaults: Ctrl/Cmd+Z, Shift+Ctrl/Cmd+Z,
    Ctrl/Cmd+Alt+Z), otherwise None."""
    if getattr(event, "value", "PRESS") != "PRESS":
        return None
    wm = getattr(context, "window_manager", None)
    kc = getattr(getattr(wm, "keyconfigs", None), "user", None)
    km = kc.keymaps.get("Screen") if kc is not None else None
    items = [k for k in km.keymap_items if k.idname in _UNDO_OPERATORS and k.active] if km is not None else []
    if items:
        for k in items:
            if k.type == event.type and k.value in ("PRESS", "ANY") and (k.any or _mods(k) == _mods(event)):
                return _UNDO_OPERATORS[k.idname]
        return None
    ctrl, shift, alt, oskey = _mods(event)
    if event.type != "Z" or not (ctrl or oskey):
        return None
    for s, a, action in _DEFAULTS:
        if (shift, alt) == (s, a):
            return action
    return None


# Regions drawn over a 3D view's main region (Region Overlap, on by default): a click there is theirs.
_OVERLAPPING = ("UI", "TOOLS", "HEADER", "TOOL_HEADER", "ASSET_SHELF", "ASSET_SHELF_HEADER")


def _covered(area, mx: float, my: float) -> bool:
    """Whether window point (mx, my) lies on a sidebar, toolbar or header of ``area``."""
    for r in getattr(area, "regions", ()):
        if r.type in _OVERLAPPING and r.width > 1 and r.height > 1 and r.x <= mx < r.x + r.width and r.y <= my < r.y + r.height:
            return True
    return False


def view3d_at(context, event):
    """(region, region_3d, (x, y)) of the 3D view main region under the mouse, or None: the
    operator's own region where it is one, else the main region of a 3D view of the window whose
    rectangle holds the mouse (window coordinates ``event.mouse_x``/``mouse_y``). A point on a
    sidebar, toolbar or header drawn over the main region (Region Overlap) is not in the view."""
    region, area = context.region, context.area
    if region is not None and getattr(region, "type", "WINDOW") == "WINDOW" and getattr(area, "type", None) == "VIEW_3D" \
            and context.region_data is not None:
        x, y = event.mouse_region_x, event.mouse_region_y
        if 0 <= x < region.width and 0 <= y < region.height and not _covered(area, getattr(region, "x", 0) + x, getattr(region, "y", 0) + y):
            return region, context.region_data, (x, y)
        return None
    areas = [area] if getattr(area, "type", None) == "VIEW_3D" else []
    screen = getattr(getattr(context, "window", None), "screen", None) or getattr(context, "screen", None)
    areas += [a for a in getattr(screen, "areas", ()) if a.type == "VIEW_3D" and a != area]
    mx, my = getattr(event, "mouse_x", None), getattr(event, "mouse_y", None)
    if mx is None:
        return None
    for a in areas:
        if _covered(a, mx, my):
            return None
        for r in a.regions:
            if r.type == "WINDOW" and r.x <= mx < r.x + r.width and r.y <= my < r.y + r.height and r.data is not None:
                return r, r.data, (mx - r.x, my - r.y)
    return None
