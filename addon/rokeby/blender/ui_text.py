"""Text that reads whole in a panel: Blender cuts a label that is wider than its row (``Warning: 1
constr…``), so long status lines are wrapped here to the width the panel gives them, measured in
the UI font (``blf``) at the window's UI scale. Only called from ``draw`` (no GPU state needed)."""

from __future__ import annotations

import blf
import bpy

# What a sidebar panel's rows lose of the region's width, in pixels at UI scale 1 (measured in a
# Blender 4.3 window: 235 px rows in a 291 px sidebar): the tab strip, the panel margins.
_PANEL_MARGINS = 56
_UNIT = 20  # Blender's widget unit at UI scale 1
_DEFAULT_REGION_WIDTH = 291  # a sidebar's default width, for drawing without a region (background mode)


def _scale() -> float:
    try:
        return bpy.context.preferences.system.ui_scale or 1.0
    except AttributeError:
        return 1.0


def text_width(text: str) -> float:
    """``text``'s width in pixels in the UI font at the UI scale."""
    style = bpy.context.preferences.ui_styles[0]
    blf.size(0, style.widget.points * _scale())
    return blf.dimensions(0, text)[0]


def row_width(context, *, icon: bool = False, boxed: bool = False) -> float:
    """Pixels a label's text has in a full-width row of the panel being drawn (after its icon)."""
    s = _scale()
    region = getattr(context, "region", None)
    width = region.width if region is not None and region.width > 1 else _DEFAULT_REGION_WIDTH * s
    width -= _PANEL_MARGINS * s + 0.8 * _UNIT * s  # margins, then the text's own padding
    if icon:
        width -= _UNIT * s
    if boxed:
        width -= 10 * s
    return max(width, 4 * _UNIT * s)


def wrap(text: str, width: float) -> list:
    """``text`` in lines no wider than ``width`` pixels, broken between words (a word wider than a
    line is broken inside)."""
    lines, line = [], ""
    for word in text.split():
        candidate = f"{line} {word}" if line else word
        if line and text_width(candidate) > width:
            lines.append(line)
            line = word
        else:
            line = candidate
        while text_width(line) > width and len(line) > 1:
            cut = len(line)
            while cut > 1 and text_width(line[:cut]) > width:
                cut -= 1
            lines.append(line[:cut])
            line = line[cut:]
    return lines + ([line] if line else [])


def label(layout, context, text: str, icon: str = "NONE", *, boxed: bool = False) -> None:
    """``layout.label`` that wraps ``text`` to the panel's width; lines after the first are indented
    to line up with the first line's text when there is an icon."""
    has_icon = icon not in ("NONE", "", None)
    lines = wrap(text, row_width(context, icon=has_icon, boxed=boxed)) or [""]
    if len(lines) == 1:
        layout.label(text=lines[0], icon=icon)
        return
    col = layout.column(align=True)
    col.label(text=lines[0], icon=icon)
    for line in lines[1:]:
        col.label(text=line, icon="BLANK1" if has_icon else "NONE")
