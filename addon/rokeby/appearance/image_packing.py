"""Painted images travel with the .blend and survive undo: they are packed (OpenEXR, full float)
after strokes and on save (a save_pre handler), and reloaded from their packed data after an
undo or redo (:func:`reload_after_undo`)."""

from __future__ import annotations

from ..blender import hooks
from ..core import schema
from .parameters import PARAMS, _tex_node


# Painted image → pointer of the packed data its pixels in memory came from. Blender's global
# undo stores packed data but not the pixels in memory: an image whose packed data an undo or redo
# swapped must be reloaded from it (``reload_after_undo``).
_PACKED: dict = {}


def pack(img) -> None:
    """Packs a painted image (OpenEXR, full float) into the .blend: saving, and every painting
    operator's undo step, keep its pixels."""
    img.file_format = "OPEN_EXR"
    img.use_half_precision = False
    # Packing again an image whose packed data is current re-reads it from its file: the painted
    # image has none, and Blender 5.0 then drops the packed data. Pack only what changed.
    if img.is_dirty or img.packed_file is None:
        img.pack()
    _PACKED[img.name] = img.packed_file.as_pointer()


def pack_painted(obj=None) -> int:
    """Packs the painted images of ``obj``'s active material (default: all) that changed since
    they were last packed; returns how many."""
    import bpy

    imgs = bpy.data.images if obj is None else [t.image for p in PARAMS if (t := _tex_node(obj, p)) is not None and t.image is not None]
    done = 0
    for img in imgs:
        if img.get(schema.APPEARANCE_PAINTED_KEY) and (img.is_dirty or img.packed_file is None or _PACKED.get(img.name) != img.packed_file.as_pointer()):
            pack(img)
            done += 1
    return done


def reload_after_undo(*_args) -> int:
    """undo_post/redo_post: painted images whose packed data the step replaced show it again."""
    import bpy

    done = 0
    for img in bpy.data.images:
        pf = img.packed_file if img.get(schema.APPEARANCE_PAINTED_KEY) else None
        if pf is not None and _PACKED.get(img.name) != pf.as_pointer():
            img.reload()
            _PACKED[img.name] = img.packed_file.as_pointer()
            done += 1
    return done


def _pack_painted_images(*_args):
    """save_pre: packs the painted images that changed into the .blend."""
    pack_painted()


def _ensure_save_handler():
    hooks.add("appearance", "save_pre", _rokeby_pack_painted_images)  # once, however often asked


def _rokeby_pack_painted_images(*args):
    _pack_painted_images(*args)


try:  # persistent: survives loading another file in the same session
    from bpy.app.handlers import persistent as _persistent

    _rokeby_pack_painted_images = _persistent(_rokeby_pack_painted_images)
except ImportError:  # pragma: no cover - outside Blender
    pass
