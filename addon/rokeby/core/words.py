"""How messages name things (bpy-free): an object's kind with its article, a status as a word.

Messages the artist reads name buttons ("Add Mirror"), not Python functions, and read as
English: "'Empty' is an empty, not a mesh", not "is a EMPTY"."""

from __future__ import annotations

# Blender's object types as words (bpy.types.Object.type); anything else is lower-cased.
_KINDS = {
    "MESH": "mesh", "CURVE": "curve", "SURFACE": "surface", "META": "metaball", "FONT": "text object",
    "CURVES": "hair curves object", "POINTCLOUD": "point cloud", "VOLUME": "volume",
    "GPENCIL": "grease pencil object", "GREASEPENCIL": "grease pencil object", "ARMATURE": "armature",
    "LATTICE": "lattice", "EMPTY": "empty", "LIGHT": "light", "LIGHT_PROBE": "light probe",
    "CAMERA": "camera", "SPEAKER": "speaker",
}

# Report statuses as the sidebar shows them (not title-cased: "Ok" is not a word).
STATUS_WORDS = {"OK": "OK", "WARNING": "Warning", "ERROR": "Error", "DISABLED": "Disabled"}


def article(word: str) -> str:
    """'a' or 'an' for ``word`` by its first letter (enough for the kinds named here)."""
    return "an" if word[:1].lower() in "aeiou" else "a"


def kind(object_type: str) -> str:
    """An object type as a noun with its article: 'EMPTY' → 'an empty', 'LIGHT' → 'a light'."""
    word = _KINDS.get(str(object_type), str(object_type).lower().replace("_", " "))
    return f"{article(word)} {word}"


def status(code: str) -> str:
    """A report status as shown to the artist: 'OK', 'Warning', 'Error', 'Disabled'."""
    return STATUS_WORDS.get(code, code.capitalize())
