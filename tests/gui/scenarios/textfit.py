"""Measures what Rokeby's panels draw: each panel's draw() runs with a recording stand-in for its
layout (it forwards every call to Blender's real layout, so the window draws as usual) which notes
each text drawn (labels, buttons, property labels) with the layout it sits in. The scenario turns
that into the width Blender gives the text at the sidebar's actual width and the width the text
needs (``blf.dimensions`` in the UI font at the UI scale): text whose need exceeds its room is cut
on screen. Helpers for scenarios: ``open_all_panels(prefix)``, ``Recorder``, ``fits(...)``."""

from __future__ import annotations

import blf
import bpy

PANEL_PREFIX = "ROKEBY_PT_"


def scale():
    return bpy.context.preferences.system.ui_scale


def unit():
    return 20 * scale()


def text_width(text: str, points: float | None = None) -> float:
    """Width of ``text`` in pixels in Blender's UI font (the widget style) at the UI scale."""
    style = bpy.context.preferences.ui_styles[0]
    blf.size(0, (points or style.widget.points) * scale())
    return blf.dimensions(0, text)[0]


class _Proxy:
    """Forwards to a real UILayout; records texts and nested layouts (kind, children)."""

    _CONTAINERS = {"row", "column", "box", "split", "column_flow", "grid_flow"}

    def __init__(self, layout, kind, node):
        object.__setattr__(self, "_l", layout)
        object.__setattr__(self, "_node", node)

    def __setattr__(self, name, value):
        setattr(self._l, name, value)

    def __getattr__(self, name):
        attr = getattr(self._l, name)
        node = self._node
        if name in self._CONTAINERS:
            def container(*a, **k):
                child = {"kind": name, "items": [], "args": {k_: v for k_, v in k.items() if isinstance(v, (int, float, bool, str))}}
                node["items"].append(child)
                return _Proxy(attr(*a, **k), name, child)
            return container
        if name in ("label", "operator", "prop", "operator_menu_enum", "prop_search", "menu", "template_list", "prop_enum"):
            def item(*a, **k):
                node["items"].append(_describe(name, a, k))
                return attr(*a, **k)
            return item
        if callable(attr) and name not in ("separator",):
            def other(*a, **k):
                node["items"].append({"kind": name, "text": "", "icon": True})
                return attr(*a, **k)
            return other
        return attr


def _describe(name, a, k):
    icon = k.get("icon", "NONE") not in ("NONE", None) or k.get("icon_value", 0) != 0
    d = {"kind": name, "icon": icon}
    if name == "label":
        d["text"] = k.get("text", a[0] if a else "")
    elif name in ("operator", "operator_menu_enum"):
        idname = a[0] if a else k.get("operator")
        text = k.get("text")
        if text is None:
            try:
                mod, op = idname.split(".")
                text = getattr(getattr(bpy.ops, mod), op).get_rna_type().name
            except Exception:  # noqa: BLE001
                text = idname
        d["text"] = text
    elif name in ("prop", "prop_search", "prop_enum"):
        data, prop = (a + (None, None))[:2] if len(a) >= 2 else (k.get("data"), k.get("property"))
        text = k.get("text")
        rna = None
        try:
            rna = data.bl_rna.properties[prop]
        except Exception:  # noqa: BLE001
            pass
        if text is None:
            text = rna.name if rna is not None else str(prop)
        d["text"] = text
        d["prop_type"] = rna.type if rna is not None else "?"
        d["is_array"] = bool(getattr(rna, "is_array", False)) if rna is not None else False
        d["expand"] = bool(k.get("expand", False))
    else:
        d["text"] = ""
    return d


def record(panel_cls, log):
    """Wraps ``panel_cls.draw`` so that each draw records its layout tree into ``log[bl_idname]``."""
    orig = panel_cls.__dict__.get("draw") or panel_cls.draw

    def draw(self, context):
        root = {"kind": "panel", "items": []}

        class Self:
            def __getattr__(_s, n):
                return getattr(self, n)

        s = Self()
        s.layout = _Proxy(self.layout, "panel", root)
        orig(s, context)
        log[getattr(panel_cls, "bl_idname", panel_cls.__name__)] = root

    panel_cls.draw = draw
    return orig


def _item_need(item) -> float:
    """Width an item needs to show its text whole (pixels)."""
    u = unit()
    text = item.get("text") or ""
    pad = 0.8 * u  # text margins inside a widget, both sides
    icon = u if item.get("icon") else 0
    if item["kind"] == "label":
        return (text_width(text) + pad + icon) if text else icon
    if not text:
        return u
    return text_width(text) + pad + icon


def cut_texts(tree, width: float) -> list:
    """The texts of a recorded layout ``tree`` that do not fit at ``width`` pixels: [(text, need, room)]."""
    out = []
    u = unit()
    boxspace = 5 * scale()

    def walk(node, w, in_row=False):
        items = node["items"]
        kind = node["kind"]
        if kind == "box":
            w -= 2 * boxspace
        if kind == "row" or kind == "split":
            # A row shares its width among its items: what the others need is taken first.
            needs = [(_sub_need(it) if it["kind"] in _Proxy._CONTAINERS else _item_need(it)) for it in items]
            for it, need in zip(items, needs):
                room = w - (sum(needs) - need) if len(items) > 1 else w
                if it["kind"] in _Proxy._CONTAINERS:
                    walk(it, room)
                else:
                    check(it, room)
        else:
            for it in items:
                if it["kind"] in _Proxy._CONTAINERS:
                    walk(it, w)
                else:
                    check(it, w)

    def check(it, room):
        text = it.get("text") or ""
        if not text or it["kind"] == "template_list":
            return
        if it["kind"] in ("prop", "prop_search") and it.get("prop_type") in ("ENUM", "POINTER", "STRING") and not it.get("expand"):
            # A menu or field with its name: Blender gives the name (with a colon) a quarter of the
            # row (measured in the window: 60 of 235 px) and the field the rest.
            need = text_width(text + ":") + 0.5 * u
            room = 0.25 * room
        elif it["kind"] in ("prop",) and it.get("prop_type") in ("FLOAT", "INT") and not it.get("is_array"):
            # A slider shows "Name: value" inside: the name needs its width plus the value's (~3 units).
            need = text_width(text) + 3.5 * u
        elif it["kind"] in ("prop",) and it.get("is_array"):
            return  # vector columns: the name is a heading above the fields
        else:
            need = _item_need(it)
        if need > room + 0.5:
            out.append((text, round(need, 1), round(room, 1)))

    def _sub_need(node):
        return sum(_item_need(i) for i in node["items"] if i["kind"] not in _Proxy._CONTAINERS) or u

    walk(tree, width)
    return out
