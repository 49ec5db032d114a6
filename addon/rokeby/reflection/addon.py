"""The reflection-editing feature registers itself: its saved properties (``props``), operators,
live updates (``handlers``, through rokeby.blender.hooks), the viewport preview and the sidebar.
The sidebar (``ui``) registers apart, last: its menus name every feature's operators."""

from __future__ import annotations

from . import handlers, operators, props
from .viewport import draw as viewport


def register():
    for module in (props, operators, handlers, viewport):
        module.register()


def unregister():
    for module in (viewport, handlers, operators, props):
        module.unregister()

